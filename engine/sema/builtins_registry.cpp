// The builtin registry's machinery: row construction, signature parsing, pattern matching
// for overload resolution, and the generated reference (docs/builtins.md).
#include <cctype>
#include <string_view>

#include "engine/sema/builtins.h"

namespace weft::sema {
namespace {

std::string Trim(std::string_view s) {
  size_t b = 0, e = s.size();
  while (b < e && s[b] == ' ') ++b;
  while (e > b && s[e - 1] == ' ') --e;
  return std::string(s.substr(b, e - b));
}

// Splits "a, b(c, d), e" at top-level commas.
std::vector<std::string> SplitTopLevel(std::string_view s) {
  std::vector<std::string> out;
  int depth = 0;
  size_t start = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '(') ++depth;
    else if (s[i] == ')') --depth;
    else if (s[i] == ',' && depth == 0) {
      out.push_back(Trim(s.substr(start, i - start)));
      start = i + 1;
    }
  }
  std::string last = Trim(s.substr(start));
  if (!last.empty() || !out.empty()) out.push_back(last);
  return out;
}

// "vec(N,Float)" -> head "vec", args {"N","Float"}; "Float" -> head "Float", no args.
void SplitHead(std::string_view p, std::string* head, std::vector<std::string>* args) {
  size_t lp = p.find('(');
  if (lp == std::string_view::npos) {
    *head = Trim(p);
    args->clear();
    return;
  }
  *head = Trim(p.substr(0, lp));
  *args = SplitTopLevel(p.substr(lp + 1, p.rfind(')') - lp - 1));
}

struct Bindings {
  bool has_scalar = false;
  ScalarKind scalar = ScalarKind::kFloat32;
  std::map<char, int> dims;
  std::map<std::string, Type> type_vars;
};

bool IsDimVar(const std::string& s) { return s.size() == 1 && std::isupper(static_cast<unsigned char>(s[0])); }

bool MatchDim(const std::string& pat, int value, Bindings* b) {
  if (IsDimVar(pat)) {
    auto it = b->dims.find(pat[0]);
    if (it == b->dims.end()) {
      b->dims[pat[0]] = value;
      return true;
    }
    return it->second == value;
  }
  return std::to_string(value) == pat;
}

bool MatchScalarClass(const std::string& cls, ScalarKind s, Bindings* b) {
  bool ok = (cls == "Float" && IsFloat(s)) || (cls == "Int" && IsInt(s)) ||
            (cls == "Scalar" && s != ScalarKind::kBool);
  if (!ok) return false;
  if (b->has_scalar) return b->scalar == s;
  b->has_scalar = true;
  b->scalar = s;
  return true;
}

bool IsScalarClass(const std::string& h) { return h == "Float" || h == "Int" || h == "Scalar"; }

bool MatchScalarPattern(const std::string& pat, ScalarKind s, Bindings* b) {
  if (IsScalarClass(pat)) return MatchScalarClass(pat, s, b);
  ScalarKind k;
  return ParseScalarName(pat, &k) && k == s;
}

bool Match(std::string_view pattern, const Type& arg, Bindings* b) {
  std::string head;
  std::vector<std::string> args;
  SplitHead(pattern, &head, &args);
  if (IsScalarClass(head)) return arg.is_scalar() && MatchScalarClass(head, arg.scalar, b);
  if (head == "Index") return arg.is_scalar() && IsInt(arg.scalar);
  if (head == "Cond") return arg.is_scalar() && !IsFloat(arg.scalar);
  if (head == "str") return arg.kind == TypeKind::kString;
  if (head == "X" || head == "Y" || head == "S") {
    if (arg.is_void() || arg.is_tuple() || arg.kind == TypeKind::kString) return false;
    if (head == "S" && !arg.is_struct()) return false;
    auto it = b->type_vars.find(head);
    if (it == b->type_vars.end()) {
      b->type_vars[head] = arg;
      return true;
    }
    return it->second == arg;
  }
  if (head == "vec" && args.size() == 2)
    return arg.is_vector() && MatchDim(args[0], arg.rows, b) && MatchScalarPattern(args[1], arg.scalar, b);
  if (head == "mat" && args.size() == 3)
    return arg.is_matrix() && MatchDim(args[0], arg.rows, b) && MatchDim(args[1], arg.cols, b) &&
           MatchScalarPattern(args[2], arg.scalar, b);
  if (head == "quat" && args.size() == 1)
    return arg.kind == TypeKind::kQuat && MatchScalarPattern(args[0], arg.scalar, b);
  if (head == "transform" && args.size() == 1)
    return arg.kind == TypeKind::kTransform && MatchScalarPattern(args[0], arg.scalar, b);
  if (head == "array" && args.size() == 2)
    return arg.is_array() && MatchDim(args[1], arg.ndim, b) && Match(args[0], arg.elem(), b);
  if (head == "tile_stack" && args.size() == 2)
    return arg.is_tile_stack() && MatchDim(args[1], arg.rows, b) && Match(args[0], arg.elem(), b);
  if (head == "tile" && args.size() >= 2) {
    if (!arg.is_tile() || arg.fixed_shape.size() + 1 != args.size()) return false;
    for (size_t d = 0; d + 1 < args.size(); ++d)
      if (!MatchDim(args[d + 1], arg.fixed_shape[d], b)) return false;
    return Match(args[0], arg.elem(), b);
  }
  auto concrete = ParseType(pattern);
  return concrete.ok() && *concrete == arg;
}

Expected<Type> Substitute(std::string_view pattern, const Bindings& b) {
  std::string head;
  std::vector<std::string> args;
  SplitHead(pattern, &head, &args);
  auto scalar_of = [&](const std::string& p) -> Expected<ScalarKind> {
    if (IsScalarClass(p)) {
      if (!b.has_scalar) return Internal("unbound scalar in builtin result " + std::string(pattern));
      return b.scalar;
    }
    ScalarKind k;
    if (!ParseScalarName(p, &k)) return Internal("bad scalar in builtin result " + std::string(pattern));
    return k;
  };
  auto dim_of = [&](const std::string& p) -> Expected<int> {
    if (IsDimVar(p)) {
      auto it = b.dims.find(p[0]);
      if (it == b.dims.end()) return Internal("unbound dimension in builtin result " + std::string(pattern));
      return it->second;
    }
    return std::stoi(p);
  };
  if (IsScalarClass(head)) {
    WEFT_ASSIGN_OR_RETURN(ScalarKind s, scalar_of(head));
    return Type::Scalar(s);
  }
  if (head == "X" || head == "Y" || head == "S") {
    auto it = b.type_vars.find(head);
    if (it == b.type_vars.end()) return Internal("unbound type variable in builtin result");
    return it->second;
  }
  if (head == "void" || head == "None") return Type::Void();
  if (head == "vec" && args.size() == 2) {
    WEFT_ASSIGN_OR_RETURN(int n, dim_of(args[0]));
    WEFT_ASSIGN_OR_RETURN(ScalarKind s, scalar_of(args[1]));
    return Type::Vector(n, s);
  }
  if (head == "mat" && args.size() == 3) {
    WEFT_ASSIGN_OR_RETURN(int r, dim_of(args[0]));
    WEFT_ASSIGN_OR_RETURN(int c, dim_of(args[1]));
    WEFT_ASSIGN_OR_RETURN(ScalarKind s, scalar_of(args[2]));
    return Type::Matrix(r, c, s);
  }
  if ((head == "quat" || head == "transform") && args.size() == 1) {
    WEFT_ASSIGN_OR_RETURN(ScalarKind s, scalar_of(args[0]));
    return head == "quat" ? Type::Quat(s) : Type::Transform(s);
  }
  if (head == "tuple") {
    std::vector<Type> elems;
    for (const auto& a : args) {
      WEFT_ASSIGN_OR_RETURN(Type t, Substitute(a, b));
      elems.push_back(std::move(t));
    }
    return Type::Tuple(std::move(elems));
  }
  if (head == "array" && args.size() == 2) {
    WEFT_ASSIGN_OR_RETURN(Type e, Substitute(args[0], b));
    WEFT_ASSIGN_OR_RETURN(int d, dim_of(args[1]));
    return Type::Array(std::move(e), d);
  }
  if (head == "tile_stack" && args.size() == 2) {
    WEFT_ASSIGN_OR_RETURN(Type e, Substitute(args[0], b));
    WEFT_ASSIGN_OR_RETURN(int n, dim_of(args[1]));
    return Type::TileStack(std::move(e), n);
  }
  if (head == "tile" && args.size() >= 2) {
    WEFT_ASSIGN_OR_RETURN(Type e, Substitute(args[0], b));
    std::vector<int> shape;
    for (size_t d = 1; d < args.size(); ++d) {
      WEFT_ASSIGN_OR_RETURN(int n, dim_of(args[d]));
      shape.push_back(n);
    }
    return Type::Tile(std::move(e), std::move(shape));
  }
  return ParseType(pattern);
}

}  // namespace

BuiltinOverload Builtin(const char* group, const char* signature, const char* doc, unsigned flags,
                        const char* native) {
  BuiltinOverload o;
  o.group = group;
  o.signature = signature;
  o.doc = doc;
  o.flags = flags;
  std::string_view sig(signature);
  size_t lp = sig.find('(');
  size_t arrow = sig.rfind("->");
  size_t rp = sig.rfind(')', arrow);
  o.name = Trim(sig.substr(0, lp));
  for (const auto& p : SplitTopLevel(sig.substr(lp + 1, rp - lp - 1))) {
    size_t colon = p.find(':');
    o.param_names.push_back(Trim(p.substr(0, colon)));
    o.param_patterns.push_back(Trim(p.substr(colon + 1)));
  }
  o.result_pattern = Trim(sig.substr(arrow + 2));
  o.native = *native ? native : o.name;
  if (!(flags & kBuiltinNotDiff)) o.adjoint = "adj_" + o.native;
  return o;
}

BuiltinRegistry::BuiltinRegistry() {
  AddScalarBuiltins(&rows_);
  AddLinalgBuiltins(&rows_);
  AddRuntimeBuiltins(&rows_);
  AddGeometryBuiltins(&rows_);
  AddVolumeBuiltins(&rows_);
  AddTileBuiltins(&rows_);
  for (size_t i = 0; i < rows_.size(); ++i) by_name_[rows_[i].name].push_back(i);
}

const BuiltinRegistry& BuiltinRegistry::Get() {
  static const BuiltinRegistry* registry = new BuiltinRegistry();
  return *registry;
}

std::vector<const BuiltinOverload*> BuiltinRegistry::Overloads(const std::string& name) const {
  std::vector<const BuiltinOverload*> out;
  auto it = by_name_.find(name);
  if (it != by_name_.end())
    for (size_t i : it->second) out.push_back(&rows_[i]);
  return out;
}

Expected<BuiltinMatch> BuiltinRegistry::Resolve(const std::string& name, const std::vector<Type>& args,
                                                 const std::vector<int>* literals) const {
  auto it = by_name_.find(name);
  if (it == by_name_.end()) return NotFound("unknown builtin '" + name + "'");
  auto literal = [&](size_t k) { return literals && k < literals->size() ? (*literals)[k] : 0; };
  for (size_t i : it->second) {
    const BuiltinOverload& o = rows_[i];
    if (o.param_patterns.size() != args.size()) continue;
    Bindings b;
    bool ok = true;
    std::vector<Type> types = args;
    // Pass 1: non-literal arguments bind the pattern variables.
    for (size_t k = 0; k < args.size() && ok; ++k)
      if (!literal(k)) ok = Match(o.param_patterns[k], args[k], &b);
    // Pass 2: literals take the bound type if they can, else their default type.
    for (size_t k = 0; k < args.size() && ok; ++k) {
      if (!literal(k)) continue;
      const std::string& p = o.param_patterns[k];
      std::vector<ScalarKind> tries;
      if ((IsScalarClass(p)) && b.has_scalar) tries.push_back(b.scalar);
      if (b.type_vars.count(p) && b.type_vars[p].is_scalar()) tries.push_back(b.type_vars[p].scalar);
      ScalarKind concrete;
      if (ParseScalarName(p, &concrete)) tries.push_back(concrete);
      if (p == "Float" && !b.has_scalar) tries.push_back(ScalarKind::kFloat32);
      tries.push_back(args[k].scalar);
      bool matched = false;
      for (ScalarKind s : tries) {
        if (literal(k) == 2 && !IsFloat(s)) continue;
        if (s == ScalarKind::kBool) continue;
        Bindings trial = b;
        if (Match(p, Type::Scalar(s), &trial)) {
          b = trial;
          types[k] = Type::Scalar(s);
          matched = true;
          break;
        }
      }
      ok = matched;
    }
    if (!ok) continue;
    auto result = Substitute(o.result_pattern, b);
    if (!result.ok()) return result.status();
    BuiltinMatch m;
    m.overload = &o;
    m.result = std::move(*result);
    m.param_types = std::move(types);
    return m;
  }
  // Warp's message for comparing values of two different types (expect_eq(vec3, vec2), ...).
  if ((name == "expect_eq" || name == "expect_neq") && args.size() == 2 && !(args[0] == args[1]))
    return InvalidArgument("Can't test equality for objects with different types");
  std::string got;
  for (size_t k = 0; k < args.size(); ++k) got += (k ? ", " : "") + TypeString(args[k]);
  std::string msg = "Couldn't find function overload for '" + name + "' that accepts (" + got + "); candidates:";
  for (size_t i : it->second) msg += "\n      " + rows_[i].signature;
  return InvalidArgument(msg);
}

std::string BuiltinRegistry::Markdown() const {
  std::string out =
      "# Kernel builtins\n\n"
      "Generated from the builtin registry (engine/sema/builtins_*.cpp) by\n"
      "`weft_engine_tests --gtest_filter=SemaBuiltinsDoc*` (it rewrites this file when\n"
      "`WEFT_WRITE_DOCS=1`). Call them as `wp.name(...)`.\n\n"
      "Type patterns: `Float` = float16/32/64 and bfloat16, `Int` = any integer, `Scalar` = any number; all\n"
      "occurrences of one pattern letter in a signature are the same type. `Index` = any integer,\n"
      "`Cond` = bool or integer, `X` = any value type, `N M K D` = sizes. The adjoint column is\n"
      "the native adjoint the backward pass calls (`-` = not differentiable: gradient stops).\n";
  std::string group;
  for (const auto& r : rows_) {
    if (r.group != group) {
      group = r.group;
      out += "\n## " + group + "\n\n| signature | adjoint | description |\n|---|---|---|\n";
    }
    auto esc = [](const std::string& s) {
      std::string e;
      for (char c : s) e += c == '|' ? std::string("\\|") : std::string(1, c);
      return e;
    };
    out += "| `" + esc(r.signature) + "` | " + (r.differentiable() ? "`wp::" + r.adjoint + "`" : std::string("-")) +
           " | " + esc(r.doc) + " |\n";
  }
  out +=
      "\n## Language-level builtins (rules in engine/sema/check_expr.cpp)\n\n"
      "| form | result | notes |\n|---|---|---|\n"
      "| `wp.tid()` | int32 | the launch index: `i = wp.tid()` its first coordinate (the flat index of a 1-D launch), `i, j = wp.tid()` (up to 4 names) its leading coordinates, row-major. In kernels and @wp.func (the calling thread). |\n"
      "| `len(a)` | int32 | `a.shape[0]` of an array; the length of a vector, quaternion (4), transform (7), matrix rows. |\n"
      "| `a.shape`, `a.shape[k]`, `a.ndim` | int32 | array extents. |\n"
      "| `range(stop)`, `range(start, stop[, step])` | - | only as the iterable of `for`; integer arguments. |\n"
      "| `wp.printf(fmt, *scalars)`, `print(values...)` | - | output reaches the launching client; in a backward pass `print(x)` prints the forward value once more and then `adj: <adjoint of x>` (Warp's), `wp.printf` is skipped. |\n"
      "| `wp.float64(x)`, `int(x)`, `float(x)`, ... | scalar | conversions; literals are retyped at compile time. |\n"
      "| `wp.vec3(...)`, `wp.mat33(...)`, `wp.quat(...)`, `wp.transform(p, q)`, `wp.spatial_vector(w, v)`, user vector/matrix types | composite | no arguments: zeros; one scalar: fill; components (scalars and/or composites, concatenated row-major); one value of another scalar type: conversion; a matrix from R-vectors: columns (Warp's legacy rule). Differentiable. |\n"
      "| `wp.vector(*args, length=, dtype=)`, `wp.matrix(*args, shape=(r, c), dtype=)`, `wp.quaternion(...)`, `wp.transformation(p, q)` | composite | as above with explicit shape/dtype (also spelled `wp.types.vector`, `wp.types.matrix`); `length` defaults to the arguments' component count, `shape` to a single matrix argument's; sizes are integer literals or module constants. |\n"
      "| `wp.svd3(A, U, sigma, V)` (and `svd2`, `qr3`, `eig3`, `quat_to_axis_angle`) | - | out-parameter form of a builtin with several results: assigns them to the trailing arguments. |\n"
      "| `wp.identity(n=N, dtype=T)`, `wp.quat_identity(dtype)`, `wp.transform_identity(dtype)` | composite | identities. |\n"
      "| `MyStruct()`, `MyStruct(a, b)`, `MyStruct(field=value, ...)` | struct | zero-initialised; fields by position (declaration order) and/or keyword. |\n"
      "| `wp.pi`, `wp.tau`, `wp.e`, `wp.inf`, `wp.nan`, `wp.half_pi`, ... | float32 literal | adapt to float64 where needed. |\n";
  return out;
}

}  // namespace weft::sema
