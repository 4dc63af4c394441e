// Geometry ids and per-launch tables; see geometry_registry.h.
#include "engine/geometry/geometry_registry.h"

#include <atomic>

namespace weft::geometry {

namespace {

uint32_t NextGeneration() {
  static std::atomic<uint32_t> next{1};
  uint32_t g = next.fetch_add(1, std::memory_order_relaxed);
  if (g == 0) g = next.fetch_add(1, std::memory_order_relaxed);   // 0 never tags a live slot
  return g;
}

}  // namespace

Expected<uint64_t> GeometryRegistry::Add(std::shared_ptr<GeometryObject> object) {
  std::lock_guard<std::mutex> lock(mu_);
  if (live_ >= kMaxGeometryObjects)
    return ResourceExhausted("the session already holds " + std::to_string(live_) +
                             " geometry objects (the limit); free some first");
  uint32_t slot;
  if (!free_.empty()) {
    slot = free_.back();
    free_.pop_back();
  } else {
    slot = static_cast<uint32_t>(slots_.size());
    slots_.emplace_back();
  }
  Slot& s = slots_[slot];
  s.generation = NextGeneration();
  s.object = std::move(object);
  ++live_;
  return wp::geometry_make_id(slot, s.generation);
}

Expected<std::shared_ptr<GeometryObject>> GeometryRegistry::Find(uint64_t id) const {
  std::lock_guard<std::mutex> lock(mu_);
  uint64_t slot = id & 0xffffffffull;
  uint32_t gen = static_cast<uint32_t>(id >> 32);
  if (slot == 0 || slot > slots_.size() || !slots_[slot - 1].object || slots_[slot - 1].generation != gen)
    return NotFound("geometry id " + std::to_string(id) +
                    " names no live object of this session (never created, already freed, or another session's)");
  return slots_[slot - 1].object;
}

Status GeometryRegistry::Remove(uint64_t id) {
  std::shared_ptr<GeometryObject> dropped;   // destroyed outside the lock
  {
    std::lock_guard<std::mutex> lock(mu_);
    uint64_t slot = id & 0xffffffffull;
    uint32_t gen = static_cast<uint32_t>(id >> 32);
    if (slot == 0 || slot > slots_.size() || !slots_[slot - 1].object || slots_[slot - 1].generation != gen)
      return NotFound("geometry id " + std::to_string(id) + " names no live object of this session");
    dropped = std::move(slots_[slot - 1].object);
    slots_[slot - 1].generation = 0;
    free_.push_back(static_cast<uint32_t>(slot - 1));
    --live_;
  }
  return Status::Ok();
}

void GeometryRegistry::Clear() {
  std::vector<Slot> dropped;
  {
    std::lock_guard<std::mutex> lock(mu_);
    dropped.swap(slots_);
    free_.clear();
    live_ = 0;
  }
}

size_t GeometryRegistry::size() const {
  std::lock_guard<std::mutex> lock(mu_);
  return live_;
}

std::shared_ptr<LaunchTable> GeometryRegistry::TableFor(const std::string& device) const {
  std::lock_guard<std::mutex> lock(mu_);
  if (live_ == 0) return nullptr;
  auto t = std::make_shared<LaunchTable>();
  t->slots.resize(slots_.size());
  for (size_t i = 0; i < slots_.size(); ++i) {
    wp::geometry_desc_t& d = t->slots[i];
    const Slot& s = slots_[i];
    if (!s.object || s.object->device() != device) {
      d = wp::geometry_desc_t{};
      continue;
    }
    s.object->Describe(&d, &t->keep);
    d.generation = s.generation;
    t->keep.push_back(s.object);
  }
  t->table.slots = t->slots.data();
  t->table.count = static_cast<uint32_t>(t->slots.size());
  return t;
}

}  // namespace weft::geometry
