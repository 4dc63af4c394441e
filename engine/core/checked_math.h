// Overflow-checked integer arithmetic for sizes that come from clients: element counts, byte
// sizes, offsets and stride spans. Every function returns false (and leaves *out unspecified)
// instead of wrapping, so a hostile shape can never size a buffer small and then walk far.
#pragma once

#include <cstdint>
#include <vector>

namespace weft {

// The largest element count or byte size the daemon accepts anywhere (2^62): products and sums
// below it are exact in int64 and uint64 and leave headroom for adding one more span.
constexpr uint64_t kMaxCheckedSize = 1ull << 62;

inline bool CheckedAdd(uint64_t a, uint64_t b, uint64_t* out) { return !__builtin_add_overflow(a, b, out); }
inline bool CheckedMul(uint64_t a, uint64_t b, uint64_t* out) { return !__builtin_mul_overflow(a, b, out); }
inline bool CheckedAdd(int64_t a, int64_t b, int64_t* out) { return !__builtin_add_overflow(a, b, out); }
inline bool CheckedMul(int64_t a, int64_t b, int64_t* out) { return !__builtin_mul_overflow(a, b, out); }

// Product of the extents (each must be >= 0) times `unit`, at most kMaxCheckedSize.
// An empty shape gives `unit`; a shape with a zero extent gives 0, but its other extents must
// still multiply (as max(d, 1)) to at most kMaxCheckedSize so that its C-contiguous strides
// fit in int64. False on a negative extent or when the product is too large.
inline bool CheckedShapeProduct(const std::vector<int64_t>& shape, uint64_t unit, uint64_t* out) {
  if (unit > kMaxCheckedSize) return false;
  uint64_t n = unit == 0 ? 1 : unit;
  bool zero = unit == 0;
  for (int64_t d : shape) {
    if (d < 0) return false;
    if (d == 0) zero = true;
    if (!CheckedMul(n, static_cast<uint64_t>(d == 0 ? 1 : d), &n) || n > kMaxCheckedSize) return false;
  }
  *out = zero ? 0 : n;
  return true;
}

}  // namespace weft
