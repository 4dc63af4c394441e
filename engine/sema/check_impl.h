// Internal to sema: the checker/lowerer shared by check.cpp (module, functions, statements)
// and check_expr.cpp (expressions, calls, constructors). Not a public interface.
#pragma once

#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "engine/sema/check.h"

namespace weft::sema {

// What an expression evaluates to: a typed variable, or a compile-time entity.
struct Value {
  enum class Kind { kVar, kModule, kType, kFunc, kBuiltin, kTuple, kString, kNone };
  Kind kind = Kind::kNone;
  int var = -1;
  Type type;                 // kType
  std::string name;          // kFunc: symbol name; kBuiltin: builtin name; kString: text
  std::vector<Value> elems;  // kTuple
  bool literal = false;      // kVar holding a numeric literal that may adapt its type
  std::string literal_text;  // its Python text
  std::string source;        // source text of the expression (array names in errors)
  // kVar of a local assigned once from a numeric literal: literal_text is that literal, used
  // where Warp takes constants (constructors, constant indices), without adapting elsewhere.
  bool const_local = false;

  static Value OfVar(int v) { Value x; x.kind = Kind::kVar; x.var = v; return x; }
};

struct LoopContext {
  int break_flag = -1;
  int continue_flag = -1;
};

// Arrays (plain, indexed or fixed-size) in t, directly or in struct fields / tuple elements.
bool ContainsArrays(const Type& t, const StructTable& structs);
// An array (not fixed-size) whose element holds arrays, anywhere in t: refused as a parameter,
// since its elements' arrays would be read from array memory the client writes.
bool ArrayOfArrays(const Type& t, const StructTable& structs);

class Checker {
 public:
  Checker(const ModuleSource& module, const std::vector<ParsedFunction>& parsed, std::vector<Diagnostic>* diags);
  Expected<Module> Run();

  // --- per-function state ---
  struct TileAlias {
    std::string base;            // the tile local viewed
    Type view;                   // the view's type
    std::vector<Value> region;   // its tile_view / tile_assign region arguments
    bool operator==(const TileAlias& o) const {
      if (base != o.base || view != o.view || region.size() != o.region.size()) return false;
      for (size_t i = 0; i < region.size(); ++i)
        if (region[i].var != o.region[i].var) return false;
      return true;
    }
  };
  struct FnState {
    Function fn;
    const ParsedFunction* parsed = nullptr;
    std::map<std::string, int> scope;
    std::vector<Stmt>* block = nullptr;
    std::vector<LoopContext> loops;
    std::map<int, int> array_param;  // var -> kernel param index (arrays and structs)
    int line = 0;                    // current user line
    bool has_bare_return = false;
    // A generic return annotation (`-> wp.Float`, `-> wp.vec(Any, float)`): the returned types
    // are inferred from the first return and must match these patterns.
    std::vector<Type> return_patterns;
    // In a gradient function (wp.func_grad): parameter name -> its wp.adjoint[...] slot (a
    // return slot; for an array parameter, the gradient array it takes as an extra parameter).
    std::map<std::string, int> adjoint_slots;
    std::vector<std::string> source_lines;
    std::map<std::string, int> assign_counts;   // name -> assignments in the whole body
    std::map<std::string, std::pair<int, std::string>> literal_locals;   // name -> (var, literal text)
    // Names bound to tuples (t = (a, b), a tuple parameter): their element values, each a var.
    std::map<std::string, Value> tuple_scope;
    // Names bound to functions (a wp.Function parameter, f = some_func): kFunc / kBuiltin values.
    std::map<std::string, Value> func_scope;
    // Tuple / function names (re)bound inside an if, for or while: which binding holds after it
    // depends on the path taken, so using them after the statement is an error.
    std::set<std::string> path_bound;
    // Loop variables of the enclosing `for ... in range(...)` loops with constant bounds: the
    // kernel variables a wp.static(...) expression may read.
    std::set<std::string> static_loop_vars;
    // Names whose binding is an untyped numeric literal (`x = 0`): name -> the literal's text.
    std::map<std::string, std::string> untyped_literal_names;
    // Names bound to a view of another tile local (`row = t[i]`, `v = wp.tile_view(t, ...)`):
    // Warp's views alias their tile, so reading the name views the tile as it is now and writing
    // into it (wp.tile_assign, row[j] = x, row += x, a func updating it) writes into the tile.
    std::map<std::string, TileAlias> tile_aliases;
    // name -> the tile locals it may view anywhere in the body (for the loop carries).
    std::map<std::string, std::set<std::string>> view_bases;
  };

  // check.cpp
  Status Error(const SourceLocation& loc, const std::string& msg);
  // An error of a class (Diagnostic::kind: "type", "value", ...) the client raises as such.
  Status ErrorOf(const char* kind, const SourceLocation& loc, const std::string& msg);
  Expected<int> InstantiateFunction(const ParsedFunction& pf, const std::vector<Type>& param_types,
                                    const SourceLocation& call_loc, int grad_of_params = -1);
  Status LowerBlock(const ast::StmtList& stmts, size_t from = 0);
  Status LowerStmt(const ast::Stmt& s);
  Status LowerStmtUnguarded(const ast::Stmt& s);
  Status LowerStmt2(const ast::Stmt& s);   // LowerStmt less the tracking of path-bound names
  Status LowerAssignTo(const ast::Expr& target, Value value);
  Expected<bool> LowerComponentAtomic(const ast::AugAssign& a);
  Status EvalSlotIndices(const ast::ExprList& indices, std::vector<Value>* out);
  Status LowerIf(int cond, const std::function<Status()>& then_fn, const std::function<Status()>& else_fn);
  Status LowerFor(const ast::For& s);
  Status LowerWhile(const ast::While& s);
  Status LowerReturn(const ast::Return& s);
  Status BindLocal(const std::string& name, int var, const SourceLocation& loc);
  int ExitFlagsGuard();
  bool MayExit(const ast::Stmt& s, bool nested_loop) const;

  // check_expr.cpp
  Expected<Value> Eval(const ast::Expr& e);
  Expected<int> EvalVar(const ast::Expr& e);          // must be a runtime value
  Expected<Value> EvalArraySlice(const ast::Subscript& s, const Value& base);
  Expected<Value> EvalArrayOverFixed(const ast::Call& c);
  Expected<int> EvalCond(const ast::Expr& e);         // bool var (ints compared with 0)
  bool MayFailOrHaveEffects(const ast::Expr& e) const;
  bool CanBranchHere() const;
  std::string HiddenLocalName(const char* what);
  Expected<int> EvalShortCircuit(const ast::BoolOp& b, size_t first);
  Expected<std::pair<int, int>> UnifyConditionalBranches(const ast::IfExp& i, const Value& a, const Value& b);
  Expected<Value> EvalConditionalBranches(const ast::IfExp& i, int cond);
  Expected<Value> EvalName(const ast::Name& n);
  Expected<Value> EvalAttribute(const ast::Attribute& a);
  Expected<Value> TypeAttribute(const Type& t, const ast::Attribute& a);
  Expected<Value> EvalCallee(const ast::Expr& f);
  Status UnknownName(const std::string& name, const SourceLocation& loc);
  Expected<Value> EvalSubscript(const ast::Subscript& s);
  // wp.adjoint[x] / wp.adjoint[x.f.g]: AdjointRoot gives x's slot and the field names after
  // it; AdjointSlot reads the (field of the) slot, AssignAdjoint writes it.
  Expected<int> AdjointRoot(const ast::Subscript& s, std::vector<std::string>* fields);
  Expected<int> AdjointSlot(const ast::Subscript& s);
  Status AssignAdjoint(const ast::Subscript& s, const Value& value);
  Expected<Value> EvalCall(const ast::Call& c);
  Status ExpandStarred(const ast::Starred& s, std::vector<Value>* out);
  // The argument `e` of wp.ref[T] parameter `param` of `func`: a place its final value can be
  // written back to (a local, an array element, a component, a struct field of one of those).
  Status CheckRefArgument(const ast::Expr* e, const std::string& param, const std::string& func,
                          const SourceLocation& loc);
  Expected<Value> EvalBinOp(const ast::BinOp& b);
  Expected<Value> EvalCompare(const ast::Compare& c);
  Expected<Value> EvalConstant(const ast::Constant& c);
  Expected<Value> LookupGlobal(const std::string& name, const SourceLocation& loc, bool* found);
  Expected<Value> CallBuiltin(const std::string& name, std::vector<Value> args, const SourceLocation& loc,
                              const ast::Call* call);
  // check_tile.cpp: the tile builtins with constant or tuple arguments; *handled false: not one.
  Expected<Value> CallTile(const std::string& name, std::vector<Value> args, const SourceLocation& loc,
                           const ast::Call* call, bool* handled);
  // A copy of the sub-tile of `base` at `offsets` (int64 vars, one per dimension) keeping the
  // dimensions `kept` with `extents`; t[...] on a tile.
  Expected<Value> TileView(int base, std::vector<int> offsets, const std::vector<int>& kept,
                           const std::vector<int>& extents, const SourceLocation& loc,
                           const std::vector<int64_t>& steps = {});
  std::vector<Value> TileRegionArgs(std::vector<int> offsets, const std::vector<int64_t>& steps,
                                    const std::vector<int>& kept);
  struct TileRegion {
    bool element = false;              // every dimension indexed by an integer
    std::vector<int> indices;          // element: int32 vars
    std::vector<int> offsets, kept, extents;   // a sub-tile (see TileView)
    std::vector<int64_t> steps;        // by dimension (1 where absent)
  };
  Expected<TileRegion> TileRegionOf(const ast::Subscript& s, const Type& tile_type);
  Expected<Value> TileSubscript(const ast::Subscript& s, const Value& base);
  Expected<int> TileUpdate(const ast::Subscript& s, const Value& base, const Value& value);
  Expected<Value> TileMap(const std::string& name, std::vector<Value> args, const SourceLocation& loc,
                          const ast::Call* call);
  Expected<Value> CallConstructor(const Type& t, std::vector<Value> args, const SourceLocation& loc,
                                  const ast::Call& call);
  Expected<Value> CallUserFunc(const std::string& name, std::vector<Value> args, const SourceLocation& loc,
                               const std::vector<std::pair<std::string, Value>>& kwargs = {},
                               const ast::Call* call = nullptr);
  Expected<Value> ResolveAndEmitBuiltin(const std::string& name, std::vector<Value> args,
                                        const SourceLocation& loc, int array_param = -1,
                                        const std::string& array_name = "");
  Expected<int> Coerce(const Value& v, const Type& want, const SourceLocation& loc, const std::string& what);
  Expected<Value> EvalConstantSymbol(const weft::ConstantValue& c, const SourceLocation& loc);
  Expected<Type> EvalTypeExpr(const ast::Expr& e);
  // `array_base`: the indices of an array element (a non-integer index of an element being
  // written, store_target_, is Warp's TypeError "Array slot write indices must be integers").
  Expected<std::vector<int>> EvalIndices(const ast::ExprList& idx, bool array_base = false);
  Expected<std::vector<int>> SliceComponents(const ast::Slice& slice, int n);
  // The components a subscript with at least one constant slice selects from a vector,
  // quaternion, transform or matrix value (v[1:3], m[0, :2], m[:2, 1:], m[::-1]), each as its
  // index vars for an Extract / Insert, and the shape they form: a vector when one dimension
  // is sliced, a matrix when both are. False when the subscript holds no slice.
  struct SliceRegion {
    std::vector<std::vector<int>> components;
    Type shape;
  };
  Expected<bool> SliceRegionOf(const ast::Subscript& s, const Type& bt, SliceRegion* out);
  int ReadSliceRegion(int base, const Type& bt, const SliceRegion& r);

  // emission helpers
  int NewVar(const Type& t, const std::string& hint = "", bool is_mutable = false);
  // A copy: references into fn.vars dangle as soon as a new variable is emitted.
  Type TypeOf(int var) const { return st_->fn.vars.at(var).type; }
  void Push(Stmt s);
  int EmitOp(OpKind kind, const Type& dst_type, std::vector<int> args, std::string text = "");
  int EmitConst(const Type& t, const std::string& cpp_text);
  int EmitRaw(const Type& t, const std::string& text, std::vector<int> args);
  void EmitCopy(int dst, int src);
  int ArrayParamOf(int var) const {
    auto it = st_->array_param.find(var);
    return it == st_->array_param.end() ? -1 : it->second;
  }

  const ModuleSource& src_;
  const std::vector<ParsedFunction>& parsed_;
  std::vector<Diagnostic>* diags_;
  Module module_;
  std::multimap<std::string, const Symbol*> symbols_;
  std::map<std::string, const ParsedFunction*> by_key_;
  std::map<std::string, int> instances_;   // instantiation key -> function index
  std::set<std::string> in_progress_;
  FnState* st_ = nullptr;
  bool store_target_ = false;   // evaluating the target of an assignment (arr[i].x = v, arr[i] += v)
  // Evaluating the base of a component or field write (`arr[i]` in `arr[i].x = v`): an array
  // element loaded now is the element the write updates (Op::slot).
  bool slot_target_ = false;
  // LowerAssignTo of the updated element of a component or field write: its store is Op::slot.
  bool slot_store_ = false;
  bool slot_store_emitted_ = false;   // a slot store was emitted (since the flag was last cleared)
  // LowerAssignTo of a name updated in place (a tile call's written argument, t[...] = v,
  // t += v, a func's by-reference tile): a name aliasing a tile view writes into the tile.
  bool write_through_ = false;
  // Warp's struct arithmetic (struct_add / struct_sub / struct_neg rows) applies only to the
  // elements of struct tiles: set while typing a tile op's element function or `t[i] op= v`.
  bool struct_arithmetic_ = false;
  // Lanes of a cooperative CPU block the module is compiled for (CpuLanesOption; 1: one thread
  // per block): wp.tile(x) has this many elements, untile gives the lane's, and t[i] op= v
  // combines the lanes' values (engine/native/lanes.h).
  int lanes_ = 1;
  int hidden_locals_ = 0;   // numbers the compiler's own locals ($bool0, $ifexp1, ...)
  // `t[i] op= v` with lanes: the operator and v, for TileUpdate to combine every lane's v into
  // the element (tile_scatter_add, tile_lanes_bit_*) instead of writing this lane's result.
  struct {
    bool active = false;
    ast::BinaryOperator op = ast::BinaryOperator::kAdd;
    Value value;
  } lane_update_;
  // The last sub-tile TileView emitted: its result and what made it (for TileAlias).
  struct {
    int result = -1;
    int base = -1;
    std::vector<Value> region;
  } last_tile_view_;
  Status WriteThroughAlias(const std::string& name, const TileAlias& alias, int value, const SourceLocation& loc);
  Expected<Value> ViewOfAlias(const TileAlias& alias, const SourceLocation& loc);
};

// Names the statements bind with `=` (or as a for target), not counting updates in place.
void CollectReboundNames(const ast::StmtList& body, std::set<std::string>* out);

// The tile local an assigned value views (`t` in `x = t[i]` or `x = wp.tile_view(t, ...)`), or
// nullptr.
const ast::Name* ViewedTileName(const ast::Expr& value);

// "12", "-3": the Python text of an integer literal.
bool IsIntLiteralText(const std::string& t);

// name -> the tile locals it is bound to a view of, anywhere in `body` (`row = t[i]`,
// `v = wp.tile_view(t, ...)`): writing through such a name assigns the tile.
void CollectTileViewBases(const ast::StmtList& body, std::map<std::string, std::set<std::string>>* out);

// The tile builtins whose calls sema/check_tile.cpp checks (some have no registry row).
bool IsTileCall(const std::string& name);
// The arguments a tile call assigns its results to (tile_matmul's `out`, the `_inplace` forms,
// tile_sort's keys and values, ...), by position and keyword; nullptr for other calls. The one
// table both the lowering (check_tile.cpp) and the loop-carry analysis (check.cpp) read.
struct TileWrittenArg {
  size_t position;
  std::string param;
};
const std::vector<TileWrittenArg>* TileWrittenArgs(const std::string& name);
// That argument's expression in `call` (positional or keyword), or nullptr.
const ast::Expr* TileWrittenTarget(const ast::Call& call, const TileWrittenArg& arg);
// A wp.ref[T] parameter's type string "ref(T)": true, with *inner set to "T".
bool RefTypeInner(const std::string& type_string, std::string* inner);
// C++ text of a Python literal in type t ("1.5" as float32 -> "wp::float32(1.5)").
Expected<std::string> CppLiteral(const Type& t, const std::string& python_text);
// Names assigned anywhere in `stmts` (targets' base names), for loop-carried analysis.
void CollectAssignedNames(const ast::StmtList& stmts, std::set<std::string>* out);
// How often each name is assigned in `stmts` (targets, loop variables, augmented assignments).
void CountAssignedNames(const ast::StmtList& stmts, std::map<std::string, int>* out);
// Source text of an expression (for messages and array names).
std::string ExprText(const ast::Expr& e);

}  // namespace weft::sema
