// Type strings (parse/print), C++ spellings and argument-block layout of kernel types.
#include "engine/sema/types.h"

#include <cctype>

#include "engine/codegen/emit_text.h"

namespace weft::sema {
namespace {

struct ScalarRow {
  ScalarKind kind;
  const char* name;
  int size;
};
constexpr ScalarRow kScalars[] = {
    {ScalarKind::kBool, "bool", 1},       {ScalarKind::kInt8, "int8", 1},
    {ScalarKind::kInt16, "int16", 2},     {ScalarKind::kInt32, "int32", 4},
    {ScalarKind::kInt64, "int64", 8},     {ScalarKind::kUInt8, "uint8", 1},
    {ScalarKind::kUInt16, "uint16", 2},   {ScalarKind::kUInt32, "uint32", 4},
    {ScalarKind::kUInt64, "uint64", 8},   {ScalarKind::kFloat16, "float16", 2},
    {ScalarKind::kFloat32, "float32", 4}, {ScalarKind::kFloat64, "float64", 8},
    {ScalarKind::kBFloat16, "bfloat16", 2},
};

// Recursive-descent reader over a type string.
class TypeReader {
 public:
  explicit TypeReader(std::string_view s) : s_(s) {}

  Expected<Type> ReadAll() {
    auto t = Read();
    if (!t.ok()) return t;
    if (pos_ != s_.size()) return Error("unexpected text");
    return t;
  }

 private:
  Status Error(const std::string& what) const {
    return InvalidArgument("bad type string '" + std::string(s_) + "': " + what + " at offset " +
                           std::to_string(pos_));
  }
  void SkipSpace() {
    while (pos_ < s_.size() && s_[pos_] == ' ') ++pos_;
  }
  std::string Ident() {
    SkipSpace();
    size_t b = pos_;
    while (pos_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[pos_])) || s_[pos_] == '_' ||
                                s_[pos_] == '.'))
      ++pos_;
    return std::string(s_.substr(b, pos_ - b));
  }
  bool Eat(char c) {
    SkipSpace();
    if (pos_ < s_.size() && s_[pos_] == c) {
      ++pos_;
      return true;
    }
    return false;
  }
  Expected<int> Int() {
    SkipSpace();
    size_t b = pos_;
    while (pos_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[pos_]))) ++pos_;
    if (b == pos_ || pos_ - b > 6) return Error("expected a small integer");
    return std::stoi(std::string(s_.substr(b, pos_ - b)));
  }
  // ",n1,n2,...)" after an element type: 1 to 4 extents, each at least 1, at most `max`
  // elements in all (`what`: "tiles", "fixed arrays" for the messages).
  Expected<std::vector<int>> Extents(int64_t max, const std::string& what) {
    std::vector<int> shape;
    int64_t total = 1;
    while (Eat(',')) {
      WEFT_ASSIGN_OR_RETURN(int n, Int());
      total *= n;
      if (n < 1 || total > max) return Error(what + " hold 1 to " + std::to_string(max) + " elements");
      shape.push_back(n);
    }
    if (!Eat(')')) return Error("expected ')'");
    if (shape.empty() || shape.size() > 4) return Error(what + " have 1 to 4 dimensions");
    return shape;
  }
  Expected<ScalarKind> Scalar() {
    std::string id = Ident();
    ScalarKind k;
    if (!ParseScalarName(id, &k)) return Error("expected a scalar type, got '" + id + "'");
    return k;
  }
  // A composite's element scalar, or a scalar pattern ("any", "any_float", ...) into *generic.
  Expected<ScalarKind> ScalarOrPattern(GenericScalar* generic) {
    const size_t at = pos_;
    std::string id = Ident();
    if (ParseGenericScalar(id, generic)) return ScalarKind::kFloat32;
    pos_ = at;
    return Scalar();
  }
  // An extent (0 is a zero-length vector or matrix, as a slice may select), or "any"
  // (kAnyExtent) in a pattern.
  Expected<int> ExtentOrAny() {
    const size_t at = pos_;
    if (Ident() == "any") return kAnyExtent;
    pos_ = at;
    WEFT_ASSIGN_OR_RETURN(int n, Int());
    if (n < 0) return Error("extent must not be negative");
    return n;
  }

  Expected<Type> Read() {
    std::string id = Ident();
    if (id.empty()) return Error("expected a type");
    ScalarKind sk;
    if (ParseScalarName(id, &sk)) return Type::Scalar(sk);
    GenericScalar category;
    if (ParseGenericScalar(id, &category)) return Type::Any(category);
    if (id == "void" || id == "None") return Type::Void();
    if (id == "function") return Type::Function();
    if (id == "vec") {
      if (!Eat('(')) return Error("expected '('");
      WEFT_ASSIGN_OR_RETURN(int n, ExtentOrAny());
      if (!Eat(',')) return Error("expected ','");
      GenericScalar g = GenericScalar::kNone;
      WEFT_ASSIGN_OR_RETURN(ScalarKind s, ScalarOrPattern(&g));
      if (!Eat(')')) return Error("expected ')'");
      if (n < kAnyExtent || n > 1024) return Error("vector length out of range");
      Type t = Type::Vector(n, s);
      t.generic = g;
      return t;
    }
    if (id == "mat") {
      if (!Eat('(')) return Error("expected '('");
      WEFT_ASSIGN_OR_RETURN(int r, ExtentOrAny());
      if (!Eat(',')) return Error("expected ','");
      WEFT_ASSIGN_OR_RETURN(int c, ExtentOrAny());
      if (!Eat(',')) return Error("expected ','");
      GenericScalar g = GenericScalar::kNone;
      WEFT_ASSIGN_OR_RETURN(ScalarKind s, ScalarOrPattern(&g));
      if (!Eat(')')) return Error("expected ')'");
      if (r < kAnyExtent || c < kAnyExtent || r > 64 || c > 64) return Error("matrix shape out of range");
      Type t = Type::Matrix(r, c, s);
      t.generic = g;
      return t;
    }
    if (id == "quat" || id == "transform" || id == "spatial_vector" || id == "spatial_matrix") {
      ScalarKind s = ScalarKind::kFloat32;
      GenericScalar g = GenericScalar::kNone;
      if (Eat('(')) {
        WEFT_ASSIGN_OR_RETURN(s, ScalarOrPattern(&g));
        if (!Eat(')')) return Error("expected ')'");
      }
      Type t = id == "quat"             ? Type::Quat(s)
               : id == "transform"      ? Type::Transform(s)
               : id == "spatial_vector" ? Type::Vector(6, s)
                                        : Type::Matrix(6, 6, s);
      t.generic = g;
      return t;
    }
    if (id == "array" || id == "indexedarray") {
      if (!Eat('(')) return Error("expected '('");
      WEFT_ASSIGN_OR_RETURN(Type elem, Read());
      int ndim = 1;
      if (Eat(',')) {
        WEFT_ASSIGN_OR_RETURN(ndim, Int());
      }
      if (!Eat(')')) return Error("expected ')'");
      if (ndim < 1 || ndim > 4) return Error("arrays have 1 to 4 dimensions");
      if (elem.is_array() || elem.is_void() || elem.is_tuple()) return Error("bad array element type");
      if (id == "indexedarray") return Type::IndexedArray(std::move(elem), ndim);
      return Type::Array(std::move(elem), ndim);
    }
    if (id == "fixedarray") {
      if (!Eat('(')) return Error("expected '('");
      WEFT_ASSIGN_OR_RETURN(Type elem, Read());
      WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, Extents(kMaxFixedArrayElements, "fixed arrays"));
      if (elem.is_array() || elem.is_void() || elem.is_tuple() || elem.is_any()) return Error("bad array element type");
      return Type::FixedArray(std::move(elem), std::move(shape));
    }
    if (id == "tile") {
      if (!Eat('(')) return Error("expected '('");
      WEFT_ASSIGN_OR_RETURN(Type elem, Read());
      WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, Extents(kMaxTileElements, "tiles"));
      if (!elem.is_scalar() && !elem.is_composite() && !elem.is_struct()) return Error("bad tile element type");
      return Type::Tile(std::move(elem), std::move(shape));
    }
    if (id == "tile_stack") {
      if (!Eat('(')) return Error("expected '('");
      WEFT_ASSIGN_OR_RETURN(Type elem, Read());
      if (!Eat(',')) return Error("expected ','");
      WEFT_ASSIGN_OR_RETURN(int n, Int());
      if (!Eat(')')) return Error("expected ')'");
      if (n < 1 || n > kMaxTileElements) return Error("tile stack capacity out of range");
      if (!elem.is_scalar() && !elem.is_composite() && !elem.is_struct()) return Error("bad tile stack element type");
      return Type::TileStack(std::move(elem), n);
    }
    if (id == "struct") {
      if (!Eat('(')) return Error("expected '('");
      std::string name = Ident();
      if (name.empty()) return Error("expected a struct name");
      if (!Eat(')')) return Error("expected ')'");
      return Type::Struct(name);
    }
    if (id == "tuple") {
      if (!Eat('(')) return Error("expected '('");
      std::vector<Type> elems;
      if (!Eat(')')) {
        do {
          WEFT_ASSIGN_OR_RETURN(Type e, Read());
          elems.push_back(std::move(e));
        } while (Eat(','));
        if (!Eat(')')) return Error("expected ')'");
      }
      return Type::Tuple(std::move(elems));
    }
    Type alias;
    if (WarpAlias(id, &alias)) return alias;
    return Error("unknown type '" + id + "'");
  }

  // Warp's short names: vec3, vec3d, vec2i, mat33, quatf, transformd, spatial_vectorf, ...
  static bool WarpAlias(const std::string& id, Type* out) {
    auto suffix = [](std::string_view s, ScalarKind* k) {
      if (s.empty() || s == "f") *k = ScalarKind::kFloat32;
      else if (s == "d") *k = ScalarKind::kFloat64;
      else if (s == "h") *k = ScalarKind::kFloat16;
      else if (s == "i") *k = ScalarKind::kInt32;
      else if (s == "ui") *k = ScalarKind::kUInt32;
      else if (s == "b") *k = ScalarKind::kInt8;
      else if (s == "ub") *k = ScalarKind::kUInt8;
      else if (s == "s") *k = ScalarKind::kInt16;
      else if (s == "us") *k = ScalarKind::kUInt16;
      else if (s == "l") *k = ScalarKind::kInt64;
      else if (s == "ul") *k = ScalarKind::kUInt64;
      else return false;
      return true;
    };
    std::string_view v(id);
    ScalarKind k;
    if (v == "float") { *out = Type::Float32(); return true; }
    if (v == "int") { *out = Type::Int32(); return true; }
    if (v == "half") { *out = Type::Scalar(ScalarKind::kFloat16); return true; }
    if (v.size() >= 4 && v.substr(0, 3) == "vec" && std::isdigit(static_cast<unsigned char>(v[3]))) {
      if (suffix(v.substr(4), &k)) { *out = Type::Vector(v[3] - '0', k); return true; }
    }
    if (v.size() >= 5 && v.substr(0, 3) == "mat" && std::isdigit(static_cast<unsigned char>(v[3])) &&
        std::isdigit(static_cast<unsigned char>(v[4]))) {
      if (suffix(v.substr(5), &k)) { *out = Type::Matrix(v[3] - '0', v[4] - '0', k); return true; }
    }
    if (v.substr(0, 4) == "quat" && suffix(v.substr(4), &k) && IsFloat(k)) { *out = Type::Quat(k); return true; }
    if (v.substr(0, 9) == "transform" && suffix(v.substr(9), &k) && IsFloat(k)) {
      *out = Type::Transform(k);
      return true;
    }
    if (v.substr(0, 14) == "spatial_vector" && suffix(v.substr(14), &k) && IsFloat(k)) {
      *out = Type::Vector(6, k);
      return true;
    }
    if (v.substr(0, 14) == "spatial_matrix" && suffix(v.substr(14), &k) && IsFloat(k)) {
      *out = Type::Matrix(6, 6, k);
      return true;
    }
    return false;
  }

  std::string_view s_;
  size_t pos_ = 0;
};

uint32_t RoundUp(uint32_t v, uint32_t a) { return (v + a - 1) / a * a; }

}  // namespace

int Type::component_count() const {
  switch (kind) {
    case TypeKind::kScalar: return 1;
    case TypeKind::kVector: return rows;
    case TypeKind::kMatrix: return rows * cols;
    case TypeKind::kQuat: return 4;
    case TypeKind::kTransform: return 7;
    default: return 0;
  }
}

bool Type::operator==(const Type& o) const {
  if (kind != o.kind) return false;
  switch (kind) {
    case TypeKind::kVoid:
    case TypeKind::kString: return true;
    case TypeKind::kAny: return generic == o.generic;
    case TypeKind::kFunction: return struct_name == o.struct_name;
    case TypeKind::kScalar: return scalar == o.scalar;
    case TypeKind::kQuat:
    case TypeKind::kTransform: return generic == o.generic && (generic != GenericScalar::kNone || scalar == o.scalar);
    case TypeKind::kVector:
      return generic == o.generic && (generic != GenericScalar::kNone || scalar == o.scalar) && rows == o.rows;
    case TypeKind::kMatrix:
      return generic == o.generic && (generic != GenericScalar::kNone || scalar == o.scalar) && rows == o.rows &&
             cols == o.cols;
    case TypeKind::kArray: return ndim == o.ndim && indexed == o.indexed && fixed_shape == o.fixed_shape && sub == o.sub;
    case TypeKind::kStruct: return struct_name == o.struct_name;
    case TypeKind::kTuple: return sub == o.sub;
    case TypeKind::kTile: return fixed_shape == o.fixed_shape && sub == o.sub;
    case TypeKind::kTileStack: return rows == o.rows && sub == o.sub;
  }
  return false;
}

bool Type::operator<(const Type& o) const { return TypeString(*this) < TypeString(o); }

bool IsFloat(ScalarKind s) {
  return s == ScalarKind::kFloat16 || s == ScalarKind::kFloat32 || s == ScalarKind::kFloat64 ||
         s == ScalarKind::kBFloat16;
}
bool IsInt(ScalarKind s) { return !IsFloat(s) && s != ScalarKind::kBool; }
bool IsSigned(ScalarKind s) {
  return s == ScalarKind::kInt8 || s == ScalarKind::kInt16 || s == ScalarKind::kInt32 ||
         s == ScalarKind::kInt64 || IsFloat(s);
}
int ScalarSize(ScalarKind s) {
  for (const auto& r : kScalars)
    if (r.kind == s) return r.size;
  return 0;
}
const char* ScalarName(ScalarKind s) {
  for (const auto& r : kScalars)
    if (r.kind == s) return r.name;
  return "?";
}
bool ParseScalarName(std::string_view name, ScalarKind* out) {
  for (const auto& r : kScalars) {
    if (name == r.name) {
      *out = r.kind;
      return true;
    }
  }
  return false;
}

bool ParseGenericScalar(std::string_view name, GenericScalar* out) {
  if (name == "any") *out = GenericScalar::kAny;
  else if (name == "any_int") *out = GenericScalar::kInt;
  else if (name == "any_float") *out = GenericScalar::kFloat;
  else if (name == "any_scalar") *out = GenericScalar::kScalar;
  else return false;
  return true;
}

const char* GenericScalarName(GenericScalar g) {
  switch (g) {
    case GenericScalar::kInt: return "any_int";
    case GenericScalar::kFloat: return "any_float";
    case GenericScalar::kScalar: return "any_scalar";
    default: return "any";
  }
}

bool ContainsAny(const Type& t) {
  if (t.is_any() || (t.is_function() && t.struct_name.empty())) return true;
  if (t.is_composite() && t.generic != GenericScalar::kNone) return true;
  if ((t.is_vector() || t.is_matrix()) && (t.rows == kAnyExtent || (t.is_matrix() && t.cols == kAnyExtent)))
    return true;
  for (const auto& s : t.sub)
    if (ContainsAny(s)) return true;
  return false;
}

namespace {
bool ScalarInCategory(GenericScalar g, ScalarKind s) {
  switch (g) {
    case GenericScalar::kNone: return false;
    case GenericScalar::kAny: return true;
    case GenericScalar::kInt: return IsInt(s);
    case GenericScalar::kFloat: return IsFloat(s);
    case GenericScalar::kScalar: return s != ScalarKind::kBool;
  }
  return false;
}
}  // namespace

bool GenericAccepts(const Type& p, const Type& a) {
  if (p.is_any()) {
    if (a.is_void() || a.is_tuple() || a.kind == TypeKind::kString) return false;
    return p.generic == GenericScalar::kAny || (a.is_scalar() && ScalarInCategory(p.generic, a.scalar));
  }
  if (p.kind != a.kind) return false;
  if (p.is_array())
    return p.ndim == a.ndim && GenericAccepts(p.elem(), a.elem());
  if (p.is_tile()) return p.fixed_shape == a.fixed_shape && GenericAccepts(p.elem(), a.elem());
  if (p.is_composite()) {
    if (p.generic == GenericScalar::kNone ? p.scalar != a.scalar : !ScalarInCategory(p.generic, a.scalar)) return false;
    if ((p.is_vector() || p.is_matrix()) && p.rows != kAnyExtent && p.rows != a.rows) return false;
    if (p.is_matrix() && p.cols != kAnyExtent && p.cols != a.cols) return false;
    return true;
  }
  if (p.is_tuple()) {
    if (p.sub.size() != a.sub.size()) return false;
    for (size_t i = 0; i < p.sub.size(); ++i)
      if (!GenericAccepts(p.sub[i], a.sub[i])) return false;
    return true;
  }
  return p == a;
}

bool IsDifferentiable(const Type& t) {
  switch (t.kind) {
    case TypeKind::kScalar:
    case TypeKind::kVector:
    case TypeKind::kMatrix:
    case TypeKind::kQuat:
    case TypeKind::kTransform: return IsFloat(t.scalar);
    case TypeKind::kStruct: return true;
    case TypeKind::kTile: return IsDifferentiable(t.elem());
    case TypeKind::kTuple:
      for (const auto& s : t.sub)
        if (IsDifferentiable(s)) return true;
      return false;
    default: return false;
  }
}

std::string WarpTypeRepr(const Type& t) {
  if (t.generic != GenericScalar::kNone) return TypeString(t);
  const char* suffix = nullptr;
  switch (t.scalar) {
    case ScalarKind::kFloat16: suffix = "h"; break;
    case ScalarKind::kFloat32: suffix = "f"; break;
    case ScalarKind::kFloat64: suffix = "d"; break;
    case ScalarKind::kInt8: suffix = "b"; break;
    case ScalarKind::kUInt8: suffix = "ub"; break;
    case ScalarKind::kInt16: suffix = "s"; break;
    case ScalarKind::kUInt16: suffix = "us"; break;
    case ScalarKind::kInt32: suffix = "i"; break;
    case ScalarKind::kUInt32: suffix = "ui"; break;
    case ScalarKind::kInt64: suffix = "l"; break;
    case ScalarKind::kUInt64: suffix = "ul"; break;
    default: break;
  }
  const std::string scalar = ScalarName(t.scalar);
  switch (t.kind) {
    case TypeKind::kScalar: return scalar;
    case TypeKind::kVector:
      if (suffix && t.rows >= 1 && t.rows <= 4) return "vec" + std::to_string(t.rows) + suffix;
      return "vector(length=" + std::to_string(t.rows) + ", dtype=" + scalar + ")";
    case TypeKind::kMatrix:
      if (suffix && t.rows >= 1 && t.rows <= 4 && t.cols >= 1 && t.cols <= 4)
        return "mat" + std::to_string(t.rows) + std::to_string(t.cols) + suffix;
      return "matrix(shape=(" + std::to_string(t.rows) + ", " + std::to_string(t.cols) + "), dtype=" + scalar + ")";
    case TypeKind::kQuat: return suffix && IsFloat(t.scalar) ? std::string("quat") + suffix : "quat(dtype=" + scalar + ")";
    case TypeKind::kTransform:
      return suffix && IsFloat(t.scalar) ? std::string("transform") + suffix : "transform(dtype=" + scalar + ")";
    default: return TypeString(t);
  }
}

std::string TypeString(const Type& t) {
  // A composite's element scalar or its pattern; an extent, or "any" in a pattern.
  auto elem = [&]() -> std::string {
    return t.generic == GenericScalar::kNone ? ScalarName(t.scalar) : GenericScalarName(t.generic);
  };
  auto extent = [](int n) { return n == kAnyExtent ? std::string("any") : std::to_string(n); };
  switch (t.kind) {
    case TypeKind::kVoid: return "void";
    case TypeKind::kAny: return GenericScalarName(t.generic);
    case TypeKind::kString: return "str";
    case TypeKind::kFunction: return t.struct_name.empty() ? "function" : "function(" + t.struct_name + ")";
    case TypeKind::kScalar: return ScalarName(t.scalar);
    case TypeKind::kVector: return "vec(" + extent(t.rows) + "," + elem() + ")";
    case TypeKind::kMatrix: return "mat(" + extent(t.rows) + "," + extent(t.cols) + "," + elem() + ")";
    case TypeKind::kQuat: return "quat(" + elem() + ")";
    case TypeKind::kTransform: return "transform(" + elem() + ")";
    case TypeKind::kArray: {
      if (t.is_fixed_array()) {
        std::string r = "fixedarray(" + TypeString(t.elem());
        for (int n : t.fixed_shape) r += "," + std::to_string(n);
        return r + ")";
      }
      return (t.indexed ? "indexedarray(" : "array(") + TypeString(t.elem()) + "," + std::to_string(t.ndim) + ")";
    }
    case TypeKind::kStruct: return "struct(" + t.struct_name + ")";
    case TypeKind::kTile: {
      std::string r = "tile(" + TypeString(t.elem());
      for (int n : t.fixed_shape) r += "," + std::to_string(n);
      return r + ")";
    }
    case TypeKind::kTileStack: return "tile_stack(" + TypeString(t.elem()) + "," + std::to_string(t.rows) + ")";
    case TypeKind::kTuple: {
      std::string s = "tuple(";
      for (size_t i = 0; i < t.sub.size(); ++i) s += (i ? "," : "") + TypeString(t.sub[i]);
      return s + ")";
    }
  }
  return "?";
}

Expected<Type> ParseType(std::string_view text) { return TypeReader(text).ReadAll(); }

const StructField* StructInfo::Find(std::string_view field, int* index) const {
  for (size_t i = 0; i < fields.size(); ++i) {
    if (fields[i].name == field) {
      if (index) *index = static_cast<int>(i);
      return &fields[i];
    }
  }
  return nullptr;
}

std::string StructCppName(std::string_view canonical) {
  return "weft_struct_" + codegen::MangleIdentifier(canonical);
}

std::string CppType(const Type& t) {
  // The element scalar of a composite: bool is the C++ keyword, not a wp:: typedef.
  auto elem = [&]() { return CppType(Type::Scalar(t.scalar)); };
  switch (t.kind) {
    case TypeKind::kVoid: return "void";
    case TypeKind::kAny: return "/*any*/void";
    case TypeKind::kString: return "const char*";
    case TypeKind::kFunction: return "/*function*/void";
    case TypeKind::kScalar:
      return t.scalar == ScalarKind::kBool ? "bool" : std::string("wp::") + ScalarName(t.scalar);
    case TypeKind::kVector: return "wp::vec_t<" + std::to_string(t.rows) + "," + elem() + ">";
    case TypeKind::kMatrix:
      return "wp::mat_t<" + std::to_string(t.rows) + "," + std::to_string(t.cols) + "," + elem() + ">";
    case TypeKind::kQuat: return "wp::quat_t<" + elem() + ">";
    case TypeKind::kTransform: return "wp::transform_t<" + elem() + ">";
    case TypeKind::kArray: {
      if (t.is_fixed_array()) {
        std::string r = "wp::fixedarray_t<" + CppType(t.elem());
        for (int d = 0; d < 4; ++d) r += "," + std::to_string(d < static_cast<int>(t.fixed_shape.size()) ? t.fixed_shape[d] : 0);
        return r + ">";
      }
      return (t.indexed ? "wp::indexedarray_t<" : "wp::array_t<") + CppType(t.elem()) + ">";
    }
    case TypeKind::kStruct: return "wp::" + StructCppName(t.struct_name);
    case TypeKind::kTile: {
      std::string r = "wp::tile_t<" + CppType(t.elem());
      for (int d = 0; d < 4; ++d) r += "," + std::to_string(d < static_cast<int>(t.fixed_shape.size()) ? t.fixed_shape[d] : 0);
      return r + ">";
    }
    case TypeKind::kTileStack: return "wp::tile_stack_t<" + CppType(t.elem()) + "," + std::to_string(t.rows) + ">";
    case TypeKind::kTuple: return "/*tuple*/void";
  }
  return "void";
}

Expected<TypeLayout> LayoutOf(const Type& t, const StructTable& structs) {
  if (ContainsAny(t)) return InvalidArgument("the generic type " + TypeString(t) + " has no layout");
  switch (t.kind) {
    case TypeKind::kScalar: {
      uint32_t s = static_cast<uint32_t>(ScalarSize(t.scalar));
      return TypeLayout{s, s};
    }
    case TypeKind::kVector:
    case TypeKind::kMatrix:
    case TypeKind::kQuat:
    case TypeKind::kTransform: {
      if (t.component_count() == 0)
        return InvalidArgument("the zero-length type " + TypeString(t) +
                               " exists only inside kernels and functions (not as a kernel argument, struct field "
                               "or array element)");
      uint32_t s = static_cast<uint32_t>(ScalarSize(t.scalar));
      return TypeLayout{s * static_cast<uint32_t>(t.component_count()), s};
    }
    case TypeKind::kArray:
      if (t.is_fixed_array()) return InvalidArgument("fixed-size arrays cannot be kernel arguments or struct fields");
      return t.indexed ? TypeLayout{88 * 5, 8} : TypeLayout{88, 8};
    case TypeKind::kStruct: {
      auto it = structs.find(t.struct_name);
      if (it == structs.end()) return InvalidArgument("unknown struct '" + t.struct_name + "'");
      uint32_t off = 0, align = 1;
      for (const auto& f : it->second.fields) {
        WEFT_ASSIGN_OR_RETURN(TypeLayout fl, LayoutOf(f.type, structs));
        off = RoundUp(off, fl.align) + fl.size;
        if (fl.align > align) align = fl.align;
      }
      if (it->second.fields.empty()) off = 1;  // C++: an empty struct has size 1
      return TypeLayout{RoundUp(off, align), align};
    }
    case TypeKind::kTile: return InvalidArgument("tiles live inside kernels and functions: they cannot be kernel arguments, struct fields or array elements");
    default: return InvalidArgument("type " + TypeString(t) + " cannot be a kernel argument");
  }
}

}  // namespace weft::sema
