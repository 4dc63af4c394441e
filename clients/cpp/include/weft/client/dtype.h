// Element types of weft arrays on the client side: a scalar kind, optionally a fixed vector /
// matrix shape of it (vec3 = float32 x [3]), or an opaque struct of N bytes. Mirrors the
// DType message of proto/weft/v1/types.proto and the canonical type strings of
// docs/protocol.md ("float32", "vec(3,float32)", "mat(3,3,float64)").
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "weft/client/status.h"

namespace weft {
inline namespace client_v1 {

// Numbering is the wire format's (weft.v1.ScalarType).
enum class ScalarType : int {
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

// Bytes of one scalar (bool is one byte); 0 for kUnspecified.
std::size_t ScalarSize(ScalarType s);
// "float32", "int64", "bool", ...; "" for kUnspecified.
const char* ScalarName(ScalarType s);

struct DType {
  ScalarType scalar = ScalarType::kUnspecified;
  std::vector<std::uint32_t> elem_shape;   // empty: a scalar; [3]: vec3; [3,3]: mat33
  std::string type_name;                   // canonical type string; required for structs
  std::uint32_t struct_size = 0;           // structs only: bytes per element

  static DType Scalar(ScalarType s) { return DType{s, {}, {}, 0}; }
  static DType Vector(std::uint32_t length, ScalarType s);
  static DType Matrix(std::uint32_t rows, std::uint32_t cols, ScalarType s);
  // An opaque struct element; `name` is the canonical struct name (module.Qualname).
  static DType Struct(std::string name, std::uint32_t byte_size);

  bool is_struct() const { return struct_size != 0; }
  // Scalars per element (1 for a scalar, 3 for vec3, 9 for mat33; 0 for a struct).
  std::size_t components() const;
  // Bytes per element.
  std::size_t element_size() const;
  // The canonical type string: type_name when set, else "float32", "vec(3,float32)",
  // "mat(3,3,float32)"; "struct(N)" for structs.
  std::string ToString() const;
  // Checks the dtype is well formed (a known scalar, 1-2 positive element dims, ...).
  Status Validate() const;

  friend bool operator==(const DType& a, const DType& b) {
    return a.scalar == b.scalar && a.elem_shape == b.elem_shape &&
           a.struct_size == b.struct_size &&
           (!a.is_struct() || a.type_name == b.type_name);
  }
};

// The dtype of a C++ scalar: DTypeOf<float>() is float32, DTypeOf<std::int64_t>() int64.
template <typename T> DType DTypeOf();
template <> inline DType DTypeOf<bool>() { return DType::Scalar(ScalarType::kBool); }
template <> inline DType DTypeOf<std::int8_t>() { return DType::Scalar(ScalarType::kInt8); }
template <> inline DType DTypeOf<std::int16_t>() { return DType::Scalar(ScalarType::kInt16); }
template <> inline DType DTypeOf<std::int32_t>() { return DType::Scalar(ScalarType::kInt32); }
template <> inline DType DTypeOf<std::int64_t>() { return DType::Scalar(ScalarType::kInt64); }
template <> inline DType DTypeOf<std::uint8_t>() { return DType::Scalar(ScalarType::kUInt8); }
template <> inline DType DTypeOf<std::uint16_t>() { return DType::Scalar(ScalarType::kUInt16); }
template <> inline DType DTypeOf<std::uint32_t>() { return DType::Scalar(ScalarType::kUInt32); }
template <> inline DType DTypeOf<std::uint64_t>() { return DType::Scalar(ScalarType::kUInt64); }
template <> inline DType DTypeOf<float>() { return DType::Scalar(ScalarType::kFloat32); }
template <> inline DType DTypeOf<double>() { return DType::Scalar(ScalarType::kFloat64); }

// Warp's common dtypes.
namespace dtypes {
inline DType float16() { return DType::Scalar(ScalarType::kFloat16); }
inline DType float32() { return DType::Scalar(ScalarType::kFloat32); }
inline DType float64() { return DType::Scalar(ScalarType::kFloat64); }
inline DType int32() { return DType::Scalar(ScalarType::kInt32); }
inline DType int64() { return DType::Scalar(ScalarType::kInt64); }
inline DType vec2() { return DType::Vector(2, ScalarType::kFloat32); }
inline DType vec3() { return DType::Vector(3, ScalarType::kFloat32); }
inline DType vec4() { return DType::Vector(4, ScalarType::kFloat32); }
inline DType mat22() { return DType::Matrix(2, 2, ScalarType::kFloat32); }
inline DType mat33() { return DType::Matrix(3, 3, ScalarType::kFloat32); }
inline DType mat44() { return DType::Matrix(4, 4, ScalarType::kFloat32); }
inline DType quat() { return DType{ScalarType::kFloat32, {4}, "quat(float32)", 0}; }
inline DType transform() { return DType{ScalarType::kFloat32, {7}, "transform(float32)", 0}; }
}  // namespace dtypes

// One element of `dtype` whose every scalar component is `value` converted to the scalar kind
// (float16 rounded to nearest even, integers truncated toward zero, bool = value != 0): the
// bytes a fill with a Python-style scalar sends. Structs are refused.
Expected<std::vector<std::byte>> EncodeFillValue(const DType& dtype, double value);

// IEEE binary16 conversions (round to nearest even; NaN and infinities kept).
std::uint16_t FloatToHalf(float f);
float HalfToFloat(std::uint16_t h);

}  // namespace client_v1
}  // namespace weft
