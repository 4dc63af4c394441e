// The typed SSA IR that sema::Check produces and codegen prints (forward and adjoint).
// Every expression result is a typed variable `var_N` assigned exactly once per execution
// of its block (SSA), except variables marked `is_mutable`: loop-carried slots, loop
// counters, break/continue/return flags and return slots, which codegen treats specially.
// Control flow is structured and jump-free: break/continue/return set flags and the rest
// of the block is guarded by `If(!flags)`, so the adjoint pass can walk statements backward.
#pragma once

#include <string>
#include <vector>

#include "engine/core/module_source.h"
#include "engine/sema/builtins.h"
#include "engine/sema/types.h"

namespace weft::sema {

struct Var {
  int id = 0;
  Type type;
  std::string hint;         // user name it was bound to, for comments
  bool is_mutable = false;  // assigned more than once (see header comment)
  bool is_param = false;
};

// How a value is built from the constructor's arguments (kConstruct).
enum class ConstructMode {
  kZero,     // all components zero (identity for quat/transform)
  kConcat,   // the arguments' scalar components, in order, fill the result (row-major)
  kFill,     // one scalar repeated
  kConvert,  // one value of the same shape and another scalar type
  kColumns,  // matrix from column vectors (Warp's legacy rule)
};

#define WEFT_FOR_EACH_IR_OP(X) \
  X(Const)      /* dst = `text`: C++ built by sema, never client text (CppLiteral checks) */ \
  X(Copy)       /* dst = args[0] */                                                       \
  X(Raw)        /* dst = `text` with $0..$n = args (not differentiable) */                \
  X(Call)       /* dst (or dsts for tuple results) = wp::builtin(args) */                \
  X(FuncCall)   /* dsts = user function `callee`(args) */                                \
  X(Construct)  /* dst = type(args) per `mode` */                                        \
  X(Load)       /* dst = args[0][args[1..]] (array read, bounds-checked) */              \
  X(Store)      /* args[0][args[1..n-1]] = args[n] (array write, bounds-checked) */       \
  X(View)       /* dst = sub-array args[0][args[1..]] (fewer indices than ndim; checked) */ \
  X(Extract)    /* dst = args[0][args[1..]] (vec/mat/quat component or matrix row) */    \
  X(Insert)     /* dst = args[0] with [args[1..n-1]] = args[n] */                        \
  X(GetField)   /* dst = args[0].text */                                                 \
  X(SetField)   /* dst = args[0] with .text = args[1] */                                 \
  X(Phi)        /* dst = args[0] ? args[1] : args[2] */                                  \
  X(Printf)     /* wp::printf(ctx, text, args...); text checked by CheckPrintfFormat */ \
  X(TileMap)    /* dst = tile of f(elements of args) (f: `builtin` or func `callee`) */    \
  X(TileReduce) /* dst = tile(1) folding args[0]'s elements with f(acc, x) */

enum class OpKind {
#define WEFT_IR_ENUM(N) k##N,
  WEFT_FOR_EACH_IR_OP(WEFT_IR_ENUM)
#undef WEFT_IR_ENUM
};
const char* OpKindName(OpKind k);

struct Op {
  OpKind kind = OpKind::kConst;
  std::vector<int> dst;   // 0..n variables
  std::vector<int> args;
  std::string text;
  const BuiltinOverload* builtin = nullptr;  // kCall; kTileMap / kTileReduce: the element function
  int callee = -1;                           // kFuncCall; kTileMap / kTileReduce: the element func
  ConstructMode mode = ConstructMode::kZero;
  int field_index = -1;                      // kGetField / kSetField
  // array accesses (kLoad, kStore, kCall with kBuiltinArrayAccess): for error reports
  int array_param = -1;                      // kernel parameter the array came from, -1 if unknown
  std::string array_name;                    // source text of the array expression
  // kLoad / kStore of a composite slot write (`a[i].x = v`, `a[i].f.y = v`, `a[i][r, c] = v`):
  // the load reads the element the write updates and the store writes it back. Their adjoint
  // is Warp's slot store: the written slot's gradient moves into v and is cleared, the
  // element's other slots keep theirs (the load is not a read of the element).
  bool slot = false;
};

struct Stmt {
  enum class Kind { kOp, kIf, kLoop };
  Kind kind = Kind::kOp;
  int line = 0;
  Op op;                                // kOp
  int cond = -1;                        // kIf: bool var; kLoop (while): bool var set by cond_body
  std::vector<Stmt> then_body;          // kIf
  std::vector<Stmt> else_body;          // kIf
  // kLoop
  bool is_while = false;
  int iter = -1, start = -1, end = -1, step = -1;  // for: iteration variable and range vars
  std::vector<Stmt> cond_body;          // while: evaluates `cond` each iteration
  std::vector<Stmt> body;
  int break_flag = -1, continue_flag = -1, return_flag = -1;  // -1 when unused
  int counter = -1;                     // iteration count (int64), kept for the adjoint
  struct Carried {
    int slot;   // mutable var read by the body
    int init;   // value before the loop (the slot is copied from it by an Op before the loop)
    int next;   // value at the end of an iteration (copied into the slot)
  };
  std::vector<Carried> carried;
};

struct Function {
  std::string name;        // user name
  std::string cpp_name;    // identifier in generated code
  std::string key;         // FunctionSource key (+ instantiation types for generics)
  std::string file;
  int def_line = 0;
  bool is_kernel = false;
  int function_id = 0;     // index into GeneratedModule::function_names
  std::vector<int> params;               // vars
  std::vector<std::string> param_names;
  std::vector<Type> returns;             // 0, 1 or more return values
  std::vector<int> return_slots;         // mutable vars holding return values
  int return_flag = -1;
  // Custom gradients (wp.func_grad): on a func, the index of its gradient function (whose
  // adj_<func> then calls it instead of reversing the body), -1 if none. On a gradient
  // function, which parameter of the forward func each of its return values is the
  // adjoint of (it returns the wp.adjoint[...] slots).
  int custom_grad = -1;
  // A custom replay (wp.func_replay): on a func, the index of the function its replay twin
  // (what a caller's backward pass runs to recompute the func's results) calls instead of
  // replaying the body, -1 if none.
  int custom_replay = -1;
  std::vector<int> grad_of_param;
  // wp.ref[T] parameters (indices into the user's parameter list): the function takes them by
  // value and returns their final values after its own return values, in this order; the
  // caller writes each back to the argument it passed (a local, an array element, a component
  // or a struct field).
  std::vector<int> ref_params;
  // On a gradient function: the forward func's array parameters whose gradient arrays it takes
  // as extra parameters after its own, in this order (wp.adjoint[a] of an array a).
  std::vector<int> grad_array_of_param;
  // Code whose adjoint cannot be generated (a differentiable `a[i].x *= v`): generating the
  // module's adjoints is then this error (Warp's); its forward code compiles.
  Diagnostic no_adjoint;
  bool may_fail = false;                 // contains bounds checks (directly or through calls)
  // Bytes of the thread's memory its tiles and fixed-size arrays take, twice (their adjoints),
  // plus the largest such total of the functions it calls (kMaxLocalValueBytes bounds it).
  int64_t local_value_bytes = 0;
  bool uses_tid = false;
  std::vector<Var> vars;
  std::vector<Stmt> body;
};

struct Module {
  std::vector<Function> functions;       // callees before callers
  StructTable structs;
  std::vector<std::string> struct_order; // definition order (fields before users)
  std::vector<int> kernels;              // indices into functions, in source order
};

// Human-readable dump (WEFT_DUMP_IR=1).
std::string DumpModule(const Module& m);

}  // namespace weft::sema
