// Sizes of the device radix sort (CudaDevice::SortPairs) that geometry builds on a GPU reserve
// scratch for: 8-bit digits over tiles of kSortTile keys, 256 digit counts per tile, then each
// digit's total.
#pragma once

#include <cstdint>

namespace weft::geometry {

// Radix sort tiles: 256 threads x 16 keys; one pass per 8-bit digit.
constexpr int64_t kSortTile = 4096;
constexpr int32_t kSortDigitBits = 8;
constexpr unsigned kSortBins = 256;

inline uint64_t RoundTo256(uint64_t v) { return (v + 255) / 256 * 256; }

// Bytes of the per-tile digit counts of a sort of n keys.
inline uint64_t SortCountsBytes(int64_t n) {
  const uint64_t tiles = static_cast<uint64_t>((n + kSortTile - 1) / kSortTile);
  return RoundTo256(kSortBins * tiles * 4 + 4);
}

// Bytes of the sort's counts and digit totals.
inline uint64_t SortHistogramBytes(int64_t n) { return SortCountsBytes(n) + RoundTo256(kSortBins * 4); }

}  // namespace weft::geometry
