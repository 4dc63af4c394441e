// DType sizes, names, validation, and the encoding of Python-style fill values (including the
// float -> IEEE half conversion).
#include "weft/client/dtype.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

namespace weft {
inline namespace client_v1 {

std::size_t ScalarSize(ScalarType s) {
  switch (s) {
    case ScalarType::kBool:
    case ScalarType::kInt8:
    case ScalarType::kUInt8: return 1;
    case ScalarType::kInt16:
    case ScalarType::kUInt16:
    case ScalarType::kFloat16: return 2;
    case ScalarType::kInt32:
    case ScalarType::kUInt32:
    case ScalarType::kFloat32: return 4;
    case ScalarType::kInt64:
    case ScalarType::kUInt64:
    case ScalarType::kFloat64: return 8;
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

DType DType::Vector(std::uint32_t length, ScalarType s) { return DType{s, {length}, {}, 0}; }

DType DType::Matrix(std::uint32_t rows, std::uint32_t cols, ScalarType s) {
  return DType{s, {rows, cols}, {}, 0};
}

DType DType::Struct(std::string name, std::uint32_t byte_size) {
  return DType{ScalarType::kUnspecified, {}, "struct(" + name + ")", byte_size};
}

std::size_t DType::components() const {
  if (is_struct()) return 0;
  std::size_t n = 1;
  for (auto d : elem_shape) n *= d;
  return n;
}

std::size_t DType::element_size() const {
  if (is_struct()) return struct_size;
  return components() * ScalarSize(scalar);
}

std::string DType::ToString() const {
  if (!type_name.empty()) return type_name;
  const std::string s = ScalarName(scalar);
  if (elem_shape.size() == 1) return "vec(" + std::to_string(elem_shape[0]) + "," + s + ")";
  if (elem_shape.size() == 2)
    return "mat(" + std::to_string(elem_shape[0]) + "," + std::to_string(elem_shape[1]) + "," +
           s + ")";
  return s;
}

Status DType::Validate() const {
  if (is_struct()) {
    if (type_name.rfind("struct(", 0) != 0)
      return InvalidArgument("struct dtype needs a type_name \"struct(NAME)\", got \"" +
                             type_name + "\"");
    return Status::Ok();
  }
  if (ScalarSize(scalar) == 0)
    return InvalidArgument("dtype has no scalar type (" + std::to_string(int(scalar)) + ")");
  if (elem_shape.size() > 2)
    return InvalidArgument("dtype element shape has " + std::to_string(elem_shape.size()) +
                           " dimensions; at most 2 (a matrix)");
  for (auto d : elem_shape)
    if (d == 0) return InvalidArgument("dtype element shape has a zero extent");
  return Status::Ok();
}

std::uint16_t FloatToHalf(float f) {
  const std::uint32_t x = std::bit_cast<std::uint32_t>(f);
  const std::uint32_t sign = (x >> 16) & 0x8000u;
  const std::uint32_t exp = (x >> 23) & 0xffu;
  std::uint32_t mant = x & 0x7fffffu;
  if (exp == 0xffu)  // inf or NaN (keep NaN quiet and non-zero)
    return static_cast<std::uint16_t>(sign | 0x7c00u | (mant ? 0x200u | (mant >> 13) : 0u));
  const int e = static_cast<int>(exp) - 127 + 15;
  if (e >= 0x1f) return static_cast<std::uint16_t>(sign | 0x7c00u);   // overflow -> inf
  if (e <= 0) {                                                         // subnormal or zero
    if (e < -10) return static_cast<std::uint16_t>(sign);
    mant |= 0x800000u;
    const int shift = 14 - e;
    std::uint32_t h = mant >> shift;
    const std::uint32_t rem = mant & ((1u << shift) - 1u);
    const std::uint32_t half = 1u << (shift - 1);
    if (rem > half || (rem == half && (h & 1u))) ++h;
    return static_cast<std::uint16_t>(sign | h);
  }
  std::uint32_t h = (static_cast<std::uint32_t>(e) << 10) | (mant >> 13);
  const std::uint32_t rem = mant & 0x1fffu;
  if (rem > 0x1000u || (rem == 0x1000u && (h & 1u))) ++h;   // may carry into the exponent
  return static_cast<std::uint16_t>(sign | h);
}

float HalfToFloat(std::uint16_t h) {
  const std::uint32_t sign = static_cast<std::uint32_t>(h & 0x8000u) << 16;
  const std::uint32_t exp = (h >> 10) & 0x1fu;
  std::uint32_t mant = h & 0x3ffu;
  std::uint32_t x;
  if (exp == 0x1fu) {
    x = sign | 0x7f800000u | (mant << 13);
  } else if (exp != 0) {
    x = sign | ((exp - 15 + 127) << 23) | (mant << 13);
  } else if (mant == 0) {
    x = sign;
  } else {  // subnormal: normalize
    int e = -1;
    do {
      ++e;
      mant <<= 1;
    } while ((mant & 0x400u) == 0);
    x = sign | (static_cast<std::uint32_t>(127 - 15 - e) << 23) | ((mant & 0x3ffu) << 13);
  }
  return std::bit_cast<float>(x);
}

namespace {

// Writes trunc(v) as a T when it is representable (a conversion of an out-of-range double is
// undefined behaviour, so nothing is converted then); false when it is not.
template <typename T>
bool PutInt(std::byte* out, double v) {
  const double t = std::trunc(v);
  // [lowest, 2^digits): both ends exact in a double, and 2^digits is the first value past max.
  if (!(std::isfinite(t) && t >= static_cast<double>(std::numeric_limits<T>::lowest()) &&
        t < std::ldexp(1.0, std::numeric_limits<T>::digits)))
    return false;
  const T x = static_cast<T>(t);
  std::memcpy(out, &x, sizeof(T));
  return true;
}

}  // namespace

Expected<std::vector<std::byte>> EncodeFillValue(const DType& dtype, double value) {
  WEFT_CLIENT_RETURN_IF_ERROR(dtype.Validate());
  if (dtype.is_struct()) return InvalidArgument("cannot fill a struct array with a number");
  const std::size_t size = ScalarSize(dtype.scalar);
  std::vector<std::byte> one(size);
  std::byte* p = one.data();
  bool fits = true;
  switch (dtype.scalar) {
    case ScalarType::kBool: {
      const std::uint8_t b = value != 0.0 ? 1 : 0;
      std::memcpy(p, &b, 1);
      break;
    }
    case ScalarType::kInt8: fits = PutInt<std::int8_t>(p, value); break;
    case ScalarType::kInt16: fits = PutInt<std::int16_t>(p, value); break;
    case ScalarType::kInt32: fits = PutInt<std::int32_t>(p, value); break;
    case ScalarType::kInt64: fits = PutInt<std::int64_t>(p, value); break;
    case ScalarType::kUInt8: fits = PutInt<std::uint8_t>(p, value); break;
    case ScalarType::kUInt16: fits = PutInt<std::uint16_t>(p, value); break;
    case ScalarType::kUInt32: fits = PutInt<std::uint32_t>(p, value); break;
    case ScalarType::kUInt64: fits = PutInt<std::uint64_t>(p, value); break;
    case ScalarType::kFloat16: {
      const std::uint16_t h = FloatToHalf(static_cast<float>(value));
      std::memcpy(p, &h, 2);
      break;
    }
    case ScalarType::kFloat32: {
      const float f = static_cast<float>(value);
      std::memcpy(p, &f, 4);
      break;
    }
    case ScalarType::kFloat64: std::memcpy(p, &value, 8); break;
    case ScalarType::kUnspecified: break;
  }
  if (!fits)
    return InvalidArgument("fill value " + std::to_string(value) + " does not fit " +
                           ScalarName(dtype.scalar));
  std::vector<std::byte> element;
  element.reserve(dtype.element_size());
  for (std::size_t i = 0; i < dtype.components(); ++i)
    element.insert(element.end(), one.begin(), one.end());
  return element;
}

}  // namespace client_v1
}  // namespace weft
