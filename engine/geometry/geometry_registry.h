// A session's geometry objects: slots addressed by opaque ids ((generation << 32) | slot + 1,
// geometry_abi.h; generations from one daemon-wide counter, so a freed object's id, another
// session's id or a made-up value never names a live slot), and the per-launch table a launch
// context points at (only this session's objects on the launch device).
// Threading: the slot vector is guarded by a mutex; objects are built and refitted on the
// session's executor (the thread that also runs its launches).
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/geometry/geometry_object.h"
#include "engine/native/geometry_abi.h"

namespace weft::geometry {

// Objects one session may hold at once.
constexpr size_t kMaxGeometryObjects = 65536;

// The table of one launch; keeps its objects alive until the launch ends.
struct LaunchTable {
  std::vector<wp::geometry_desc_t> slots;
  std::vector<std::shared_ptr<const void>> keep;   // the objects and the memory they point to
  wp::geometry_table_t table{};
};

class GeometryRegistry {
 public:
  Expected<uint64_t> Add(std::shared_ptr<GeometryObject> object);
  // The live object `id` names, or NOT_FOUND naming the id.
  Expected<std::shared_ptr<GeometryObject>> Find(uint64_t id) const;
  Status Remove(uint64_t id);
  void Clear();
  size_t size() const;
  // The table for a launch on `device`; null when the session holds no objects at all.
  std::shared_ptr<LaunchTable> TableFor(const std::string& device) const;

 private:
  struct Slot {
    uint32_t generation = 0;
    std::shared_ptr<GeometryObject> object;   // null: free
  };
  mutable std::mutex mu_;
  std::vector<Slot> slots_;
  std::vector<uint32_t> free_;
  size_t live_ = 0;
};

}  // namespace weft::geometry
