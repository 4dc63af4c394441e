// Semantic analysis, expression level: names (locals, client symbols, Python builtins, the
// wp module), literals with Warp's rules (int -> int32, float -> float32, literals adapt to a
// typed operand), operators, comparisons, component/array/struct access, and calls:
// builtins through the registry, type constructors, user funcs (overloads, generics).
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "engine/sema/check_impl.h"
#include "engine/sema/printf_format.h"

namespace weft::sema {
namespace {

const std::map<ast::BinaryOperator, std::string>& BinaryBuiltins() {
  static const std::map<ast::BinaryOperator, std::string> kNames = {
      {ast::BinaryOperator::kAdd, "add"},       {ast::BinaryOperator::kSub, "sub"},
      {ast::BinaryOperator::kMul, "mul"},       {ast::BinaryOperator::kMatMul, "mul"},
      {ast::BinaryOperator::kDiv, "div"},       {ast::BinaryOperator::kFloorDiv, "floordiv"},
      {ast::BinaryOperator::kMod, "mod"},       {ast::BinaryOperator::kPow, "pow"},
      {ast::BinaryOperator::kLShift, "lshift"}, {ast::BinaryOperator::kRShift, "rshift"},
      {ast::BinaryOperator::kBitOr, "bit_or"},  {ast::BinaryOperator::kBitXor, "bit_xor"},
      {ast::BinaryOperator::kBitAnd, "bit_and"},
  };
  return kNames;
}

// Function symbol target of a global bound to a builtin: "__weft_builtin__.<name>" (a dotted
// name, as every function target; no module of a Python program is named so).
constexpr const char* kBuiltinTargetPrefix = "__weft_builtin__.";


std::string FloatText(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  std::string s = buf;
  if (s.find_first_of(".eE") == std::string::npos) s += ".0";
  return s;
}

// Builtins whose call rules live here rather than in the registry.
bool IsSpecialBuiltin(const std::string& n) {
  static const std::set<std::string> kNames = {"tid",          "len",           "range",
                                               "printf",       "print",         "vector",
                                               "matrix",       "identity",      "quat_identity",
                                               "transform_identity", "quaternion", "transformation",
                                               "zeros",        "cast",          "static",
                                               "adjoint"};
  return kNames.count(n) != 0 || IsTileCall(n);
}

}  // namespace

bool IsIntLiteralText(const std::string& t) {
  if (t.empty()) return false;
  size_t i = (t[0] == '-' || t[0] == '+') ? 1 : 0;
  if (i >= t.size()) return false;
  for (; i < t.size(); ++i)
    if (!std::isdigit(static_cast<unsigned char>(t[i]))) return false;
  return true;
}

std::string ExprText(const ast::Expr& e) {
  if (const auto* n = ast::As<ast::Name>(&e)) return n->id;
  if (const auto* a = ast::As<ast::Attribute>(&e)) return ExprText(*a->value) + "." + a->attr;
  if (const auto* c = ast::As<ast::Constant>(&e)) return c->text;
  if (const auto* s = ast::As<ast::Subscript>(&e)) {
    std::string out = ExprText(*s->value) + "[";
    for (size_t i = 0; i < s->indices.size(); ++i) out += (i ? ", " : "") + ExprText(*s->indices[i]);
    return out + "]";
  }
  if (const auto* c = ast::As<ast::Call>(&e)) return ExprText(*c->func) + "(...)";
  return "<expr>";
}

Expected<std::string> CppLiteral(const Type& t, const std::string& text) {
  std::string s = text;
  while (!s.empty() && s.front() == ' ') s.erase(s.begin());
  while (!s.empty() && s.back() == ' ') s.pop_back();
  if (t.is_scalar()) {
    if (t.scalar == ScalarKind::kBool) {
      if (s == "True" || s == "1") return std::string("true");
      if (s == "False" || s == "0") return std::string("false");
      return InvalidArgument("'" + s + "' is not a bool literal");
    }
    std::string ct = CppType(t);
    if (IsInt(t.scalar)) {
      if (s == "True") s = "1";
      if (s == "False") s = "0";
      if (!IsIntLiteralText(s)) return InvalidArgument("'" + s + "' is not an integer literal");
      return ct + "(" + s + (ScalarSize(t.scalar) == 8 ? (IsSigned(t.scalar) ? "ll" : "ull") : "") + ")";
    }
    if (s == "inf" || s == "+inf") return ct + "(wp::positive_inf())";
    if (s == "-inf") return ct + "(-wp::positive_inf())";
    if (s == "nan" || s == "-nan") return ct + "(wp::quiet_nan())";
    char* end = nullptr;
    double v = std::strtod(s.c_str(), &end);
    if (s.empty() || *end != '\0') {
      if (s == "True") v = 1;
      else if (s == "False") v = 0;
      else return InvalidArgument("'" + s + "' is not a number");
    }
    std::string f = FloatText(v);
    if (t.scalar == ScalarKind::kFloat16 || t.scalar == ScalarKind::kBFloat16) return ct + "(" + f + "f)";
    return ct + "(" + f + ")";
  }
  if (t.is_composite()) {
    // "(1.0, 2.0, 3.0)" or nested "((1, 0), (0, 1))": flatten the numbers.
    std::vector<std::string> parts;
    std::string cur;
    for (char c : s) {
      if (c == '(' || c == ')' || c == '[' || c == ']' || c == ',') {
        if (!cur.empty()) parts.push_back(cur);
        cur.clear();
      } else if (c != ' ') {
        cur += c;
      }
    }
    if (!cur.empty()) parts.push_back(cur);
    if (static_cast<int>(parts.size()) != t.component_count())
      return InvalidArgument("constant '" + s + "' has " + std::to_string(parts.size()) + " components; " +
                             TypeString(t) + " needs " + std::to_string(t.component_count()));
    std::string out = "wp::cg_concat<" + CppType(t) + ">(";
    for (size_t i = 0; i < parts.size(); ++i) {
      WEFT_ASSIGN_OR_RETURN(std::string p, CppLiteral(Type::Scalar(t.scalar), parts[i]));
      out += (i ? ", " : "") + p;
    }
    return out + ")";
  }
  return InvalidArgument("constants of type " + TypeString(t) + " are not supported");
}

// ---------------------------------------------------------------------------------------
// Expressions
// ---------------------------------------------------------------------------------------

Expected<Value> Checker::Eval(const ast::Expr& e) {
  switch (e.kind) {
    case ast::ExprKind::kName: return EvalName(static_cast<const ast::Name&>(e));
    case ast::ExprKind::kConstant: return EvalConstant(static_cast<const ast::Constant&>(e));
    case ast::ExprKind::kAttribute: return EvalAttribute(static_cast<const ast::Attribute&>(e));
    case ast::ExprKind::kSubscript: return EvalSubscript(static_cast<const ast::Subscript&>(e));
    case ast::ExprKind::kSlice: return Error(e.loc, "slices are not supported in kernels");
    case ast::ExprKind::kCall: return EvalCall(static_cast<const ast::Call&>(e));
    case ast::ExprKind::kBinOp: return EvalBinOp(static_cast<const ast::BinOp&>(e));
    case ast::ExprKind::kUnaryOp: {
      const auto& u = static_cast<const ast::UnaryOp&>(e);
      if (u.op == ast::UnaryOperator::kNot) {
        WEFT_ASSIGN_OR_RETURN(int c, EvalCond(*u.operand));
        return Value::OfVar(EmitRaw(Type::Bool(), "!$0", {c}));
      }
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*u.operand));
      if (u.op == ast::UnaryOperator::kMinus && v.kind == Value::Kind::kVar && v.literal) {
        std::string text = v.literal_text[0] == '-' ? v.literal_text.substr(1) : "-" + v.literal_text;
        WEFT_ASSIGN_OR_RETURN(std::string cpp, CppLiteral(TypeOf(v.var), text));
        Value r = Value::OfVar(EmitConst(TypeOf(v.var), cpp));
        r.literal = true;
        r.literal_text = text;
        return r;
      }
      const char* fn = u.op == ast::UnaryOperator::kMinus ? "neg" : u.op == ast::UnaryOperator::kPlus ? "pos" : "invert";
      return ResolveAndEmitBuiltin(fn, {v}, e.loc);
    }
    case ast::ExprKind::kBoolOp: {
      const auto& b = static_cast<const ast::BoolOp&>(e);
      bool lazy = false;
      for (size_t i = 1; i < b.values.size(); ++i) lazy = lazy || MayFailOrHaveEffects(*b.values[i]);
      if (lazy && CanBranchHere()) {
        WEFT_ASSIGN_OR_RETURN(int r, EvalShortCircuit(b, 0));
        return Value::OfVar(r);
      }
      std::vector<int> vs;
      std::string text = "(";
      for (size_t i = 0; i < b.values.size(); ++i) {
        WEFT_ASSIGN_OR_RETURN(int c, EvalCond(*b.values[i]));
        vs.push_back(c);
        text += (i ? (b.op == ast::BoolOperator::kAnd ? " && $" : " || $") : "$") + std::to_string(i);
      }
      return Value::OfVar(EmitRaw(Type::Bool(), text + ")", vs));
    }
    case ast::ExprKind::kCompare: return EvalCompare(static_cast<const ast::Compare&>(e));
    case ast::ExprKind::kIfExp: {
      const auto& i = static_cast<const ast::IfExp&>(e);
      WEFT_ASSIGN_OR_RETURN(int c, EvalCond(*i.test));
      if ((MayFailOrHaveEffects(*i.body) || MayFailOrHaveEffects(*i.orelse)) && CanBranchHere())
        return EvalConditionalBranches(i, c);
      WEFT_ASSIGN_OR_RETURN(Value a, Eval(*i.body));
      WEFT_ASSIGN_OR_RETURN(Value b, Eval(*i.orelse));
      WEFT_ASSIGN_OR_RETURN(auto branches, UnifyConditionalBranches(i, a, b));
      return Value::OfVar(EmitOp(OpKind::kPhi, TypeOf(branches.first), {c, branches.first, branches.second}));
    }
    case ast::ExprKind::kTuple: {
      const auto& t = static_cast<const ast::Tuple&>(e);
      Value v;
      v.kind = Value::Kind::kTuple;
      for (const auto& el : t.elts) {
        WEFT_ASSIGN_OR_RETURN(Value x, Eval(*el));
        v.elems.push_back(x);
      }
      return v;
    }
    case ast::ExprKind::kList: return Error(e.loc, "lists are not supported in kernels; use a vector type");
    case ast::ExprKind::kStarred:
      return ErrorOf("type", e.loc, "Starred expressions are only supported as positional arguments of a call");
  }
  return Error(e.loc, "unsupported expression");
}

// ---------------------------------------------------------------------------------------
// Conditional evaluation: `a and b`, `a or b` and `x if c else y` evaluate an operand only
// when Python would. An operand that can fail (an array access, a bounds check) or act (a
// call) is lowered inside an `if`, so `arr and arr[i] == 0` never reads a None array and
// `t if i < 0 else a[i]` never reads a[-1]; pure operands keep a select.
// ---------------------------------------------------------------------------------------

bool Checker::MayFailOrHaveEffects(const ast::Expr& e) const {
  bool found = false;
  std::function<void(const ast::Expr&)> walk = [&](const ast::Expr& x) {
    if (found) return;
    switch (x.kind) {
      case ast::ExprKind::kSubscript:
      case ast::ExprKind::kCall: found = true; return;
      case ast::ExprKind::kAttribute: walk(*static_cast<const ast::Attribute&>(x).value); return;
      case ast::ExprKind::kBinOp: {
        const auto& b = static_cast<const ast::BinOp&>(x);
        walk(*b.left), walk(*b.right);
        return;
      }
      case ast::ExprKind::kUnaryOp: walk(*static_cast<const ast::UnaryOp&>(x).operand); return;
      case ast::ExprKind::kBoolOp:
        for (const auto& v : static_cast<const ast::BoolOp&>(x).values) walk(*v);
        return;
      case ast::ExprKind::kCompare: {
        const auto& c = static_cast<const ast::Compare&>(x);
        walk(*c.left);
        for (const auto& v : c.comparators) walk(*v);
        return;
      }
      case ast::ExprKind::kIfExp: {
        const auto& i = static_cast<const ast::IfExp&>(x);
        walk(*i.test), walk(*i.body), walk(*i.orelse);
        return;
      }
      case ast::ExprKind::kTuple:
        for (const auto& v : static_cast<const ast::Tuple&>(x).elts) walk(*v);
        return;
      default: return;
    }
  };
  walk(e);
  return found;
}

// Branches need a statement list to go into, and lanes of a cooperative block must all reach
// the block's synchronizations, so there an operand is evaluated unconditionally.
bool Checker::CanBranchHere() const { return st_ != nullptr && st_->block != nullptr && lanes_ == 1; }

std::string Checker::HiddenLocalName(const char* what) {
  return std::string("$") + what + std::to_string(hidden_locals_++);   // never a Python identifier
}

Expected<int> Checker::EvalShortCircuit(const ast::BoolOp& b, size_t first) {
  WEFT_ASSIGN_OR_RETURN(int c, EvalCond(*b.values[first]));
  if (first + 1 == b.values.size()) return c;
  const std::string name = HiddenLocalName("bool");
  st_->scope[name] = c;
  const int go_on = b.op == ast::BoolOperator::kAnd ? c : EmitRaw(Type::Bool(), "!$0", {c});
  WEFT_RETURN_IF_ERROR(LowerIf(go_on, [&]() -> Status {
    WEFT_ASSIGN_OR_RETURN(int rest, EvalShortCircuit(b, first + 1));
    st_->scope[name] = rest;
    return Status::Ok();
  }, {}));
  const int result = st_->scope[name];
  st_->scope.erase(name);
  return result;
}

Expected<std::pair<int, int>> Checker::UnifyConditionalBranches(const ast::IfExp& i, const Value& a, const Value& b) {
  if (a.kind != Value::Kind::kVar || b.kind != Value::Kind::kVar)
    return Error(i.loc, "both branches of a conditional expression must be values");
  int av = a.var, bv = b.var;
  if (a.literal && !b.literal) {
    WEFT_ASSIGN_OR_RETURN(av, Coerce(a, TypeOf(bv), i.body->loc, "the first branch"));
  } else if (b.literal && !a.literal) {
    WEFT_ASSIGN_OR_RETURN(bv, Coerce(b, TypeOf(av), i.orelse->loc, "the second branch"));
  }
  if (TypeOf(av) != TypeOf(bv))
    return Error(i.loc, "the branches of a conditional expression have types " + TypeString(TypeOf(av)) + " and " +
                            TypeString(TypeOf(bv)));
  return std::make_pair(av, bv);
}

namespace {
bool IsLiteralExpr(const ast::Expr& e) {
  if (ast::As<ast::Constant>(&e)) return true;
  const auto* u = ast::As<ast::UnaryOp>(&e);
  return u && u->op == ast::UnaryOperator::kMinus && ast::As<ast::Constant>(u->operand.get());
}
}  // namespace

// `x if c else y` with a branch that must not run unless chosen: each branch in its own arm of an
// `if`. A literal branch takes the other branch's type, so the arm with the literal goes second.
Expected<Value> Checker::EvalConditionalBranches(const ast::IfExp& i, int cond) {
  const bool swap = IsLiteralExpr(*i.body) && !IsLiteralExpr(*i.orelse);
  const ast::Expr& first = swap ? *i.orelse : *i.body;
  const ast::Expr& second = swap ? *i.body : *i.orelse;
  const int arm_cond = swap ? EmitRaw(Type::Bool(), "!$0", {cond}) : cond;
  const std::string name = HiddenLocalName("ifexp");
  Value first_value;
  WEFT_RETURN_IF_ERROR(LowerIf(
      arm_cond,
      [&]() -> Status {
        WEFT_ASSIGN_OR_RETURN(first_value, Eval(first));
        if (first_value.kind != Value::Kind::kVar)
          return Error(i.loc, "both branches of a conditional expression must be values");
        st_->scope[name] = first_value.var;
        return Status::Ok();
      },
      [&]() -> Status {
        WEFT_ASSIGN_OR_RETURN(Value second_value, Eval(second));
        const Value& a = swap ? second_value : first_value;
        const Value& b = swap ? first_value : second_value;
        WEFT_ASSIGN_OR_RETURN(auto branches, UnifyConditionalBranches(i, a, b));
        // The first arm's value is already final: only the second arm's may be converted.
        if ((swap ? branches.second : branches.first) != first_value.var)
          return Error(i.loc, "the branches of a conditional expression have types " +
                                  TypeString(TypeOf(branches.first)) + " and " + TypeString(TypeOf(branches.second)));
        st_->scope[name] = swap ? branches.first : branches.second;
        return Status::Ok();
      }));
  const int result = st_->scope[name];
  st_->scope.erase(name);
  return Value::OfVar(result);
}

Expected<int> Checker::EvalVar(const ast::Expr& e) {
  WEFT_ASSIGN_OR_RETURN(Value v, Eval(e));
  if (v.kind != Value::Kind::kVar) return Error(e.loc, "'" + ExprText(e) + "' is not a value");
  return v.var;
}

Expected<int> Checker::EvalCond(const ast::Expr& e) {
  WEFT_ASSIGN_OR_RETURN(Value v, Eval(e));
  if (v.kind != Value::Kind::kVar) return Error(e.loc, "'" + ExprText(e) + "' is not a value");
  const Type& t = TypeOf(v.var);
  if (t == Type::Bool()) return v.var;
  if (t.is_scalar() && IsInt(t.scalar)) return EmitRaw(Type::Bool(), "($0 != 0)", {v.var});
  // An array is true unless it is None (Warp's `if arr:` / `if not arr:`).
  if (t.is_array() && !t.is_fixed_array()) return EmitRaw(Type::Bool(), "(!wp::is_null($0))", {v.var});
  return Error(e.loc, "a condition must be bool, an integer or an array, got " + TypeString(t));
}

Expected<Value> Checker::EvalConstant(const ast::Constant& c) {
  Value v;
  switch (c.type) {
    case ast::Constant::Type::kInt: {
      if (!c.int_fits_u64) return Error(c.loc, "integer literal " + c.text + " does not fit in 64 bits");
      // int32 when it fits, else int64, else (2^63 .. 2^64-1, as in wp.uint64(0xFF51AFD7ED558CCD)) uint64.
      Type t = c.int_value <= 2147483647ull           ? Type::Int32()
               : c.int_value <= 9223372036854775807ull ? Type::Scalar(ScalarKind::kInt64)
                                                       : Type::Scalar(ScalarKind::kUInt64);
      std::string text = std::to_string(c.int_value);
      WEFT_ASSIGN_OR_RETURN(std::string cpp, CppLiteral(t, text));
      v = Value::OfVar(EmitConst(t, cpp));
      v.literal = true;
      v.literal_text = text;
      return v;
    }
    case ast::Constant::Type::kFloat: {
      std::string text = FloatText(c.float_value);
      WEFT_ASSIGN_OR_RETURN(std::string cpp, CppLiteral(Type::Float32(), text));
      v = Value::OfVar(EmitConst(Type::Float32(), cpp));
      v.literal = true;
      v.literal_text = text;
      return v;
    }
    case ast::Constant::Type::kBool:   // the text lets constant flags be read (tile_load's bounds_check=False)
      v = Value::OfVar(EmitConst(Type::Bool(), c.bool_value ? "true" : "false"));
      v.literal_text = c.bool_value ? "True" : "False";
      return v;
    case ast::Constant::Type::kString:
      v.kind = Value::Kind::kString;
      v.name = c.string_value;
      return v;
    case ast::Constant::Type::kNone: v.kind = Value::Kind::kNone; return v;
  }
  return Error(c.loc, "unsupported literal");
}

Expected<Value> Checker::EvalConstantSymbol(const weft::ConstantValue& c, const SourceLocation& loc) {
  auto t = ParseType(c.type);
  if (!t.ok()) return Error(loc, "constant of unsupported type '" + c.type + "'");
  auto cpp = CppLiteral(*t, c.value);
  if (!cpp.ok()) return Error(loc, cpp.status().message());
  Value v = Value::OfVar(EmitConst(*t, *cpp));
  if (t->is_scalar() && t->scalar != ScalarKind::kBool) {
    v.literal = true;
    v.literal_text = c.value;
    if (IsFloat(t->scalar) && IsIntLiteralText(c.value)) v.literal_text += ".0";
    // Python ints and floats adapt like literals; typed wp.constant(wp.float64(..)) keep theirs.
    if (t->scalar != ScalarKind::kInt32 && t->scalar != ScalarKind::kFloat32) v.literal = false;
  }
  return v;
}

Expected<Value> Checker::LookupGlobal(const std::string& name, const SourceLocation& loc, bool* found) {
  *found = true;
  auto range = symbols_.equal_range(name);
  if (range.first != range.second) {
    const Symbol& s = *range.first->second;
    Value v;
    switch (s.kind) {
      case Symbol::Kind::kBuiltinModule: v.kind = Value::Kind::kModule; return v;
      case Symbol::Kind::kConstant: return EvalConstantSymbol(s.constant, loc);
      case Symbol::Kind::kFunction:
        if (s.target.rfind(kBuiltinTargetPrefix, 0) == 0) {
          // A global bound to a builtin (TARGET = wp.sin): the builtin itself.
          const std::string b = s.target.substr(std::string(kBuiltinTargetPrefix).size());
          if (BuiltinRegistry::Get().Overloads(b).empty() && !IsSpecialBuiltin(b))
            return Error(loc, "'" + name + "' names no weft builtin ('" + b + "')");
          v.kind = Value::Kind::kBuiltin;
          v.name = b;
          return v;
        }
        v.kind = Value::Kind::kFunc;
        v.name = name;
        return v;
      case Symbol::Kind::kType: {
        auto t = ParseType(s.target);
        if (!t.ok()) return Error(loc, "'" + name + "': " + t.status().message());
        if (ContainsAny(*t))
          return Error(loc, "'" + name + "' is the generic type " + TypeString(*t) +
                                " (for annotations): kernel code cannot construct or declare values of it");
        v.kind = Value::Kind::kType;
        v.type = *t;
        return v;
      }
    }
  }
  // Python builtins Warp accepts without the wp. prefix.
  static const std::set<std::string> kPyBuiltins = {"range", "len", "print", "min", "max", "abs", "round", "pow"};
  if (kPyBuiltins.count(name)) {
    Value v;
    v.kind = Value::Kind::kBuiltin;
    v.name = name;
    return v;
  }
  if (name == "int" || name == "float" || name == "bool") {
    Value v;
    v.kind = Value::Kind::kType;
    v.type = name == "int" ? Type::Int32() : name == "float" ? Type::Float32() : Type::Bool();
    return v;
  }
  *found = false;
  return Value{};
}

Expected<Value> Checker::EvalName(const ast::Name& n) {
  if (auto alias = st_->tile_aliases.find(n.id); alias != st_->tile_aliases.end()) {   // the tile as it is now
    const TileAlias a = alias->second;
    WEFT_ASSIGN_OR_RETURN(Value v, ViewOfAlias(a, n.loc));
    v.source = n.id;
    return v;
  }
  auto it = st_->scope.find(n.id);
  if (it != st_->scope.end()) {
    Value v = Value::OfVar(it->second);
    v.source = n.id;
    auto lit = st_->literal_locals.find(n.id);
    if (lit != st_->literal_locals.end() && lit->second.first == it->second) {
      v.const_local = true;
      v.literal_text = lit->second.second;
    }
    return v;
  }
  auto tu = st_->tuple_scope.find(n.id);
  if (tu != st_->tuple_scope.end()) return tu->second;
  if (st_->path_bound.count(n.id))
    return Error(n.loc, "'" + n.id + "' holds a tuple or function bound inside an if, for or while; which one "
                        "depends on the path taken: bind it before the statement, or use it inside");
  auto fu = st_->func_scope.find(n.id);
  if (fu != st_->func_scope.end()) return fu->second;
  bool found = false;
  WEFT_ASSIGN_OR_RETURN(Value v, LookupGlobal(n.id, n.loc, &found));
  if (!found) return UnknownName(n.id, n.loc);
  v.source = n.id;
  return v;
}

namespace {
// "a.b.c" for a chain of names, "" otherwise.
std::string DottedName(const ast::Expr& e) {
  if (const auto* n = ast::As<ast::Name>(&e)) return n->id;
  if (const auto* a = ast::As<ast::Attribute>(&e)) {
    std::string base = DottedName(*a->value);
    return base.empty() ? "" : base + "." + a->attr;
  }
  return "";
}
std::string RootName(const ast::Expr& e) {
  if (const auto* n = ast::As<ast::Name>(&e)) return n->id;
  if (const auto* a = ast::As<ast::Attribute>(&e)) return RootName(*a->value);
  return "";
}
}  // namespace

Expected<Value> Checker::EvalAttribute(const ast::Attribute& a) {
  std::string dotted = DottedName(a);
  if (!dotted.empty() && !st_->scope.count(RootName(a)) && symbols_.count(dotted)) {
    bool found = false;
    return LookupGlobal(dotted, a.loc, &found);
  }
  WEFT_ASSIGN_OR_RETURN(Value base, Eval(*a.value));
  if (base.kind == Value::Kind::kModule) {
    const std::string& n = a.attr;
    Value v;
    if (base.name == "Volume") {   // wp.Volume.CLOSEST, wp.Volume.LINEAR: sampling modes
      if (n != "CLOSEST" && n != "LINEAR")
        return Error(a.attr_loc, "'wp.Volume." + n + "' is not supported in kernels (wp.Volume.CLOSEST, wp.Volume.LINEAR)");
      const std::string text = n == "CLOSEST" ? "0" : "1";
      WEFT_ASSIGN_OR_RETURN(std::string cpp, CppLiteral(Type::Int32(), text));
      v = Value::OfVar(EmitConst(Type::Int32(), cpp));
      v.literal = true;
      v.literal_text = text;
      return v;
    }
    if (n == "types") {  // wp.types.vector(...), wp.types.matrix(...): the same builtins
      v.kind = Value::Kind::kModule;
      return v;
    }
    if (n == "Volume") {
      v.kind = Value::Kind::kModule;
      v.name = "Volume";
      return v;
    }
    if (BuiltinRegistry::Get().Has(n) || IsSpecialBuiltin(n)) {
      v.kind = Value::Kind::kBuiltin;
      v.name = n;
      return v;
    }
    auto t = ParseType(n);
    if (t.ok() && !t->is_void() && !t->is_any()) {
      v.kind = Value::Kind::kType;
      v.type = *t;
      return v;
    }
    static const std::map<std::string, std::string> kConstants = {
        {"pi", "3.14159265358979323846"}, {"tau", "6.28318530717958647692"},  {"e", "2.71828182845904523536"},
        {"half_pi", "1.57079632679489661923"}, {"inf", "inf"}, {"nan", "nan"}, {"INF", "inf"}, {"NAN", "nan"},
        {"phi", "1.61803398874989484820"}, {"sqrt_two", "1.41421356237309504880"}, {"log2e", "1.44269504088896340736"},
        {"ln_two", "0.69314718055994530942"}, {"ln_ten", "2.30258509299404568402"}, {"log10e", "0.43429448190325182765"},
        // Warp's names (warp/_src/constants.py), upper and lower case
        {"PI", "3.14159265358979323846"}, {"TAU", "6.28318530717958647692"}, {"E", "2.71828182845904523536"},
        {"HALF_PI", "1.57079632679489661923"}, {"PHI", "1.61803398874989484820"}, {"LOG2E", "1.44269504088896340736"},
        {"LOG10E", "0.43429448190325182765"}, {"LN2", "0.69314718055994530942"}, {"ln2", "0.69314718055994530942"},
        {"LN10", "2.30258509299404568402"}, {"ln10", "2.30258509299404568402"}};
    if (auto c = kConstants.find(n); c != kConstants.end()) {
      WEFT_ASSIGN_OR_RETURN(std::string cpp, CppLiteral(Type::Float32(), c->second));
      v = Value::OfVar(EmitConst(Type::Float32(), cpp));
      v.literal = true;
      v.literal_text = c->second;
      return v;
    }
    return Error(a.attr_loc, "'wp." + n + "' is not a supported builtin, type or constant");
  }
  if (base.kind == Value::Kind::kType) return TypeAttribute(base.type, a);
  if (base.kind != Value::Kind::kVar) return Error(a.loc, "'" + ExprText(a) + "' is not supported");
  const Type bt = TypeOf(base.var);
  if (bt.is_array() && a.attr == "dtype") return TypeAttribute(bt, a);
  if (bt.is_array()) {
    if (a.attr == "shape") {
      Value v;
      v.kind = Value::Kind::kTuple;
      v.name = "__shape";   // a.shape[k] past the dimensions reads 0 (Warp's shape_t)
      if (bt.is_fixed_array()) {
        for (int n : bt.fixed_shape) {
          Value e = Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(n) + ")"));
          e.literal = true;
          e.literal_text = std::to_string(n);
          v.elems.push_back(e);
        }
        return v;
      }
      for (int k = 0; k < bt.ndim; ++k)
        v.elems.push_back(Value::OfVar(EmitRaw(Type::Int32(),
                                               bt.indexed ? "wp::int32(wp::array_dim($0, " + std::to_string(k) + "))"
                                                          : "wp::int32($0.shape[" + std::to_string(k) + "])",
                                               {base.var})));
      return v;
    }
    if (a.attr == "ndim") return Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(bt.ndim) + ")"));
    return Error(a.attr_loc, "arrays have no attribute '" + a.attr + "' in kernels (use .shape)");
  }
  if (bt.is_struct()) {
    const StructInfo& si = module_.structs.at(bt.struct_name);
    int fi = -1;
    const StructField* f = si.Find(a.attr, &fi);
    if (!f) return Error(a.attr_loc, "struct " + bt.struct_name + " has no field '" + a.attr + "'");
    int v = EmitOp(OpKind::kGetField, f->type, {base.var}, a.attr);
    st_->block->back().op.field_index = fi;
    if (ArrayParamOf(base.var) >= 0) st_->array_param[v] = ArrayParamOf(base.var);
    Value r = Value::OfVar(v);
    r.source = ExprText(a);
    return r;
  }
  if (bt.is_composite() && (a.attr == "dtype" || a.attr == "length")) return TypeAttribute(bt, a);
  if (bt.is_vector() || bt.kind == TypeKind::kQuat) {
    static const std::string kXYZW = "xyzw";
    size_t k = a.attr.size() == 1 ? kXYZW.find(a.attr[0]) : std::string::npos;
    if (k == std::string::npos || static_cast<int>(k) >= bt.component_count())
      return ErrorOf("attribute", a.attr_loc, "`" + a.attr + "` is not an attribute of '" + ExprText(*a.value) + "' (" +
                                                  TypeString(bt) + ")");
    int ki = EmitConst(Type::Int32(), "wp::int32(" + std::to_string(k) + ")");
    return Value::OfVar(EmitOp(OpKind::kExtract, Type::Scalar(bt.scalar), {base.var, ki}));
  }
  if (bt.kind == TypeKind::kTransform && (a.attr == "p" || a.attr == "q")) {
    return ResolveAndEmitBuiltin(a.attr == "p" ? "transform_get_translation" : "transform_get_rotation", {base}, a.loc);
  }
  return Error(a.attr_loc, "a value of type " + TypeString(bt) + " has no attribute '" + a.attr + "'");
}

// An attribute of a type or of a value's type (wp.vec3.length, type(a).dtype, v.dtype, an array's
// .dtype): an array's element type, a composite's scalar type and length, as Warp resolves them.
Expected<Value> Checker::TypeAttribute(const Type& t, const ast::Attribute& a) {
  auto int_const = [&](int n) {
    Value v = Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(n) + ")"));
    v.literal = true;
    v.literal_text = std::to_string(n);
    return v;
  };
  Value r;
  r.kind = Value::Kind::kType;
  if (a.attr == "dtype" && t.is_array()) {
    r.type = t.elem();
    return r;
  }
  if (a.attr == "dtype" && (t.is_composite() || t.is_scalar())) {
    r.type = Type::Scalar(t.scalar);
    return r;
  }
  if (a.attr == "length" && t.is_composite() && !t.is_matrix()) return int_const(t.component_count());
  if (a.attr == "ndim" && t.is_array()) return int_const(t.ndim);
  return Error(a.attr_loc, "`" + a.attr + "` is not an attribute of type " + TypeString(t));
}

// a[1:3], a[:2, 1:], a[i, ::2] on an array or fixed-size array: a view (Python's slice rules:
// negative bounds count from the end, bounds clamp to the extent, a negative step walks backward; an
// integer index drops its dimension). Its gradient is the same view of the gradient array.
Expected<Value> Checker::EvalArraySlice(const ast::Subscript& s, const Value& base) {
  const Type bt = TypeOf(base.var);
  if (static_cast<int>(s.indices.size()) > bt.ndim)
    return Error(s.loc, "array '" + ExprText(*s.value) + "' has " + std::to_string(bt.ndim) + " dimensions but " +
                            std::to_string(s.indices.size()) + " indices were given");
  std::vector<int> vars{base.var};
  auto int_var = [&](const ast::Expr* e, const char* dflt) -> Expected<int> {
    if (!e) return EmitConst(Type::Scalar(ScalarKind::kInt64), dflt);
    WEFT_ASSIGN_OR_RETURN(Value v, Eval(*e));
    if (v.kind != Value::Kind::kVar || !TypeOf(v.var).is_scalar() || !IsInt(TypeOf(v.var).scalar))
      return Error(e->loc, "slice bound '" + ExprText(*e) + "' must be an integer");
    return v.var;
  };
  std::string kinds, vals;
  int out_ndim = 0;
  for (size_t d = 0; d < s.indices.size(); ++d) {
    const ast::Expr* e = s.indices[d].get();
    if (const auto* sl = ast::As<ast::Slice>(e)) {
      WEFT_ASSIGN_OR_RETURN(int lo, int_var(sl->lower.get(), "wp::cg_slice_none"));
      WEFT_ASSIGN_OR_RETURN(int hi, int_var(sl->upper.get(), "wp::cg_slice_none"));
      WEFT_ASSIGN_OR_RETURN(int st, int_var(sl->step.get(), "wp::int64(1)"));
      for (int v : {lo, hi, st}) vars.push_back(v);
      kinds += "1, ";
      ++out_ndim;
    } else {
      WEFT_ASSIGN_OR_RETURN(int iv, int_var(e, "0"));
      vars.push_back(iv);
      vars.push_back(iv);
      vars.push_back(iv);
      kinds += "0, ";
    }
    const size_t b = vars.size() - 3;
    vals += (d ? ", " : "") + std::string("{wp::int64($") + std::to_string(b) + "), wp::int64($" + std::to_string(b + 1) +
            "), wp::int64($" + std::to_string(b + 2) + ")}";
  }
  out_ndim += bt.ndim - static_cast<int>(s.indices.size());
  if (out_ndim < 1) return Error(s.loc, "a slice of '" + ExprText(*s.value) + "' keeps no dimension");
  for (size_t d = s.indices.size(); d < 4; ++d) kinds += "0, ";
  kinds.resize(kinds.size() - 2);
  // $@: the launch context, function id and line (a zero step is reported there).
  const std::string text = "wp::cg_slice($@, wp::as_array($0), " + std::to_string(s.indices.size()) + ", wp::cg_slice_kinds_t{{" +
                           kinds + "}}, wp::cg_slice_bounds_t{{" + vals + "}})";
  int v = EmitRaw(Type::Array(bt.elem(), out_ndim), text, vars);
  if (ArrayParamOf(base.var) >= 0) st_->array_param[v] = ArrayParamOf(base.var);
  Value r = Value::OfVar(v);
  r.source = ExprText(s);
  return r;
}

Expected<std::vector<int>> Checker::EvalIndices(const ast::ExprList& idx, bool array_base) {
  std::vector<int> out;
  for (const auto& e : idx) {
    if (ast::As<ast::Slice>(e.get())) return Error(e->loc, "slices are not supported in kernels");
    bool store = store_target_, slot = slot_target_;
    store_target_ = slot_target_ = false;   // an index expression is a read
    Expected<Value> ev = Eval(*e);
    store_target_ = store;
    slot_target_ = slot;
    WEFT_ASSIGN_OR_RETURN(Value v, std::move(ev));
    if (array_base && store && v.kind == Value::Kind::kVar && TypeOf(v.var).is_scalar() && !IsInt(TypeOf(v.var).scalar))
      return ErrorOf("type", e->loc, "Array slot write indices must be integers, got `" + TypeString(TypeOf(v.var)) + "`");
    if (v.kind != Value::Kind::kVar || !TypeOf(v.var).is_scalar() || !IsInt(TypeOf(v.var).scalar))
      return Error(e->loc, "index '" + ExprText(*e) + "' must be an integer" +
                               (v.kind == Value::Kind::kVar ? ", got " + TypeString(TypeOf(v.var)) : std::string()));
    out.push_back(v.var);
  }
  return out;
}

// The components a constant slice `lower:upper:step` selects from a value of n components,
// with Python's rules (negative bounds count from the end, bounds are clamped).
Expected<std::vector<int>> Checker::SliceComponents(const ast::Slice& sl, int n) {
  auto bound = [&](const ast::ExprPtr& e, long def, long* out) -> Status {
    *out = def;
    if (!e) return Status::Ok();
    WEFT_ASSIGN_OR_RETURN(Value v, Eval(*e));
    if (v.kind != Value::Kind::kVar || !(v.literal || v.const_local) || v.literal_text.empty() ||
        v.literal_text.find_first_not_of("-0123456789") != std::string::npos || v.literal_text.size() > 9)
      return ErrorOf("value", e->loc, "Slice component must be a compile-time constant (an integer literal)");
    *out = std::stol(v.literal_text);
    return Status::Ok();
  };
  long step = 1, lo = 0, hi = 0;
  WEFT_RETURN_IF_ERROR(bound(sl.step, 1, &step));
  if (step == 0) return Error(sl.loc, "slice step cannot be zero");
  WEFT_RETURN_IF_ERROR(bound(sl.lower, step > 0 ? 0 : n - 1, &lo));
  WEFT_RETURN_IF_ERROR(bound(sl.upper, step > 0 ? n : -n - 1, &hi));
  auto clamp = [&](long v) {
    if (v < 0) v += n;
    if (step > 0) return v < 0 ? 0L : (v > n ? static_cast<long>(n) : v);
    return v < -1 ? -1L : (v > n - 1 ? static_cast<long>(n - 1) : v);
  };
  lo = clamp(lo);
  hi = (sl.upper || step > 0) ? clamp(hi) : -1;
  std::vector<int> out;
  for (long i = lo; step > 0 ? i < hi : i > hi; i += step) out.push_back(static_cast<int>(i));
  return out;   // may be empty: a zero-length vector (Python's rule; `v[4:]` of a vec4)
}

Expected<bool> Checker::SliceRegionOf(const ast::Subscript& s, const Type& bt, SliceRegion* out) {
  bool has_slice = false;
  for (const auto& e : s.indices) has_slice |= ast::As<ast::Slice>(e.get()) != nullptr;
  if (!has_slice) return false;
  auto konst = [&](int c) { return EmitConst(Type::Int32(), "wp::int32(" + std::to_string(c) + ")"); };
  if (bt.is_vector() || bt.kind == TypeKind::kQuat || bt.kind == TypeKind::kTransform) {
    if (s.indices.size() != 1) return Error(s.loc, TypeString(bt) + " takes one index");
    WEFT_ASSIGN_OR_RETURN(std::vector<int> comps,
                          SliceComponents(*ast::As<ast::Slice>(s.indices[0].get()), bt.component_count()));
    out->components.clear();
    for (int c : comps) out->components.push_back({konst(c)});
    out->shape = Type::Vector(static_cast<int>(comps.size()), bt.scalar);
    return true;
  }
  if (!bt.is_matrix()) return Error(s.loc, "a value of type " + TypeString(bt) + " cannot be sliced");
  if (s.indices.size() > 2) return Error(s.loc, "a matrix takes one (row) or two indices");
  // Per dimension: the index vars it selects, and whether it is a slice (keeps the dimension).
  std::vector<int> dim_vars[2];
  bool dim_sliced[2] = {true, true};
  for (int d = 0; d < 2; ++d) {
    const int extent = d == 0 ? bt.rows : bt.cols;
    const ast::Expr* e = d < static_cast<int>(s.indices.size()) ? s.indices[d].get() : nullptr;
    if (const auto* sl = e ? ast::As<ast::Slice>(e) : nullptr) {
      WEFT_ASSIGN_OR_RETURN(std::vector<int> comps, SliceComponents(*sl, extent));
      for (int c : comps) dim_vars[d].push_back(konst(c));
    } else if (e) {
      const bool store = store_target_, slot = slot_target_;
      store_target_ = slot_target_ = false;   // an index expression is a read
      Expected<Value> ev = Eval(*e);
      store_target_ = store;
      slot_target_ = slot;
      WEFT_ASSIGN_OR_RETURN(Value iv, std::move(ev));
      if (iv.kind != Value::Kind::kVar || !TypeOf(iv.var).is_scalar() || !IsInt(TypeOf(iv.var).scalar))
        return Error(e->loc, "index '" + ExprText(*e) + "' must be an integer");
      dim_vars[d].push_back(iv.var);
      dim_sliced[d] = false;
    } else {
      for (int c = 0; c < extent; ++c) dim_vars[d].push_back(konst(c));   // m[a:b]: every column
    }
  }
  out->components.clear();
  for (int r : dim_vars[0])
    for (int c : dim_vars[1]) out->components.push_back({r, c});
  const int nr = static_cast<int>(dim_vars[0].size()), nc = static_cast<int>(dim_vars[1].size());
  if (dim_sliced[0] && dim_sliced[1]) out->shape = Type::Matrix(nr, nc, bt.scalar);
  else out->shape = Type::Vector(dim_sliced[0] ? nr : nc, bt.scalar);
  return true;
}

int Checker::ReadSliceRegion(int base, const Type& bt, const SliceRegion& r) {
  std::vector<int> parts;
  for (const std::vector<int>& idx : r.components) {
    std::vector<int> args{base};
    args.insert(args.end(), idx.begin(), idx.end());
    parts.push_back(EmitOp(OpKind::kExtract, Type::Scalar(bt.scalar), args));
  }
  Stmt st;
  st.op.kind = OpKind::kConstruct;
  st.op.mode = ConstructMode::kConcat;
  int d = NewVar(r.shape);
  st.op.dst.push_back(d);
  st.op.args = parts;
  Push(std::move(st));
  return d;
}

// wp.adjoint[x] in a gradient function (wp.func_grad): the adjoint slot of parameter x, and
// the struct fields of wp.adjoint[x.f.g].
Expected<int> Checker::AdjointRoot(const ast::Subscript& s, std::vector<std::string>* fields) {
  if (st_->adjoint_slots.empty())
    return Error(s.loc, "wp.adjoint[...] is only available in a gradient function (@wp.func_grad)");
  const ast::Expr* e = s.indices.size() == 1 ? s.indices[0].get() : nullptr;
  std::vector<std::string> names;
  while (const auto* at = e ? ast::As<ast::Attribute>(e) : nullptr) {
    names.push_back(at->attr);
    e = at->value.get();
  }
  const auto* n = e ? ast::As<ast::Name>(e) : nullptr;
  auto it = n ? st_->adjoint_slots.find(n->id) : st_->adjoint_slots.end();
  if (it == st_->adjoint_slots.end())
    return Error(s.loc, "wp.adjoint[...] takes a differentiable parameter of the function (or a field of a struct "
                        "parameter), got '" + (s.indices.empty() ? std::string() : ExprText(*s.indices[0])) + "'");
  fields->assign(names.rbegin(), names.rend());
  if (!fields->empty() && TypeOf(it->second).is_array())
    return Error(s.loc, "wp.adjoint[" + ExprText(*s.indices[0]) + "]: an array has no fields");
  return it->second;
}

Expected<int> Checker::AdjointSlot(const ast::Subscript& s) {
  std::vector<std::string> fields;
  WEFT_ASSIGN_OR_RETURN(int v, AdjointRoot(s, &fields));
  for (const std::string& name : fields) {
    const Type t = TypeOf(v);
    const StructField* f = nullptr;
    int fi = -1;
    if (t.is_struct()) f = module_.structs.at(t.struct_name).Find(name, &fi);
    if (!f)
      return Error(s.loc, "wp.adjoint[" + ExprText(*s.indices[0]) + "]: " + TypeString(t) + " has no field '" + name +
                              "'");
    v = EmitOp(OpKind::kGetField, f->type, {v}, name);
    st_->block->back().op.field_index = fi;
  }
  return v;
}

// wp.adjoint[x] = value, wp.adjoint[x.f] = value (the slot with field f replaced).
Status Checker::AssignAdjoint(const ast::Subscript& s, const Value& value) {
  std::vector<std::string> fields;
  WEFT_ASSIGN_OR_RETURN(int root, AdjointRoot(s, &fields));
  const std::string text = ExprText(*s.indices[0]);
  if (TypeOf(root).is_array())
    return Error(s.loc, "wp.adjoint[" + text + "] is the gradient array of '" + text + "': assign its elements");
  std::vector<int> path{root};
  std::vector<int> field_index;
  for (const std::string& name : fields) {
    const Type t = TypeOf(path.back());
    const StructField* f = nullptr;
    int fi = -1;
    if (t.is_struct()) f = module_.structs.at(t.struct_name).Find(name, &fi);
    if (!f) return Error(s.loc, "wp.adjoint[" + text + "]: " + TypeString(t) + " has no field '" + name + "'");
    path.push_back(EmitOp(OpKind::kGetField, f->type, {path.back()}, name));
    st_->block->back().op.field_index = fi;
    field_index.push_back(fi);
  }
  WEFT_ASSIGN_OR_RETURN(int v, Coerce(value, TypeOf(path.back()), s.loc, "the adjoint of '" + text + "'"));
  for (size_t k = fields.size(); k-- > 0;) {
    v = EmitOp(OpKind::kSetField, TypeOf(path[k]), {path[k], v}, fields[k]);
    st_->block->back().op.field_index = field_index[k];
  }
  EmitCopy(root, v);
  return Status::Ok();
}

Expected<Value> Checker::EvalSubscript(const ast::Subscript& s) {
  WEFT_ASSIGN_OR_RETURN(Value base, Eval(*s.value));
  if (base.kind == Value::Kind::kBuiltin && base.name == "adjoint") {
    WEFT_ASSIGN_OR_RETURN(int slot, AdjointSlot(s));
    return Value::OfVar(slot);
  }
  if (base.kind == Value::Kind::kVar && TypeOf(base.var).is_tile()) {
    // t[i, j], t[i], t[a:b, :]
    return TileSubscript(s, base);
  }
  if (base.kind == Value::Kind::kVar && !TypeOf(base.var).is_array()) {
    // v[a:b:c], m[i, a:b], m[a:b, c:d]: the selected components as a vector or matrix
    const Type bt = TypeOf(base.var);
    SliceRegion region;
    WEFT_ASSIGN_OR_RETURN(bool sliced, SliceRegionOf(s, bt, &region));
    if (sliced) return Value::OfVar(ReadSliceRegion(base.var, bt, region));
  }
  if (base.kind == Value::Kind::kTuple) {
    const auto* c = s.indices.size() == 1 ? ast::As<ast::Constant>(s.indices[0].get()) : nullptr;
    if (!c && s.indices.size() == 1 && !base.elems.empty()) {
      // t[i] with i known only at run time: elements of one type, selected by i (an index
      // outside the tuple reads the last element).
      WEFT_ASSIGN_OR_RETURN(Value iv, Eval(*s.indices[0]));
      if (iv.kind == Value::Kind::kVar && iv.literal && IsIntLiteralText(iv.literal_text)) {
        const long long k = std::stoll(iv.literal_text);
        if (k < 0 || k >= static_cast<long long>(base.elems.size()))
          return Error(s.indices[0]->loc, "index " + iv.literal_text + " out of range for a tuple of " +
                                              std::to_string(base.elems.size()));
        return base.elems[static_cast<size_t>(k)];
      }
      if (iv.kind != Value::Kind::kVar || !TypeOf(iv.var).is_scalar() || !IsInt(TypeOf(iv.var).scalar))
        return Error(s.loc, "a tuple takes one integer index");
      const Type et = base.elems[0].kind == Value::Kind::kVar ? TypeOf(base.elems[0].var) : Type::Void();
      std::vector<int> vars{iv.var};
      for (const Value& e : base.elems) {
        if (e.kind != Value::Kind::kVar || TypeOf(e.var) != et)
          return Error(s.loc, "a tuple indexed with a value known only at run time must hold elements of one type");
        vars.push_back(e.var);
      }
      std::string text = "$" + std::to_string(vars.size() - 1);
      for (size_t k = base.elems.size() - 1; k-- > 0;)
        text = "($0 == " + std::to_string(k) + " ? $" + std::to_string(k + 1) + " : " + text + ")";
      return Value::OfVar(EmitRaw(et, text, vars));
    }
    if (!c || c->type != ast::Constant::Type::kInt)
      return Error(s.loc, "a tuple (such as .shape) takes one constant integer index");
    if (base.name == "__shape" && c->int_value >= base.elems.size() && c->int_value < 4) {
      Value z = Value::OfVar(EmitConst(Type::Int32(), "wp::int32(0)"));
      z.literal = true;
      z.literal_text = "0";
      return z;
    }
    if (c->int_value >= base.elems.size())
      return Error(s.indices[0]->loc, "index " + std::to_string(c->int_value) + " out of range for a tuple of " +
                                          std::to_string(base.elems.size()));
    return base.elems[c->int_value];
  }
  if (base.kind != Value::Kind::kVar) return Error(s.loc, "'" + ExprText(*s.value) + "' cannot be indexed");
  const Type bt = TypeOf(base.var);
  bool has_slice = false;
  for (const auto& e : s.indices) has_slice |= ast::As<ast::Slice>(e.get()) != nullptr;
  if (has_slice && bt.is_array() && !bt.indexed) return EvalArraySlice(s, base);
  WEFT_ASSIGN_OR_RETURN(std::vector<int> idx, EvalIndices(s.indices, bt.is_array()));
  if (bt.is_array()) {
    if (static_cast<int>(idx.size()) < bt.ndim) {
      // a[i] on a 2-D array: the sub-array with the leading indices fixed (a view; its
      // gradient is the same view of the gradient array).
      std::vector<int> args{base.var};
      args.insert(args.end(), idx.begin(), idx.end());
      Type vt = Type::Array(bt.elem(), bt.ndim - static_cast<int>(idx.size()));
      vt.indexed = bt.indexed;
      int v = EmitOp(OpKind::kView, vt, args);
      st_->block->back().op.array_param = ArrayParamOf(base.var);
      st_->block->back().op.array_name = ExprText(*s.value);
      if (ArrayParamOf(base.var) >= 0) st_->array_param[v] = ArrayParamOf(base.var);
      st_->fn.may_fail = true;
      Value r = Value::OfVar(v);
      r.source = ExprText(s);
      return r;
    }
    if (static_cast<int>(idx.size()) != bt.ndim)
      return Error(s.loc, "array '" + ExprText(*s.value) + "' has " + std::to_string(bt.ndim) + " dimensions but " +
                              std::to_string(idx.size()) + " indices were given");
    std::vector<int> args{base.var};
    args.insert(args.end(), idx.begin(), idx.end());
    int v = EmitOp(OpKind::kLoad, bt.elem(), args);
    st_->block->back().op.array_param = ArrayParamOf(base.var);
    st_->block->back().op.array_name = ExprText(*s.value);
    st_->block->back().op.slot = slot_target_;
    st_->fn.may_fail = true;
    return Value::OfVar(v);
  }
  Type comp;
  if (bt.is_vector() || bt.kind == TypeKind::kQuat || bt.kind == TypeKind::kTransform) {
    if (idx.size() != 1) return Error(s.loc, TypeString(bt) + " takes one index");
    comp = Type::Scalar(bt.scalar);
  } else if (bt.is_matrix()) {
    if (idx.size() == 2) comp = Type::Scalar(bt.scalar);
    else if (idx.size() == 1) comp = Type::Vector(bt.cols, bt.scalar);
    else return Error(s.loc, "a matrix takes one (row) or two indices");
  } else {
    return Error(s.loc, "a value of type " + TypeString(bt) + " cannot be indexed");
  }
  std::vector<int> args{base.var};
  args.insert(args.end(), idx.begin(), idx.end());
  return Value::OfVar(EmitOp(OpKind::kExtract, comp, args));
}

Expected<Value> Checker::EvalBinOp(const ast::BinOp& b) {
  WEFT_ASSIGN_OR_RETURN(Value l, Eval(*b.left));
  WEFT_ASSIGN_OR_RETURN(Value r, Eval(*b.right));
  const std::string& name = BinaryBuiltins().at(b.op);
  // + - * // % of two integer constants (literals, wp.constant ints) is a constant, as Python
  // computes it (floor division and modulo), so that `shape=(TILE_M // 2, TILE_N * 2)` is one.
  // Folded only where the result fits int32 and nothing divides by zero (typed constants such as
  // wp.uint8(200) keep their type's arithmetic); otherwise the runtime operator, as before.
  auto python_int = [this](const Value& v) {   // an untyped integer constant (int32 / int64 literal)
    return v.kind == Value::Kind::kVar && v.literal && IsIntLiteralText(v.literal_text) && v.literal_text.size() < 19 &&
           (TypeOf(v.var) == Type::Int32() || TypeOf(v.var) == Type::Scalar(ScalarKind::kInt64));
  };
  if (python_int(l) && python_int(r)) {
    const long long x = std::stoll(l.literal_text), y = std::stoll(r.literal_text);
    bool fold = true;
    long long v = 0;
    switch (b.op) {
      case ast::BinaryOperator::kAdd: v = x + y; break;
      case ast::BinaryOperator::kSub: v = x - y; break;
      case ast::BinaryOperator::kMul:
        fold = (x == 0 || std::llabs(y) <= 0x7fffffffffffLL / std::max(1LL, std::llabs(x))) &&
               std::llabs(x) <= 0x7fffffffffffLL;
        if (fold) v = x * y;
        break;
      case ast::BinaryOperator::kFloorDiv:
      case ast::BinaryOperator::kMod: {
        fold = y != 0;
        if (!fold) break;
        long long q = x / y, m = x % y;
        if (m != 0 && ((m < 0) != (y < 0))) {   // Python rounds the quotient down
          q -= 1;
          m += y;
        }
        v = b.op == ast::BinaryOperator::kFloorDiv ? q : m;
        break;
      }
      default: fold = false;
    }
    if (fold && v >= -2147483648LL && v <= 2147483647LL) {
      Value c = Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(v) + ")"));
      c.literal = true;
      c.literal_text = std::to_string(v);
      c.source = ExprText(b);
      return c;
    }
  }
  auto is_tile = [this](const Value& v) { return v.kind == Value::Kind::kVar && TypeOf(v.var).is_tile(); };
  if (b.op == ast::BinaryOperator::kMatMul && is_tile(l) && is_tile(r)) {   // a @ b of tiles: tile_matmul
    bool handled = false;
    return CallTile("tile_matmul", {l, r}, b.loc, nullptr, &handled);
  }
  // An operator on a struct is the user's @wp.func of the operator's builtin name (`add` for +,
  // `mul` for *, ...), as in Warp: no builtin takes a struct.
  auto is_struct = [this](const Value& v) { return v.kind == Value::Kind::kVar && TypeOf(v.var).is_struct(); };
  if (is_struct(l) || is_struct(r)) {
    auto range = symbols_.equal_range(name);
    for (auto it = range.first; it != range.second; ++it)
      if (it->second->kind == Symbol::Kind::kFunction) return CallUserFunc(name, {l, r}, b.loc);
  }
  return ResolveAndEmitBuiltin(name, {l, r}, b.loc);
}

Expected<Value> Checker::EvalCompare(const ast::Compare& c) {
  WEFT_ASSIGN_OR_RETURN(Value left, Eval(*c.left));
  std::vector<int> parts;
  for (size_t i = 0; i < c.ops.size(); ++i) {
    WEFT_ASSIGN_OR_RETURN(Value right, Eval(*c.comparators[i]));
    auto op = c.ops[i];
    if (op == ast::CompareOperator::kIs || op == ast::CompareOperator::kIsNot || op == ast::CompareOperator::kIn ||
        op == ast::CompareOperator::kNotIn)
      return Error(c.loc, std::string("'") + ast::Spelling(op) + "' is not supported in kernels");
    if (left.kind != Value::Kind::kVar || right.kind != Value::Kind::kVar)
      return Error(c.loc, "comparisons need runtime values");
    int lv = left.var, rv = right.var;
    if (left.literal && !right.literal) {
      WEFT_ASSIGN_OR_RETURN(lv, Coerce(left, TypeOf(rv), c.left->loc, "the left operand"));
    } else if (right.literal && !left.literal) {
      WEFT_ASSIGN_OR_RETURN(rv, Coerce(right, TypeOf(lv), c.comparators[i]->loc, "the right operand"));
    }
    const Type& lt = TypeOf(lv);
    const Type& rt = TypeOf(rv);
    bool eq_op = op == ast::CompareOperator::kEq || op == ast::CompareOperator::kNotEq;
    // Zero-length vectors and matrices (slices selecting nothing) of one scalar type are equal
    // whatever their shapes, as in Warp: nothing differs.
    auto empty = [](const Type& t) {
      return (t.is_vector() && t.rows == 0) || (t.is_matrix() && (t.rows == 0 || t.cols == 0));
    };
    if (eq_op && lt != rt && empty(lt) && empty(rt) && lt.scalar == rt.scalar) {
      parts.push_back(EmitRaw(Type::Bool(), op == ast::CompareOperator::kEq ? "true" : "false", {}));
      left = right;
      continue;
    }
    if (lt != rt || !(lt.is_scalar() || (eq_op && lt.is_composite())))
      return ErrorOf("type", c.loc, std::string("cannot compare ") + TypeString(lt) + " " + ast::Spelling(op) + " " +
                              TypeString(rt) + (lt.is_scalar() && rt.is_scalar() ? " (both sides need the same scalar type)"
                                                                                  : " (both sides need the same type)"));
    parts.push_back(EmitRaw(Type::Bool(), std::string("($0 ") + ast::Spelling(op) + " $1)", {lv, rv}));
    left = right;
  }
  if (parts.size() == 1) return Value::OfVar(parts[0]);
  std::string text = "(";
  for (size_t i = 0; i < parts.size(); ++i) text += (i ? " && $" : "$") + std::to_string(i);
  return Value::OfVar(EmitRaw(Type::Bool(), text + ")", parts));
}

Expected<int> Checker::Coerce(const Value& v, const Type& want, const SourceLocation& loc, const std::string& what) {
  if (v.kind != Value::Kind::kVar) return Error(loc, what + " is not a value");
  const Type& have = TypeOf(v.var);
  if (have == want) return v.var;
  if (v.literal && want.is_scalar() && want.scalar != ScalarKind::kBool) {
    bool is_int_literal = IsIntLiteralText(v.literal_text);
    if (IsFloat(want.scalar) || is_int_literal) {
      auto cpp = CppLiteral(want, v.literal_text);
      if (cpp.ok()) return EmitConst(want, *cpp);
    }
  }
  return Error(loc, what + " has type " + TypeString(have) + ", expected " + TypeString(want));
}

Expected<Type> Checker::EvalTypeExpr(const ast::Expr& e) {
  WEFT_ASSIGN_OR_RETURN(Value v, Eval(e));
  if (v.kind != Value::Kind::kType) return Error(e.loc, "'" + ExprText(e) + "' is not a type");
  return v.type;
}

// ---------------------------------------------------------------------------------------
// Calls
// ---------------------------------------------------------------------------------------

// `*x` as a call argument: x's components in order (vector and quaternion components, matrix
// rows, tuple elements), with constant slices of those, or the elements of a constant slice
// of a 1-D array (`*a[:3]`: explicit upper bound, no negative bounds or step).
Status Checker::ExpandStarred(const ast::Starred& s, std::vector<Value>* out) {
  const ast::Expr& inner = *s.value;
  auto components = [&](int var, const std::vector<int>& which) -> Status {
    const Type t = TypeOf(var);
    const Type comp = t.is_matrix() ? Type::Vector(t.cols, t.scalar) : Type::Scalar(t.scalar);
    for (int k : which) {
      int ci = EmitConst(Type::Int32(), "wp::int32(" + std::to_string(k) + ")");
      out->push_back(Value::OfVar(EmitOp(OpKind::kExtract, comp, {var, ci})));
    }
    return Status::Ok();
  };
  auto count_of = [&](const Type& t) { return t.is_matrix() ? t.rows : t.component_count(); };
  auto unpackable = [](const Type& t) { return t.is_vector() || t.is_matrix() || t.kind == TypeKind::kQuat; };
  const auto* sub = ast::As<ast::Subscript>(&inner);
  const auto* sl = sub && sub->indices.size() == 1 ? ast::As<ast::Slice>(sub->indices[0].get()) : nullptr;
  if (sl) {
    WEFT_ASSIGN_OR_RETURN(Value base, Eval(*sub->value));
    const Type bt = base.kind == Value::Kind::kVar ? TypeOf(base.var) : Type();
    if (base.kind == Value::Kind::kVar && bt.is_array()) {
      if (bt.ndim != 1)
        return ErrorOf("type", sl->loc, "Starred slices of arrays need a 1-D array, '" + ExprText(*sub->value) +
                                            "' has " + std::to_string(bt.ndim) + " dimensions");
      auto bound = [&](const ast::ExprPtr& e, long def, long* v) -> Status {
        *v = def;
        if (!e) return Status::Ok();
        WEFT_ASSIGN_OR_RETURN(Value x, Eval(*e));
        if (x.kind != Value::Kind::kVar || !(x.literal || x.const_local) || x.literal_text.empty() ||
            x.literal_text.find_first_not_of("-0123456789") != std::string::npos || x.literal_text.size() > 9)
          return ErrorOf("value", e->loc, "Slice component must be a compile-time constant (an integer literal)");
        *v = std::stol(x.literal_text);
        return Status::Ok();
      };
      if (!sl->upper)
        return ErrorOf("value", sl->loc, "Starred array slice requires explicit upper bound: '" + ExprText(inner) + "'");
      long lo = 0, hi = 0, step = 1;
      WEFT_RETURN_IF_ERROR(bound(sl->lower, 0, &lo));
      WEFT_RETURN_IF_ERROR(bound(sl->upper, 0, &hi));
      WEFT_RETURN_IF_ERROR(bound(sl->step, 1, &step));
      if (lo < 0 || hi < 0) return ErrorOf("value", sl->loc, "Slice bounds cannot be negative for arrays");
      if (step <= 0)
        return ErrorOf("value", sl->loc, step == 0 ? "Slice step cannot be zero" : "Slice step cannot be negative for arrays");
      if ((hi - lo) / step > 1024) return ErrorOf("value", sl->loc, "Starred array slice selects more than 1024 elements");
      for (long k = lo; k < hi; k += step) {
        int ci = EmitConst(Type::Int32(), "wp::int32(" + std::to_string(k) + ")");
        out->push_back(Value::OfVar(EmitOp(OpKind::kLoad, bt.elem(), {base.var, ci})));
        st_->block->back().op.array_param = ArrayParamOf(base.var);
        st_->block->back().op.array_name = ExprText(*sub->value);
        st_->fn.may_fail = true;
      }
      return Status::Ok();
    }
    if (base.kind == Value::Kind::kVar && unpackable(bt)) {
      WEFT_ASSIGN_OR_RETURN(std::vector<int> which, SliceComponents(*sl, count_of(bt)));
      return components(base.var, which);
    }
  }
  WEFT_ASSIGN_OR_RETURN(Value v, Eval(inner));
  if (v.kind == Value::Kind::kTuple) {
    for (const auto& e : v.elems) out->push_back(e);
    return Status::Ok();
  }
  if (v.kind == Value::Kind::kVar && unpackable(TypeOf(v.var))) {
    std::vector<int> all(count_of(TypeOf(v.var)));
    for (size_t k = 0; k < all.size(); ++k) all[k] = static_cast<int>(k);
    return components(v.var, all);
  }
  return ErrorOf("type", s.loc,
                 "Starred expressions are only supported for vectors, quaternions, matrices, tuples and constant "
                 "slices of arrays; '" + ExprText(inner) + "' is " +
                     (v.kind == Value::Kind::kVar ? "a " + TypeString(TypeOf(v.var)) : std::string("not a value")));
}

// wp.array(ptr=f.ptr, shape=(n, ...), dtype=T) in a kernel, f a fixed-size array: an array of
// T over f's elements (Warp reinterprets the memory). weft kernels have no pointers, so `ptr`
// must be a fixed-size array's .ptr, the shape constant, and the view must fit in f's elements
// with T's alignment at most its element's (checked here, at compile time).
Expected<Value> Checker::EvalArrayOverFixed(const ast::Call& c) {
  const ast::Expr* ptr = nullptr;
  const ast::Expr* shape = nullptr;
  const ast::Expr* dtype = nullptr;
  for (const auto& kw : c.keywords) {
    if (kw.name == "ptr") ptr = kw.value.get();
    else if (kw.name == "shape") shape = kw.value.get();
    else if (kw.name == "dtype") dtype = kw.value.get();
    else return Error(kw.value->loc, "wp.array() in a kernel takes ptr=, shape= and dtype=");
  }
  const auto* pa = ptr ? ast::As<ast::Attribute>(ptr) : nullptr;
  if (!c.args.empty() || !pa || pa->attr != "ptr" || !shape || !dtype)
    return Error(c.loc, "wp.array() in a kernel takes ptr=<fixed-size array>.ptr, a constant shape= and dtype= "
                        "(weft kernels have no pointers)");
  WEFT_ASSIGN_OR_RETURN(Value base, Eval(*pa->value));
  if (base.kind != Value::Kind::kVar || !TypeOf(base.var).is_fixed_array())
    return Error(pa->value->loc, "'" + ExprText(*pa->value) + "' is not a fixed-size array (wp.zeros(shape=..., dtype=...)): "
                                 "weft kernels have no pointers");
  const Type ft = TypeOf(base.var);
  WEFT_ASSIGN_OR_RETURN(Type elem, EvalTypeExpr(*dtype));
  std::vector<const ast::Expr*> dims;
  if (const auto* tu = ast::As<ast::Tuple>(shape)) {
    for (const auto& e : tu->elts) dims.push_back(e.get());
  } else {
    dims.push_back(shape);
  }
  if (dims.empty() || dims.size() > 4) return Error(shape->loc, "an array has 1 to 4 dimensions");
  std::vector<int64_t> ext;
  int64_t count = 1;
  for (const ast::Expr* d : dims) {
    WEFT_ASSIGN_OR_RETURN(Value v, Eval(*d));
    if (v.kind != Value::Kind::kVar || !v.literal || !IsIntLiteralText(v.literal_text) || v.literal_text[0] == '-' ||
        v.literal_text.size() > 6)
      return Error(d->loc, "the shape of wp.array(ptr=...) in a kernel must be constant");
    ext.push_back(std::stoll(v.literal_text));
    if (ext.back() < 1) return Error(d->loc, "the shape of wp.array(ptr=...) in a kernel has extents of at least 1");
    count *= ext.back();
    if (count > (int64_t{1} << 24)) return Error(c.loc, "wp.array(ptr=...): the view is larger than its fixed-size array");
  }
  auto el = LayoutOf(elem, module_.structs);
  auto fl = LayoutOf(ft.elem(), module_.structs);
  if (!el.ok() || !fl.ok() || elem.is_array()) return Error(dtype->loc, "wp.array(ptr=...): bad dtype " + TypeString(elem));
  if (ContainsArrays(elem, module_.structs) || ContainsArrays(ft.elem(), module_.structs))
    return Error(c.loc, "wp.array(ptr=...): the elements may not hold arrays (their addresses would be reinterpreted)");
  int64_t have = fl->size;
  for (int n : ft.fixed_shape) have *= n;
  if (count * static_cast<int64_t>(el->size) > have)
    return Error(c.loc, "wp.array(ptr=...): " + std::to_string(count) + " elements of " + TypeString(elem) + " (" +
                            std::to_string(count * el->size) + " bytes) do not fit in '" + ExprText(*pa->value) + "' (" +
                            std::to_string(have) + " bytes)");
  if (el->align > fl->align)
    return Error(c.loc, "wp.array(ptr=...): " + TypeString(elem) + " needs a stricter alignment than the elements of '" +
                            ExprText(*pa->value) + "'");
  std::string text = "wp::cg_reinterpret<" + CppType(elem) + ">(wp::as_array($0)";
  for (int64_t n : ext) text += ", wp::int64(" + std::to_string(n) + ")";
  text += ")";
  int v = EmitRaw(Type::Array(elem, static_cast<int>(ext.size())), text, {base.var});
  return Value::OfVar(v);
}

// A name bound nowhere: weft's words and Warp's (tests match "Referencing undefined symbol"), a
// KeyError in the client as in Warp.
Status Checker::UnknownName(const std::string& name, const SourceLocation& loc) {
  return ErrorOf("key", loc, "unknown name '" + name + "' (Referencing undefined symbol: " + name + ")");
}

// The function of a call. A bare name bound nowhere (no local, global or Python builtin) names
// the wp builtin or type of that name, as Warp resolves callees: `vec3(...)`, `expect_eq(...)`.
Expected<Value> Checker::EvalCallee(const ast::Expr& f) {
  const auto* n = ast::As<ast::Name>(&f);
  if (!n || st_->scope.count(n->id) || st_->tuple_scope.count(n->id) || st_->func_scope.count(n->id) ||
      st_->path_bound.count(n->id))
    return Eval(f);
  bool found = false;
  WEFT_ASSIGN_OR_RETURN(Value v, LookupGlobal(n->id, n->loc, &found));
  if (found) {
    v.source = n->id;
    return v;
  }
  Value w;
  if (BuiltinRegistry::Get().Has(n->id) || IsSpecialBuiltin(n->id)) {
    w.kind = Value::Kind::kBuiltin;
    w.name = n->id;
    return w;
  }
  auto t = ParseType(n->id);
  if (t.ok() && !t->is_void() && !ContainsAny(*t) && !t->is_struct() && !t->is_tuple()) {
    w.kind = Value::Kind::kType;
    w.type = *t;
    return w;
  }
  return UnknownName(n->id, n->loc);
}

Expected<Value> Checker::EvalCall(const ast::Call& c) {
  if (const auto* fa = ast::As<ast::Attribute>(c.func.get()); fa && fa->attr == "array") {
    auto owner = Eval(*fa->value);
    if (owner.ok() && owner->kind == Value::Kind::kModule) return EvalArrayOverFixed(c);
  }
  if (const auto* fn = ast::As<ast::Name>(c.func.get());
      fn && fn->id == "type" && !st_->scope.count("type") && !symbols_.count("type")) {
    // type(x): the type of a value, as a constructor or for its .dtype/.length (Warp's type()).
    if (c.args.size() != 1 || !c.keywords.empty() || ast::As<ast::Starred>(c.args[0].get()))
      return Error(c.loc, "type() takes one value");
    WEFT_ASSIGN_OR_RETURN(Value v, Eval(*c.args[0]));
    if (v.kind != Value::Kind::kVar) return Error(c.args[0]->loc, "type() takes a value, got '" + ExprText(*c.args[0]) + "'");
    Value t;
    t.kind = Value::Kind::kType;
    t.type = TypeOf(v.var);
    t.source = ExprText(c);
    return t;
  }
  if (const auto* fn = ast::As<ast::Name>(c.func.get());
      fn && fn->id == "slice" && !st_->scope.count("slice") && !symbols_.count("slice")) {
    // slice(start, stop[, step]) as Python's: a tuple named "slice" of its three parts (None where
    // left out), which wp.tile_view reads as a slice of a dimension.
    if (c.args.empty() || c.args.size() > 3 || !c.keywords.empty())
      return Error(c.loc, "slice() takes (stop), (start, stop) or (start, stop, step)");
    std::vector<Value> parts;
    for (const auto& a : c.args) {
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*a));
      parts.push_back(v);
    }
    if (parts.size() == 1) parts.insert(parts.begin(), Value());
    while (parts.size() < 3) parts.push_back(Value());
    Value t;
    t.kind = Value::Kind::kTuple;
    t.name = "slice";
    t.elems = std::move(parts);
    t.source = ExprText(c);
    return t;
  }
  WEFT_ASSIGN_OR_RETURN(Value callee, EvalCallee(*c.func));
  if (callee.kind == Value::Kind::kBuiltin && callee.name == "tile_arange") {
    // A bound past int64 (2**70) has no integer type to carry it: Warp's message, which points
    // at the float spelling, rather than the literal's own error.
    static const char* kOne[] = {"stop"};
    static const char* kMore[] = {"start", "stop", "step"};
    for (size_t k = 0; k < c.args.size() && k < 3; ++k) {
      const ast::Expr* e = c.args[k].get();
      if (const auto* u = ast::As<ast::UnaryOp>(e); u && u->op == ast::UnaryOperator::kMinus) e = u->operand.get();
      const auto* lit = ast::As<ast::Constant>(e);
      if (lit && lit->type == ast::Constant::Type::kInt && (!lit->int_fits_u64 || lit->int_value > 9223372036854775807ull))
        return ErrorOf("value", c.args[k]->loc, std::string("tile_arange() ") + (c.args.size() == 1 ? kOne[0] : kMore[k]) +
                                                   "=" + ExprText(*c.args[k]) + " is too wide to use as an integer "
                                                   "bound; write it as a floating-point literal");
    }
  }
  std::vector<Value> args;
  for (const auto& a : c.args) {
    if (const auto* star = ast::As<ast::Starred>(a.get())) {
      WEFT_RETURN_IF_ERROR(ExpandStarred(*star, &args));
      continue;
    }
    WEFT_ASSIGN_OR_RETURN(Value v, Eval(*a));
    args.push_back(v);
  }
  switch (callee.kind) {
    case Value::Kind::kBuiltin: return CallBuiltin(callee.name, std::move(args), c.loc, &c);
    case Value::Kind::kType: return CallConstructor(callee.type, std::move(args), c.loc, c);
    case Value::Kind::kFunc: {
      std::vector<std::pair<std::string, Value>> kwargs;
      for (const auto& kw : c.keywords) {
        WEFT_ASSIGN_OR_RETURN(Value v, Eval(*kw.value));
        kwargs.emplace_back(kw.name, v);
      }
      return CallUserFunc(callee.name, std::move(args), c.loc, kwargs, &c);
    }
    default: return Error(c.func->loc, "'" + ExprText(*c.func) + "' is not callable");
  }
}

// The element scalar types an atomic builtin works on (Warp's rule, the same words): add and
// sub [u]int32, [u]int64, float16, bfloat16, float32, float64; min and max the same without
// float16; cas and exch [u]int32, [u]int64, float32, float64; and, or, xor [u]int32, [u]int64.
// Explicit wp.atomic_* calls only: `arr[i] += v` on other element types stays allowed (Warp
// does a non-atomic read-modify-write there; weft's stays atomic).
static Status CheckAtomicElement(const std::string& name, const Type& arr) {
  if (name.rfind("atomic_", 0) != 0 || !arr.is_array()) return Status::Ok();
  const std::string op = name.substr(7);
  const Type elem = arr.elem();
  const ScalarKind s = elem.scalar;
  const bool wide_int = s == ScalarKind::kInt32 || s == ScalarKind::kUInt32 || s == ScalarKind::kInt64 ||
                        s == ScalarKind::kUInt64;
  const bool wide_float = s == ScalarKind::kFloat32 || s == ScalarKind::kFloat64;
  bool ok = true;
  const char* allowed = "";
  if (op == "add" || op == "sub") {
    ok = wide_int || wide_float || s == ScalarKind::kFloat16 || s == ScalarKind::kBFloat16;
    allowed = "[u]int32, [u]int64, float16, bfloat16, float32, or float64";
  } else if (op == "min" || op == "max") {
    ok = wide_int || wide_float || s == ScalarKind::kBFloat16;
    allowed = "[u]int32, [u]int64, bfloat16, float32, or float64";
  } else if (op == "cas" || op == "exch") {
    ok = wide_int || wide_float;
    allowed = "[u]int32, [u]int64, float32, or float64";
  } else if (op == "and" || op == "or" || op == "xor") {
    ok = wide_int;
    allowed = "[u]int32 or [u]int64";
  }
  if (ok || elem.generic != GenericScalar::kNone) return Status::Ok();
  return InvalidArgument(name + "() operations only work on arrays with " + allowed +
                         " as the underlying scalar types, but got " + WarpTypeRepr(elem) + " (with scalar type " +
                         ScalarName(s) + ")");
}

Expected<Value> Checker::ResolveAndEmitBuiltin(const std::string& name, std::vector<Value> args,
                                               const SourceLocation& loc, int array_param,
                                               const std::string& array_name) {
  // An operator with a tile operand applies element-wise (Warp's tile arithmetic).
  static const std::set<std::string> kTileOperators = {"add",    "sub",    "mul",     "div",     "floordiv",
                                                       "mod",    "pow",    "lshift",  "rshift",  "bit_or",
                                                       "bit_xor", "bit_and", "neg",   "pos",     "invert"};
  if (kTileOperators.count(name)) {
    for (const Value& a : args) {
      if (a.kind != Value::Kind::kVar || !TypeOf(a.var).is_tile()) continue;
      Value f;
      f.kind = Value::Kind::kBuiltin;
      f.name = name;
      // Warp's rule for tile products and quotients: one side's element is a scalar
      auto elem_of = [&](const Value& v) {
        const Type t = v.kind == Value::Kind::kVar ? TypeOf(v.var) : Type::Void();
        return t.is_tile() ? t.elem() : t;
      };
      if ((name == "mul" || name == "div") && args.size() == 2 && !elem_of(args[0]).is_scalar() &&
          !elem_of(args[1]).is_scalar()) {
        auto operand = [&](const Value& v) {
          if (v.kind != Value::Kind::kVar) return v.source;
          const Type t = TypeOf(v.var);
          return t.is_tile() ? "tile<" + WarpTypeRepr(t.elem()) + ">" : WarpTypeRepr(t);
        };
        const bool both_tiles = args[0].kind == Value::Kind::kVar && args[1].kind == Value::Kind::kVar &&
                                TypeOf(args[0].var).is_tile() && TypeOf(args[1].var).is_tile();
        if (both_tiles)   // Warp's two messages: tile by tile, tile by value
          return ErrorOf("type", loc, "tile " + name + ": one operand's element type must be scalar, got " +
                                          TypeString(elem_of(args[0])) + " and " + TypeString(elem_of(args[1])));
        return ErrorOf("type", loc, std::string(name == "mul" ? "Cannot multiply " : "Cannot divide ") +
                                        operand(args[0]) + " by " + operand(args[1]) +
                                        ": at least one operand must be a scalar type");
      }
      args.insert(args.begin(), f);
      return TileMap("tile_map", std::move(args), loc, nullptr);
    }
  }
  std::vector<Type> types;
  std::vector<int> literals;
  for (const auto& a : args) {
    if (a.kind == Value::Kind::kString) {
      types.push_back(Type::String());
      literals.push_back(0);
      continue;
    }
    if (a.kind != Value::Kind::kVar)
      return Error(loc, "argument of '" + name + "' is not a value" + (a.source.empty() ? "" : ": '" + a.source + "'"));
    types.push_back(TypeOf(a.var));
    literals.push_back(a.literal ? (IsIntLiteralText(a.literal_text) ? 1 : 2) : 0);
  }
  auto m = BuiltinRegistry::Get().Resolve(name, types, &literals);
  if (!m.ok()) {
    std::string msg = m.status().message();
    return Error(loc, msg);
  }
  if (m->overload->native.rfind("struct_", 0) == 0 && !struct_arithmetic_)
    return ErrorOf("type", loc, "'" + name + "' of Warp structs is defined only on the elements of struct tiles "
                                "(t + u, t - u, -t, t[i] += s, wp.tile_sum), field by field");
  Stmt s;
  s.op.kind = OpKind::kCall;
  s.op.builtin = m->overload;
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i].kind == Value::Kind::kString) return Error(loc, "string arguments are only allowed in printf");
    int v = args[i].var;
    if (TypeOf(v) != m->param_types[i]) {
      WEFT_ASSIGN_OR_RETURN(v, Coerce(args[i], m->param_types[i], loc, "argument " + std::to_string(i + 1)));
    }
    s.op.args.push_back(v);
  }
  Value out;
  if (m->result.is_tuple()) {
    out.kind = Value::Kind::kTuple;
    for (const auto& t : m->result.sub) {
      int d = NewVar(t);
      s.op.dst.push_back(d);
      out.elems.push_back(Value::OfVar(d));
    }
  } else if (!m->result.is_void()) {
    int d = NewVar(m->result);
    s.op.dst.push_back(d);
    out = Value::OfVar(d);
  }
  if (m->overload->flags & kBuiltinArrayAccess) {
    s.op.array_param = array_param >= 0 ? array_param : ArrayParamOf(args[0].var);
    s.op.array_name = !array_name.empty() ? array_name : args[0].source;
    st_->fn.may_fail = true;
  }
  Push(std::move(s));
  return out;
}

Expected<Value> Checker::CallBuiltin(const std::string& name, std::vector<Value> args, const SourceLocation& loc,
                                     const ast::Call* call) {
  if (name.rfind("tile", 0) == 0 || name == "untile") {
    bool handled = false;
    auto r = CallTile(name, args, loc, call, &handled);
    if (handled) return r;
  }
  if (!args.empty() && args[0].kind == Value::Kind::kVar) {
    Status atomic = CheckAtomicElement(name, TypeOf(args[0].var));
    if (!atomic.ok()) return Error(loc, atomic.message());
  }
  auto kwarg = [&](const std::string& k) -> const ast::Expr* {
    if (!call) return nullptr;
    for (const auto& kw : call->keywords)
      if (kw.name == k) return kw.value.get();
    return nullptr;
  };
  auto dtype_kw = [&](ScalarKind def) -> Expected<ScalarKind> {
    const ast::Expr* d = kwarg("dtype");
    if (!d) return def;
    WEFT_ASSIGN_OR_RETURN(Type t, EvalTypeExpr(*d));
    if (!t.is_scalar()) return Error(d->loc, "dtype must be a scalar type");
    return t.scalar;
  };
  // A compile-time size: an integer literal or a module constant holding one.
  auto const_int = [&](const ast::Expr* e, const char* what) -> Expected<int> {
    if (!e) return Error(loc, std::string(what) + " must be a small integer constant");
    auto v = Eval(*e);
    if (!v.ok()) return v.status();
    if (v->kind != Value::Kind::kVar || !v->literal || !IsIntLiteralText(v->literal_text) ||
        v->literal_text[0] == '-' || v->literal_text.size() > 3 || std::stoi(v->literal_text) > 64)
      return Error(e->loc, std::string(what) + " must be a small integer constant (0 to 64)");
    return std::stoi(v->literal_text);
  };
  if (lanes_ > 1 && (name == "tile_bvh_query_next" || name == "bvh_query_next_tiled" ||
                     name == "tile_mesh_query_aabb_next" || name == "mesh_query_aabb_next_tiled")) {
    // cooperative CPU blocks: a tile of the block's lanes per _next (engine/native/geometry_tiled.h)
    const bool bvh = name.find("bvh") != std::string::npos;
    args.insert(args.begin(), Value::OfVar(NewVar(Type::Tile(Type::Int32(), {lanes_}), "tile shape")));
    return ResolveAndEmitBuiltin(bvh ? "tile_bvh_query_next_lanes" : "tile_mesh_query_aabb_next_lanes", std::move(args), loc);
  }
  if (name == "tid") {
    if (!args.empty()) return Error(loc, "wp.tid() takes no arguments");
    // In a @wp.func: the calling thread's index (codegen passes __tid_flat to every func).
    st_->fn.uses_tid = true;
    Value v = Value::OfVar(EmitRaw(Type::Int32(), "wp::int32(wp::cg_tid_first(__ctx, __tid_flat))", {}));
    v.name = "__tid";
    return v;
  }
  if ((name == "transform_set_translation" || name == "transform_set_rotation") && call && call->args.size() == 2 &&
      call->keywords.empty()) {
    // Warp writes xform in place; here the registry row computes the updated transform and the
    // first argument (a name, field or element) is assigned it. The call itself gives None.
    WEFT_ASSIGN_OR_RETURN(Value updated, ResolveAndEmitBuiltin(name, std::move(args), loc));
    WEFT_RETURN_IF_ERROR(LowerAssignTo(*call->args[0], updated));
    return Value();
  }
  // Volumes: the value type of volume_sample / volume_sample_grad / volume_lookup is the dtype=
  // keyword, passed on as a value of that type (the rows' last parameter); the forms with Warp's
  // out-parameter `grad` (the last positional argument) return (value, grad): the gradient is
  // assigned to the argument and the call gives the value.
  if (call && name.rfind("volume_", 0) == 0) {
    const bool typed = (name == "volume_sample" || name == "volume_sample_grad" || name == "volume_lookup") &&
                       kwarg("dtype") != nullptr;
    // The positional inputs of the grad forms; one more argument is the out-parameter.
    const size_t grad_inputs = name == "volume_sample_grad_index" ? 5
                               : (name == "volume_sample_grad" || name == "volume_sample_grad_f") ? 3
                                                                                                  : 0;
    const bool grad_out = grad_inputs != 0 && args.size() == grad_inputs + 1 && (typed || name != "volume_sample_grad");
    if (typed || grad_out) {
      for (const auto& kw : call->keywords)
        if (!typed || kw.name != "dtype") return Error(loc, "wp." + name + "() got an unexpected keyword argument '" + kw.name + "'");
      std::vector<Value> inputs = std::move(args);
      Value args_grad;
      if (grad_out) {
        args_grad = inputs.back();
        inputs.pop_back();
      }
      if (typed) {
        WEFT_ASSIGN_OR_RETURN(Type t, EvalTypeExpr(*kwarg("dtype")));
        inputs.push_back(Value::OfVar(EmitRaw(t, "wp::cg_zeros<" + CppType(t) + ">()", {})));
      }
      const Value grad_arg = grad_out ? args_grad : Value();
      WEFT_ASSIGN_OR_RETURN(Value result, ResolveAndEmitBuiltin(name, std::move(inputs), loc));
      if (!grad_out) return result;
      if (result.elems.size() != 2) return Error(loc, "wp." + name + "(): internal result shape");
      if (grad_arg.kind == Value::Kind::kVar && result.elems[1].kind == Value::Kind::kVar &&
          TypeOf(grad_arg.var) != TypeOf(result.elems[1].var)) {
        return Error(call->args.back()->loc, "Incompatible gradient type, expected " +
                                                 WarpTypeRepr(TypeOf(result.elems[1].var)) + ", got " +
                                                 WarpTypeRepr(TypeOf(grad_arg.var)));
      }
      WEFT_RETURN_IF_ERROR(LowerAssignTo(*call->args.back(), result.elems[1]));
      return result.elems[0];
    }
  }
  // Warp's out-parameter form of builtins with several results: wp.svd3(A, U, sigma, V)
  // assigns the results to the trailing arguments (names, fields or elements), as
  // U, sigma, V = wp.svd3(A) does.
  if (call && call->keywords.empty() && !args.empty()) {
    for (const BuiltinOverload* o : BuiltinRegistry::Get().Overloads(name)) {
      if (o->result_pattern.rfind("tuple(", 0) != 0) continue;
      size_t n_in = o->param_patterns.size();
      if (n_in >= args.size()) continue;
      std::vector<Value> inputs(args.begin(), args.begin() + static_cast<long>(n_in));
      std::vector<Type> in_types;
      bool values = true;
      for (const auto& a : inputs) {
        values &= a.kind == Value::Kind::kVar;
        if (values) in_types.push_back(TypeOf(a.var));
      }
      if (!values) continue;
      auto m = BuiltinRegistry::Get().Resolve(name, in_types);
      if (!m.ok() || !m->result.is_tuple() || m->result.sub.size() + n_in != args.size()) continue;
      WEFT_ASSIGN_OR_RETURN(Value results, ResolveAndEmitBuiltin(name, std::move(inputs), loc));
      for (size_t k = 0; k < results.elems.size(); ++k)
        WEFT_RETURN_IF_ERROR(LowerAssignTo(*call->args[n_in + k], results.elems[k]));
      return Value();
    }
  }
  if ((name == "matrix_from_rows" || name == "matrix_from_cols") && !args.empty() && args.size() <= 64 &&
      (!call || call->keywords.empty())) {
    // Any number of vectors of one type: rows fill the matrix row-major (a concatenation),
    // columns use the column constructor; both are differentiable constructions.
    for (const auto& a : args)
      if (a.kind != Value::Kind::kVar || !TypeOf(a.var).is_vector() || TypeOf(a.var) != TypeOf(args[0].var))
        return Error(loc, "wp." + name + " takes vectors of one type");
    const Type vt = TypeOf(args[0].var);
    int n = static_cast<int>(args.size());
    bool rows = name == "matrix_from_rows";
    Type t = rows ? Type::Matrix(n, vt.rows, vt.scalar) : Type::Matrix(vt.rows, n, vt.scalar);
    Stmt st;
    st.op.kind = OpKind::kConstruct;
    st.op.mode = rows ? ConstructMode::kConcat : ConstructMode::kColumns;
    int d = NewVar(t);
    st.op.dst.push_back(d);
    for (const auto& a : args) st.op.args.push_back(a.var);
    Push(std::move(st));
    return Value::OfVar(d);
  }
  if (name == "range") return Error(loc, "range() is only allowed as the iterable of a for loop");
  if (name == "len" && args.size() == 1 && args[0].kind == Value::Kind::kTuple) {
    const std::string n = std::to_string(args[0].elems.size());
    Value v = Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + n + ")"));
    v.literal = true;
    v.literal_text = n;
    return v;
  }
  if (name == "len") {
    if (args.size() != 1 || args[0].kind != Value::Kind::kVar) return Error(loc, "len() takes one value");
    const Type& t = TypeOf(args[0].var);
    if (t.is_fixed_array())
      return Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(t.fixed_shape[0]) + ")"));
    if (t.is_tile()) {   // a constant (wp.static(len(t)) reads it)
      Value n = Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(t.fixed_shape[0]) + ")"));
      n.literal = true;
      n.literal_text = std::to_string(t.fixed_shape[0]);
      return n;
    }
    if (t.is_indexed_array()) return Value::OfVar(EmitRaw(Type::Int32(), "wp::len($0)", {args[0].var}));
    if (t.is_array()) return Value::OfVar(EmitRaw(Type::Int32(), "wp::int32($0.shape[0])", {args[0].var}));
    if (t.is_vector() || t.kind == TypeKind::kQuat || t.kind == TypeKind::kTransform)
      return Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(t.component_count()) + ")"));
    if (t.is_matrix()) return Value::OfVar(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(t.rows) + ")"));
    return Error(loc, "len() of a value of type " + TypeString(t));
  }
  if (name == "printf") {
    if (args.empty() || args[0].kind != Value::Kind::kString)
      return Error(loc, "wp.printf takes a format string literal first");
    if (args.size() - 1 > 32)
      return ErrorOf("value", loc, "the maximum number of variadic arguments that can be passed to `printf` is 32");
    Stmt s;
    s.op.kind = OpKind::kPrintf;
    std::vector<Type> types;
    for (size_t i = 1; i < args.size(); ++i) {
      if (args[i].kind != Value::Kind::kVar || !TypeOf(args[i].var).is_scalar())
        return Error(loc, "wp.printf arguments must be scalars");
      s.op.args.push_back(args[i].var);
      types.push_back(TypeOf(args[i].var));
    }
    auto format = CheckPrintfFormat(args[0].name, types);
    if (!format.ok()) return Error(loc, format.status().message());
    s.op.text = std::move(*format);
    Push(std::move(s));
    return Value{};
  }
  if (name == "print") {
    for (const auto& a : args) {
      if (a.kind == Value::Kind::kString) {
        Stmt s;
        s.op.kind = OpKind::kPrintf;
        s.op.text = LiteralFormat(a.name) + "\n";  // a format: '%' doubled
        Push(std::move(s));
        continue;
      }
      WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin("print", {a}, loc));
      (void)r;
    }
    return Value{};
  }
  if (name == "quat_identity" || name == "transform_identity") {
    WEFT_ASSIGN_OR_RETURN(ScalarKind s, dtype_kw(ScalarKind::kFloat32));
    if (!args.empty()) {
      if (args[0].kind != Value::Kind::kType || !args[0].type.is_scalar()) return Error(loc, name + " takes a dtype");
      s = args[0].type.scalar;
    }
    Type t = name == "quat_identity" ? Type::Quat(s) : Type::Transform(s);
    return Value::OfVar(EmitConst(t, "wp::cg_identity<" + CppType(t) + ">()"));
  }
  if (name == "identity") {
    const ast::Expr* n = kwarg("n");
    if (!n && call && !call->args.empty()) n = call->args[0].get();
    WEFT_ASSIGN_OR_RETURN(int dim, const_int(n, "identity(n=...)"));
    WEFT_ASSIGN_OR_RETURN(ScalarKind s, dtype_kw(ScalarKind::kFloat32));
    Type t = Type::Matrix(dim, dim, s);
    std::string text = "wp::cg_identity<" + CppType(t) + ">()";
    return Value::OfVar(EmitConst(t, text));
  }
  if (name == "vector" || name == "matrix" || name == "quaternion" || name == "transformation") {
    std::vector<Value> vals;
    for (auto& a : args) vals.push_back(a);
    ScalarKind def = ScalarKind::kFloat32;
    for (const auto& v : vals)
      if (v.kind == Value::Kind::kVar && !v.literal) {
        def = TypeOf(v.var).scalar;
        break;
      }
    if (name == "vector" && !kwarg("dtype")) {
      // Without dtype every value must have one type (Warp): 1.0 and 2 do not mix.
      int ints = 0, floats = 0;
      for (const auto& v : vals) {
        if (v.kind != Value::Kind::kVar || !TypeOf(v.var).is_scalar()) continue;
        const bool is_int = v.literal ? IsIntLiteralText(v.literal_text) : IsInt(TypeOf(v.var).scalar);
        (is_int ? ints : floats)++;
      }
      if (ints && floats) return ErrorOf("type", loc, "all values given when constructing a vector must have the same type");
    }
    WEFT_ASSIGN_OR_RETURN(ScalarKind s, dtype_kw(def));
    Type t;
    if (name == "vector") {
      // length: given, else the number of components of the arguments (a vector argument
      // counts its components: wp.vector(v, dtype=wp.float16) converts v).
      int len = 0;
      for (const auto& v : vals)
        if (v.kind == Value::Kind::kVar) len += TypeOf(v.var).is_composite() ? TypeOf(v.var).component_count() : 1;
      if (const ast::Expr* l = kwarg("length")) {
        const auto* lc = ast::As<ast::Constant>(l);
        const bool one_vector = vals.size() == 1 && vals[0].kind == Value::Kind::kVar && TypeOf(vals[0].var).is_vector();
        if (lc && lc->type == ast::Constant::Type::kInt && lc->int_fits_u64 && len > 0 &&
            lc->int_value != static_cast<uint64_t>(len) &&
            !(vals.size() == 1 && vals[0].kind == Value::Kind::kVar && TypeOf(vals[0].var).is_scalar()))
          return Error(loc, one_vector ? "incompatible vector of length " + lc->int_decimal +
                                             " given when copy constructing a vector of length " + std::to_string(len)
                                       : "incompatible number of values given (" + std::to_string(len) +
                                             ") when constructing a vector of length " + lc->int_decimal);
        WEFT_ASSIGN_OR_RETURN(len, const_int(l, "length"));
      }
      if (len <= 0) return Error(loc, "the `length` argument must be specified when zero-initializing a vector");
      t = Type::Vector(len, s);
    } else if (name == "matrix") {
      const ast::Expr* sh = kwarg("shape");
      const auto* tu = sh ? ast::As<ast::Tuple>(sh) : nullptr;
      if (!sh && vals.size() == 1 && vals[0].kind == Value::Kind::kVar && TypeOf(vals[0].var).is_matrix()) {
        const Type mt = TypeOf(vals[0].var);
        t = Type::Matrix(mt.rows, mt.cols, s);
        ast::Call empty;
        return CallConstructor(t, std::move(vals), loc, call ? *call : empty);
      }
      if (!sh && !vals.empty())
        return Error(loc, "the `shape` argument must be specified when initializing a matrix by value");
      if (!tu || tu->elts.size() != 2) return Error(loc, "wp.matrix needs shape=(rows, cols)");
      WEFT_ASSIGN_OR_RETURN(int r, const_int(tu->elts[0].get(), "rows"));
      WEFT_ASSIGN_OR_RETURN(int cc, const_int(tu->elts[1].get(), "cols"));
      t = Type::Matrix(r, cc, s);
    } else if (name == "quaternion") {
      t = Type::Quat(s);
    } else {
      t = Type::Transform(s);
    }
    ast::Call empty;
    return CallConstructor(t, std::move(vals), loc, call ? *call : empty);
  }
  if (name == "zeros") {
    // wp.zeros(shape=..., dtype=...) in a kernel or func: a fixed-size array value, zeroed.
    const ast::Expr* sh = kwarg("shape");
    const ast::Expr* dt = kwarg("dtype");
    if (call && !call->args.empty()) sh = call->args[0].get();
    if (call && call->args.size() > 1) dt = call->args[1].get();
    const std::string kNotConst = "the `shape` argument must be specified as a constant when zero-initializing an array";
    if (!sh) return Error(loc, kNotConst);
    std::vector<const ast::Expr*> dims;
    if (const auto* tu = ast::As<ast::Tuple>(sh)) {
      for (const auto& e : tu->elts) dims.push_back(e.get());
    } else {
      dims.push_back(sh);
    }
    if (dims.empty() || dims.size() > 4) return Error(sh->loc, "a fixed-size array has 1 to 4 dimensions");
    std::vector<int> shape;
    int64_t total = 1;
    for (const ast::Expr* d : dims) {
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*d));
      if (v.kind != Value::Kind::kVar || !v.literal || !IsIntLiteralText(v.literal_text) || v.literal_text[0] == '-' ||
          v.literal_text.size() > 5)
        return Error(d->loc, kNotConst);
      const int n = std::stoi(v.literal_text);
      total *= n;
      if (n < 1 || total > kMaxFixedArrayElements)
        return Error(d->loc, "a fixed-size array holds 1 to " + std::to_string(kMaxFixedArrayElements) + " elements");
      shape.push_back(n);
    }
    Type elem = Type::Float32();
    if (dt) {
      WEFT_ASSIGN_OR_RETURN(elem, EvalTypeExpr(*dt));
    }
    if (elem.is_array() || elem.is_void() || elem.is_tuple() || elem.is_any() || elem.kind == TypeKind::kString)
      return Error(loc, "wp.zeros: bad dtype " + TypeString(elem));
    Type t = Type::FixedArray(elem, shape);
    Stmt st;
    st.op.kind = OpKind::kConstruct;
    st.op.mode = ConstructMode::kZero;
    int d = NewVar(t);
    st.op.dst.push_back(d);
    Push(std::move(st));
    return Value::OfVar(d);
  }
  if (name == "static" && args.size() == 1 && (!call || call->keywords.empty()) &&
      ((args[0].kind == Value::Kind::kVar && args[0].literal) || args[0].kind == Value::Kind::kType ||
       args[0].kind == Value::Kind::kFunc))
    return args[0];   // a value known while compiling (len() of a tuple, a constant)
  if (name == "static" && call && args.size() == 1 && call->keywords.empty() && args[0].kind == Value::Kind::kVar &&
      call->args.size() == 1 && !TypeOf(args[0].var).is_array()) {
    // wp.static(expr) the client could not evaluate: it reads kernel variables. Warp evaluates
    // it while generating code, which it can when those are loop variables of range loops with
    // constant bounds (it unrolls them) or literal-valued locals; weft evaluates it at run time
    // in each iteration, to the same value.
    std::string bad;
    std::function<void(const ast::Expr&)> walk = [&](const ast::Expr& e) {
      if (!bad.empty()) return;
      if (const auto* n = ast::As<ast::Name>(&e)) {
        const bool local = st_->scope.count(n->id) || st_->tuple_scope.count(n->id);
        if (local && !st_->static_loop_vars.count(n->id) && !st_->literal_locals.count(n->id)) bad = n->id;
        return;
      }
      if (const auto* a = ast::As<ast::Attribute>(&e)) return walk(*a->value);
      if (const auto* sub = ast::As<ast::Subscript>(&e)) {
        walk(*sub->value);
        for (const auto& i : sub->indices) walk(*i);
        return;
      }
      if (const auto* c = ast::As<ast::Call>(&e)) {
        // len(x) of a value whose length its type fixes (vector, matrix, quaternion, fixed-size
        // array, tuple) is known while compiling, whatever x holds
        const auto* fn = ast::As<ast::Name>(c->func.get());
        const auto* arg = c->args.size() == 1 ? ast::As<ast::Name>(c->args[0].get()) : nullptr;
        if (fn && fn->id == "len" && arg && c->keywords.empty()) {
          if (st_->tuple_scope.count(arg->id)) return;
          auto it = st_->scope.find(arg->id);
          if (it != st_->scope.end()) {
            const Type t = TypeOf(it->second);
            if (t.is_composite() || t.is_fixed_array()) return;
          }
        }
        walk(*c->func);
        for (const auto& a : c->args) walk(*a);
        for (const auto& k : c->keywords) walk(*k.value);
        return;
      }
      if (const auto* b = ast::As<ast::BinOp>(&e)) return walk(*b->left), walk(*b->right);
      if (const auto* u = ast::As<ast::UnaryOp>(&e)) return walk(*u->operand);
      if (const auto* b = ast::As<ast::BoolOp>(&e)) {
        for (const auto& v : b->values) walk(*v);
        return;
      }
      if (const auto* c = ast::As<ast::Compare>(&e)) {
        walk(*c->left);
        for (const auto& v : c->comparators) walk(*v);
        return;
      }
      if (const auto* i = ast::As<ast::IfExp>(&e)) return walk(*i->test), walk(*i->body), walk(*i->orelse);
      if (const auto* t = ast::As<ast::Tuple>(&e)) {
        for (const auto& v : t->elts) walk(*v);
        return;
      }
      if (ast::As<ast::Constant>(&e)) return;
      bad = ExprText(e);
    };
    walk(*call->args[0]);
    if (bad.empty()) return args[0];
    return Error(loc, "Error evaluating static expression: name '" + bad + "' is not defined. Make sure all variables "
                      "used in the static expression are constant. (In weft it may read constants, literal-valued "
                      "locals and the variables of range loops with constant bounds.)");
  }
  if (name == "cast" || name == "static")
    return Error(loc, "wp." + name + "() is not supported in weft kernels yet");
  if (call && !call->keywords.empty()) {
    // Map keywords onto the parameter names of each overload in turn.
    std::string last_error;
    for (const BuiltinOverload* o : BuiltinRegistry::Get().Overloads(name)) {
      if (o->param_names.size() != args.size() + call->keywords.size()) continue;
      std::vector<Value> full = args;
      full.resize(o->param_names.size());
      bool ok = true;
      for (const auto& kw : call->keywords) {
        size_t k = 0;
        while (k < o->param_names.size() && o->param_names[k] != kw.name) ++k;
        if (k < args.size() || k >= o->param_names.size()) {
          ok = false;
          break;
        }
        auto v = Eval(*kw.value);
        if (!v.ok()) return v.status();
        full[k] = *v;
      }
      if (!ok) continue;
      bool complete = true;
      for (const auto& f : full) complete &= f.kind != Value::Kind::kNone;
      if (!complete) continue;
      return ResolveAndEmitBuiltin(name, std::move(full), loc);
    }
    return Error(call->keywords[0].loc, "no overload of '" + name + "' has a parameter '" + call->keywords[0].name + "'");
  }
  return ResolveAndEmitBuiltin(name, std::move(args), loc);
}

Expected<Value> Checker::CallConstructor(const Type& t, std::vector<Value> args, const SourceLocation& loc,
                                         const ast::Call& call) {
  // A local assigned once from a literal converts as that literal (Warp's constant Vars).
  for (auto& a : args)
    if (a.kind == Value::Kind::kVar && a.const_local) a.literal = true;
  Stmt s;
  s.op.kind = OpKind::kConstruct;
  int d = -1;
  if (t.is_struct()) {
    auto it = module_.structs.find(t.struct_name);
    if (it == module_.structs.end()) return Error(loc, "unknown struct '" + t.struct_name + "'");
    const StructInfo& info = it->second;
    if (args.size() > info.fields.size())
      return Error(loc, "struct " + t.struct_name + " has " + std::to_string(info.fields.size()) + " fields but " +
                            std::to_string(args.size()) + " positional arguments were given");
    d = NewVar(t);
    s.op.mode = ConstructMode::kZero;
    s.op.dst.push_back(d);
    Push(std::move(s));
    // Positional arguments set the fields in declaration order (as Warp), keywords by name.
    for (size_t k = 0; k < args.size(); ++k) {
      const StructField& f = info.fields[k];
      WEFT_ASSIGN_OR_RETURN(int cv, Coerce(args[k], f.type, loc, "field '" + f.name + "'"));
      int nd = EmitOp(OpKind::kSetField, t, {d, cv}, f.name);
      st_->block->back().op.field_index = static_cast<int>(k);
      d = nd;
    }
    for (const auto& kw : call.keywords) {
      int fi = -1;
      const StructField* f = it->second.Find(kw.name, &fi);
      if (!f) return Error(kw.loc, "struct " + t.struct_name + " has no field '" + kw.name + "'");
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*kw.value));
      WEFT_ASSIGN_OR_RETURN(int cv, Coerce(v, f->type, kw.value->loc, "field '" + kw.name + "'"));
      int nd = EmitOp(OpKind::kSetField, t, {d, cv}, kw.name);
      st_->block->back().op.field_index = fi;
      d = nd;
    }
    return Value::OfVar(d);
  }
  bool transform_parts = false;   // wp.transform(p=..., q=...): q defaults to the identity
  for (const auto& kw : call.keywords) {
    if (t.kind == TypeKind::kTransform && (kw.name == "p" || kw.name == "q")) {
      transform_parts = true;
      continue;
    }
    if (kw.name != "dtype" && kw.name != "length" && kw.name != "shape")
      return Error(kw.loc, "unexpected keyword '" + kw.name + "' for " + TypeString(t));
  }
  if (transform_parts) {
    std::vector<Value> parts(args.begin(), args.end());
    if (parts.size() > 2) return Error(loc, TypeString(t) + "(p, q) takes at most two arguments");
    parts.resize(2);
    for (const auto& kw : call.keywords) {
      if (kw.name != "p" && kw.name != "q") continue;
      Value& slot = parts[kw.name == "p" ? 0 : 1];
      if (slot.kind != Value::Kind::kNone) return Error(kw.loc, "'" + kw.name + "' given twice");
      WEFT_ASSIGN_OR_RETURN(slot, Eval(*kw.value));
    }
    if (parts[0].kind == Value::Kind::kNone) return Error(loc, TypeString(t) + "() needs its translation p");
    if (parts[1].kind == Value::Kind::kNone)
      parts[1] = Value::OfVar(EmitConst(Type::Quat(t.scalar), "wp::cg_identity<" + CppType(Type::Quat(t.scalar)) + ">()"));
    args = std::move(parts);
  }
  for (const auto& a : args)
    if (a.kind != Value::Kind::kVar) return Error(loc, "constructor arguments of " + TypeString(t) + " must be values");
  if (t.is_scalar()) {
    if (args.size() != 1) return Error(loc, TypeString(t) + "() takes exactly one argument");
    const Type& at = TypeOf(args[0].var);
    if (at == t) return args[0];
    if (args[0].literal) {
      auto cpp = CppLiteral(t, args[0].literal_text);
      if (cpp.ok()) return Value::OfVar(EmitConst(t, *cpp));
    }
    if (!at.is_scalar()) return Error(loc, "cannot convert " + TypeString(at) + " to " + TypeString(t));
    s.op.mode = ConstructMode::kConvert;
  } else if (t.is_composite()) {
    int n = t.component_count();
    // Warp's wording for vectors and matrices ("this vector", "a matrix of shape (2, 2)").
    const char* noun = t.is_matrix() ? "matrix" : "vector";
    auto size_text = [](const Type& x) {
      return x.is_matrix() ? "shape (" + std::to_string(x.rows) + ", " + std::to_string(x.cols) + ")"
                           : "length " + std::to_string(x.component_count());
    };
    auto scalar_of = [&](const Value& a, const char* what) -> Expected<int> {
      if (!a.literal && TypeOf(a.var).is_scalar() && TypeOf(a.var).scalar != t.scalar &&
          (t.is_vector() || t.is_matrix()))
        return ErrorOf("type", loc, std::string(what) + noun + " are expected to be of the type `" +
                                        TypeString(Type::Scalar(t.scalar)) + "`");
      return Coerce(a, Type::Scalar(t.scalar), loc, "component");
    };
    if (args.empty()) {
      s.op.mode = ConstructMode::kZero;
    } else if (args.size() == 1 && TypeOf(args[0].var).is_scalar()) {
      s.op.mode = ConstructMode::kFill;
      if (!args[0].literal && TypeOf(args[0].var).scalar != t.scalar && (t.is_vector() || t.is_matrix()))
        return ErrorOf("type", loc, std::string("the value used to fill this ") + noun +
                                        " is expected to be of the type `" + TypeString(Type::Scalar(t.scalar)) + "`");
      WEFT_ASSIGN_OR_RETURN(int v, Coerce(args[0], Type::Scalar(t.scalar), loc, "the fill value"));
      args[0] = Value::OfVar(v);
    } else if (args.size() == 1 && (t.is_vector() || t.is_matrix()) && TypeOf(args[0].var).kind == t.kind &&
               (TypeOf(args[0].var).component_count() != n ||
                (t.is_matrix() && TypeOf(args[0].var).rows != t.rows))) {
      return Error(loc, std::string("incompatible ") + noun + " of " + size_text(t) +
                            " given when copy constructing a " + noun + " of " + size_text(TypeOf(args[0].var)));
    } else if (args.size() == 1 && TypeOf(args[0].var).kind == t.kind &&
               TypeOf(args[0].var).component_count() == n) {
      if (TypeOf(args[0].var) == t) return args[0];
      s.op.mode = ConstructMode::kConvert;
    } else if (t.is_matrix() && static_cast<int>(args.size()) == t.cols && TypeOf(args[0].var).is_vector()) {
      s.op.mode = ConstructMode::kColumns;
      for (auto& a : args)
        if (TypeOf(a.var) != Type::Vector(t.rows, t.scalar))
          return Error(loc, TypeString(t) + " from columns needs " + std::to_string(t.cols) + " vectors of type " +
                                TypeString(Type::Vector(t.rows, t.scalar)) + ", got " + TypeString(TypeOf(a.var)));
    } else {
      s.op.mode = ConstructMode::kConcat;
      int total = 0;
      for (auto& a : args) {
        const Type& at = TypeOf(a.var);
        if (at.is_scalar()) {
          WEFT_ASSIGN_OR_RETURN(int v, scalar_of(a, "all values used to initialize this "));
          a = Value::OfVar(v);
          total += 1;
        } else if (at.is_composite() && at.scalar == t.scalar) {
          total += at.component_count();
        } else {
          return Error(loc, "cannot build " + TypeString(t) + " from a value of type " + TypeString(at));
        }
      }
      if (total != n) {
        if (t.is_vector() || t.is_matrix())
          return Error(loc, "incompatible number of values given (" + std::to_string(total) + ") when constructing a " +
                                noun + " of " + size_text(t));
        return Error(loc, TypeString(t) + " needs " + std::to_string(n) + " components, got " + std::to_string(total));
      }
    }
  } else {
    return Error(loc, "values of type " + TypeString(t) + " cannot be constructed in kernels");
  }
  d = NewVar(t);
  s.op.dst.push_back(d);
  for (const auto& a : args) s.op.args.push_back(a.var);
  Push(std::move(s));
  return Value::OfVar(d);
}


bool RefTypeInner(const std::string& ts, std::string* inner) {
  if (ts.size() < 6 || ts.compare(0, 4, "ref(") != 0 || ts.back() != ')') return false;
  *inner = ts.substr(4, ts.size() - 5);
  return true;
}

Status Checker::CheckRefArgument(const ast::Expr* e, const std::string& param, const std::string& func,
                                 const SourceLocation& loc) {
  const std::string what = "the argument of wp.ref parameter '" + param + "' of '" + func + "'";
  if (!e) return Error(loc, what + " must be passed by position or keyword, not unpacked with *");
  const ast::Expr* root = e;
  while (true) {
    if (const auto* sub = ast::As<ast::Subscript>(root)) {
      for (const auto& i : sub->indices)
        if (ast::As<ast::Slice>(i.get())) return Error(e->loc, what + " cannot be a slice");
      root = sub->value.get();
    } else if (const auto* at = ast::As<ast::Attribute>(root)) {
      root = at->value.get();
    } else {
      break;
    }
  }
  const auto* n = ast::As<ast::Name>(root);
  if (!n || !st_->scope.count(n->id))
    return Error(e->loc, what + " must be a variable, an array element, a component or a struct field "
                              "(a place the function can write to), got '" + ExprText(*e) + "'");
  auto lit = st_->untyped_literal_names.find(n->id);
  if (root == e && lit != st_->untyped_literal_names.end()) {
    const std::string& text = lit->second;
    const bool is_float = text.find_first_of(".eE") != std::string::npos && text.rfind("0x", 0) != 0;
    return Error(e->loc, "'" + n->id + "' holds the constant " + text + "; to pass it to " + what +
                             ", give it a type: " + n->id + " = wp." + (is_float ? "float32" : "int32") + "(" + text + ")");
  }
  return Status::Ok();
}

Expected<Value> Checker::CallUserFunc(const std::string& name, std::vector<Value> args, const SourceLocation& loc,
                                      const std::vector<std::pair<std::string, Value>>& kwargs, const ast::Call* call) {
  auto range = symbols_.equal_range(name);
  struct Candidate {
    const ParsedFunction* pf;
    std::vector<Type> types;
    bool generic;
    std::vector<bool> refs;   // wp.ref[T] parameters
  };
  std::vector<Candidate> cands;
  std::string sigs;
  for (auto it = range.first; it != range.second; ++it) {
    if (it->second->kind != Symbol::Kind::kFunction) continue;
    auto f = by_key_.find(it->second->target);
    if (f == by_key_.end()) return Error(loc, "function '" + name + "' (key '" + it->second->target + "') was not sent");
    Candidate c{f->second, {}, false, {}};
    bool ok = true;
    for (const auto& ts : f->second->source->param_types) {
      std::string inner;
      const bool is_ref = RefTypeInner(ts, &inner);
      c.refs.push_back(is_ref);
      auto t = ParseType(is_ref ? inner : ts);
      if (!t.ok()) return Error(loc, "function '" + name + "': " + t.status().message());
      c.generic |= ContainsAny(*t);
      c.types.push_back(*t);
    }
    sigs += "\n      " + name + "(";
    for (size_t i = 0; i < c.types.size(); ++i) sigs += (i ? ", " : "") + TypeString(c.types[i]);
    sigs += ")";
    if (ok) cands.push_back(std::move(c));
  }
  // Passes, as Warp resolves overloads: (0) a concrete overload taking the arguments' own
  // types (an int literal is int32, so f(1) calls f(x: int) rather than f(x: float)),
  // (1) a generic overload, (2) a concrete overload after literal adaptation (f(1) calls
  // f(x: float) when that is the only one). Keyword arguments bind by parameter name;
  // parameters left out take their defaults.
  for (int pass = 0; pass < 3; ++pass) {
    for (auto& c : cands) {
      if (c.generic != (pass == 1)) continue;
      const auto& params = c.pf->def->params;
      if (args.size() > c.types.size() || params.size() != c.types.size()) continue;
      std::vector<const Value*> slots(c.types.size(), nullptr);
      for (size_t i = 0; i < args.size(); ++i) slots[i] = &args[i];
      bool ok = true;
      for (const auto& [kname, kval] : kwargs) {
        size_t k = 0;
        while (k < params.size() && params[k].name != kname) ++k;
        if (k == params.size() || slots[k]) {
          ok = false;
          break;
        }
        slots[k] = &kval;
      }
      for (size_t i = 0; i < slots.size() && ok; ++i)
        if (!slots[i] && !params[i].default_value) ok = false;
      if (!ok) continue;
      std::vector<Type> inst = c.types;
      for (size_t i = 0; i < slots.size() && ok; ++i) {
        if (!slots[i]) continue;
        const Value& a = *slots[i];
        if (c.types[i].is_function() || a.kind == Value::Kind::kFunc || a.kind == Value::Kind::kBuiltin) {
          ok = c.types[i].is_function() && (a.kind == Value::Kind::kFunc || a.kind == Value::Kind::kBuiltin);
          if (!ok) break;
          inst[i] = Type::Function((a.kind == Value::Kind::kFunc ? "func:" : "builtin:") + a.name);
          continue;
        }
        if (a.kind == Value::Kind::kTuple) {
          // a tuple for a tuple parameter of the same element types, or for an Any parameter
          std::vector<Type> elems;
          for (const Value& e : a.elems) {
            if (e.kind != Value::Kind::kVar) break;
            elems.push_back(TypeOf(e.var));
          }
          const Type& p = c.types[i];
          ok = elems.size() == a.elems.size() &&
               (p.is_any() || (p.is_tuple() && p.sub.size() == elems.size()));
          for (size_t k = 0; ok && p.is_tuple() && k < elems.size(); ++k)
            ok = p.sub[k] == elems[k] || (ContainsAny(p.sub[k]) && GenericAccepts(p.sub[k], elems[k]));
          if (!ok) break;
          inst[i] = Type::Tuple(elems);
          continue;
        }
        if (a.kind != Value::Kind::kVar) {
          ok = false;
          break;
        }
        if (c.refs[i]) {   // a reference takes a value of its own type (no conversion)
          ok = c.types[i] == TypeOf(a.var) || (ContainsAny(c.types[i]) && GenericAccepts(c.types[i], TypeOf(a.var)));
          if (ok) inst[i] = TypeOf(a.var);
          if (!ok) break;
          continue;
        }
        Type at = TypeOf(a.var);
        // A fixed-size array passed for an array parameter: the callee gets an array view of
        // the caller's elements (writes reach them, as in Warp).
        if (at.is_fixed_array() && c.types[i].is_array() && !c.types[i].is_fixed_array() && !c.types[i].indexed)
          at = Type::Array(at.elem(), at.ndim);
        if (c.types[i] == at) continue;
        if (ContainsAny(c.types[i])) {
          ok = GenericAccepts(c.types[i], at);
          inst[i] = at;
        } else {
          ok = pass == 2 && a.literal && c.types[i].is_scalar() && c.types[i].scalar != ScalarKind::kBool &&
               (IsFloat(c.types[i].scalar) || IsIntLiteralText(a.literal_text));
        }
      }
      if (!ok) continue;
      // wp.ref[T] arguments: each must name a place the result can be written back to.
      std::vector<const ast::Expr*> ref_targets(slots.size(), nullptr);
      for (size_t i = 0; i < slots.size(); ++i) {
        if (!c.refs[i]) continue;
        if (!slots[i])
          return Error(loc, "'" + params[i].name + "' of '" + name + "' is a wp.ref parameter: it needs an argument");
        const ast::Expr* e = nullptr;
        if (call) {
          bool starred = false;
          for (const auto& a : call->args) starred |= ast::As<ast::Starred>(a.get()) != nullptr;
          if (!starred && i < call->args.size() && i < args.size()) e = call->args[i].get();
          for (const auto& kw : call->keywords)
            if (kw.name == params[i].name) e = kw.value.get();
        }
        WEFT_RETURN_IF_ERROR(CheckRefArgument(e, params[i].name, name, loc));
        ref_targets[i] = e;
      }
      // Tiles and tile stacks are passed by reference (Warp): what the function does to one
      // reaches the caller's variable. A temporary argument has no place and is not written.
      if (call && call->args.size() == args.size())
        for (size_t i = 0; i < slots.size() && i < call->args.size(); ++i) {
          if (c.refs[i] || !slots[i] || slots[i]->kind != Value::Kind::kVar) continue;
          const Type t = TypeOf(slots[i]->var);
          const auto* n = ast::As<ast::Name>(call->args[i].get());
          if ((t.is_tile() || t.is_tile_stack()) && n && st_->scope.count(n->id))
            ref_targets[i] = call->args[i].get();
        }
      std::vector<int> argv;
      for (size_t i = 0; i < slots.size(); ++i) {
        if (slots[i] && inst[i].is_function()) continue;   // compile-time: no argument
        if (slots[i] && slots[i]->kind == Value::Kind::kTuple) {
          for (const Value& e : slots[i]->elems) argv.push_back(e.var);
          continue;
        }
        if (slots[i] && slots[i]->kind == Value::Kind::kVar && TypeOf(slots[i]->var).is_fixed_array() &&
            inst[i].is_array() && !inst[i].is_fixed_array()) {
          argv.push_back(EmitRaw(inst[i], "wp::as_array($0)", {slots[i]->var}));
          continue;
        }
        if (slots[i]) {
          WEFT_ASSIGN_OR_RETURN(int v, Coerce(*slots[i], inst[i], loc, "argument '" + params[i].name + "'"));
          argv.push_back(v);
          continue;
        }
        WEFT_ASSIGN_OR_RETURN(Value dv, Eval(*params[i].default_value));
        if (inst[i].is_function()) {
          if (dv.kind != Value::Kind::kFunc && dv.kind != Value::Kind::kBuiltin)
            return Error(params[i].loc, "the default of '" + params[i].name + "' is not a function");
          inst[i] = Type::Function((dv.kind == Value::Kind::kFunc ? "func:" : "builtin:") + dv.name);
          continue;
        }
        if (dv.kind != Value::Kind::kVar)
          return Error(params[i].loc, "the default of '" + params[i].name + "' is not a value");
        if (ContainsAny(inst[i])) inst[i] = TypeOf(dv.var);
        WEFT_ASSIGN_OR_RETURN(int v, Coerce(dv, inst[i], params[i].loc, "default of '" + params[i].name + "'"));
        argv.push_back(v);
      }
      WEFT_ASSIGN_OR_RETURN(int idx, InstantiateFunction(*c.pf, inst, loc));
      const Function& callee = module_.functions[idx];
      const std::vector<int> ref_params = callee.ref_params;
      const size_t own_returns = callee.returns.size() - ref_params.size();
      Stmt s;
      s.op.kind = OpKind::kFuncCall;
      s.op.callee = idx;
      s.op.args = argv;
      std::vector<int> dsts;
      for (const auto& t : callee.returns) dsts.push_back(NewVar(t));
      s.op.dst = dsts;
      Value out;
      if (own_returns == 1) {
        out = Value::OfVar(dsts[0]);
      } else if (own_returns > 1) {
        out.kind = Value::Kind::kTuple;
        for (size_t k = 0; k < own_returns; ++k) out.elems.push_back(Value::OfVar(dsts[k]));
      }
      st_->fn.may_fail |= module_.functions[idx].may_fail;
      Push(std::move(s));
      // the final values of the wp.ref[T] parameters, written back to the arguments' places
      for (size_t k = 0; k < ref_params.size(); ++k) {
        const ast::Expr* target = ref_targets.at(static_cast<size_t>(ref_params[k]));
        if (!target && !c.refs[static_cast<size_t>(ref_params[k])]) continue;   // a temporary tile
        if (!target) return Error(loc, "wp.ref argument of '" + name + "' has no place to write to");
        write_through_ = true;
        WEFT_RETURN_IF_ERROR(LowerAssignTo(*target, Value::OfVar(dsts[own_returns + k])));
      }
      return out;
    }
  }
  std::string got;
  for (size_t i = 0; i < args.size(); ++i)
    got += (i ? ", " : "") +
           (args[i].kind == Value::Kind::kVar ? TypeString(TypeOf(args[i].var)) : std::string("<non-value>"));
  for (const auto& [kname, kval] : kwargs)
    got += (got.empty() ? "" : ", ") + kname + "=" +
           (kval.kind == Value::Kind::kVar ? TypeString(TypeOf(kval.var)) : std::string("<non-value>"));
  return Error(loc, "no overload of function '" + name + "' accepts (" + got + "); candidates:" + sigs);
}

}  // namespace weft::sema
