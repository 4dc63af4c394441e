// Sizes of the device radix sort (CudaDevice::SortPairs) that geometry builds on a GPU reserve
// scratch for: tiles of kSortTile keys, 16 digit counts per tile.
#pragma once

#include <cstdint>

namespace weft::geometry {

// Radix sort tiles: 256 threads x 8 keys.
constexpr int64_t kSortTile = 2048;

inline uint64_t RoundTo256(uint64_t v) { return (v + 255) / 256 * 256; }

// Bytes of the per-tile digit counts of a sort of n keys.
inline uint64_t SortHistogramBytes(int64_t n) {
  const uint64_t tiles = static_cast<uint64_t>((n + kSortTile - 1) / kSortTile);
  return RoundTo256(16 * tiles * 4 + 4);
}

}  // namespace weft::geometry
