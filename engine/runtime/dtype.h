// Array element types as the runtime sees them (engine twin of weft.v1.DType): scalar kind,
// fixed element shape (vectors, matrices) or an opaque struct size, and the canonical type string.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "engine/core/status.h"

namespace weft {

// Numbering matches weft.v1.ScalarType (part of the wire format).
enum class ScalarType : int32_t {
  kUnspecified = 0,
  kBool = 1,
  kInt8 = 2,
  kInt16 = 3,
  kInt32 = 4,
  kInt64 = 5,
  kUInt8 = 6,
  kUInt16 = 7,
  kUInt32 = 8,
  kUInt64 = 9,
  kFloat16 = 10,
  kFloat32 = 11,
  kFloat64 = 12,
};

// Bytes of one scalar; 0 for kUnspecified / unknown values.
uint32_t ScalarSize(ScalarType s);
// "float32", "int8", ... ; "" for kUnspecified / unknown values.
const char* ScalarName(ScalarType s);
bool IsFloatScalar(ScalarType s);

struct DType {
  ScalarType scalar = ScalarType::kUnspecified;
  std::vector<uint32_t> elem_shape;  // [] scalar, [N] vector, [R,C] matrix
  std::string type_name;             // canonical type string; required for structs
  uint32_t struct_size = 0;          // structs only: bytes per element

  bool is_struct() const { return struct_size != 0; }
  // Bytes of one element.
  uint64_t ElementSize() const;
  // Bytes of the scalar component (alignment unit); struct elements use 1.
  uint32_t ComponentSize() const;
  // Canonical type string: type_name when set, else built from scalar + elem_shape
  // ("float32", "vec(3,float32)", "mat(3,3,float64)").
  std::string Name() const;
  // The name built from scalar + elem_shape only (ignores type_name).
  std::string StructuralName() const;
  // The same into buf without allocating: its length (0 when it does not fit).
  static constexpr size_t kStructuralNameMax = 48;   // "mat(64,64,float64)" fits
  size_t FormatStructuralName(char* buf, size_t size) const;
  // Checks the dtype describes a real element type.
  Status Validate() const;
  // True when a kernel parameter declared with element type `param_dtype` accepts this dtype
  // ("any" accepts everything).
  bool MatchesParam(const std::string& param_dtype) const;
};

}  // namespace weft
