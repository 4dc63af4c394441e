// The kernel language's syntax tree: every node kind of Warp's Python subset, as parsed by
// engine/lang/parser.h. One X-macro list for expressions and one for statements drives the
// node structs' `kind`, the visitor (ExprVisitor / StmtVisitor below), the printer
// (ast_printer.cpp) and, in sema, the type checker: a new kind does not compile until every
// switch over the list handles it.
//
// Ownership: a parent owns its children through std::unique_ptr (ExprPtr / StmtPtr).
// Locations: every node carries a SourceLocation in the USER's file:
//   line   = FunctionSource.first_line + (line in FunctionSource.source) - 1
//   column = 1-based column in FunctionSource.source (the client dedents the source, so this
//            is the column in the dedented text; the original indentation is not sent).
// Annotation slots for semantic analysis (engine/sema), never touched by lang:
//   Expr::type_id  int, -1 until sema assigns the index of the expression's type.
//   Expr::sema / Stmt::sema  opaque pointer, nullptr until sema sets it; the AST never frees
//            it (sema keeps the pointee alive in its own arena).
// The parser rejects every construct outside the subset with a diagnostic; what it accepts
// but sema must still police is marked "sema checks" below.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/core/module_source.h"

namespace weft::ast {

// ---------------------------------------------------------------------------------------
// Node kinds
// ---------------------------------------------------------------------------------------

// X(NodeName)
#define WEFT_FOR_EACH_AST_EXPR(X) \
  X(Name)                         \
  X(Constant)                     \
  X(Attribute)                    \
  X(Subscript)                    \
  X(Slice)                        \
  X(Call)                         \
  X(BinOp)                        \
  X(UnaryOp)                      \
  X(BoolOp)                       \
  X(Compare)                      \
  X(IfExp)                        \
  X(Tuple)                        \
  X(List)                         \
  X(Starred)

#define WEFT_FOR_EACH_AST_STMT(X) \
  X(FunctionDef)                  \
  X(Assign)                       \
  X(AnnAssign)                    \
  X(AugAssign)                    \
  X(If)                           \
  X(For)                          \
  X(While)                        \
  X(Break)                        \
  X(Continue)                     \
  X(Return)                       \
  X(ExprStmt)                     \
  X(Pass)                         \
  X(Assert)

enum class ExprKind {
#define WEFT_AST_ENUM_ENTRY(N) k##N,
  WEFT_FOR_EACH_AST_EXPR(WEFT_AST_ENUM_ENTRY)
};
enum class StmtKind {
  WEFT_FOR_EACH_AST_STMT(WEFT_AST_ENUM_ENTRY)
#undef WEFT_AST_ENUM_ENTRY
};

const char* ExprKindName(ExprKind k);  // "Name", "Constant", ...
const char* StmtKindName(StmtKind k);  // "FunctionDef", "Assign", ...

// ---------------------------------------------------------------------------------------
// Operators: X(Enumerator, python spelling, python ast name)
// ---------------------------------------------------------------------------------------

#define WEFT_FOR_EACH_BINARY_OPERATOR(X) \
  X(kAdd, "+", "Add")                    \
  X(kSub, "-", "Sub")                    \
  X(kMul, "*", "Mult")                   \
  X(kMatMul, "@", "MatMult")             \
  X(kDiv, "/", "Div")                    \
  X(kFloorDiv, "//", "FloorDiv")         \
  X(kMod, "%", "Mod")                    \
  X(kPow, "**", "Pow")                   \
  X(kLShift, "<<", "LShift")             \
  X(kRShift, ">>", "RShift")             \
  X(kBitOr, "|", "BitOr")                \
  X(kBitXor, "^", "BitXor")              \
  X(kBitAnd, "&", "BitAnd")

#define WEFT_FOR_EACH_UNARY_OPERATOR(X) \
  X(kPlus, "+", "UAdd")                 \
  X(kMinus, "-", "USub")                \
  X(kInvert, "~", "Invert")             \
  X(kNot, "not", "Not")

#define WEFT_FOR_EACH_BOOL_OPERATOR(X) \
  X(kAnd, "and", "And")                \
  X(kOr, "or", "Or")

#define WEFT_FOR_EACH_COMPARE_OPERATOR(X) \
  X(kEq, "==", "Eq")                      \
  X(kNotEq, "!=", "NotEq")                \
  X(kLt, "<", "Lt")                       \
  X(kLtE, "<=", "LtE")                    \
  X(kGt, ">", "Gt")                       \
  X(kGtE, ">=", "GtE")                    \
  X(kIs, "is", "Is")                      \
  X(kIsNot, "is not", "IsNot")            \
  X(kIn, "in", "In")                      \
  X(kNotIn, "not in", "NotIn")

#define WEFT_AST_OP_ENTRY(E, S, N) E,
enum class BinaryOperator { WEFT_FOR_EACH_BINARY_OPERATOR(WEFT_AST_OP_ENTRY) };
enum class UnaryOperator { WEFT_FOR_EACH_UNARY_OPERATOR(WEFT_AST_OP_ENTRY) };
enum class BoolOperator { WEFT_FOR_EACH_BOOL_OPERATOR(WEFT_AST_OP_ENTRY) };
enum class CompareOperator { WEFT_FOR_EACH_COMPARE_OPERATOR(WEFT_AST_OP_ENTRY) };
#undef WEFT_AST_OP_ENTRY

// Python spelling ("+", "not in") and Python ast name ("Add", "NotIn") of each operator.
const char* Spelling(BinaryOperator op);
const char* Spelling(UnaryOperator op);
const char* Spelling(BoolOperator op);
const char* Spelling(CompareOperator op);
const char* AstName(BinaryOperator op);
const char* AstName(UnaryOperator op);
const char* AstName(BoolOperator op);
const char* AstName(CompareOperator op);

// ---------------------------------------------------------------------------------------
// Base classes
// ---------------------------------------------------------------------------------------

struct Node {
  SourceLocation loc;  // first character of the node (see the header comment for mapping)
  virtual ~Node() = default;
};

struct Expr : Node {
  explicit Expr(ExprKind k) : kind(k) {}
  const ExprKind kind;
  int type_id = -1;        // sema: index of this expression's type; -1 = not yet typed
  void* sema = nullptr;    // sema: opaque annotation, not owned by the AST
};

struct Stmt : Node {
  explicit Stmt(StmtKind k) : kind(k) {}
  const StmtKind kind;
  void* sema = nullptr;    // sema: opaque annotation, not owned by the AST
};

using ExprPtr = std::unique_ptr<Expr>;
using StmtPtr = std::unique_ptr<Stmt>;
using ExprList = std::vector<ExprPtr>;
using StmtList = std::vector<StmtPtr>;

// Checked downcasts: `if (auto* c = ast::As<ast::Call>(e)) ...`; nullptr on a kind mismatch.
template <typename T, typename B>
T* As(B* node) {
  return node && node->kind == T::kKind ? static_cast<T*>(node) : nullptr;
}
template <typename T, typename B>
const T* As(const B* node) {
  return node && node->kind == T::kKind ? static_cast<const T*>(node) : nullptr;
}

// ---------------------------------------------------------------------------------------
// Expressions
// ---------------------------------------------------------------------------------------

// `x`, `wp`, `float`, `range`, `True` is NOT a Name (it is a Constant).
struct Name : Expr {
  static constexpr ExprKind kKind = ExprKind::kName;
  Name() : Expr(kKind) {}
  std::string id;
};

// A literal. Negative numbers are UnaryOp(kMinus, Constant): Python's grammar.
struct Constant : Expr {
  static constexpr ExprKind kKind = ExprKind::kConstant;
  Constant() : Expr(kKind) {}
  enum class Type { kInt, kFloat, kBool, kNone, kString };
  Type type = Type::kNone;
  std::string text;          // the literal as written in the source (`0x_FF`, `1e-3`, `'a\n'`)
  // kInt: exact value in decimal digits, arbitrary precision (Python ints are unbounded;
  // sema decides whether it fits the target type). `int_fits_u64` says whether int_value
  // holds the exact value.
  std::string int_decimal;
  uint64_t int_value = 0;
  bool int_fits_u64 = true;
  double float_value = 0.0;  // kFloat: nearest double (as Python's float())
  bool bool_value = false;   // kBool
  std::string string_value;  // kString: decoded bytes (escapes processed; adjacent literals joined)
};

// `value.attr`: `wp.vec3`, `p.x`, `a.shape`, `mymod.N`.
struct Attribute : Expr {
  static constexpr ExprKind kKind = ExprKind::kAttribute;
  Attribute() : Expr(kKind) {}
  ExprPtr value;
  std::string attr;
  SourceLocation attr_loc;  // location of the attribute name after the dot
};

// `value[i]`, `value[i, j]`: `indices` has one entry per comma-separated index (a Python
// tuple index `a[i, j]` is stored as two indices, not as one Tuple). An index may be a Slice
// (sema checks where slices are allowed). `a[(i, j)]` is one index that is a Tuple.
struct Subscript : Expr {
  static constexpr ExprKind kKind = ExprKind::kSubscript;
  Subscript() : Expr(kKind) {}
  ExprPtr value;
  ExprList indices;
};

// `lower:upper:step` inside a subscript only; any part may be null.
struct Slice : Expr {
  static constexpr ExprKind kKind = ExprKind::kSlice;
  Slice() : Expr(kKind) {}
  ExprPtr lower;
  ExprPtr upper;
  ExprPtr step;
};

struct Keyword {
  SourceLocation loc;  // location of the keyword name
  std::string name;
  ExprPtr value;
};

// `func(args..., name=value...)`. A positional argument may be a Starred (`f(*v)`); `**k` is
// rejected by the parser.
struct Call : Expr {
  static constexpr ExprKind kKind = ExprKind::kCall;
  Call() : Expr(kKind) {}
  ExprPtr func;
  ExprList args;
  std::vector<Keyword> keywords;
};

// loc is the left operand's start (Python's ast); op_loc is the operator's.
struct BinOp : Expr {
  static constexpr ExprKind kKind = ExprKind::kBinOp;
  BinOp() : Expr(kKind) {}
  BinaryOperator op = BinaryOperator::kAdd;
  ExprPtr left;
  ExprPtr right;
  SourceLocation op_loc;
};

struct UnaryOp : Expr {
  static constexpr ExprKind kKind = ExprKind::kUnaryOp;
  UnaryOp() : Expr(kKind) {}
  UnaryOperator op = UnaryOperator::kMinus;
  ExprPtr operand;
};

// `a and b and c` is ONE BoolOp with three values (Python's ast).
struct BoolOp : Expr {
  static constexpr ExprKind kKind = ExprKind::kBoolOp;
  BoolOp() : Expr(kKind) {}
  BoolOperator op = BoolOperator::kAnd;
  ExprList values;  // size >= 2
};

// `a < b <= c`: left = a, ops = {<, <=}, comparators = {b, c} (Python's ast; means
// `a < b and b <= c` with b evaluated once).
struct Compare : Expr {
  static constexpr ExprKind kKind = ExprKind::kCompare;
  Compare() : Expr(kKind) {}
  ExprPtr left;
  std::vector<CompareOperator> ops;
  ExprList comparators;  // same size as ops
};

// `body if test else orelse`
struct IfExp : Expr {
  static constexpr ExprKind kKind = ExprKind::kIfExp;
  IfExp() : Expr(kKind) {}
  ExprPtr test;
  ExprPtr body;
  ExprPtr orelse;
};

// `(a, b)`, `a, b` (return values, unpacking targets, subscript tuples in parentheses).
struct Tuple : Expr {
  static constexpr ExprKind kKind = ExprKind::kTuple;
  Tuple() : Expr(kKind) {}
  ExprList elts;
  bool parenthesized = false;
};

// `[a, b]` (e.g. `wp.vec3([...])`-style arguments, `shape=[...]`; sema checks where allowed).
struct List : Expr {
  static constexpr ExprKind kKind = ExprKind::kList;
  List() : Expr(kKind) {}
  ExprList elts;
};

// `*value`, only as a positional call argument (`wp.vec4(*v, 1.0)`): sema expands it into
// the components of a vector, quaternion, matrix (its rows), tuple or constant array slice.
struct Starred : Expr {
  static constexpr ExprKind kKind = ExprKind::kStarred;
  Starred() : Expr(kKind) {}
  ExprPtr value;
};

// ---------------------------------------------------------------------------------------
// Statements
// ---------------------------------------------------------------------------------------

struct Param {
  SourceLocation loc;       // location of the parameter name
  std::string name;
  ExprPtr annotation;       // null when not annotated (sema checks kernels annotate all)
  ExprPtr default_value;    // null when none (`def f(x: float, y: float = 1.0)`)
};

// `def name(params) -> returns: body`. Docstrings (a string-constant expression statement
// first in the body) are moved to `docstring` and not kept in `body`. Decorator lines in
// front of the def are skipped; their text is kept in `decorators` for diagnostics.
struct FunctionDef : Stmt {
  static constexpr StmtKind kKind = StmtKind::kFunctionDef;
  FunctionDef() : Stmt(kKind) {}
  std::string name;
  std::vector<Param> params;
  ExprPtr returns;          // null when no `->` annotation
  StmtList body;
  std::string docstring;
  std::vector<std::string> decorators;  // e.g. "wp.kernel", "wp.func" (without '@')
};

// `t1 = t2 = value`: targets in source order (Name, Tuple of targets, Subscript, Attribute;
// sema checks the target forms). Tuple unpacking `a, b = f()` has one Tuple target.
struct Assign : Stmt {
  static constexpr StmtKind kKind = StmtKind::kAssign;
  Assign() : Stmt(kKind) {}
  ExprList targets;  // size >= 1
  ExprPtr value;
};

// `target: annotation = value` (value may be null: `x: float`).
struct AnnAssign : Stmt {
  static constexpr StmtKind kKind = StmtKind::kAnnAssign;
  AnnAssign() : Stmt(kKind) {}
  ExprPtr target;
  ExprPtr annotation;
  ExprPtr value;
};

// `target op= value` (op is the binary operator: `+=` -> kAdd).
struct AugAssign : Stmt {
  static constexpr StmtKind kKind = StmtKind::kAugAssign;
  AugAssign() : Stmt(kKind) {}
  ExprPtr target;
  BinaryOperator op = BinaryOperator::kAdd;
  ExprPtr value;
  SourceLocation op_loc;  // location of the `op=` token
};

// `if test: body else: orelse`. `elif` is an If that is the only statement of orelse, with
// is_elif = true (Python's ast, plus the flag for printing).
struct If : Stmt {
  static constexpr StmtKind kKind = StmtKind::kIf;
  If() : Stmt(kKind) {}
  ExprPtr test;
  StmtList body;
  StmtList orelse;
  bool is_elif = false;
};

// `for target in iter: body` (sema checks iter is range(...) or another iterable Warp allows,
// and that target is a Name). `for ... else` is rejected by the parser.
struct For : Stmt {
  static constexpr StmtKind kKind = StmtKind::kFor;
  For() : Stmt(kKind) {}
  ExprPtr target;
  ExprPtr iter;
  StmtList body;
};

// `while test: body` (`while ... else` is rejected by the parser).
struct While : Stmt {
  static constexpr StmtKind kKind = StmtKind::kWhile;
  While() : Stmt(kKind) {}
  ExprPtr test;
  StmtList body;
};

struct Break : Stmt {
  static constexpr StmtKind kKind = StmtKind::kBreak;
  Break() : Stmt(kKind) {}
};

struct Continue : Stmt {
  static constexpr StmtKind kKind = StmtKind::kContinue;
  Continue() : Stmt(kKind) {}
};

// `return`, `return x`, `return a, b` (value is then a Tuple with parenthesized = false).
struct Return : Stmt {
  static constexpr StmtKind kKind = StmtKind::kReturn;
  Return() : Stmt(kKind) {}
  ExprPtr value;  // null for a bare return
};

// An expression used as a statement (calls: `wp.atomic_add(...)`, `print(x)`).
struct ExprStmt : Stmt {
  static constexpr StmtKind kKind = StmtKind::kExprStmt;
  ExprStmt() : Stmt(kKind) {}
  ExprPtr value;
};

struct Pass : Stmt {
  static constexpr StmtKind kKind = StmtKind::kPass;
  Pass() : Stmt(kKind) {}
};

// `assert test` / `assert test, msg` (Warp checks asserts in debug builds).
struct Assert : Stmt {
  static constexpr StmtKind kKind = StmtKind::kAssert;
  Assert() : Stmt(kKind) {}
  ExprPtr test;
  ExprPtr msg;  // null when absent
};

// ---------------------------------------------------------------------------------------
// Visitors: switch over the X-macro lists. Derive and implement Visit<Kind>(Kind&) for every
// kind; a missing one is a compile error.
//   struct Printer : ast::ExprVisitor<Printer, std::string> {
//     std::string VisitName(ast::Name& n) { ... } ... };
// ---------------------------------------------------------------------------------------

template <typename Derived, typename R = void>
class ExprVisitor {
 public:
  R VisitExpr(Expr& e) {
    switch (e.kind) {
#define WEFT_AST_VISIT_CASE(N) \
  case ExprKind::k##N:         \
    return static_cast<Derived*>(this)->Visit##N(static_cast<N&>(e));
      WEFT_FOR_EACH_AST_EXPR(WEFT_AST_VISIT_CASE)
#undef WEFT_AST_VISIT_CASE
    }
    __builtin_unreachable();
  }
};

template <typename Derived, typename R = void>
class StmtVisitor {
 public:
  R VisitStmt(Stmt& s) {
    switch (s.kind) {
#define WEFT_AST_VISIT_CASE(N) \
  case StmtKind::k##N:         \
    return static_cast<Derived*>(this)->Visit##N(static_cast<N&>(s));
      WEFT_FOR_EACH_AST_STMT(WEFT_AST_VISIT_CASE)
#undef WEFT_AST_VISIT_CASE
    }
    __builtin_unreachable();
  }
};

// The same over const nodes: implement Visit<Kind>(const Kind&).
template <typename Derived, typename R = void>
class ConstExprVisitor {
 public:
  R VisitExpr(const Expr& e) {
    switch (e.kind) {
#define WEFT_AST_VISIT_CASE(N) \
  case ExprKind::k##N:         \
    return static_cast<Derived*>(this)->Visit##N(static_cast<const N&>(e));
      WEFT_FOR_EACH_AST_EXPR(WEFT_AST_VISIT_CASE)
#undef WEFT_AST_VISIT_CASE
    }
    __builtin_unreachable();
  }
};

template <typename Derived, typename R = void>
class ConstStmtVisitor {
 public:
  R VisitStmt(const Stmt& s) {
    switch (s.kind) {
#define WEFT_AST_VISIT_CASE(N) \
  case StmtKind::k##N:         \
    return static_cast<Derived*>(this)->Visit##N(static_cast<const N&>(s));
      WEFT_FOR_EACH_AST_STMT(WEFT_AST_VISIT_CASE)
#undef WEFT_AST_VISIT_CASE
    }
    __builtin_unreachable();
  }
};

}  // namespace weft::ast
