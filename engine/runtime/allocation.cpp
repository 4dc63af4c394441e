// Allocation helpers: element counts, contiguous strides, shape formatting.
#include "engine/runtime/allocation.h"

namespace weft {

uint64_t Allocation::element_count() const {
  uint64_t n = 1;
  for (int64_t d : shape) n *= static_cast<uint64_t>(d);
  return n;
}

std::vector<int64_t> ContiguousStrides(const std::vector<int64_t>& shape, uint64_t elem_size) {
  std::vector<int64_t> s(shape.size());
  int64_t step = static_cast<int64_t>(elem_size);
  for (size_t i = shape.size(); i-- > 0;) {
    s[i] = step;
    step *= shape[i] > 0 ? shape[i] : 1;
  }
  return s;
}

bool HasContiguousStrides(const std::vector<int64_t>& shape, const std::vector<int64_t>& strides,
                          uint64_t elem_size) {
  if (strides.size() != shape.size()) return false;
  int64_t step = static_cast<int64_t>(elem_size);
  for (size_t i = shape.size(); i-- > 0;) {
    if (strides[i] != step) return false;
    if (__builtin_mul_overflow(step, shape[i] > 0 ? shape[i] : 1, &step)) return false;
  }
  return true;
}

std::string ShapeString(const std::vector<int64_t>& shape) {
  std::string s = "(";
  for (size_t i = 0; i < shape.size(); ++i) {
    if (i) s += ", ";
    s += std::to_string(shape[i]);
  }
  if (shape.size() == 1) s += ",";
  return s + ")";
}

}  // namespace weft
