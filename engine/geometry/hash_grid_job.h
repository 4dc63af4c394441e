// Device memory of one hash grid build on a GPU (engine/geometry -> Device::BuildHashGrid): the
// points, the grid's cell bounds and sorted point ids, and the scratch the sort needs. Every
// address is device memory the session or the grid object owns; every size is checked by the
// geometry object before the job is made.
#pragma once

#include <cstdint>

#include "engine/geometry/device_sort.h"

namespace weft::geometry {

struct HashGridBuildJob {
  uintptr_t points = 0;       // n vec3 of `scalar_size`-byte floats (2: float16, 4, 8), contiguous
  int32_t scalar_size = 4;
  int64_t n = 0;              // < 2^31
  float cell_width = 1.0f;    // > 0, finite
  int32_t dim[3] = {1, 1, 1};
  int64_t cells = 1;          // dim product, <= kMaxHashGridCells
  uintptr_t cell_starts = 0;  // cells int32 each
  uintptr_t cell_ends = 0;
  uintptr_t sorted_ids = 0;   // n int32
  uintptr_t groups = 0;       // grouped build: n int32 group ids (the user's array), else 0
  uintptr_t sorted_groups = 0;  // grouped build: n int32, the group of each sorted id
  uintptr_t scratch = 0;      // HashGridScratchBytes(n) bytes
};

// Scratch of a device build of n points: two key buffers, a second id buffer and the sort's
// per-tile digit counts, each 256-byte aligned.
inline uint64_t HashGridScratchBytes(int64_t n) {
  return 3 * RoundTo256(static_cast<uint64_t>(n) * 4) + SortHistogramBytes(n);
}

}  // namespace weft::geometry
