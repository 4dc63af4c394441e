// Tile builtins in kernels and funcs (Warp's tile programming): the calls whose result type
// depends on constant arguments (a shape, an axis, a dtype) or whose arguments are tuples
// (offsets). Each is checked here and rewritten into a row of builtins_tile.cpp: a `like`
// variable (a tile of the result's type, never written or read) carries the shape, and a tuple
// offset becomes one int64 index per dimension. Tiles belong to the thread computing them
// (engine/native/tile.h; docs/tiles.md).
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

#include "engine/sema/check_impl.h"

namespace weft::sema {

bool IsTileCall(const std::string& n) {
  static const char* kNames[] = {"tile_zeros", "tile_ones", "tile_full", "tile_arange", "tile_load", "tile_store",
                                 "tile_atomic_add", "tile_sum", "tile_broadcast", "tile_astype", "tile_matmul",
                                 "tile_extract", "tile", "untile", "tile_transpose", "tile_max", "tile_min",
                                 "tile_argmax", "tile_argmin", "tile_view", "tile_map", "tile_reduce",
                                 "tile_empty", "tile_axpy", "tile_assign", "tile_reshape", "tile_squeeze",
                                 "tile_cholesky", "tile_cholesky_inplace", "tile_cholesky_solve",
                                 "tile_cholesky_solve_inplace", "tile_lower_solve_inplace", "tile_upper_solve_inplace",
                                 "tile_fft", "tile_ifft", "tile_load_indexed", "tile_store_indexed",
                                 "tile_atomic_add_indexed", "tile_sort", "tile_randi", "tile_randf",
                                 "tile_from_thread", "tile_stack", "tile_stack_push", "tile_stack_pop",
                                 "tile_stack_clear", "tile_scatter_add", "tile_scatter_masked"};
  for (const char* k : kNames)
    if (n == k) return true;
  return false;
}

const std::vector<TileWrittenArg>* TileWrittenArgs(const std::string& name) {
  static const std::map<std::string, std::vector<TileWrittenArg>> kTable = {
      {"tile_matmul", {{2, "out"}}},
      {"tile_axpy", {{2, "dest"}}},
      {"tile_assign", {{0, "dst"}}},
      {"tile_cholesky_inplace", {{0, "A"}}},
      {"tile_cholesky_solve_inplace", {{1, "y"}}},
      {"tile_lower_solve_inplace", {{1, "y"}}},
      {"tile_upper_solve_inplace", {{1, "z"}}},
      {"tile_fft", {{0, "inout"}}},
      {"tile_ifft", {{0, "inout"}}},
      {"tile_sort", {{0, "keys"}, {1, "values"}}},
      {"tile_stack_push", {{0, "s"}}},
      {"tile_stack_pop", {{0, "s"}}},
      {"tile_stack_clear", {{0, "s"}}},
      {"tile_scatter_add", {{0, "a"}}},
      {"tile_scatter_masked", {{0, "a"}}},
  };
  auto it = kTable.find(name);
  return it == kTable.end() ? nullptr : &it->second;
}

const ast::Expr* TileWrittenTarget(const ast::Call& call, const TileWrittenArg& arg) {
  const ast::Expr* target = call.args.size() > arg.position ? call.args[arg.position].get() : nullptr;
  for (const auto& kw : call.keywords)
    if (kw.name == arg.param) target = kw.value.get();
  return target;
}

namespace {

// Work bounds of the tile ops whose cost grows with the square of a length.
constexpr int kMaxDirectDftLength = 4096;
constexpr int kMaxTileSortLength = 4096;

std::string ShapeText(const std::vector<int>& s) {
  std::string r = "(";
  for (size_t i = 0; i < s.size(); ++i) r += (i ? ", " : "") + std::to_string(s[i]);
  return r + (s.size() == 1 ? ",)" : ")");
}

}  // namespace

Expected<Value> Checker::CallTile(const std::string& name, std::vector<Value> args, const SourceLocation& loc,
                                  const ast::Call* call, bool* handled) {
  *handled = IsTileCall(name);
  if (!*handled) return Value();
  if (name == "tile_map" || name == "tile_reduce") return TileMap(name, std::move(args), loc, call);

  // Parameters by name: positional arguments first, then keywords.
  auto bind = [&](std::vector<std::string> names, std::vector<Value>* out) -> Status {
    out->assign(names.size(), Value());
    if (args.size() > names.size())
      return Error(loc, "wp." + name + "() takes at most " + std::to_string(names.size()) + " arguments");
    for (size_t i = 0; i < args.size(); ++i) (*out)[i] = args[i];
    if (!call) return Status::Ok();
    for (const auto& kw : call->keywords) {
      size_t k = 0;
      while (k < names.size() && names[k] != kw.name) ++k;
      if (k == names.size()) return Error(kw.loc, "wp." + name + "() has no parameter '" + kw.name + "'");
      if ((*out)[k].kind != Value::Kind::kNone) return Error(kw.loc, "wp." + name + "() got '" + kw.name + "' twice");
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*kw.value));
      (*out)[k] = v;
    }
    return Status::Ok();
  };
  auto value_of = [&](const Value& v, const char* what) -> Expected<int> {
    if (v.kind != Value::Kind::kVar) return Error(loc, "wp." + name + "(): " + what + " must be a value");
    return v.var;
  };
  auto tile_arg = [&](const Value& v, const char* what) -> Expected<int> {
    WEFT_ASSIGN_OR_RETURN(int var, value_of(v, what));
    if (!TypeOf(var).is_tile())
      return Error(loc, "wp." + name + "(): " + what + " must be a tile, got " + TypeString(TypeOf(var)));
    return var;
  };
  auto const_int = [&](const Value& v, const char* what) -> Expected<int64_t> {
    if (v.kind != Value::Kind::kVar || v.literal_text.empty() ||
        v.literal_text.find_first_not_of("-0123456789") != std::string::npos || v.literal_text.size() > 12)
      return Error(loc, "wp." + name + "(): " + what + " must be an integer constant");
    return std::stoll(v.literal_text);
  };
  // A shape: an integer constant or a tuple of them, each 1 or more, at most kMaxTileElements
  // elements in all.
  auto shape_of = [&](const Value& v) -> Expected<std::vector<int>> {
    std::vector<Value> dims = v.kind == Value::Kind::kTuple ? v.elems : std::vector<Value>{v};
    if (v.kind == Value::Kind::kNone) return Error(loc, "wp." + name + "() needs a shape");
    if (dims.empty() || dims.size() > 4)
      return ErrorOf("value", loc,
                     name + "() output must have between one and four dimensions, got " + std::to_string(dims.size()) +
                         " (a tile has 1 to 4)");
    std::vector<int> shape;
    int64_t total = 1;
    for (const Value& d : dims) {
      WEFT_ASSIGN_OR_RETURN(int64_t n, const_int(d, "each extent of the shape"));
      if (n < 1) return Error(loc, "wp." + name + "(): tile extents must be positive, got " + std::to_string(n));
      total *= n;
      if (total > kMaxTileElements)
        return Error(loc, "wp." + name + "(): a tile holds at most " + std::to_string(kMaxTileElements) + " elements");
      shape.push_back(static_cast<int>(n));
    }
    return shape;
  };
  auto dtype_of = [&](const Value& v, Type def) -> Expected<Type> {
    if (v.kind == Value::Kind::kNone) return def;
    if (v.kind != Value::Kind::kType) return Error(loc, "wp." + name + "(): dtype must be a type");
    if (!v.type.is_scalar() && !v.type.is_composite() && !v.type.is_struct())
      return Error(loc, "wp." + name + "(): tile elements are scalars, vectors, matrices, quaternions, transforms or structs");
    return v.type;
  };
  // The offset of a load or store: one int64 per dimension (zeros when left out).
  auto offsets_of = [&](const Value& v, int ndim) -> Expected<std::vector<Value>> {
    std::vector<Value> parts;
    if (v.kind == Value::Kind::kNone) {
      for (int d = 0; d < ndim; ++d) parts.push_back(Value::OfVar(EmitConst(Type::Scalar(ScalarKind::kInt64), "wp::int64(0)")));
      return parts;
    }
    std::vector<Value> given = v.kind == Value::Kind::kTuple ? v.elems : std::vector<Value>{v};
    if (static_cast<int>(given.size()) != ndim)
      return Error(loc, "wp." + name + "(): the offset has " + std::to_string(given.size()) + " entries for a " +
                            std::to_string(ndim) + "-D array");
    for (const Value& g : given) {
      if (g.kind != Value::Kind::kVar || !TypeOf(g.var).is_scalar() || !IsInt(TypeOf(g.var).scalar))
        return Error(loc, "wp." + name + "(): offsets must be integers");
      parts.push_back(Value::OfVar(EmitRaw(Type::Scalar(ScalarKind::kInt64), "wp::int64($0)", {g.var})));
    }
    return parts;
  };
  // A tile of type t that only carries its type to a native: never written, never read.
  auto like = [&](const Type& t) { return Value::OfVar(NewVar(t, "tile shape")); };
  auto flag_true = [&](const Value& v) { return v.kind == Value::Kind::kNone || v.literal_text != "False"; };

  // The forms that update a tile argument assign their result to it (a name, field or element).
  // The forms that update arguments assign their results to them (TileWrittenArgs: the `which`-th
  // written argument of this call; a name, field or element).
  auto assign_to_arg = [&](size_t which, const Value& r) -> Expected<Value> {
    const auto* written = TileWrittenArgs(name);
    const ast::Expr* target = call && written ? TileWrittenTarget(*call, written->at(which)) : nullptr;
    if (!target) return Error(loc, "wp." + name + "(): " + (written ? written->at(which).param : "the argument") +
                                       " must name a tile");
    write_through_ = true;   // an update in place: a view argument writes into its tile
    WEFT_RETURN_IF_ERROR(LowerAssignTo(*target, r));
    return Value();
  };
  std::vector<Value> p;
  if (name == "tile_zeros" || name == "tile_empty" || name == "tile_ones" || name == "tile_full") {
    const bool full = name == "tile_full";
    if (full) {
      WEFT_RETURN_IF_ERROR(bind({"shape", "value", "dtype", "storage"}, &p));
    } else {
      WEFT_RETURN_IF_ERROR(bind({"shape", "dtype", "storage"}, &p));
    }
    WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, shape_of(p[0]));
    Type def = Type::Float32();
    if (full && p[1].kind == Value::Kind::kVar) def = TypeOf(p[1].var);   // the fill value's type (Warp)
    WEFT_ASSIGN_OR_RETURN(Type elem, dtype_of(p[full ? 2 : 1], def));
    const Type tt = Type::Tile(elem, shape);
    if (elem.is_struct() && name == "tile_ones")
      return ErrorOf("type", loc, "wp.tile_ones() does not support Warp struct types (" + TypeString(elem) + ")");
    if (name == "tile_zeros" || name == "tile_empty") {   // tile_empty: zeros as well
      Stmt st;
      st.op.kind = OpKind::kConstruct;
      st.op.mode = ConstructMode::kZero;
      const int d = NewVar(tt);
      st.op.dst.push_back(d);
      Push(std::move(st));
      return Value::OfVar(d);
    }
    int v;
    if (full) {
      if (p[1].kind != Value::Kind::kVar) return Error(loc, "wp.tile_full() needs a value");
      WEFT_ASSIGN_OR_RETURN(v, Coerce(p[1], elem, loc, "value"));
    } else {
      v = EmitRaw(elem, CppType(elem) + "(1)", {});
    }
    return Value::OfVar(EmitRaw(tt, "wp::tile_full<" + CppType(tt) + ">($0)", {v}));
  }
  if (name == "tile_stack") {   // an empty stack
    WEFT_RETURN_IF_ERROR(bind({"capacity", "dtype"}, &p));
    WEFT_ASSIGN_OR_RETURN(int64_t cap, const_int(p[0], "capacity"));
    if (cap < 1 || cap > kMaxTileElements)
      return ErrorOf("value", loc, "wp.tile_stack(): capacity must be a positive integer of at most " +
                                       std::to_string(kMaxTileElements) + ", got " + std::to_string(cap));
    WEFT_ASSIGN_OR_RETURN(Type elem, dtype_of(p[1], Type::Float32()));
    Stmt st;
    st.op.kind = OpKind::kConstruct;
    st.op.mode = ConstructMode::kZero;
    const int d = NewVar(Type::TileStack(elem, static_cast<int>(cap)));
    st.op.dst.push_back(d);
    Push(std::move(st));
    return Value::OfVar(d);
  }
  if (name == "tile_stack_push" || name == "tile_stack_pop" || name == "tile_stack_clear") {
    if (name == "tile_stack_push") {
      WEFT_RETURN_IF_ERROR(bind({"s", "value", "has_value"}, &p));
    } else {
      WEFT_RETURN_IF_ERROR(bind({"s"}, &p));
    }
    WEFT_ASSIGN_OR_RETURN(int sv, value_of(p[0], "s"));
    const Type stt = TypeOf(sv);
    if (!stt.is_tile_stack()) return Error(loc, "wp." + name + "(): s must be a wp.tile_stack, got " + TypeString(stt));
    if (name == "tile_stack_clear") {
      WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin("tile_stack_cleared", {p[0]}, loc));
      return assign_to_arg(0, r);
    }
    if (name == "tile_stack_pop") {
      WEFT_ASSIGN_OR_RETURN(Value top, ResolveAndEmitBuiltin("tile_stack_top", {p[0]}, loc));
      WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin("tile_stack_popped", {p[0]}, loc));
      WEFT_ASSIGN_OR_RETURN(Value unused, assign_to_arg(0, r));
      (void)unused;
      return top;
    }
    if (p[1].kind != Value::Kind::kVar) return Error(loc, "wp.tile_stack_push() needs a value");
    const Type vt = TypeOf(p[1].var);   // the element type, or an integer literal for a numeric stack
    const bool int_literal = p[1].literal && IsIntLiteralText(p[1].literal_text) && stt.elem().is_scalar() &&
                             stt.elem().scalar != ScalarKind::kBool;
    if (vt != stt.elem() && !int_literal)
      return ErrorOf("type", loc, "wp.tile_stack_push(): the value's type " + TypeString(vt) +
                                      " does not match the stack's element type " + TypeString(stt.elem()));
    WEFT_ASSIGN_OR_RETURN(int v, Coerce(p[1], stt.elem(), loc, "value"));
    Value has = p[2].kind == Value::Kind::kNone ? Value::OfVar(EmitConst(Type::Bool(), "true")) : p[2];
    if (has.kind != Value::Kind::kVar) return Error(loc, "wp.tile_stack_push(): has_value must be a bool");
    WEFT_ASSIGN_OR_RETURN(int hv, Coerce(has, Type::Bool(), loc, "has_value"));
    std::vector<Value> a{p[0], Value::OfVar(v), Value::OfVar(hv)};
    WEFT_ASSIGN_OR_RETURN(Value slot, ResolveAndEmitBuiltin("tile_stack_push_slot", a, loc));
    WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin("tile_stack_pushed", a, loc));
    WEFT_ASSIGN_OR_RETURN(Value unused, assign_to_arg(0, r));
    (void)unused;
    return slot;
  }
  if (name == "tile_scatter_add" || name == "tile_scatter_masked") {
    // (a, i[, j, k, l], value, has_value[, atomic]): as many indices as a has dimensions. With
    // one thread per block no two threads meet at an element, so `atomic` changes nothing.
    if (args.empty()) return Error(loc, "wp." + name + "() needs a tile as its first argument");
    WEFT_ASSIGN_OR_RETURN(int a, tile_arg(args[0], "a"));
    const Type tt = TypeOf(a);
    std::vector<std::string> names{"a"};
    for (int d = 0; d < tt.ndim; ++d) names.push_back(std::string(1, "ijkl"[d]));
    names.push_back("value");
    names.push_back("has_value");
    if (name == "tile_scatter_add") names.push_back("atomic");
    WEFT_RETURN_IF_ERROR(bind(names, &p));
    std::vector<Value> full{p[0]};
    for (int d = 1; d <= tt.ndim; ++d) {
      if (p[d].kind != Value::Kind::kVar || !TypeOf(p[d].var).is_scalar() || !IsInt(TypeOf(p[d].var).scalar))
        return Error(loc, "wp." + name + "(): index " + names[d] + " must be an integer");
      full.push_back(p[d]);
    }
    const Value& value = p[tt.ndim + 1];
    const Value& has = p[tt.ndim + 2];
    if (value.kind != Value::Kind::kVar) return Error(loc, "wp." + name + "() needs a value");
    if (has.kind != Value::Kind::kVar) return Error(loc, "wp." + name + "() needs has_value (a bool)");
    if (TypeOf(value.var) != tt.elem() && !(value.literal && tt.elem().is_scalar()))
      return ErrorOf("type", loc, "wp." + name + "(): the value's type " + WarpTypeRepr(TypeOf(value.var)) +
                                      " does not match the tile's element type " + WarpTypeRepr(tt.elem()));
    WEFT_ASSIGN_OR_RETURN(int v, Coerce(value, tt.elem(), loc, "value"));
    WEFT_ASSIGN_OR_RETURN(int hv, Coerce(has, Type::Bool(), loc, "has_value"));
    if (name == "tile_scatter_add" && p.back().kind != Value::Kind::kNone &&
        p.back().literal_text != "True" && p.back().literal_text != "False")
      return Error(loc, "wp.tile_scatter_add(): atomic must be a constant (True or False)");
    full.push_back(Value::OfVar(v));
    full.push_back(Value::OfVar(hv));
    WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin(name, std::move(full), loc));
    WEFT_ASSIGN_OR_RETURN(Value unused, assign_to_arg(0, r));
    (void)unused;
    return Value();
  }
  if (name == "tile_from_thread") {
    // One thread per block: the value of "thread thread_idx" is this thread's value.
    WEFT_RETURN_IF_ERROR(bind({"shape", "value", "thread_idx", "storage"}, &p));
    WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, shape_of(p[0]));
    WEFT_ASSIGN_OR_RETURN(int v, value_of(p[1], "value"));
    const Type tt = Type::Tile(TypeOf(v), shape);
    if (!TypeOf(v).is_scalar() && !TypeOf(v).is_composite() && !TypeOf(v).is_struct())
      return Error(loc, "wp.tile_from_thread(): value must be a scalar, vector, matrix, quaternion, transform or struct");
    if (lanes_ > 1) {   // lanes: lane thread_idx's value (zero when that lane does not run)
      if (p[2].kind != Value::Kind::kVar) return Error(loc, "wp.tile_from_thread() needs thread_idx");
      WEFT_ASSIGN_OR_RETURN(int from, Coerce(p[2], Type::Int32(), loc, "thread_idx"));
      return Value::OfVar(EmitRaw(tt, "wp::tile_from_lane<" + CppType(tt) + ">($@, $0, $1)", {v, from}));
    }
    return Value::OfVar(EmitRaw(tt, "wp::tile_full<" + CppType(tt) + ">($0)", {v}));
  }
  if (name == "tile_randi" || name == "tile_randf") {
    const bool ints = name == "tile_randi";
    WEFT_RETURN_IF_ERROR(bind({"shape", "rng", "min", "max", "storage"}, &p));
    WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, shape_of(p[0]));
    if (p[1].kind != Value::Kind::kVar) return Error(loc, "wp." + name + "() needs rng (a wp.rand_init state)");
    WEFT_ASSIGN_OR_RETURN(int rng, Coerce(p[1], Type::Scalar(ScalarKind::kUInt32), loc, "rng"));
    const Type elem = ints ? Type::Int32() : Type::Float32();
    const Type tt = Type::Tile(elem, shape);
    const bool ranged = p[2].kind != Value::Kind::kNone || p[3].kind != Value::Kind::kNone;
    if (!ranged) return Value::OfVar(EmitRaw(tt, "wp::" + name + "<" + CppType(tt) + ">($@, $0)", {rng}));
    if (p[2].kind != Value::Kind::kVar || p[3].kind != Value::Kind::kVar)
      return Error(loc, "wp." + name + "() takes both min and max");
    WEFT_ASSIGN_OR_RETURN(int lo, Coerce(p[2], elem, loc, "min"));
    WEFT_ASSIGN_OR_RETURN(int hi, Coerce(p[3], elem, loc, "max"));
    return Value::OfVar(EmitRaw(tt, "wp::" + name + "<" + CppType(tt) + ">($@, $0, $1, $2)", {rng, lo, hi}));
  }
  if (name == "tile_arange") {
    // tile_arange(stop), (start, stop) or (start, stop, step): constants, as the shape depends
    // on them; integers exactly (int64), floats as float64, numpy's count ceil((stop - start) / step).
    Value dtype_v;
    if (call)
      for (const auto& kw : call->keywords) {
        if (kw.name == "dtype") {
          WEFT_ASSIGN_OR_RETURN(dtype_v, Eval(*kw.value));
        } else if (kw.name != "storage") {
          return Error(kw.loc, "tile_arange() has no parameter '" + kw.name + "'");
        }
      }
    if (args.empty() || args.size() > 3)
      return ErrorOf("type", loc, "tile_arange() accepts at most 3 positional arguments, got " + std::to_string(args.size()));
    static const char* kOne[] = {"stop"};
    static const char* kMore[] = {"start", "stop", "step"};
    struct Bound {
      const char* name;
      std::string text;
      bool is_int;
      long long i;
      double f;
    };
    std::vector<Bound> b;
    for (size_t k = 0; k < args.size(); ++k) {
      const char* pname = args.size() == 1 ? kOne[0] : kMore[k];
      const Value& a = args[k];
      if (a.kind != Value::Kind::kVar || a.literal_text.empty())
        return ErrorOf("value", loc, std::string("tile_arange() arguments must be compile time constants, but ") + pname +
                                         " is not");
      Bound x{pname, a.literal_text, false, 0, 0.0};
      const std::string& t = a.literal_text;
      x.is_int = t.find_first_not_of("-0123456789") == std::string::npos;
      errno = 0;
      char* end = nullptr;
      if (x.is_int) {
        x.i = std::strtoll(t.c_str(), &end, 10);
        if (errno == ERANGE)
          return ErrorOf("value", loc, std::string("tile_arange() ") + pname + "=" + t + " is too wide to use as an integer bound");
        x.f = static_cast<double>(x.i);
      } else {
        x.f = std::strtod(t.c_str(), &end);   // ERANGE with a finite value: a subnormal, kept
        char shortest[32];   // messages show the value as Python writes it (1e+300, not 1.0000000000000001e+300)
        const auto written = std::to_chars(shortest, shortest + sizeof(shortest), x.f);
        if (written.ec == std::errc()) {
          x.text.assign(shortest, written.ptr);
          if (x.text.find_first_of(".eni") == std::string::npos) x.text += ".0";
        }
        if (!std::isfinite(x.f))
          return ErrorOf("value", loc, std::string("tile_arange() ") + pname + "=" + t + " is out of range");
      }
      if (!end || *end) return ErrorOf("value", loc, std::string("tile_arange() ") + pname + "=" + t + " is not a number");
      b.push_back(x);
    }
    bool ints = true;
    for (const Bound& x : b) ints &= x.is_int;
    WEFT_ASSIGN_OR_RETURN(Type elem, dtype_of(dtype_v, ints ? Type::Int32() : Type::Float32()));
    if (!elem.is_scalar() || elem.scalar == ScalarKind::kBool)
      return ErrorOf("type", loc, "tile_arange() requires a numeric scalar dtype, got " + TypeString(elem));
    const bool int_dtype = IsInt(elem.scalar);
    // A double as the float dtype holds it (round to nearest even; float16 / bfloat16: `bits`
    // significant bits, subnormal below 2^(min_exp - 1); beyond the largest finite: infinite).
    auto round_to = [](double v, int bits, int min_exp) {
      if (v == 0.0 || !std::isfinite(v)) return v;
      int e = 0;
      std::frexp(v, &e);
      const int quantum = (e < min_exp ? min_exp : e) - bits;
      return std::ldexp(std::nearbyint(std::ldexp(v, -quantum)), quantum);
    };
    auto as_elem = [&](double v) {
      if (elem.scalar == ScalarKind::kFloat32) return static_cast<double>(static_cast<float>(v));
      const double r = elem.scalar == ScalarKind::kFloat16 ? round_to(v, 11, -13)
                       : elem.scalar == ScalarKind::kBFloat16 ? round_to(v, 8, -125) : v;
      const double top = elem.scalar == ScalarKind::kFloat16 ? 65504.0
                         : elem.scalar == ScalarKind::kBFloat16 ? 3.3895313892515355e38 : HUGE_VAL;
      return std::fabs(r) > top ? std::copysign(HUGE_VAL, r) : r;
    };
    if (!int_dtype) {   // every bound within the float dtype's range, then rounded to it (Warp counts those)
      const double top = elem.scalar == ScalarKind::kFloat16 ? 65504.0
                         : elem.scalar == ScalarKind::kFloat32 ? 3.4028234663852886e38 : 1.7976931348623157e308;
      for (Bound& x : b) {
        if (std::fabs(x.f) > top)
          return ErrorOf("value", loc, std::string("tile_arange() ") + x.name + "=" + x.text + " is out of range for " +
                                           TypeString(elem));
        x.f = elem.scalar == ScalarKind::kFloat32 && x.is_int ? static_cast<float>(x.i) : as_elem(x.f);
      }
    }
    if (int_dtype) {   // every bound an integer of the dtype
      const int bits = ScalarSize(elem.scalar) * 8;
      const bool is_signed = IsSigned(elem.scalar);
      for (Bound& x : b) {
        if (!x.is_int) {
          if (x.f != std::floor(x.f))
            return ErrorOf("value", loc, std::string("tile_arange() ") + x.name + "=" + x.text + " has a fractional part");
          if (std::fabs(x.f) >= 9.2e18)
            return ErrorOf("value", loc, std::string("tile_arange() ") + x.name + "=" + x.text + " is out of range");
          x.i = static_cast<long long>(x.f);
        }
        const long double lo = is_signed ? -std::ldexp(1.0L, bits - 1) : 0.0L;
        const long double hi = is_signed ? std::ldexp(1.0L, bits - 1) - 1 : std::ldexp(1.0L, bits) - 1;
        if (static_cast<long double>(x.i) < lo || static_cast<long double>(x.i) > hi)
          return ErrorOf("value", loc, std::string("tile_arange() ") + x.name + "=" + x.text + " is out of range for " +
                                           TypeString(elem));
      }
    }
    const bool one = b.size() == 1;
    auto at = [&](int k, long long di, double df) {
      return b.size() > static_cast<size_t>(k) ? b[k] : Bound{"", std::to_string(di), true, di, df};
    };
    const Bound start = one ? Bound{"start", "0", true, 0, 0.0} : b[0];
    const Bound stop = one ? b[0] : b[1];
    const Bound step = b.size() == 3 ? b[2] : at(9, 1, 1.0);
    if ((int_dtype && step.i == 0) || (!int_dtype && step.f == 0.0))
      return ErrorOf("value", loc, "tile_arange() step cannot be zero");
    long double count;
    if (int_dtype) {
      const __int128 span = static_cast<__int128>(stop.i) - start.i;
      const __int128 st = step.i;
      __int128 n = (span > 0) == (st > 0) && span != 0 ? (span + st - (st > 0 ? 1 : -1)) / st : 0;
      count = static_cast<long double>(n);
    } else if (step.f > 0 ? start.f < stop.f : start.f > stop.f) {
      // Warp's count: the quotient as the dtype holds it (0.3f / 0.1f is 3, not 3.0000001), its
      // ceiling, at least one (a non-empty range holds start)
      const double quotient = as_elem((stop.f - start.f) / step.f);
      if (!std::isfinite(quotient))
        return ErrorOf("value", loc, "tile_arange() start=" + start.text + ", stop=" + stop.text + ", step=" + step.text +
                                         " spans more elements than can be counted; the step is too small for the range");
      count = std::max(1.0L, std::ceil(static_cast<long double>(quotient)));
    } else {
      count = 0;
    }
    if (!(count >= 1))
      return ErrorOf("value", loc, "tile_arange() requires a non-empty range: a zero-length tile cannot be built");
    if (count > kMaxTileElements)
      return ErrorOf("value", loc, "tile_arange() spans more elements than can be counted in one tile (at most " +
                                       std::to_string(kMaxTileElements) + ")");
    const Type tt = Type::Tile(elem, {static_cast<int>(count)});
    auto lit = [&](const Bound& x) {
      if (int_dtype) return CppType(elem) + "(" + std::to_string(x.i) + "LL)";
      char buf[64];
      std::snprintf(buf, sizeof(buf), "%.17g", x.f);
      return CppType(elem) + "(" + buf + ")";
    };
    return Value::OfVar(EmitRaw(tt, "wp::tile_arange<" + CppType(tt) + ">(" + lit(start) + ", " + lit(step) + ")", {}));
  }
  if (name == "tile_load") {
    WEFT_RETURN_IF_ERROR(bind({"a", "shape", "offset", "storage", "bounds_check", "aligned"}, &p));
    WEFT_ASSIGN_OR_RETURN(int a, value_of(p[0], "a"));
    const Type at = TypeOf(a);
    if (!at.is_array() || at.is_indexed_array() || at.is_fixed_array())
      return Error(loc, "wp.tile_load() loads from an array, got " + TypeString(at));
    WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, shape_of(p[1]));
    if (static_cast<int>(shape.size()) != at.ndim)
      return Error(loc, "wp.tile_load(): the tile shape " + ShapeText(shape) + " has " + std::to_string(shape.size()) +
                            " dimensions, the array " + std::to_string(at.ndim));
    if (!flag_true(p[4])) {
      // bounds_check=False: weft checks every access all the same (docs/tiles.md).
    }
    WEFT_ASSIGN_OR_RETURN(std::vector<Value> off, offsets_of(p[2], at.ndim));
    std::vector<Value> full{like(Type::Tile(at.elem(), shape)), p[0]};
    full.insert(full.end(), off.begin(), off.end());
    return ResolveAndEmitBuiltin("tile_load", std::move(full), loc);
  }
  if (name == "tile_store" || name == "tile_atomic_add") {
    WEFT_RETURN_IF_ERROR(bind({"a", "t", "offset", "bounds_check", "aligned"}, &p));
    WEFT_ASSIGN_OR_RETURN(int a, value_of(p[0], "a"));
    WEFT_ASSIGN_OR_RETURN(int t, tile_arg(p[1], "t"));
    const Type at = TypeOf(a), tt = TypeOf(t);
    if (!at.is_array() || at.is_indexed_array() || at.is_fixed_array())
      return Error(loc, "wp." + name + "() writes into an array, got " + TypeString(at));
    if (at.ndim != tt.ndim)
      return Error(loc, "wp." + name + "(): a " + std::to_string(tt.ndim) + "-D tile into a " + std::to_string(at.ndim) +
                            "-D array");
    if (at.elem() != tt.elem())
      return Error(loc, "wp." + name + "(): the tile holds " + TypeString(tt.elem()) + ", the array " + TypeString(at.elem()));
    if (name == "tile_atomic_add" && !tt.elem().is_struct()) {   // Warp's atomic scalar set
      const ScalarKind sk = tt.elem().scalar;
      const bool atomic_scalar = sk == ScalarKind::kInt32 || sk == ScalarKind::kInt64 || sk == ScalarKind::kUInt32 ||
                                 sk == ScalarKind::kUInt64 || sk == ScalarKind::kFloat16 || sk == ScalarKind::kBFloat16 ||
                                 sk == ScalarKind::kFloat32 || sk == ScalarKind::kFloat64;
      if (!atomic_scalar)
        return ErrorOf("", loc, "tile_atomic_add() only supports tiles with [u]int32, [u]int64, float16, bfloat16, "
                                "float32, or float64 as the underlying scalar type, but got " + WarpTypeRepr(tt.elem()));
    }
    WEFT_ASSIGN_OR_RETURN(std::vector<Value> off, offsets_of(p[2], at.ndim));
    std::vector<Value> full{p[0]};
    full.insert(full.end(), off.begin(), off.end());
    full.push_back(p[1]);
    return ResolveAndEmitBuiltin(name, std::move(full), loc);
  }
  if (name == "tile_sum" || name == "tile_max" || name == "tile_min" || name == "tile_argmax" || name == "tile_argmin") {
    WEFT_RETURN_IF_ERROR(bind({"a", "axis"}, &p));
    WEFT_ASSIGN_OR_RETURN(int a, tile_arg(p[0], "a"));
    if (TypeOf(a).elem().is_struct() && name != "tile_sum")   // sums add structs field by field
      return ErrorOf("type", loc, name + "() does not support Warp struct tile elements (" +
                                      WarpTypeRepr(TypeOf(a).elem()) + ")");
    if (p[1].kind == Value::Kind::kNone) return ResolveAndEmitBuiltin(name, {p[0]}, loc);
    if (name != "tile_sum") return Error(loc, "wp." + name + "(axis=...) is not supported in weft kernels yet");
    WEFT_ASSIGN_OR_RETURN(int64_t axis, const_int(p[1], "axis"));
    const Type tt = TypeOf(a);
    if (axis < 0) axis += tt.ndim;
    if (axis < 0 || axis >= tt.ndim)
      return Error(loc, "wp.tile_sum(): axis " + p[1].literal_text + " is outside a " + std::to_string(tt.ndim) + "-D tile");
    if (tt.ndim == 1) return ResolveAndEmitBuiltin("tile_sum", {p[0]}, loc);
    std::vector<int> shape = tt.fixed_shape;
    shape.erase(shape.begin() + axis);
    Value ax = Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(axis) + ")"));
    return ResolveAndEmitBuiltin("tile_sum_axis", {like(Type::Tile(tt.elem(), shape)), p[0], ax}, loc);
  }
  if (name == "tile_broadcast") {
    WEFT_RETURN_IF_ERROR(bind({"a", "shape", "storage"}, &p));
    WEFT_ASSIGN_OR_RETURN(int a, tile_arg(p[0], "a"));
    WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, shape_of(p[1]));
    const Type tt = TypeOf(a);
    bool ok = shape.size() >= tt.fixed_shape.size();
    for (size_t d = 0; ok && d < tt.fixed_shape.size(); ++d) {
      const int have = tt.fixed_shape[tt.fixed_shape.size() - 1 - d], want = shape[shape.size() - 1 - d];
      ok = have == 1 || have == want;
    }
    if (!ok) return Error(loc, "wp.tile_broadcast(): cannot broadcast a tile of shape " + ShapeText(tt.fixed_shape) +
                                   " to " + ShapeText(shape));
    return ResolveAndEmitBuiltin("tile_broadcast", {like(Type::Tile(tt.elem(), shape)), p[0]}, loc);
  }
  if (name == "tile_astype") {
    WEFT_RETURN_IF_ERROR(bind({"t", "dtype"}, &p));
    WEFT_ASSIGN_OR_RETURN(int a, tile_arg(p[0], "t"));
    const Type tt = TypeOf(a);
    WEFT_ASSIGN_OR_RETURN(Type elem, dtype_of(p[1], tt.elem()));
    if (!elem.is_scalar() || !tt.elem().is_scalar()) return Error(loc, "wp.tile_astype() converts tiles of scalars");
    return ResolveAndEmitBuiltin("tile_astype", {like(Type::Tile(elem, tt.fixed_shape)), p[0]}, loc);
  }
  if (name == "tile_matmul") {
    WEFT_RETURN_IF_ERROR(bind({"a", "b", "out", "alpha", "beta"}, &p));
    WEFT_ASSIGN_OR_RETURN(int a, tile_arg(p[0], "a"));
    WEFT_ASSIGN_OR_RETURN(int b, tile_arg(p[1], "b"));
    const Type ta = TypeOf(a), tb = TypeOf(b);
    if (ta.ndim != 2 || tb.ndim != 2 || ta.fixed_shape[1] != tb.fixed_shape[0])
      return Error(loc, "wp.tile_matmul(): shapes " + ShapeText(ta.fixed_shape) + " and " + ShapeText(tb.fixed_shape) +
                            " do not multiply");
    const Type elem = ta.elem();
    const Type out_t = Type::Tile(elem, {ta.fixed_shape[0], tb.fixed_shape[1]});
    auto scalar = [&](const Value& v, const char* dflt, const char* what) -> Expected<Value> {
      if (v.kind == Value::Kind::kNone) return Value::OfVar(EmitConst(elem, CppType(elem) + "(" + dflt + ")"));
      WEFT_ASSIGN_OR_RETURN(int s, Coerce(v, elem, loc, what));
      return Value::OfVar(s);
    };
    const bool has_out = p[2].kind != Value::Kind::kNone;
    WEFT_ASSIGN_OR_RETURN(Value alpha, scalar(p[3], "1", "alpha"));
    WEFT_ASSIGN_OR_RETURN(Value beta, scalar(p[4], has_out ? "1" : "0", "beta"));
    Value c;   // the value form: alpha a b + 0 * zeros (a zero tile, since it is read)
    if (!has_out) {
      Stmt zero;
      zero.op.kind = OpKind::kConstruct;
      zero.op.mode = ConstructMode::kZero;
      zero.op.dst.push_back(NewVar(out_t));
      c = Value::OfVar(zero.op.dst[0]);
      Push(std::move(zero));
    }
    if (has_out) {
      WEFT_ASSIGN_OR_RETURN(int o, tile_arg(p[2], "out"));
      if (TypeOf(o) != out_t)
        return Error(loc, "wp.tile_matmul(): out is " + TypeString(TypeOf(o)) + ", the product " + TypeString(out_t));
      c = p[2];
    }
    WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin("tile_matmul", {p[0], p[1], c, alpha, beta}, loc));
    if (!has_out) return r;
    return assign_to_arg(0, r);   // the out form assigns the product to `out`
  }
  if (name == "tile_axpy") {
    WEFT_RETURN_IF_ERROR(bind({"alpha", "src", "dest"}, &p));
    WEFT_ASSIGN_OR_RETURN(int src, tile_arg(p[1], "src"));
    WEFT_ASSIGN_OR_RETURN(int dest, tile_arg(p[2], "dest"));
    if (TypeOf(src) != TypeOf(dest))
      return Error(loc, "wp.tile_axpy(): src is " + TypeString(TypeOf(src)) + ", dest " + TypeString(TypeOf(dest)));
    if (p[0].kind != Value::Kind::kVar) return Error(loc, "wp.tile_axpy(): alpha must be a value");
    const Type elem = TypeOf(src).elem();   // alpha: the element's scalar (vector and matrix tiles too)
    const Type alpha_type = elem.is_vector() || elem.is_matrix() ? Type::Scalar(elem.scalar) : elem;
    WEFT_ASSIGN_OR_RETURN(int alpha, Coerce(p[0], alpha_type, loc, "alpha"));
    WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin("tile_axpy", {Value::OfVar(alpha), p[1], p[2]}, loc));
    return assign_to_arg(0, r);
  }
  if (name == "tile_assign") {
    WEFT_RETURN_IF_ERROR(bind({"dst", "src", "offset"}, &p));
    WEFT_ASSIGN_OR_RETURN(int dst, tile_arg(p[0], "dst"));
    WEFT_ASSIGN_OR_RETURN(int src, tile_arg(p[1], "src"));
    const Type dt = TypeOf(dst), st = TypeOf(src);
    Value srcv = p[1];
    if (dt.ndim == st.ndim && dt.elem() != st.elem() && dt.elem().is_scalar() && st.elem().is_scalar()) {
      // another scalar type: converted, as Warp does
      WEFT_ASSIGN_OR_RETURN(srcv, ResolveAndEmitBuiltin("tile_astype", {like(Type::Tile(dt.elem(), st.fixed_shape)), p[1]}, loc));
    } else if (dt.ndim != st.ndim || dt.elem() != st.elem()) {
      return Error(loc, "wp.tile_assign(): cannot assign a " + TypeString(st) + " into a " + TypeString(dt));
    }
    WEFT_ASSIGN_OR_RETURN(std::vector<Value> off, offsets_of(p[2], dt.ndim));
    std::vector<Value> full{p[0], srcv};
    std::vector<int> off_vars, kept;
    for (int d = 0; d < dt.ndim; ++d) {
      off_vars.push_back(off[d].var);
      kept.push_back(d);
    }
    for (const Value& v : TileRegionArgs(off_vars, {}, kept)) full.push_back(v);
    WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin("tile_assign", std::move(full), loc));
    return assign_to_arg(0, r);
  }
  if (name == "tile_reshape" || name == "tile_squeeze") {
    const bool squeeze = name == "tile_squeeze";
    WEFT_RETURN_IF_ERROR(bind({"t", squeeze ? "axis" : "shape"}, &p));
    WEFT_ASSIGN_OR_RETURN(int a, tile_arg(p[0], "t"));
    const Type tt = TypeOf(a);
    int64_t size = 1;
    for (int n : tt.fixed_shape) size *= n;
    std::vector<int> shape;
    if (!squeeze) {
      // One extent may be -1: what the others leave.
      std::vector<Value> dims = p[1].kind == Value::Kind::kTuple ? p[1].elems : std::vector<Value>{p[1]};
      if (p[1].kind == Value::Kind::kNone) return Error(loc, "wp.tile_reshape() needs a shape");
      if (dims.empty() || dims.size() > 4) return Error(loc, "wp.tile_reshape(): a tile has 1 to 4 dimensions");
      int64_t known = 1;
      int infer = -1;
      for (size_t d = 0; d < dims.size(); ++d) {
        WEFT_ASSIGN_OR_RETURN(int64_t n, const_int(dims[d], "each extent of the shape"));
        if (n == -1 && infer < 0) {
          infer = static_cast<int>(d);
          shape.push_back(1);
          continue;
        }
        if (n < 1 || n > kMaxTileElements) return Error(loc, "wp.tile_reshape(): bad extent " + std::to_string(n));
        known *= n;
        shape.push_back(static_cast<int>(n));
      }
      if (infer >= 0 && known > 0 && size % known == 0) shape[infer] = static_cast<int>(size / known);
      int64_t got = 1;
      for (int n : shape) got *= n;
      if (got != size)
        return Error(loc, "wp.tile_reshape(): cannot reshape a tile of shape " + ShapeText(tt.fixed_shape) + " to " +
                              ShapeText(shape));
    } else {
      std::vector<bool> drop(tt.fixed_shape.size(), false);
      if (p[1].kind == Value::Kind::kNone) {
        for (size_t d = 0; d < drop.size(); ++d) drop[d] = tt.fixed_shape[d] == 1;
      } else {
        std::vector<Value> axes = p[1].kind == Value::Kind::kTuple ? p[1].elems : std::vector<Value>{p[1]};
        for (const Value& ax : axes) {
          WEFT_ASSIGN_OR_RETURN(int64_t k, const_int(ax, "axis"));
          if (k < -tt.ndim || k >= tt.ndim)
            return ErrorOf("value", loc, "tile_squeeze() axis " + std::to_string(k) +
                                             " is out of bounds for tile with " + std::to_string(tt.ndim) + " dimensions");
          if (k < 0) k += tt.ndim;
          if (tt.fixed_shape[k] != 1)
            return Error(loc, "wp.tile_squeeze(): axis " + ax.literal_text + " is not an extent of 1 of a tile of shape " +
                                  ShapeText(tt.fixed_shape));
          drop[k] = true;
        }
      }
      for (size_t d = 0; d < drop.size(); ++d)
        if (!drop[d]) shape.push_back(tt.fixed_shape[d]);
      if (shape.empty()) shape.push_back(1);
    }
    return ResolveAndEmitBuiltin("tile_reshape", {like(Type::Tile(tt.elem(), shape)), p[0]}, loc);
  }
  if (name == "tile_view") {
    WEFT_RETURN_IF_ERROR(bind({"t", "offset", "shape"}, &p));
    WEFT_ASSIGN_OR_RETURN(int a, tile_arg(p[0], "t"));
    const Type tt = TypeOf(a);
    std::vector<Value> given = p[1].kind == Value::Kind::kTuple ? p[1].elems : std::vector<Value>{p[1]};
    if (p[1].kind == Value::Kind::kNone || given.empty() || static_cast<int>(given.size()) > tt.ndim)
      return Error(loc, "wp.tile_view(): the offset has 1 to " + std::to_string(tt.ndim) + " entries");
    std::vector<int> offsets;
    bool any_slice = false;
    for (const Value& g : given) any_slice |= g.kind == Value::Kind::kTuple && g.name == "slice";
    if (any_slice) {   // offset=(slice(a, b, c), i, ...): the sub-tile as t[a:b:c, i, ...] names it
      if (p[2].kind != Value::Kind::kNone)
        return ErrorOf("value", loc, "wp.tile_view(): 'shape' together with a slice in the offset is ambiguous: "
                                     "the slices give the shape");
      std::vector<int64_t> steps;
      std::vector<int> kept, extents;
      for (int d = 0; d < tt.ndim; ++d) {
        const int extent = tt.fixed_shape[d];
        if (d >= static_cast<int>(given.size()) || (given[d].kind == Value::Kind::kTuple && given[d].name == "slice")) {
          auto part = [&](size_t k, int64_t dflt, bool* given_part) -> Expected<int64_t> {
            *given_part = false;
            if (d >= static_cast<int>(given.size()) || given[d].elems[k].kind == Value::Kind::kNone) return dflt;
            const Value& v = given[d].elems[k];
            if (v.kind != Value::Kind::kVar || v.literal_text.empty() ||
                v.literal_text.find_first_not_of("-0123456789") != std::string::npos || v.literal_text.size() > 12)
              return ErrorOf("value", loc, "wp.tile_view(): slice bounds must be compile-time constant integers");
            *given_part = true;
            return std::stoll(v.literal_text);
          };
          bool has_start, has_stop, has_step;
          WEFT_ASSIGN_OR_RETURN(int64_t step, part(2, 1, &has_step));
          if (step == 0) return ErrorOf("value", loc, "wp.tile_view(): slice step cannot be zero");
          WEFT_ASSIGN_OR_RETURN(int64_t start, part(0, step > 0 ? 0 : extent - 1, &has_start));
          WEFT_ASSIGN_OR_RETURN(int64_t stop, part(1, step > 0 ? extent : -1, &has_stop));
          // Python's slice.indices(extent)
          auto clamp = [&](int64_t v, bool given_part, int64_t lo, int64_t hi) {
            if (!given_part) return v;
            if (v < 0) v += extent;
            return v < lo ? lo : (v > hi ? hi : v);
          };
          start = clamp(start, has_start, step > 0 ? 0 : -1, step > 0 ? extent : extent - 1);
          stop = clamp(stop, has_stop, step > 0 ? 0 : -1, step > 0 ? extent : extent - 1);
          const int64_t count = step > 0 ? (stop > start ? (stop - start + step - 1) / step : 0)
                                         : (start > stop ? (start - stop - step - 1) / -step : 0);
          if (count <= 0) return ErrorOf("value", loc, "wp.tile_view(): an empty tile slice");
          offsets.push_back(EmitConst(Type::Scalar(ScalarKind::kInt64), "wp::int64(" + std::to_string(start) + ")"));
          steps.resize(static_cast<size_t>(d) + 1, 1);
          steps[static_cast<size_t>(d)] = step;
          kept.push_back(d);
          extents.push_back(static_cast<int>(count));
          continue;
        }
        const Value& g = given[d];
        if (g.kind != Value::Kind::kVar || !TypeOf(g.var).is_scalar() || !IsInt(TypeOf(g.var).scalar))
          return ErrorOf("value", loc, "wp.tile_view(): offsets must be integers or slices");
        offsets.push_back(EmitRaw(Type::Scalar(ScalarKind::kInt64), "wp::int64($0)", {g.var}));
      }
      if (kept.empty()) return ErrorOf("value", loc, "wp.tile_view(): a view needs at least one sliced dimension");
      return TileView(a, offsets, kept, extents, loc, steps);
    }
    for (size_t d = 0; d < given.size(); ++d) {
      const Value& g = given[d];
      if (g.kind != Value::Kind::kVar || !TypeOf(g.var).is_scalar() || !IsInt(TypeOf(g.var).scalar))
        return ErrorOf("value", loc, "wp.tile_view(): offsets must be integers or slices");
      if (!g.literal_text.empty() && g.literal_text.find_first_not_of("-0123456789") == std::string::npos &&
          g.literal_text.size() <= 12) {   // a constant offset outside the tile: an error now
        const int64_t o = std::stoll(g.literal_text);
        if (o < 0 || o >= tt.fixed_shape[d])
          return ErrorOf("value", loc, "wp.tile_view(): offset " + g.literal_text + " is out of bounds for axis " +
                                           std::to_string(d) + " with extent " + std::to_string(tt.fixed_shape[d]));
      }
      offsets.push_back(EmitRaw(Type::Scalar(ScalarKind::kInt64), "wp::int64($0)", {g.var}));
    }
    std::vector<int> kept, extents;
    if (p[2].kind == Value::Kind::kNone) {
      for (int d = static_cast<int>(given.size()); d < tt.ndim; ++d) {
        kept.push_back(d);
        extents.push_back(tt.fixed_shape[d]);
      }
      if (kept.empty()) return Error(loc, "wp.tile_view(): an offset for every dimension needs a shape");
    } else {
      WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, shape_of(p[2]));
      if (static_cast<int>(shape.size()) > tt.ndim)
        return Error(loc, "wp.tile_view(): the shape has more dimensions than the tile");
      for (size_t d = 0; d < shape.size(); ++d) {
        kept.push_back(tt.ndim - static_cast<int>(shape.size()) + static_cast<int>(d));
        extents.push_back(shape[d]);
      }
    }
    while (static_cast<int>(offsets.size()) < tt.ndim)
      offsets.push_back(EmitConst(Type::Scalar(ScalarKind::kInt64), "wp::int64(0)"));
    return TileView(a, offsets, kept, extents, loc);
  }
  if (name == "tile_cholesky" || name == "tile_cholesky_inplace" || name == "tile_cholesky_solve" ||
      name == "tile_cholesky_solve_inplace") {
    const bool solve = name.find("solve") != std::string::npos;
    const bool inplace = name.find("inplace") != std::string::npos;
    if (solve) {
      WEFT_RETURN_IF_ERROR(bind({"L", "y", "fill_mode"}, &p));
    } else {
      WEFT_RETURN_IF_ERROR(bind({"A", "fill_mode"}, &p));
    }
    const Value& mode = p[solve ? 2 : 1];
    bool upper = false;
    if (mode.kind != Value::Kind::kNone) {
      if (mode.kind != Value::Kind::kString || (mode.name != "lower" && mode.name != "upper"))
        return ErrorOf("value", loc, "wp." + name + "(): fill_mode must be \"lower\" or \"upper\"");
      upper = mode.name == "upper";
    }
    Value up = Value::OfVar(EmitConst(Type::Bool(), upper ? "true" : "false"));
    std::vector<Value> call_args{p[0]};
    if (solve) call_args.push_back(p[1]);
    call_args.push_back(up);
    WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin(solve ? "tile_cholesky_solve" : "tile_cholesky", call_args, loc));
    if (!inplace) return r;
    return assign_to_arg(0, r);
  }
  if (name == "tile_load_indexed" || name == "tile_store_indexed" || name == "tile_atomic_add_indexed") {
    const bool load = name == "tile_load_indexed";
    if (load) {
      WEFT_RETURN_IF_ERROR(bind({"a", "indices", "shape", "offset", "axis", "storage"}, &p));
    } else {
      WEFT_RETURN_IF_ERROR(bind({"a", "indices", "t", "offset", "axis"}, &p));
    }
    WEFT_ASSIGN_OR_RETURN(int a, value_of(p[0], "a"));
    const Type at = TypeOf(a);
    if (!at.is_array() || at.is_indexed_array() || at.is_fixed_array())
      return Error(loc, "wp." + name + "() takes an array, got " + TypeString(at));
    WEFT_ASSIGN_OR_RETURN(int ix, tile_arg(p[1], "indices"));
    const Type it = TypeOf(ix);
    if (it.ndim != 1 || it.elem() != Type::Int32())
      return ErrorOf("type", loc, "wp." + name + "(): indices must be a 1-D tile of int32, got " + TypeString(it));
    Type tt;
    if (load) {
      WEFT_ASSIGN_OR_RETURN(std::vector<int> shape, shape_of(p[2]));
      tt = Type::Tile(at.elem(), shape);
    } else {
      WEFT_ASSIGN_OR_RETURN(int t, tile_arg(p[2], "t"));
      tt = TypeOf(t);
      if (tt.elem() != at.elem())
        return Error(loc, "wp." + name + "(): the tile holds " + TypeString(tt.elem()) + ", the array " + TypeString(at.elem()));
    }
    if (tt.ndim != at.ndim)
      return Error(loc, "wp." + name + "(): a " + std::to_string(tt.ndim) + "-D tile and a " + std::to_string(at.ndim) +
                            "-D array");
    int64_t axis = 0;
    if (p[4].kind != Value::Kind::kNone) {
      WEFT_ASSIGN_OR_RETURN(axis, const_int(p[4], "axis"));
    }
    if (axis < 0) axis += tt.ndim;
    if (axis < 0 || axis >= tt.ndim)
      return Error(loc, "wp." + name + "(): axis is outside a " + std::to_string(tt.ndim) + "-D tile");
    if (it.fixed_shape[0] < tt.fixed_shape[axis])
      return Error(loc, "wp." + name + "(): " + std::to_string(it.fixed_shape[0]) + " indices for an axis of extent " +
                            std::to_string(tt.fixed_shape[axis]));
    WEFT_ASSIGN_OR_RETURN(std::vector<Value> off, offsets_of(p[3], at.ndim));
    while (off.size() < 4) off.push_back(Value::OfVar(EmitConst(Type::Scalar(ScalarKind::kInt64), "wp::int64(0)")));
    Value ax = Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(axis) + ")"));
    std::vector<Value> full = load ? std::vector<Value>{like(tt), p[0], p[1], ax} : std::vector<Value>{p[0], p[1], p[2], ax};
    full.insert(full.end(), off.begin(), off.end());
    return ResolveAndEmitBuiltin(name, std::move(full), loc);
  }
  if (name == "tile_sort") {
    WEFT_RETURN_IF_ERROR(bind({"keys", "values"}, &p));
    WEFT_ASSIGN_OR_RETURN(int kt, tile_arg(p[0], "keys"));
    if (TypeOf(kt).ndim == 1 && TypeOf(kt).fixed_shape[0] > kMaxTileSortLength)   // an insertion sort: n^2 work
      return ErrorOf("value", loc, "wp.tile_sort() sorts at most " + std::to_string(kMaxTileSortLength) + " elements, got " +
                                       std::to_string(TypeOf(kt).fixed_shape[0]));
    WEFT_ASSIGN_OR_RETURN(Value sorted, ResolveAndEmitBuiltin("tile_sort", {p[0], p[1]}, loc));
    WEFT_ASSIGN_OR_RETURN(Value unused, assign_to_arg(0, sorted.elems.at(0)));
    (void)unused;
    return assign_to_arg(1, sorted.elems.at(1));
  }
  if (name == "tile_fft" || name == "tile_ifft") {   // in place: the transform is assigned to the argument
    WEFT_RETURN_IF_ERROR(bind({"inout"}, &p));
    WEFT_ASSIGN_OR_RETURN(int t, tile_arg(p[0], "inout"));
    const Type tt = TypeOf(t);
    if (!tt.elem().is_vector() || tt.elem().rows != 2 || !IsFloat(tt.elem().scalar))
      return ErrorOf("type", loc, "wp." + name + "() transforms tiles of complex values (vec2 of floats), got " + TypeString(tt));
    // Lengths that are not powers of two take the direct sum (n^2 work per row): bounded.
    const int n = tt.fixed_shape.back();
    if ((n & (n - 1)) != 0 && n > kMaxDirectDftLength)
      return ErrorOf("value", loc, "wp." + name + "(): a transform length that is not a power of two may be at most " +
                                       std::to_string(kMaxDirectDftLength) + ", got " + std::to_string(n));
    WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin(name, {p[0]}, loc));
    return assign_to_arg(0, r);
  }
  if (name == "tile_lower_solve_inplace" || name == "tile_upper_solve_inplace") {
    const bool lower = name == "tile_lower_solve_inplace";
    WEFT_RETURN_IF_ERROR(bind({lower ? "L" : "U", lower ? "y" : "z"}, &p));
    WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin(lower ? "tile_lower_solve" : "tile_upper_solve", {p[0], p[1]}, loc));
    return assign_to_arg(0, r);
  }
  if (name == "tile") {
    WEFT_RETURN_IF_ERROR(bind({"x", "preserve_type"}, &p));
    WEFT_ASSIGN_OR_RETURN(int x, value_of(p[0], "x"));
    const Type xt = TypeOf(x);
    const bool preserve = p[1].kind == Value::Kind::kVar && p[1].literal_text == "True";
    if (lanes_ > 1) {   // lanes: one element per lane of the block (engine/native/lanes.h)
      std::vector<int> shape;
      if (xt.is_vector() && !preserve) shape = {xt.rows, lanes_};
      else if (xt.is_matrix() && !preserve) shape = {xt.rows, xt.cols, lanes_};
      else shape = {lanes_};
      const Type et = shape.size() > 1 ? Type::Scalar(xt.scalar) : xt;
      if (shape.size() == 1 && !xt.is_scalar() && !xt.is_composite() && !xt.is_struct())
        return Error(loc, "wp.tile(x) takes a scalar, vector, matrix, quaternion, transform or struct, got " + TypeString(xt));
      const int like = NewVar(Type::Tile(et, shape), "tile shape");
      return ResolveAndEmitBuiltin(shape.size() > 1 ? "tile_split_lanes" : "tile_lanes", {Value::OfVar(like), p[0]}, loc);
    }
    if ((xt.is_vector() || xt.is_matrix()) && !preserve) return ResolveAndEmitBuiltin("tile_split", {p[0]}, loc);
    if (!xt.is_scalar() && !xt.is_composite() && !xt.is_struct())
      return Error(loc, "wp.tile(x) takes a scalar, vector, matrix, quaternion, transform or struct, got " + TypeString(xt));
    return ResolveAndEmitBuiltin("tile", {p[0]}, loc);
  }
  if (name == "tile_extract") {
    WEFT_ASSIGN_OR_RETURN(int a, tile_arg(args.empty() ? Value() : args[0], "a"));
    if (static_cast<int>(args.size()) - 1 != TypeOf(a).ndim)
      return Error(loc, "wp.tile_extract() takes one index per dimension of the tile (" + std::to_string(TypeOf(a).ndim) + ")");
    for (size_t k = 1; k < args.size(); ++k) {
      if (args[k].kind != Value::Kind::kVar || !TypeOf(args[k].var).is_scalar() || !IsInt(TypeOf(args[k].var).scalar))
        return Error(loc, "wp.tile_extract(): indices must be integers");
      args[k] = Value::OfVar(EmitRaw(Type::Int32(), "wp::int32($0)", {args[k].var}));
    }
    return ResolveAndEmitBuiltin(name, std::move(args), loc);
  }
  // untile, tile_transpose: rows as they are.
  if (call && !call->keywords.empty()) return Error(loc, "wp." + name + "() takes no keyword arguments");
  if (name == "untile" && lanes_ > 1) {   // lanes: the lane's element of a tile of the block's lanes
    if (args.size() != 1 || args[0].kind != Value::Kind::kVar || !TypeOf(args[0].var).is_tile())
      return Error(loc, "wp.untile() takes one tile");
    const Type at = TypeOf(args[0].var);
    if (at.fixed_shape.empty() || at.fixed_shape.back() != lanes_)
      return ErrorOf("value", loc, "wp.untile(): the tile's last dimension must be the block's " + std::to_string(lanes_) +
                                       " threads (block_dim), got " + TypeString(at));
    return ResolveAndEmitBuiltin("untile_lanes", std::move(args), loc);
  }
  return ResolveAndEmitBuiltin(name, std::move(args), loc);
}

Expected<Value> Checker::TileView(int base, std::vector<int> offsets, const std::vector<int>& kept,
                                  const std::vector<int>& extents, const SourceLocation& loc,
                                  const std::vector<int64_t>& steps) {
  const Type tt = TypeOf(base);
  for (size_t d = 0; d < kept.size(); ++d)
    if (steps.empty() && extents[d] > tt.fixed_shape[kept[d]])
      return Error(loc, "a view of extent " + std::to_string(extents[d]) + " in dimension " + std::to_string(kept[d]) +
                            " of a tile of shape " + ShapeText(tt.fixed_shape));
  std::vector<Value> args{Value::OfVar(NewVar(Type::Tile(tt.elem(), extents), "tile shape")), Value::OfVar(base)};
  const std::vector<Value> region = TileRegionArgs(std::move(offsets), steps, kept);
  for (const Value& v : region) args.push_back(v);
  WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin("tile_view", std::move(args), loc));
  last_tile_view_.result = r.var;
  last_tile_view_.base = base;
  last_tile_view_.region = region;
  return r;
}

Status Checker::WriteThroughAlias(const std::string& name, const TileAlias& alias, int value, const SourceLocation& loc) {
  WEFT_RETURN_IF_ERROR(BindLocal(name, value, loc));
  auto base = st_->scope.find(alias.base);
  if (base == st_->scope.end()) return Error(loc, "'" + name + "' views '" + alias.base + "', which is gone");
  Value current = Value::OfVar(base->second);
  auto outer = st_->tile_aliases.find(alias.base);
  if (outer != st_->tile_aliases.end()) {   // the base is itself a view: as it is now
    WEFT_ASSIGN_OR_RETURN(current, ViewOfAlias(outer->second, loc));
  }
  std::vector<Value> args{current, Value::OfVar(value)};
  for (const Value& v : alias.region) args.push_back(v);
  WEFT_ASSIGN_OR_RETURN(Value u, ResolveAndEmitBuiltin("tile_assign", std::move(args), loc));
  if (outer != st_->tile_aliases.end()) {
    const TileAlias next = outer->second;
    return WriteThroughAlias(alias.base, next, u.var, loc);
  }
  return BindLocal(alias.base, u.var, loc);
}

Expected<Value> Checker::ViewOfAlias(const TileAlias& alias, const SourceLocation& loc) {
  auto base = st_->scope.find(alias.base);
  if (base == st_->scope.end()) return Error(loc, "a tile view outlived the tile '" + alias.base + "'");
  Value current = Value::OfVar(base->second);
  auto outer = st_->tile_aliases.find(alias.base);
  if (outer != st_->tile_aliases.end()) {
    const TileAlias next = outer->second;
    WEFT_ASSIGN_OR_RETURN(current, ViewOfAlias(next, loc));
  }
  std::vector<Value> args{Value::OfVar(NewVar(alias.view, "tile shape")), current};
  for (const Value& v : alias.region) args.push_back(v);
  return ResolveAndEmitBuiltin("tile_view", std::move(args), loc);
}

// The region arguments of tile_view / tile_assign: 4 int64 offsets and 4 steps by the tile's
// dimension (missing ones 0 and 1) and the dims code of the kept dimensions.
std::vector<Value> Checker::TileRegionArgs(std::vector<int> offsets, const std::vector<int64_t>& steps,
                                           const std::vector<int>& kept) {
  std::vector<Value> out;
  while (offsets.size() < 4) offsets.push_back(EmitConst(Type::Scalar(ScalarKind::kInt64), "wp::int64(0)"));
  for (int o : offsets) out.push_back(Value::OfVar(o));
  for (size_t d = 0; d < 4; ++d) {
    const int64_t st = d < steps.size() ? steps[d] : 1;
    out.push_back(Value::OfVar(EmitConst(Type::Scalar(ScalarKind::kInt64), "wp::int64(" + std::to_string(st) + ")")));
  }
  int dims = 0;
  for (size_t d = 0; d < kept.size(); ++d) dims |= kept[d] << (4 * d);
  out.push_back(Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(dims) + ")")));
  return out;
}

// The part of a tile a subscript names: t[i, j] (one element: `element`, its int32 indices),
// t[i] (the sub-tile of the remaining dimensions), t[a:b, :] (a sub-tile; slice bounds are
// constants, the step 1): int64 offsets per dimension, the dimensions kept and their extents.
Expected<Checker::TileRegion> Checker::TileRegionOf(const ast::Subscript& s, const Type& tt) {
  TileRegion r;
  if (static_cast<int>(s.indices.size()) > tt.ndim)
    return Error(s.loc, "a " + std::to_string(tt.ndim) + "-D tile takes at most " + std::to_string(tt.ndim) + " indices");
  bool any_slice = false;
  for (const auto& e : s.indices) any_slice |= ast::As<ast::Slice>(e.get()) != nullptr;
  r.element = !any_slice && static_cast<int>(s.indices.size()) == tt.ndim;
  auto const_bound = [&](const ast::Expr* e, int64_t dflt, int extent) -> Expected<int64_t> {
    if (!e) return dflt;
    WEFT_ASSIGN_OR_RETURN(Value v, Eval(*e));
    if (v.kind != Value::Kind::kVar || v.literal_text.empty() ||
        v.literal_text.find_first_not_of("-0123456789") != std::string::npos || v.literal_text.size() > 12)
      return Error(e->loc, "tile slice bounds must be integer constants");
    int64_t n = std::stoll(v.literal_text);
    if (n < 0) n += extent;
    return n < 0 ? 0 : (n > extent ? extent : n);
  };
  for (int d = 0; d < tt.ndim; ++d) {
    const int extent = tt.fixed_shape[d];
    const ast::Expr* e = d < static_cast<int>(s.indices.size()) ? s.indices[d].get() : nullptr;
    const auto* sl = e ? ast::As<ast::Slice>(e) : nullptr;
    if (e && !sl) {
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*e));
      if (v.kind != Value::Kind::kVar || !TypeOf(v.var).is_scalar() || !IsInt(TypeOf(v.var).scalar))
        return Error(e->loc, "tile indices must be integers or slices");
      // NumPy's rule: a negative index counts from the end. A constant outside the extent is a
      // compile error; a runtime one is wrapped here and checked by the op at launch.
      int index;
      if (!v.literal_text.empty() && v.literal_text.find_first_not_of("-0123456789") == std::string::npos &&
          v.literal_text.size() <= 12) {
        int64_t n = std::stoll(v.literal_text);
        if (n < -extent || n >= extent)
          return ErrorOf("value", e->loc, "tile index " + v.literal_text + " is out of bounds for axis " +
                                              std::to_string(d) + " with extent " + std::to_string(extent));
        if (n < 0) n += extent;
        index = EmitConst(Type::Scalar(ScalarKind::kInt64), "wp::int64(" + std::to_string(n) + ")");
      } else {
        index = EmitRaw(Type::Scalar(ScalarKind::kInt64), "wp::tile_wrap_index(wp::int64($0), " + std::to_string(extent) + ")",
                        {v.var});
      }
      if (r.element) {
        r.indices.push_back(EmitRaw(Type::Int32(), "wp::int32($0)", {index}));
        continue;
      }
      r.offsets.push_back(index);
      continue;
    }
    // Python's slice rules with constant bounds: the first element and the count.
    int64_t step = 1, first = 0, count = extent;
    if (sl) {
      if (sl->step) {
        WEFT_ASSIGN_OR_RETURN(Value sv, Eval(*sl->step));
        if (sv.kind != Value::Kind::kVar || sv.literal_text.empty() ||
            sv.literal_text.find_first_not_of("-0123456789") != std::string::npos || sv.literal_text.size() > 12)
          return Error(sl->step->loc, "tile slice steps must be integer constants");
        step = std::stoll(sv.literal_text);
        if (step == 0) return ErrorOf("value", sl->step->loc, "slice step cannot be zero");
      }
      if (step > 0) {
        WEFT_ASSIGN_OR_RETURN(int64_t lo, const_bound(sl->lower.get(), 0, extent));
        WEFT_ASSIGN_OR_RETURN(int64_t hi, const_bound(sl->upper.get(), extent, extent));
        first = lo;
        count = hi > lo ? (hi - lo + step - 1) / step : 0;
      } else {
        auto back = [&](const ast::Expr* e, int64_t dflt) -> Expected<int64_t> {   // clamped to [-1, extent - 1]
          if (!e) return dflt;
          WEFT_ASSIGN_OR_RETURN(int64_t n, const_bound(e, dflt, extent));
          WEFT_ASSIGN_OR_RETURN(Value v, Eval(*e));
          const int64_t raw = std::stoll(v.literal_text);
          if (raw < 0 && raw + extent < 0) return int64_t{-1};
          return n > extent - 1 ? extent - 1 : n;
        };
        WEFT_ASSIGN_OR_RETURN(int64_t lo, back(sl->lower.get(), extent - 1));
        WEFT_ASSIGN_OR_RETURN(int64_t hi, back(sl->upper.get(), -1));
        first = lo;
        count = lo > hi ? (lo - hi + (-step) - 1) / (-step) : 0;
      }
      if (count <= 0) return Error(sl->loc, "an empty tile slice");
    }
    r.offsets.push_back(EmitConst(Type::Scalar(ScalarKind::kInt64), "wp::int64(" + std::to_string(first) + ")"));
    r.steps.resize(static_cast<size_t>(d) + 1, 1);
    r.steps[static_cast<size_t>(d)] = step;
    r.kept.push_back(d);
    r.extents.push_back(static_cast<int>(count));
  }
  return r;
}

Expected<Value> Checker::TileSubscript(const ast::Subscript& s, const Value& base) {
  const Type bt = TypeOf(base.var);
  // t[idx, :]: a 1-D tile of integers on one axis, ':' on the others (a gather).
  for (size_t d = 0; d < s.indices.size(); ++d) {
    if (ast::As<ast::Slice>(s.indices[d].get())) continue;
    WEFT_ASSIGN_OR_RETURN(Value iv, Eval(*s.indices[d]));
    if (iv.kind != Value::Kind::kVar || !TypeOf(iv.var).is_tile()) continue;
    const Type it = TypeOf(iv.var);
    if (it.ndim != 1 || !it.elem().is_scalar() || !IsInt(it.elem().scalar))
      return ErrorOf("type", s.indices[d]->loc, "a tile index must be a 1-D integer index tile, got " + TypeString(it));
    for (size_t o = 0; o < s.indices.size(); ++o) {
      if (o == d) continue;
      const auto* sl = ast::As<ast::Slice>(s.indices[o].get());
      if (!sl || sl->lower || sl->upper || sl->step)
        return ErrorOf("value", s.indices[o]->loc, "indexing a tile with an index tile requires ':' on all other axes");
    }
    std::vector<int> shape = bt.fixed_shape;
    shape[d] = it.fixed_shape[0];
    const int like = NewVar(Type::Tile(bt.elem(), shape), "tile shape");
    const int axis = EmitConst(Type::Int32(), "wp::int32(" + std::to_string(d) + ")");
    return ResolveAndEmitBuiltin("tile_gather", {Value::OfVar(like), base, iv, Value::OfVar(axis)}, s.loc);
  }
  WEFT_ASSIGN_OR_RETURN(TileRegion r, TileRegionOf(s, TypeOf(base.var)));
  if (r.element) {
    std::vector<Value> args{base};
    for (int i : r.indices) args.push_back(Value::OfVar(i));
    return ResolveAndEmitBuiltin("tile_extract", std::move(args), s.loc);
  }
  return TileView(base.var, r.offsets, r.kept, r.extents, s.loc, r.steps);
}

// t[i, j] = v (an element), t[i] = row, t[a:b, :] = block (a tile of the part's shape): the
// updated tile, which the caller assigns to t.
Expected<int> Checker::TileUpdate(const ast::Subscript& s, const Value& base, const Value& value) {
  const Type tt = TypeOf(base.var);
  WEFT_ASSIGN_OR_RETURN(TileRegion r, TileRegionOf(s, tt));
  if (r.element) {
    std::string row = "tile_insert";
    Value element = value;
    const bool lane_update = lane_update_.active;
    if (lane_update) {   // `t[i] op= v` with lanes: every lane's v combined into the element
      lane_update_.active = false;
      element = lane_update_.value;
      const ast::BinaryOperator op = lane_update_.op;
      row = op == ast::BinaryOperator::kBitAnd  ? "tile_lanes_bit_and"
            : op == ast::BinaryOperator::kBitOr ? "tile_lanes_bit_or"
            : op == ast::BinaryOperator::kBitXor ? "tile_lanes_bit_xor"
                                                 : "tile_scatter_add";
    }
    WEFT_ASSIGN_OR_RETURN(int v, Coerce(element, tt.elem(), s.loc, "the tile element"));
    if (lane_update && lane_update_.op == ast::BinaryOperator::kSub) {
      const bool saved = struct_arithmetic_;
      struct_arithmetic_ = tt.elem().is_struct();
      Expected<Value> negated = ResolveAndEmitBuiltin("neg", {Value::OfVar(v)}, s.loc);
      struct_arithmetic_ = saved;
      WEFT_ASSIGN_OR_RETURN(Value n, std::move(negated));
      v = n.var;
    }
    std::vector<Value> args{base};
    for (int i : r.indices) args.push_back(Value::OfVar(i));
    args.push_back(Value::OfVar(v));
    if (row == "tile_scatter_add") args.push_back(Value::OfVar(EmitConst(Type::Bool(), "true")));
    WEFT_ASSIGN_OR_RETURN(Value u, ResolveAndEmitBuiltin(row, std::move(args), s.loc));
    return u.var;
  }
  const Type vt = TypeOf(value.var);
  if (!vt.is_tile() || vt.fixed_shape != r.extents)
    return ErrorOf("value", s.loc, "shape mismatch: assigning to a tile view requires a tile of matching shape " +
                                       ShapeText(r.extents) + ", got " + TypeString(vt));
  Value src = value;
  if (vt.elem() != tt.elem()) {
    if (!vt.elem().is_scalar() || !tt.elem().is_scalar())
      return Error(s.loc, "cannot assign a " + TypeString(vt) + " into a " + TypeString(tt));
    WEFT_ASSIGN_OR_RETURN(src, ResolveAndEmitBuiltin("tile_astype", {Value::OfVar(NewVar(Type::Tile(tt.elem(), vt.fixed_shape), "tile shape")), value}, s.loc));
  }
  std::vector<Value> args{base, src};
  for (const Value& v : TileRegionArgs(r.offsets, r.steps, r.kept)) args.push_back(v);
  WEFT_ASSIGN_OR_RETURN(Value u, ResolveAndEmitBuiltin("tile_assign", std::move(args), s.loc));
  return u.var;
}

// wp.tile_map(f, a, b, ...) and wp.tile_reduce(f, a): f (a builtin or a @wp.func) is resolved
// for the element types as an ordinary call would be, in a scratch block, and must come out as
// one call taking the element values as they are.
Expected<Value> Checker::TileMap(const std::string& name, std::vector<Value> args, const SourceLocation& loc,
                                 const ast::Call* call) {
  const bool reduce = name == "tile_reduce";
  // tile_reduce(op, a, axis): a constant axis (positional or keyword).
  Value axis_v;
  if (call)
    for (const auto& kw : call->keywords) {
      if (!reduce || kw.name != "axis") return Error(kw.loc, "wp." + name + "() has no parameter '" + kw.name + "'");
      WEFT_ASSIGN_OR_RETURN(axis_v, Eval(*kw.value));
    }
  if (reduce && args.size() == 3 && axis_v.kind == Value::Kind::kNone) {
    axis_v = args[2];
    args.pop_back();
  }
  if (args.size() < 2 || (reduce && args.size() != 2))
    return Error(loc, reduce ? "wp.tile_reduce() takes (op, a[, axis])" : "wp.tile_map() takes (op, a, ...)");
  const Value f = args[0];
  if (f.kind != Value::Kind::kBuiltin && f.kind != Value::Kind::kFunc)
    return Error(loc, "wp." + name + "(): the first argument must be a builtin or a @wp.func");
  std::vector<int> shape;
  std::vector<Value> inputs(args.begin() + 1, args.end());
  std::vector<Value> elems;
  std::vector<bool> is_tile;
  for (const Value& a : inputs) {
    if (a.kind != Value::Kind::kVar) return Error(loc, "wp." + name + "(): arguments must be values");
    const Type t = TypeOf(a.var);
    if (!t.is_tile()) {
      if (reduce) return Error(loc, "wp.tile_reduce(): a must be a tile, got " + TypeString(t));
      elems.push_back(a);
      is_tile.push_back(false);
      continue;
    }
    if (shape.empty()) shape = t.fixed_shape;
    if (t.fixed_shape != shape)
      return Error(loc, "wp." + name + "(): tiles of different shapes (" + TypeString(TypeOf(inputs[0].var)) + ", " +
                            TypeString(t) + ")");
    elems.push_back(Value::OfVar(NewVar(t.elem(), "tile element")));
    is_tile.push_back(true);
  }
  if (shape.empty()) return Error(loc, "wp." + name + "() needs a tile argument");
  if (reduce) elems.push_back(Value::OfVar(NewVar(TypeOf(elems[0].var), "tile element")));

  std::vector<Stmt> scratch;
  std::vector<Stmt>* saved = st_->block;
  st_->block = &scratch;
  const bool saved_struct_arithmetic = struct_arithmetic_;
  struct_arithmetic_ = f.kind == Value::Kind::kBuiltin;   // a builtin applied to struct elements
  auto r = f.kind == Value::Kind::kBuiltin ? CallBuiltin(f.name, elems, loc, nullptr) : CallUserFunc(f.name, elems, loc);
  struct_arithmetic_ = saved_struct_arithmetic;
  st_->block = saved;
  const Type elem0 = TypeOf(elems[0].var);
  if (!r.ok() && reduce && elem0.is_struct())   // Warp's message
    return ErrorOf("type", loc, "tile_reduce() operator " + f.name + " has no overload accepting Warp struct tile element type " +
                                    WarpTypeRepr(elem0));
  if (!r.ok()) return r.status();
  const std::string what = "wp." + name + "(" + f.name + ", ...)";
  if (scratch.empty() || scratch.back().kind != Stmt::Kind::kOp ||
      (scratch.back().op.kind != OpKind::kCall && scratch.back().op.kind != OpKind::kFuncCall) ||
      scratch.back().op.dst.size() != 1 || scratch.back().op.args.size() != elems.size())
    return Error(loc, what + ": the function must return one value per element");
  const Op elem_call = scratch.back().op;
  if (elem_call.builtin && (elem_call.builtin->needs_ctx() ||
                            (elem_call.builtin->flags & (kBuiltinNeedsLoc | kBuiltinArrayAccess | kBuiltinWritesArgs |
                                                         kBuiltinSideEffect))))
    return Error(loc, what + ": this builtin cannot be applied element-wise");
  // Elements pass as they are; a non-tile argument may have been converted (a literal).
  std::vector<int> op_args;
  for (size_t k = 0; k < inputs.size(); ++k) {
    if (is_tile[k] && elem_call.args[k] != elems[k].var)
      return Error(loc, what + ": the function must take the tiles' element type " + TypeString(TypeOf(elems[k].var)) +
                            " as it is");
    op_args.push_back(is_tile[k] ? inputs[k].var : elem_call.args[k]);
  }
  if (reduce && (elem_call.args[0] != elems[0].var || elem_call.args[1] != elems[1].var))
    return Error(loc, what + ": the function must take two elements as they are");
  const Type result = TypeOf(elem_call.dst[0]);
  if (reduce && result != elem0)
    return ErrorOf("type", loc, "tile_reduce() operator " + f.name + " must return the tile element type " +
                                    WarpTypeRepr(elem0) + ", got " + WarpTypeRepr(result));
  if (!result.is_scalar() && !result.is_composite() && !result.is_struct())
    return Error(loc, what + ": tile elements are scalars, vectors, matrices, quaternions, transforms or structs");
  for (size_t k = 0; k + 1 < scratch.size(); ++k) {   // conversions of non-tile arguments
    for (int a : scratch[k].op.args)
      for (const Value& e : elems)
        if (a == e.var) return Error(loc, what + ": the function must take the tiles' elements as they are");
    st_->block->push_back(scratch[k]);
  }
  Stmt s;
  s.op.kind = reduce ? OpKind::kTileReduce : OpKind::kTileMap;
  s.op.builtin = elem_call.builtin;
  s.op.callee = elem_call.callee;
  s.op.args = op_args;
  std::vector<int> out_shape = reduce ? std::vector<int>{1} : shape;
  if (reduce && axis_v.kind != Value::Kind::kNone) {
    if (axis_v.kind != Value::Kind::kVar || axis_v.literal_text.empty() ||
        axis_v.literal_text.find_first_not_of("-0123456789") != std::string::npos || axis_v.literal_text.size() > 3)
      return Error(loc, "wp.tile_reduce(): axis must be an integer constant");
    int axis = std::stoi(axis_v.literal_text);
    const int nd = static_cast<int>(shape.size());
    if (axis < 0) axis += nd;
    if (axis < 0 || axis >= nd)
      return Error(loc, "wp.tile_reduce(): axis " + axis_v.literal_text + " is outside a " + std::to_string(nd) + "-D tile");
    if (nd > 1) {
      out_shape = shape;
      out_shape.erase(out_shape.begin() + axis);
      const int like = NewVar(Type::Tile(result, out_shape), "tile shape");
      s.op.args = {like, op_args[0], EmitConst(Type::Int32(), "wp::int32(" + std::to_string(axis) + ")")};
    }
  }
  const int d = NewVar(Type::Tile(result, out_shape));
  s.op.dst.push_back(d);
  if (elem_call.callee >= 0) st_->fn.may_fail |= module_.functions[elem_call.callee].may_fail;
  Push(std::move(s));
  return Value::OfVar(d);
}

}  // namespace weft::sema
