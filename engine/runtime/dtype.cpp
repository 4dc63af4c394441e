// DType: sizes, canonical names, validation and matching against kernel parameter types.
#include "engine/runtime/dtype.h"

#include <cstdio>
#include <string_view>

namespace weft {

uint32_t ScalarSize(ScalarType s) {
  switch (s) {
    case ScalarType::kBool: case ScalarType::kInt8: case ScalarType::kUInt8: return 1;
    case ScalarType::kInt16: case ScalarType::kUInt16: case ScalarType::kFloat16: return 2;
    case ScalarType::kInt32: case ScalarType::kUInt32: case ScalarType::kFloat32: return 4;
    case ScalarType::kInt64: case ScalarType::kUInt64: case ScalarType::kFloat64: return 8;
    case ScalarType::kUnspecified: return 0;
  }
  return 0;
}

const char* ScalarName(ScalarType s) {
  switch (s) {
    case ScalarType::kBool: return "bool";
    case ScalarType::kInt8: return "int8";
    case ScalarType::kInt16: return "int16";
    case ScalarType::kInt32: return "int32";
    case ScalarType::kInt64: return "int64";
    case ScalarType::kUInt8: return "uint8";
    case ScalarType::kUInt16: return "uint16";
    case ScalarType::kUInt32: return "uint32";
    case ScalarType::kUInt64: return "uint64";
    case ScalarType::kFloat16: return "float16";
    case ScalarType::kFloat32: return "float32";
    case ScalarType::kFloat64: return "float64";
    case ScalarType::kUnspecified: return "";
  }
  return "";
}

bool IsFloatScalar(ScalarType s) {
  return s == ScalarType::kFloat16 || s == ScalarType::kFloat32 || s == ScalarType::kFloat64;
}

uint64_t DType::ElementSize() const {
  if (is_struct()) return struct_size;
  uint64_t n = ScalarSize(scalar);
  for (uint32_t d : elem_shape) n *= d;
  return n;
}

uint32_t DType::ComponentSize() const { return is_struct() ? 1 : ScalarSize(scalar); }

// The structural name into `buf` (on the stack of the callers: MatchesParam runs for every array
// argument of every launch); its length, or 0 when it does not fit.
size_t DType::FormatStructuralName(char* buf, size_t size) const {
  const char* s = ScalarName(scalar);
  int n;
  if (elem_shape.size() == 1) n = std::snprintf(buf, size, "vec(%u,%s)", elem_shape[0], s);
  else if (elem_shape.size() == 2) n = std::snprintf(buf, size, "mat(%u,%u,%s)", elem_shape[0], elem_shape[1], s);
  else n = std::snprintf(buf, size, "%s", s);
  return n > 0 && static_cast<size_t>(n) < size ? static_cast<size_t>(n) : 0;
}

std::string DType::StructuralName() const {
  char buf[kStructuralNameMax];
  return std::string(buf, FormatStructuralName(buf, sizeof(buf)));
}

std::string DType::Name() const {
  if (!type_name.empty()) return type_name;
  return StructuralName();
}

Status DType::Validate() const {
  if (is_struct()) {
    if (type_name.rfind("struct(", 0) != 0)
      return InvalidArgument("dtype: a struct element (struct_size " + std::to_string(struct_size) +
                             ") needs type_name \"struct(NAME)\", got \"" + type_name + "\"");
    if (struct_size > (1u << 20)) return InvalidArgument("dtype: struct_size too large");
    return Status::Ok();
  }
  if (ScalarSize(scalar) == 0)
    return InvalidArgument("dtype: unknown or unspecified scalar type " +
                           std::to_string(static_cast<int>(scalar)));
  if (elem_shape.size() > 2)
    return InvalidArgument("dtype: element shape has " + std::to_string(elem_shape.size()) +
                           " dimensions; at most 2 (matrix)");
  for (uint32_t d : elem_shape)
    if (d == 0 || d > 64)
      return InvalidArgument("dtype: element dimension " + std::to_string(d) + " not in 1..64");
  return Status::Ok();
}

bool DType::MatchesParam(const std::string& param_dtype) const {
  if (param_dtype.empty() || param_dtype == "any") return true;
  if (!type_name.empty() && param_dtype == type_name) return true;
  if (is_struct()) return false;
  char buf[kStructuralNameMax];
  return param_dtype == std::string_view(buf, FormatStructuralName(buf, sizeof(buf)));
}

}  // namespace weft
