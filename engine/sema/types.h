// The kernel language's value types: scalars, vec, mat, quat, transform, array(T, ndim),
// struct, any, void, tuple (multiple returns) and string (printf formats), and the generic
// patterns of @wp.func/@wp.kernel annotations (typing.Any, wp.Int/Float/Scalar, vectors and
// matrices of any length or scalar category).
// Owns: canonical type strings (docs/protocol.md) both ways, the C++ spelling of each type
// in generated code, and size/alignment for the kernel argument layout.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "engine/core/status.h"

namespace weft::sema {

enum class ScalarKind : uint8_t {
  kBool,
  kInt8,
  kInt16,
  kInt32,
  kInt64,
  kUInt8,
  kUInt16,
  kUInt32,
  kUInt64,
  kFloat16,
  kFloat32,
  kFloat64,
  kBFloat16,  // bfloat16: float32's upper 16 bits (wp::bfloat16)
};

enum class TypeKind : uint8_t {
  kVoid,
  kScalar,
  kVector,     // rows = length
  kMatrix,     // rows x cols
  kQuat,
  kTransform,
  kArray,      // sub[0] = element type, ndim; `indexed`: Warp's indexedarray (data + index arrays)
  kStruct,     // struct_name (canonical)
  kAny,        // typing.Any in generic funcs (`generic` narrows it to a scalar category); never reaches codegen
  kTuple,      // sub = element types (multiple return values)
  kString,     // a string literal (printf format); not a storable value
  kTile,       // a tile (Warp's tile programming): sub[0] = element type, fixed_shape = extents
               // (1 to 4, known while compiling); a kernel-local value, never an argument
  kTileStack,  // a tile stack (wp.tile_stack): sub[0] = element type, rows = capacity; a kernel-local value
  kFunction,   // a wp.Function parameter: struct_name = its target ("func:<name>" / "builtin:<name>"),
               // empty in a declaration (any function); a compile-time value, never stored
};

// A scalar pattern of a generic annotation: typing.Any ("any"), wp.Int ("any_int": the
// integer types), wp.Float ("any_float": the float types), wp.Scalar ("any_scalar": both, not
// bool). On kAny it narrows what the parameter takes to scalars of that category; on a
// vec/mat/quat/transform it stands for the element scalar.
enum class GenericScalar : uint8_t { kNone, kAny, kInt, kFloat, kScalar };

// Elements of one fixed-size array (a kernel-local value on the thread's stack).
constexpr int kMaxFixedArrayElements = 4096;

// Elements of one tile (a kernel-local value: the thread's own on every device).
constexpr int kMaxTileElements = 1 << 16;

// Thread memory (stack on the CPU) that the tiles and fixed-size arrays of a kernel and the
// funcs it calls may take, adjoints included: a kernel over it is a compile error.
constexpr int64_t kMaxLocalValueBytes = int64_t{2} << 20;
// The same for all the lanes of a cooperative CPU block together (each lane holds its tiles).
constexpr int64_t kMaxLaneBlockValueBytes = int64_t{256} << 20;

// The extent of a vector or matrix pattern that takes any length ("vec(any,float32)").
constexpr int kAnyExtent = -1;

struct Type {
  TypeKind kind = TypeKind::kVoid;
  ScalarKind scalar = ScalarKind::kFloat32;  // scalar, or the element scalar of vec/mat/quat/transform
  GenericScalar generic = GenericScalar::kNone;  // kAny's category; a composite's pattern scalar
  int rows = 0;   // vec length / mat rows (0: a zero-length vector); kAnyExtent in a pattern
  int cols = 0;   // mat cols; kAnyExtent in a pattern
  int ndim = 0;
  bool indexed = false;  // kArray: an indexed array (wp::indexedarray_t: data + int32 index arrays)
  // kArray: a fixed-size array (wp.zeros(shape=..., dtype=...) in a kernel): a value holding its
  // elements (wp::fixedarray_t), one extent per dimension (ndim = size()); empty otherwise.
  std::vector<int> fixed_shape;
  std::vector<Type> sub;
  std::string struct_name;

  static Type Void() { return {}; }
  static Type Any(GenericScalar category = GenericScalar::kAny) {
    Type t; t.kind = TypeKind::kAny; t.generic = category; return t;
  }
  static Type String() { Type t; t.kind = TypeKind::kString; return t; }
  static Type Scalar(ScalarKind s) { Type t; t.kind = TypeKind::kScalar; t.scalar = s; return t; }
  static Type Bool() { return Scalar(ScalarKind::kBool); }
  static Type Int32() { return Scalar(ScalarKind::kInt32); }
  static Type Float32() { return Scalar(ScalarKind::kFloat32); }
  static Type Vector(int n, ScalarKind s) { Type t = Scalar(s); t.kind = TypeKind::kVector; t.rows = n; return t; }
  static Type Matrix(int r, int c, ScalarKind s) {
    Type t = Scalar(s); t.kind = TypeKind::kMatrix; t.rows = r; t.cols = c; return t;
  }
  static Type Quat(ScalarKind s) { Type t = Scalar(s); t.kind = TypeKind::kQuat; return t; }
  static Type Transform(ScalarKind s) { Type t = Scalar(s); t.kind = TypeKind::kTransform; return t; }
  static Type Array(Type elem, int ndim) {
    Type t; t.kind = TypeKind::kArray; t.ndim = ndim; t.sub.push_back(std::move(elem)); return t;
  }
  static Type IndexedArray(Type elem, int ndim) { Type t = Array(std::move(elem), ndim); t.indexed = true; return t; }
  static Type FixedArray(Type elem, std::vector<int> shape) {
    Type t = Array(std::move(elem), static_cast<int>(shape.size()));
    t.fixed_shape = std::move(shape);
    return t;
  }
  static Type Tile(Type elem, std::vector<int> shape) {
    Type t;
    t.kind = TypeKind::kTile;
    t.ndim = static_cast<int>(shape.size());
    t.sub.push_back(std::move(elem));
    t.fixed_shape = std::move(shape);
    return t;
  }
  static Type TileStack(Type elem, int capacity) {
    Type t;
    t.kind = TypeKind::kTileStack;
    t.rows = capacity;
    t.sub.push_back(std::move(elem));
    return t;
  }
  static Type Struct(std::string name) { Type t; t.kind = TypeKind::kStruct; t.struct_name = std::move(name); return t; }
  static Type Function(std::string target = "") {
    Type t;
    t.kind = TypeKind::kFunction;
    t.struct_name = std::move(target);
    return t;
  }
  static Type Tuple(std::vector<Type> elems) { Type t; t.kind = TypeKind::kTuple; t.sub = std::move(elems); return t; }

  bool is_void() const { return kind == TypeKind::kVoid; }
  bool is_scalar() const { return kind == TypeKind::kScalar; }
  bool is_array() const { return kind == TypeKind::kArray; }  // plain or indexed
  bool is_indexed_array() const { return kind == TypeKind::kArray && indexed; }
  bool is_fixed_array() const { return kind == TypeKind::kArray && !fixed_shape.empty(); }
  bool is_struct() const { return kind == TypeKind::kStruct; }
  bool is_vector() const { return kind == TypeKind::kVector; }
  bool is_matrix() const { return kind == TypeKind::kMatrix; }
  bool is_tuple() const { return kind == TypeKind::kTuple; }
  bool is_any() const { return kind == TypeKind::kAny; }
  bool is_function() const { return kind == TypeKind::kFunction; }
  bool is_tile() const { return kind == TypeKind::kTile; }
  bool is_tile_stack() const { return kind == TypeKind::kTileStack; }
  // vec, mat, quat, transform: fixed-size aggregates of one scalar type
  bool is_composite() const {
    return kind == TypeKind::kVector || kind == TypeKind::kMatrix || kind == TypeKind::kQuat ||
           kind == TypeKind::kTransform;
  }
  const Type& elem() const { return sub.at(0); }  // array or tile element type
  // Number of scalar components of a composite (vec N, mat R*C, quat 4, transform 7).
  int component_count() const;

  bool operator==(const Type& o) const;
  bool operator!=(const Type& o) const { return !(*this == o); }
  bool operator<(const Type& o) const;  // for maps; compares canonical strings
};

bool IsFloat(ScalarKind s);
bool IsInt(ScalarKind s);      // signed or unsigned integer, not bool
bool IsSigned(ScalarKind s);
int ScalarSize(ScalarKind s);  // bytes
const char* ScalarName(ScalarKind s);  // canonical: "float32"
bool ParseScalarName(std::string_view name, ScalarKind* out);
// "any", "any_int", "any_float", "any_scalar" (typing.Any, wp.Int, wp.Float, wp.Scalar).
bool ParseGenericScalar(std::string_view name, GenericScalar* out);
const char* GenericScalarName(GenericScalar g);

// Does `t` or anything inside it contain `any` (a generic to instantiate)?
bool ContainsAny(const Type& t);
// Does a generic parameter type (a pattern: `any`, a scalar category, a vector of any length,
// an array of any element, ...) accept a value of the concrete type `a`? A concrete `p`
// accepts only itself.
bool GenericAccepts(const Type& p, const Type& a);
// Float scalars and aggregates of floats, and structs (through their float fields): values
// whose adjoints carry gradient.
bool IsDifferentiable(const Type& t);

// Canonical string (docs/protocol.md), e.g. "array(vec(3,float32),1)".
std::string TypeString(const Type& t);
// The name Warp's messages give a type (its type_repr): float32, vec3f, vec3ub, mat22d, quatf,
// transformd, vector(length=5, dtype=float32), matrix(shape=(2, 5), dtype=float64); other
// types: TypeString.
std::string WarpTypeRepr(const Type& t);
// Parses a canonical type string. Accepts the aliases spatial_vector(S) / spatial_matrix(S)
// and Warp's short names (vec3, vec3d, mat33, quatf, transformd, float, int, ...).
Expected<Type> ParseType(std::string_view text);

// A struct's definition with its types resolved.
struct StructField {
  std::string name;
  Type type;
};
struct StructInfo {
  std::string name;      // canonical, "mymod.Particle"
  std::string cpp_name;  // identifier in generated code
  std::vector<StructField> fields;
  const StructField* Find(std::string_view field, int* index = nullptr) const;
};
using StructTable = std::map<std::string, StructInfo>;

// Identifier of a struct in generated code (declared in namespace wp), mangled by
// codegen::MangleIdentifier: "mymod.Particle" -> "weft_struct_mymodZ2EParticle".
std::string StructCppName(std::string_view canonical);

// C++ spelling in generated code: wp::float32, wp::vec_t<3,wp::float32>, wp::array_t<...>,
// wp::weft_struct_<name>.
std::string CppType(const Type& t);

struct TypeLayout {
  uint32_t size = 0;
  uint32_t align = 1;
};
// Size and alignment as the generated C++ lays the value out (arrays = wp::array_abi_t:
// 88 bytes, 8-aligned; indexed arrays: the data array and 4 index arrays, 440 bytes; structs: fields in declaration order at their natural alignment).
Expected<TypeLayout> LayoutOf(const Type& t, const StructTable& structs);

}  // namespace weft::sema
