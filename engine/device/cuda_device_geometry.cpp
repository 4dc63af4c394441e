// The geometry table of a session's launches on a GPU (geometry_abi.h): the descriptors of the
// session's objects on this device, with the device addresses of their arrays and build
// products, copied into device memory on the session's stream. A launch reuses the last table
// while the descriptors are byte-for-byte the same (the usual case: objects built once, queried
// by many launches); otherwise a new table is uploaded and the old one retired, freed with the
// objects it kept alive once the stream is idle (Drain), since launches still queued read it.
#include <cstring>

#include "engine/device/cuda_device.h"
#include "engine/geometry/geometry_registry.h"
#include "engine/native/geometry_abi.h"
#include "engine/runtime/session.h"

namespace weft {

namespace {
constexpr size_t kTableHeader = 64;   // geometry_table_t, padded; the descriptors follow
static_assert(sizeof(wp::geometry_table_t) <= kTableHeader);
}  // namespace

Expected<uint64_t> CudaDevice::GeometryTable(Session& s, Stream& st) {
  std::shared_ptr<geometry::LaunchTable> table = s.geometry().TableFor(name_);
  if (!table) return uint64_t{0};
  const size_t descs = table->slots.size() * sizeof(wp::geometry_desc_t);
  Stream::GeometryUpload& cur = st.geometry;
  if (cur.memory && cur.image.size() == kTableHeader + descs &&
      std::memcmp(cur.image.data() + kTableHeader, table->slots.data(), descs) == 0) {
    cur.keep = std::move(table);   // the same objects (or ones with identical descriptors)
    return static_cast<uint64_t>(cur.memory);
  }
  Stream::GeometryUpload next;
  next.image.assign(kTableHeader + descs, '\0');
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemAlloc(&next.memory, next.image.size()), "cuMemAlloc (geometry table)"));
  wp::geometry_table_t header{};
  header.slots = reinterpret_cast<const wp::geometry_desc_t*>(static_cast<uintptr_t>(next.memory + kTableHeader));
  header.count = static_cast<wp::uint32>(table->slots.size());
  std::memcpy(next.image.data(), &header, sizeof(header));
  if (descs) std::memcpy(next.image.data() + kTableHeader, table->slots.data(), descs);
  Status copied = driver_->Check(
      driver_->MemcpyHtoDAsync(next.memory, next.image.data(), next.image.size(), st.stream), "cuMemcpyHtoDAsync (geometry table)");
  if (!copied.ok()) {
    driver_->MemFree(next.memory);
    return copied;
  }
  next.keep = std::move(table);
  if (cur.memory) st.geometry_retired.push_back(std::move(cur));
  cur = std::move(next);
  return static_cast<uint64_t>(cur.memory);
}

void CudaDevice::ReleaseGeometry(Stream& st, bool all) {
  for (Stream::GeometryUpload& g : st.geometry_retired)
    if (g.memory) driver_->MemFree(g.memory);
  st.geometry_retired.clear();
  if (all) {
    if (st.geometry.memory) driver_->MemFree(st.geometry.memory);
    st.geometry = Stream::GeometryUpload{};
  }
}

}  // namespace weft
