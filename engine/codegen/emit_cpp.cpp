// C++ emission of the SSA IR: forward code, side-effect-free replay, adjoint (reverse) code,
// kernel entry points per target and argument-block layouts.
//
// Adjoint scheme (docs/autodiff.md): a backward function first replays the forward code
// (skipping array writes, atomics and prints), then walks the statements backward calling
// wp::adj_* (builtins) and adj_<func> (user funcs). Loops are reversed by recomputation:
// for reverse iteration k the loop-carried slots are reset to their values before the loop
// and iterations 0..k-1 are replayed, then iteration k is replayed and its adjoint run.
// Time O(n^2) body executions for n iterations, no extra memory. Loops with no carried
// slots jump straight to iteration k (O(n)).
#include "engine/codegen/emit_cpp.h"

#include <algorithm>
#include <functional>
#include <map>
#include <set>

#include "engine/codegen/emit_text.h"

namespace weft::codegen {
namespace {

using namespace sema;

uint32_t RoundUp(uint32_t v, uint32_t a) { return (v + a - 1) / a * a; }

std::string BaseName(const std::string& path) {
  size_t s = path.find_last_of('/');
  return s == std::string::npos ? path : path.substr(s + 1);
}

// A struct field's member name in generated code.
std::string FieldName(const std::string& name) { return "f_" + MangleIdentifier(name); }

bool HasArrays(const Type& t, const StructTable& structs) {
  if (t.is_array()) return true;
  if (!t.is_struct()) return false;
  auto it = structs.find(t.struct_name);
  if (it == structs.end()) return false;
  for (const auto& f : it->second.fields)
    if (HasArrays(f.type, structs)) return true;
  return false;
}

// Indexed arrays in t (directly or in struct fields): their adjoints take the primal's indices.
bool HasIndexedArrays(const Type& t, const StructTable& structs) {
  if (t.is_indexed_array()) return true;
  if (!t.is_struct()) return false;
  auto it = structs.find(t.struct_name);
  if (it == structs.end()) return false;
  for (const auto& f : it->second.fields)
    if (HasIndexedArrays(f.type, structs)) return true;
  return false;
}

// The text sema emits for `i = wp.tid()` (one name): the kernel's launch index (its first
// coordinate; the flat index of a 1-D launch), always in [0, threads of the launch).
constexpr const char* kTidFirstText = "wp::int32(wp::cg_tid_first(__ctx, __tid_flat))";

void CollectTidVars(const std::vector<Stmt>& stmts, std::set<int>* out) {
  for (const Stmt& s : stmts) {
    if (s.kind == Stmt::Kind::kOp) {
      if (s.op.kind == OpKind::kRaw && s.op.text == kTidFirstText && s.op.dst.size() == 1) out->insert(s.op.dst[0]);
      continue;
    }
    CollectTidVars(s.then_body, out);
    CollectTidVars(s.else_body, out);
    CollectTidVars(s.cond_body, out);
    CollectTidVars(s.body, out);
  }
}

// p[i] of a kernel where p is a 1-D plain-array parameter (the argument itself, never
// reassigned) and i a variable holding wp.tid(): within bounds whenever p holds at least as many
// elements as the launch has threads. Returns the parameter's index, or -1.
int TidIndexedAccess(const Function& f, const std::set<int>& tid_vars, int array, const std::vector<int>& idx) {
  if (!f.is_kernel || idx.size() != 1 || !tid_vars.count(idx[0])) return -1;
  const Var& a = f.vars.at(array);
  const Var& i = f.vars.at(idx[0]);
  if (!a.is_param || a.is_mutable || i.is_mutable || !a.type.is_array() || a.type.is_indexed_array() ||
      a.type.is_fixed_array() || a.type.ndim != 1)
    return -1;
  for (size_t k = 0; k < f.params.size(); ++k)
    if (f.params[k] == array) return static_cast<int>(k);
  return -1;
}

// Every forward access of f that TidIndexedAccess accepts: its parameters, in order; `loaded`
// (when given): those of them read by a plain load (what a coarsened entry prefetches).
void CollectTidIndexedParams(const Function& f, const std::set<int>& tid_vars, const std::vector<Stmt>& stmts,
                             std::set<uint32_t>* out, std::set<uint32_t>* loaded = nullptr) {
  for (const Stmt& s : stmts) {
    if (s.kind != Stmt::Kind::kOp) {
      CollectTidIndexedParams(f, tid_vars, s.then_body, out, loaded);
      CollectTidIndexedParams(f, tid_vars, s.else_body, out, loaded);
      CollectTidIndexedParams(f, tid_vars, s.cond_body, out, loaded);
      CollectTidIndexedParams(f, tid_vars, s.body, out, loaded);
      continue;
    }
    const Op& op = s.op;
    std::vector<int> idx;
    if (op.kind == OpKind::kLoad || op.kind == OpKind::kView) {
      idx.assign(op.args.begin() + 1, op.args.end());
    } else if (op.kind == OpKind::kStore) {
      idx.assign(op.args.begin() + 1, op.args.end() - 1);
    } else if (op.kind == OpKind::kCall && (op.builtin->flags & kBuiltinArrayAccess)) {
      const int ndim = f.vars.at(op.args[0]).type.ndim;
      idx.assign(op.args.begin() + 1, op.args.begin() + 1 + ndim);
    } else {
      continue;
    }
    const int p = TidIndexedAccess(f, tid_vars, op.args[0], idx);
    if (p < 0) continue;
    out->insert(static_cast<uint32_t>(p));
    if (loaded && op.kind == OpKind::kLoad) loaded->insert(static_cast<uint32_t>(p));
  }
}

// The parameters of f whose p[wp.tid()] load, a statement of the body itself (not under a
// branch or loop: always executed), comes after a store or an array-access call, with p not
// accessed at wp.tid() before it. The compiler cannot move such a load above the store (the
// arrays may overlap), so each thread waits for two memory latencies one after the other; the
// trusted entry prefetches these first.
std::set<uint32_t> TidLoadsAfterAStore(const Function& f, const std::set<int>& tid_vars) {
  std::set<uint32_t> late, touched;
  bool stored = false;
  auto writes = [](const Op& op) {
    return op.kind == OpKind::kStore || (op.kind == OpKind::kCall && (op.builtin->flags & kBuiltinArrayAccess));
  };
  for (const Stmt& s : f.body) {
    if (s.kind != Stmt::Kind::kOp) {   // a branch or loop: its accesses and stores count
      std::vector<const std::vector<Stmt>*> todo{&s.then_body, &s.else_body, &s.cond_body, &s.body};
      while (!todo.empty()) {
        const std::vector<Stmt>* block = todo.back();
        todo.pop_back();
        for (const Stmt& t : *block) {
          if (t.kind != Stmt::Kind::kOp)
            todo.insert(todo.end(), {&t.then_body, &t.else_body, &t.cond_body, &t.body});
          else
            stored = stored || writes(t.op);
        }
      }
      for (const auto* block : {&s.then_body, &s.else_body, &s.cond_body, &s.body})
        CollectTidIndexedParams(f, tid_vars, *block, &touched);
      continue;
    }
    std::set<uint32_t> accessed;
    CollectTidIndexedParams(f, tid_vars, std::vector<Stmt>{s}, &accessed);
    if (s.op.kind == OpKind::kLoad && stored)
      for (uint32_t p : accessed)
        if (!touched.count(p)) late.insert(p);
    touched.insert(accessed.begin(), accessed.end());
    stored = stored || writes(s.op);
  }
  return late;
}

// `#line N "file"` (emit_text.h) for generated code that belongs to user line N of f's file.
std::string UserLine(const Function& f, int line) {
  return codegen::LineDirective(static_cast<uint32_t>(line > 0 ? line : 1), f.file) + "\n";
}

// Prefixes every line of a generated chunk (argument blocks, entry points) with the line
// directive of f's def line.
std::string MapToDefLine(const Function& f, const std::string& chunk) {
  std::string directive = UserLine(f, f.def_line), out;
  size_t b = 0;
  while (b < chunk.size()) {
    size_t e = chunk.find('\n', b);
    if (e == std::string::npos) e = chunk.size() - 1;
    out += directive;
    out.append(chunk, b, e - b + 1);
    b = e + 1;
  }
  if (!out.empty() && out.back() != '\n') out += '\n';
  return out;
}

class FnEmitter {
 public:
  enum class Mode { kForward, kReplay, kAdjoint };

  FnEmitter(const Module& m, const Function& f, const CodegenOptions& o, std::string* out)
      : m_(m), f_(f), opt_(o), out_(*out) {
    if (opt_.trust_tid_indices && f_.is_kernel) CollectTidVars(f_.body, &tid_vars_);
  }

  // `static inline R name(ctx, params)` (forward or replay twin) or the adjoint function.
  void EmitFunc(Mode mode) {
    mode_ = mode;
    std::string ret = "void";
    if (f_.returns.size() == 1 && mode != Mode::kAdjoint) ret = CppType(f_.returns[0]);
    std::string name = mode == Mode::kForward ? f_.cpp_name : mode == Mode::kReplay ? "replay_" + f_.cpp_name
                                                                                    : "adj_" + f_.cpp_name;
    // __tid_flat: the calling thread's flat index, passed down from the kernel so that
    // wp.tid() works inside @wp.func (as in Warp).
    std::string sig = "static inline WP_CALLABLE " + ret + " " + name + "(const wp::launch_context_t* __ctx, wp::int64 __tid_flat";
    for (int p : f_.params) sig += ", " + CppType(T(p)) + " " + V(p);
    if (mode == Mode::kAdjoint) {
      for (int p : f_.params) sig += ", " + CppType(T(p)) + "& " + A(p);
      for (size_t i = 0; i < f_.returns.size(); ++i) sig += ", const " + CppType(f_.returns[i]) + "& __adj_ret" + std::to_string(i);
    } else if (f_.returns.size() > 1) {
      for (size_t i = 0; i < f_.returns.size(); ++i) sig += ", " + CppType(f_.returns[i]) + "& __ret" + std::to_string(i);
    }
    sig += ")";
    fail_ = (ret == "void") ? "return;" : "return wp::cg_zeros<" + ret + ">();";
    Line("// " + CommentText(BaseName(f_.file)) + ":" + std::to_string(f_.def_line) + ": @wp.func " + CommentText(f_.name) +
         (mode == Mode::kReplay ? " (replay: no side effects)" : mode == Mode::kAdjoint ? " (adjoint)" : ""));
    Line(sig + " {");
    ++indent_;
    Line("(void)__ctx;");
    Line("(void)__tid_flat;");
    if (f_.uses_tid) {
      Line("wp::int64 __tid[4];");
      Line("wp::cg_unravel(__ctx->bounds, __tid_flat, __tid);");
      Line("(void)__tid;");
    }
    if (mode == Mode::kReplay && f_.custom_replay >= 0) {   // wp.func_replay
      const Function& r = m_.functions.at(f_.custom_replay);
      Line("// custom replay: " + CommentText(r.name));
      std::string args = "__ctx, __tid_flat";
      for (int p : f_.params) args += ", " + V(p);
      if (f_.returns.size() == 1) {
        Line("return " + r.cpp_name + "(" + args + ");");
      } else {
        for (size_t i = 0; i < f_.returns.size(); ++i) args += ", __ret" + std::to_string(i);
        Line(r.cpp_name + "(" + args + ");");
      }
      --indent_;
      Line("}");
      Line("");
      return;
    }
    if (mode == Mode::kAdjoint && f_.custom_grad >= 0) {
      EmitCustomGradCall();
      --indent_;
      Line("}");
      Line("");
      return;
    }
    Decls(mode == Mode::kAdjoint);
    print_in_replay_ = mode == Mode::kAdjoint;
    Fwd(f_.body, mode != Mode::kForward);
    print_in_replay_ = false;
    if (mode == Mode::kAdjoint) {
      for (size_t i = 0; i < f_.return_slots.size(); ++i)
        if (Diff(T(f_.return_slots[i]))) Line("wp::cg_accum(" + A(f_.return_slots[i]) + ", __adj_ret" + std::to_string(i) + ");");
      Rev(f_.body);
    } else if (f_.returns.size() == 1) {
      Line("return " + V(f_.return_slots[0]) + ";");
    } else {
      for (size_t i = 0; i < f_.return_slots.size(); ++i) Line("__ret" + std::to_string(i) + " = " + V(f_.return_slots[i]) + ";");
    }
    --indent_;
    Line("}");
    Line("");
  }

  // adj_<func> of a func with a custom gradient (wp.func_grad): calls the gradient function
  // with the func's arguments and the adjoints of its results, and accumulates the adjoints
  // it returns into the parameters' adjoints.
  void EmitCustomGradCall() {
    const Function& g = m_.functions.at(f_.custom_grad);
    Line("// custom gradient: " + CommentText(g.name));
    std::string args = "__ctx, __tid_flat";
    for (int p : f_.params) args += ", " + V(p);
    for (size_t i = 0; i < f_.returns.size(); ++i) args += ", __adj_ret" + std::to_string(i);
    for (int p : g.grad_array_of_param) args += ", " + A(f_.params.at(p));   // gradient arrays
    std::vector<std::string> results;
    for (size_t k = 0; k < g.returns.size(); ++k) {
      results.push_back("__grad" + std::to_string(k));
      Line(CppType(g.returns[k]) + " " + results.back() + "{};");
    }
    if (g.returns.size() == 1) {
      Line(results[0] + " = " + g.cpp_name + "(" + args + ");");
    } else {
      for (const auto& r : results) args += ", " + r;
      Line(g.cpp_name + "(" + args + ");");
    }
    for (size_t k = 0; k < g.grad_of_param.size(); ++k)
      Line("wp::cg_accum(" + A(f_.params.at(g.grad_of_param[k])) + ", " + results[k] + ");");
  }

  // The per-thread body of a kernel: forward, or backward (replay + adjoint).
  void EmitKernelBody(bool backward, const std::string& args_struct, const std::string& name) {
    mode_ = backward ? Mode::kAdjoint : Mode::kForward;
    fail_ = "return;";
    Line("// " + CommentText(BaseName(f_.file)) + ":" + std::to_string(f_.def_line) + ": @wp.kernel " + CommentText(f_.name) +
         (backward ? " (backward)" : ""));
    // Forced inline: a body left out of line would take the kernel parameters' addresses
    // across a call.
    std::string sig = "static WP_FORCEINLINE WP_CALLABLE void " + name + "(const wp::launch_context_t* __ctx, const " +
                      args_struct + "& __args, ";
    if (backward) sig += "const " + args_struct + "& __adj_args, ";
    Line(sig + "wp::int64 __tid_flat) {");
    ++indent_;
    Line("wp::int64 __tid[4];");
    Line("wp::cg_unravel(__ctx->bounds, __tid_flat, __tid);");
    Line("(void)__tid;");
    for (size_t i = 0; i < f_.params.size(); ++i) {
      int p = f_.params[i];
      Line(CppType(T(p)) + " " + V(p) + " = __args.p" + std::to_string(i) + ";  // " + CommentText(f_.param_names[i]));
      if (backward) Line(CppType(T(p)) + " " + A(p) + " = __adj_args.p" + std::to_string(i) + ";");
      if (backward && HasIndexedArrays(T(p), m_.structs)) Line("wp::cg_indexed_adjoint(" + A(p) + ", " + V(p) + ");");
    }
    Decls(backward);
    print_in_replay_ = backward;
    Fwd(f_.body, backward);
    print_in_replay_ = false;
    if (backward) Rev(f_.body);
    --indent_;
    Line("}");
    Line("");
  }

 private:
  const Type& T(int v) const { return f_.vars[v].type; }
  bool Mut(int v) const { return f_.vars[v].is_mutable; }
  static std::string V(int v) { return "var_" + std::to_string(v); }
  static std::string A(int v) { return "adj_" + std::to_string(v); }
  bool Diff(const Type& t) const { return IsDifferentiable(t); }
  bool Links(const Type& t) const { return mode_ == Mode::kAdjoint && HasArrays(t, m_.structs); }

  // Every line carries a #line directive naming the user's file and line, so a C++ compiler
  // error in generated code (a weft bug) still points at the user's statement.
  void Line(const std::string& s) { out_ += LineText(s); }
  std::string LineText(const std::string& s) const {
    std::string t = UserLine(f_, last_line_ > 0 ? last_line_ : f_.def_line);
    t.append(static_cast<size_t>(indent_) * 2, ' ');
    t += s;
    t += '\n';
    return t;
  }
  void Loc(int line) {
    if (line > 0 && line != last_line_) {
      Line("// " + CommentText(BaseName(f_.file)) + ":" + std::to_string(line));
      last_line_ = line;
    }
  }

  // Every variable is declared at the top of the function (the adjoint code reads them after
  // the forward replay). Adjoints and mutable variables (loop-carried slots, flags, return
  // slots) start at zero. A single-assignment (SSA) temporary is assigned before any read, so
  // scalars and vec/mat/quat/transform values are declared without an initialiser
  // (wp::cg_uninit): zero stores at function entry make every temporary live from the entry
  // block, and clang's SROA then takes time quadratic in the kernel's size (docs/security.md,
  // Compile time; bench/bench_compile_size.py).
  void Decls(bool adj) {
    std::set<int> params(f_.params.begin(), f_.params.end());
    for (const auto& v : f_.vars) {
      if (params.count(v.id) || v.type.is_void() || v.type.is_tuple() || v.type.kind == TypeKind::kString) continue;
      std::string ct = CppType(v.type);
      std::string init = "{}";
      if (!Mut(v.id)) {
        switch (v.type.kind) {
          case TypeKind::kScalar: init = ""; break;
          case TypeKind::kVector:
          case TypeKind::kMatrix:
          case TypeKind::kQuat:
          case TypeKind::kTransform: init = "{wp::cg_uninit}"; break;
          case TypeKind::kTile: init = ""; break;   // written before any read (a `like` tile is never read)
          default: break;
        }
      }
      Line(ct + " " + V(v.id) + init + ";" + (v.hint.empty() ? "" : "  // " + CommentText(v.hint)));
      if (adj) Line(ct + " " + A(v.id) + "{};");
    }
  }

  std::string Args(const std::vector<int>& vs, size_t from = 0, size_t to = std::string::npos, bool adj = false) {
    std::string s;
    to = std::min(to, vs.size());
    for (size_t i = from; i < to; ++i) s += (s.empty() ? "" : ", ") + (adj ? A(vs[i]) : V(vs[i]));
    return s;
  }

  // Bounds check of an array access; `adjoint`: of the access to the array's adjoint (its
  // gradient array, which has its own data and shape) in reverse code.
  void Check(const Op& op, int line, int array, const std::vector<int>& idx, bool adjoint = false) {
    if (!opt_.bounds_checks) return;
    if (!adjoint && CheckedBefore(array, idx)) return;
    // The trusted variant: the launch was proven in range (CodegenOptions::trust_tid_indices).
    if (!adjoint && !tid_vars_.empty() && TidIndexedAccess(f_, tid_vars_, array, idx) >= 0) return;
    std::string s = std::string(adjoint ? "if (!wp::cg_check_adj(__ctx, " : "if (!wp::cg_check(__ctx, ") +
                    std::to_string(f_.function_id) + ", " + std::to_string(line) + ", " +
                    std::to_string(f_.is_kernel ? op.array_param : -1) + ", " + CppStringLiteral(op.array_name) + ", " +
                    (adjoint ? A(array) : V(array));
    for (int k = 0; k < 4; ++k) s += ", " + (k < static_cast<int>(idx.size()) ? V(idx[k]) : std::string("0"));
    s += ", " + std::to_string(idx.size()) + ")) " + fail_;
    if (adjoint || !Hoist(array, idx, LineText(s))) Line(s);
  }

  // Bounds checks of loads and views move up to just after the definition of their operands,
  // within a run of statements without side effects (a "region": no store, atomic, call of a
  // func, print, branch or loop inside). The loads of a statement like y[i] = a*x[i] + y[i] then
  // follow each other with no branch between them, so the GPU has them in flight together; with
  // a check between two loads, the second one waited for the first. Checks keep their order
  // (the first failing access of a thread is still the one reported), and a thread whose check
  // fails stops before any side effect, as before.
  struct Region {
    std::vector<size_t> marks;    // marks[k]: where a check placed before region statement k goes
    std::map<int, int> last_def;  // variable -> index of the region statement that last set it
    int floor = 0;                // checks may not move above this statement (their order)
    bool open = false;
    std::map<std::vector<int>, int> checked;   // {array, indices...} -> statement its check precedes
  };
  // True when the same array variable was checked with the same index variables earlier in
  // the region and none of them was set since: y[i] = ... y[i] checks y[i] once.
  bool CheckedBefore(int array, const std::vector<int>& idx) const {
    if (!region_.open) return false;
    std::vector<int> key{array};
    key.insert(key.end(), idx.begin(), idx.end());
    auto it = region_.checked.find(key);
    if (it == region_.checked.end()) return false;
    for (int v : key) {
      auto d = region_.last_def.find(v);
      if (d != region_.last_def.end() && d->second >= it->second) return false;
    }
    return true;
  }
  void RegionReset() { region_ = Region{}; }
  void RegionBegin(const Stmt& s) {
    if (!region_.open) {
      region_ = Region{};
      region_.open = true;
    }
    region_.marks.push_back(out_.size());
    (void)s;
  }
  void RegionEnd(const Stmt& s) {
    const int k = static_cast<int>(region_.marks.size()) - 1;
    if (s.kind == Stmt::Kind::kOp && Pure(s.op)) {
      for (int d : s.op.dst) region_.last_def[d] = k;
    } else {
      RegionReset();
    }
  }
  // What a builtin call does among the lanes of a cooperative CPU block (CodegenOptions::
  // cpu_lanes > 1): nothing special; wait for them first (a tile read from an array: a tile
  // load); or leave the call to the leader (a call with effects that takes a tile: tile stores
  // and atomic adds, the print of a tile). Every lane holds the same tiles, so one lane's write
  // is the block's.
  enum class LaneRole { kNone, kWaitFirst, kLeader };
  LaneRole LaneRoleOf(const Op& op) const {
    if (opt_.cpu_lanes <= 1 || op.kind != OpKind::kCall) return LaneRole::kNone;
    bool takes_tile = false, takes_array = false;
    for (int a : op.args) {
      takes_tile |= T(a).is_tile();
      takes_array |= T(a).is_array();
    }
    if (op.builtin->side_effect() && takes_tile) return LaneRole::kLeader;
    if (takes_array && op.dst.size() == 1 && T(op.dst[0]).is_tile()) return LaneRole::kWaitFirst;
    return LaneRole::kNone;
  }
  bool Pure(const Op& op) const {
    switch (op.kind) {
      case OpKind::kStore:
      case OpKind::kFuncCall:
      case OpKind::kPrintf:
      case OpKind::kTileMap:
      case OpKind::kTileReduce: return false;
      case OpKind::kCall:
        return !(op.builtin->side_effect() || op.builtin->needs_ctx() ||
                 (op.builtin->flags & (kBuiltinArrayAccess | kBuiltinNeedsLoc | kBuiltinWritesArgs)));
      default: return true;
    }
  }
  // Inserts `text` (a whole check line) at the earliest allowed place; false: not a hoistable
  // check (the caller emits it here).
  bool Hoist(int array, const std::vector<int>& idx, const std::string& text) {
    if (!region_.open || region_.marks.empty() || !hoisting_) return false;
    const int cur = static_cast<int>(region_.marks.size()) - 1;
    int t = region_.floor;
    auto after_def = [&](int v) {
      auto it = region_.last_def.find(v);
      if (it != region_.last_def.end()) t = std::max(t, it->second + 1);
    };
    after_def(array);
    for (int v : idx) after_def(v);
    if (t > cur) t = cur;
    // Also at t == cur (no move): inserted at the mark, which then moves past it, so a later
    // check placed at the same statement comes after this one.
    out_.insert(region_.marks[t], text);
    for (int k = t; k <= cur; ++k) region_.marks[k] += text.size();
    region_.floor = t;
    std::vector<int> key{array};
    key.insert(key.end(), idx.begin(), idx.end());
    region_.checked[key] = t;
    return true;
  }

  void Fwd(const std::vector<Stmt>& stmts, bool replay) {
    RegionReset();
    for (const auto& s : stmts) {
      RegionBegin(s);
      Loc(s.line);
      switch (s.kind) {
        case Stmt::Kind::kOp:
          hoisting_ = s.op.kind == OpKind::kLoad || s.op.kind == OpKind::kView;
          FwdOp(s.op, s.line, replay);
          hoisting_ = false;
          break;
        case Stmt::Kind::kIf:
          Line("if (" + V(s.cond) + ") {");
          ++indent_;
          Fwd(s.then_body, replay);
          --indent_;
          if (!s.else_body.empty()) {
            Line("} else {");
            ++indent_;
            Fwd(s.else_body, replay);
            --indent_;
          }
          Line("}");
          break;
        case Stmt::Kind::kLoop: FwdLoop(s, replay); break;
      }
      RegionEnd(s);
    }
    RegionReset();
  }

  void LoopBack(const Stmt& s) {
    for (const auto& c : s.carried)
      if (c.next != c.slot) Line(V(c.slot) + " = " + V(c.next) + ";");
  }

  // Loops poll the launch's cancel word (wp::cg_loop_poll) so a cancelled launch ends.
  std::string PollDecl(const std::string& counter) {
    return opt_.loop_cancel_poll ? "wp::uint32 " + counter + " = 0u;" : std::string();
  }
  void Poll(const std::string& counter) {
    if (opt_.loop_cancel_poll) Line("if (wp::cg_loop_poll(__ctx, " + counter + ")) break;");
  }

  void FwdLoop(const Stmt& s, bool replay) {
    const std::string poll = "__poll" + std::to_string(s.counter);
    Line(V(s.break_flag) + " = false;");
    if (replay) Line(V(s.counter) + " = 0;");
    Line("{ " + PollDecl(poll));
    if (!s.is_while) {
      Line("for (" + V(s.iter) + " = " + V(s.start) + "; wp::cg_range_continue(" + V(s.iter) + ", " + V(s.end) + ", " +
           V(s.step) + "); " + V(s.iter) + " += " + V(s.step) + ") {");
      ++indent_;
      Poll(poll);
    } else {
      Line("for (;;) {");
      ++indent_;
      Poll(poll);
      Fwd(s.cond_body, replay);
      Line("if (!" + V(s.cond) + ") break;");
    }
    Line(V(s.continue_flag) + " = false;");
    if (replay) Line("++" + V(s.counter) + ";");
    Fwd(s.body, replay);
    LoopBack(s);
    Line("if (" + V(s.break_flag) + " || " + V(s.return_flag) + ") break;");
    --indent_;
    Line("}}");
  }

  void FwdOp(const Op& op, int line, bool replay) {
    auto d = [&](size_t i = 0) { return V(op.dst.at(i)); };
    switch (op.kind) {
      case OpKind::kConst: Line(d() + " = " + op.text + ";"); return;
      case OpKind::kCopy:
        Line(d() + " = " + V(op.args[0]) + ";");
        if (Links(T(op.dst[0]))) Line("wp::cg_link(" + A(op.dst[0]) + ", " + A(op.args[0]) + ");");
        return;
      case OpKind::kRaw: {
        const std::string at = "__ctx, " + std::to_string(f_.function_id) + ", " + std::to_string(line);
        std::string text;
        for (size_t i = 0; i < op.text.size(); ++i) {
          if (op.text[i] == '$' && i + 1 < op.text.size() && op.text[i + 1] == '@') {   // where it runs
            text += at;
            ++i;
          } else if (op.text[i] == '$' && i + 1 < op.text.size() && std::isdigit(static_cast<unsigned char>(op.text[i + 1]))) {
            size_t j = i + 1;
            int k = 0;
            while (j < op.text.size() && std::isdigit(static_cast<unsigned char>(op.text[j]))) k = k * 10 + (op.text[j++] - '0');
            text += V(op.args.at(k));
            i = j - 1;
          } else {
            text += op.text[i];
          }
        }
        Line(d() + " = " + text + ";");
        if (Links(T(op.dst[0]))) {
          // an array-valued expression (a slice, a fixed array's view): its adjoint is the same
          // expression of the arguments' adjoint arrays
          std::string adj;
          for (size_t i = 0; i < op.text.size(); ++i) {
            if (op.text[i] == '$' && i + 1 < op.text.size() && op.text[i + 1] == '@') {
              adj += at;
              ++i;
            } else if (op.text[i] == '$' && i + 1 < op.text.size() && std::isdigit(static_cast<unsigned char>(op.text[i + 1]))) {
              size_t j = i + 1;
              int k = 0;
              while (j < op.text.size() && std::isdigit(static_cast<unsigned char>(op.text[j]))) k = k * 10 + (op.text[j++] - '0');
              const int a = op.args.at(k);
              adj += HasArrays(T(a), m_.structs) ? A(a) : V(a);
              i = j - 1;
            } else {
              adj += op.text[i];
            }
          }
          Line(A(op.dst[0]) + " = " + adj + ";");
        }
        return;
      }
      case OpKind::kCall: {
        const BuiltinOverload* b = op.builtin;
        if (replay && b->side_effect() && !(b->native == "print" && print_in_replay_)) return;
        std::string name = "wp::" + b->native;
        std::string args = Args(op.args);
        if (b->needs_ctx() || (b->flags & kBuiltinNeedsLoc)) {
          bool at = b->native.rfind("expect_", 0) == 0;
          if (at || (b->flags & kBuiltinNeedsLoc)) {
            if (at) name += "_at";
            args = "__ctx, " + std::to_string(f_.function_id) + ", " + std::to_string(line) + (args.empty() ? "" : ", ") + args;
          } else {
            args = "__ctx" + std::string(args.empty() ? "" : ", ") + args;
          }
        }
        if (b->flags & kBuiltinArrayAccess) {
          int ndim = T(op.args[0]).ndim;
          Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.begin() + 1 + ndim));
        }
        // Cooperative CPU blocks (engine/native/lanes.h): a tile load waits for the block's
        // lanes (their writes before it are seen); a tile store or atomic add, or a tile's
        // print, is performed by the leader alone between two waits, its result then handed
        // to every lane.
        const LaneRole role = LaneRoleOf(op);
        if (role != LaneRole::kNone) Line("wp::lane_sync(__ctx);");
        if (role == LaneRole::kLeader) Line("if (wp::lane_leads(__ctx)) {");
        if (op.dst.size() > 1) Line(name + "(" + args + ", " + Args(op.dst) + ");");
        else if (op.dst.empty()) Line(name + "(" + args + ");");
        else Line(d() + " = " + name + "(" + args + ");");
        if (role == LaneRole::kLeader) {
          Line("}");
          for (int v : op.dst) Line("wp::lane_broadcast(__ctx, " + V(v) + ");");
          Line("wp::lane_sync(__ctx);");
        }
        if (op.dst.size() == 1 && Links(T(op.dst[0]))) Line("wp::cg_link_grads(" + A(op.dst[0]) + ", " + d() + ");");
        return;
      }
      case OpKind::kFuncCall: {
        const Function& callee = m_.functions.at(op.callee);
        std::string name = (replay ? "replay_" : "") + callee.cpp_name;
        std::string args = "__ctx, __tid_flat" + std::string(op.args.empty() ? "" : ", ") + Args(op.args);
        if (op.dst.size() > 1) Line(name + "(" + args + ", " + Args(op.dst) + ");");
        else if (op.dst.empty()) Line(name + "(" + args + ");");
        else Line(d() + " = " + name + "(" + args + ");");
        if (callee.may_fail && opt_.bounds_checks) Line("if (wp::launch_failed(__ctx)) " + fail_);
        return;
      }
      case OpKind::kConstruct: {
        std::string t = CppType(T(op.dst[0]));
        switch (op.mode) {
          case ConstructMode::kZero: Line(d() + " = wp::cg_zeros<" + t + ">();"); return;
          case ConstructMode::kConcat: Line(d() + " = wp::cg_concat<" + t + ">(" + Args(op.args) + ");"); return;
          case ConstructMode::kFill: Line(d() + " = wp::cg_fill<" + t + ">(" + Args(op.args) + ");"); return;
          case ConstructMode::kConvert:
            if (T(op.dst[0]).is_scalar()) Line(d() + " = " + t + "(" + Args(op.args) + ");");
            else Line(d() + " = wp::cg_convert<" + t + ">(" + Args(op.args) + ");");
            return;
          case ConstructMode::kColumns: Line(d() + " = wp::cg_from_cols<" + t + ">(" + Args(op.args) + ");"); return;
        }
        return;
      }
      case OpKind::kLoad:
        Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.end()));
        Line(d() + " = wp::load(" + Args(op.args) + ");");
        return;
      case OpKind::kStore:
        if (replay) return;
        Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.end() - 1));
        Line("wp::store(" + Args(op.args) + ");");
        return;
      case OpKind::kView:
        Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.end()));
        Line(d() + " = wp::view(" + Args(op.args) + ");");
        // the view's adjoint is the same view of the gradient array
        if (Links(T(op.dst[0]))) Line(A(op.dst[0]) + " = wp::view(" + A(op.args[0]) + ", " + Args(op.args, 1) + ");");
        return;
      case OpKind::kExtract: Line(d() + " = wp::cg_extract(" + Args(op.args) + ");"); return;
      case OpKind::kInsert: Line(d() + " = wp::cg_insert(" + Args(op.args) + ");"); return;
      case OpKind::kGetField:
        Line(d() + " = " + V(op.args[0]) + "." + FieldName(op.text) + ";");
        if (Links(T(op.dst[0]))) Line("wp::cg_link(" + A(op.dst[0]) + ", " + A(op.args[0]) + "." + FieldName(op.text) + ");");
        return;
      case OpKind::kSetField:
        Line(d() + " = " + V(op.args[0]) + ";");
        Line(d() + "." + FieldName(op.text) + " = " + V(op.args[1]) + ";");
        if (Links(T(op.dst[0]))) {
          Line("wp::cg_link(" + A(op.dst[0]) + ", " + A(op.args[0]) + ");");
          if (Links(T(op.args[1]))) Line("wp::cg_link(" + A(op.dst[0]) + "." + FieldName(op.text) + ", " + A(op.args[1]) + ");");
        }
        return;
      case OpKind::kPhi:
        Line(d() + " = " + V(op.args[0]) + " ? " + V(op.args[1]) + " : " + V(op.args[2]) + ";");
        if (Links(T(op.dst[0])))
          Line("wp::cg_link(" + A(op.dst[0]) + ", " + V(op.args[0]) + " ? " + A(op.args[1]) + " : " + A(op.args[2]) + ");");
        return;
      case OpKind::kPrintf:
        if (replay) return;
        Line("wp::printf(__ctx, " + CppStringLiteral(op.text) + (op.args.empty() ? "" : ", ") + Args(op.args) + ");");
        return;
      case OpKind::kTileMap:
        Line(d() + " = wp::tile_map<" + CppType(T(op.dst[0])) + ">(" + ElementFn(op, replay) + ", " + Args(op.args) + ");");
        return;
      case OpKind::kTileReduce:
        Line(d() + " = wp::tile_reduce(" + ElementFn(op, replay) + ", " + Args(op.args) + ");");
        return;
    }
  }

  // The element function of a tile map or reduce as a C++ lambda: forward (replay: the func's
  // replay twin) or, `adjoint`, its adjoint taking (args..., adj_args..., adj_ret).
  std::string ElementFn(const Op& op, bool replay, bool adjoint = false) const {
    std::string call;
    if (op.builtin) {
      call = "wp::" + (adjoint ? op.builtin->adjoint : op.builtin->native) + "(x...)";
    } else {
      const Function& callee = m_.functions.at(op.callee);
      call = (adjoint ? "adj_" : replay ? "replay_" : "") + callee.cpp_name + "(__ctx, __tid_flat, x...)";
    }
    return adjoint ? "[&](auto&&... x) { " + call + "; }" : "[&](const auto&... x) { return " + call + "; }";
  }

  // Adjoint of a block: statements in reverse order.
  void Rev(const std::vector<Stmt>& stmts) {
    for (auto it = stmts.rbegin(); it != stmts.rend(); ++it) {
      const Stmt& s = *it;
      switch (s.kind) {
        case Stmt::Kind::kOp: {
          size_t before = out_.size();
          int saved = last_line_;
          Loc(s.line);
          size_t mark = out_.size();
          RevOp(s.op, s.line);
          if (out_.size() == mark) {  // nothing emitted: drop the location comment
            out_.resize(before);
            last_line_ = saved;
          }
          break;
        }
        case Stmt::Kind::kIf: {
          Loc(s.line);
          Line("if (" + V(s.cond) + ") {");
          ++indent_;
          Rev(s.then_body);
          --indent_;
          if (!s.else_body.empty()) {
            Line("} else {");
            ++indent_;
            Rev(s.else_body);
            --indent_;
          }
          Line("}");
          break;
        }
        case Stmt::Kind::kLoop: Loc(s.line); RevLoop(s); break;
      }
    }
  }

  void CollectDefs(const std::vector<Stmt>& stmts, std::set<int>* out) const {
    for (const auto& s : stmts) {
      switch (s.kind) {
        case Stmt::Kind::kOp:
          for (int d : s.op.dst) out->insert(d);
          break;
        case Stmt::Kind::kIf:
          CollectDefs(s.then_body, out);
          CollectDefs(s.else_body, out);
          break;
        case Stmt::Kind::kLoop:
          CollectDefs(s.cond_body, out);
          CollectDefs(s.body, out);
          for (const auto& c : s.carried) out->insert(c.slot);
          break;
      }
    }
  }

  void RevLoop(const Stmt& s) {
    std::string k = "__k" + std::to_string(s.counter);
    std::string j = "__j" + std::to_string(s.counter);
    bool restore = !s.carried.empty() || s.is_while;
    const std::string poll_k = "__pollk" + std::to_string(s.counter);
    const std::string poll_j = "__pollj" + std::to_string(s.counter);
    Line("{ " + PollDecl(poll_k));
    Line("for (wp::int64 " + k + " = " + V(s.counter) + " - 1; " + k + " >= 0; --" + k + ") {");
    ++indent_;
    Poll(poll_k);
    Line(V(s.break_flag) + " = false;");
    Line(V(s.return_flag) + " = false;");
    if (restore) {
      Line("// recompute the loop state at the start of iteration " + k);
      for (const auto& c : s.carried) Line(V(c.slot) + " = " + V(c.init) + ";");
      if (!s.is_while) Line(V(s.iter) + " = " + V(s.start) + ";");
      Line(PollDecl(poll_j));
      Line("for (wp::int64 " + j + " = 0; " + j + " < " + k + "; ++" + j + ") {");
      ++indent_;
      Poll(poll_j);
      if (s.is_while) Fwd(s.cond_body, true);
      Line(V(s.continue_flag) + " = false;");
      Fwd(s.body, true);
      LoopBack(s);
      if (!s.is_while) Line(V(s.iter) + " += " + V(s.step) + ";");
      --indent_;
      Line("}");
    } else {
      Line(V(s.iter) + " = " + V(s.start) + " + " + V(s.step) + " * (" + CppType(T(s.iter)) + ")" + k + ";");
    }
    Line("// replay iteration " + k + ", then its adjoint");
    Line(V(s.continue_flag) + " = false;");
    Fwd(s.body, true);
    for (auto c = s.carried.rbegin(); c != s.carried.rend(); ++c) {
      if (c->next == c->slot || !Diff(T(c->slot))) continue;
      Line("wp::cg_accum(" + A(c->next) + ", " + A(c->slot) + ");");
      Line(A(c->slot) + " = wp::cg_zeros<" + CppType(T(c->slot)) + ">();");
    }
    Rev(s.body);
    std::set<int> defs;
    CollectDefs(s.body, &defs);
    CollectDefs(s.cond_body, &defs);
    for (const auto& c : s.carried) defs.erase(c.slot);
    for (int v : defs)
      if (Diff(T(v)) && !T(v).is_void() && !T(v).is_tuple()) Line(A(v) + " = wp::cg_zeros<" + CppType(T(v)) + ">();");
    --indent_;
    Line("}}");
  }

  void RevOp(const Op& op, int line) {
    auto dt = [&]() -> const Type& { return T(op.dst.at(0)); };
    switch (op.kind) {
      case OpKind::kConst:
      case OpKind::kRaw:
      case OpKind::kView:
      case OpKind::kPrintf: return;
      case OpKind::kTileMap:
      case OpKind::kTileReduce: {
        if (!Diff(dt()) || (op.builtin && !op.builtin->differentiable())) return;
        if (op.kind == OpKind::kTileReduce) {
          Line("wp::adj_tile_reduce(" + ElementFn(op, true, true) + ", " + ElementFn(op, true) + ", " + Args(op.args) +
               ", " + Args(op.args, 0, std::string::npos, true) + ", " + A(op.dst[0]) + ");");
          return;
        }
        std::string refs;
        for (int a : op.args) refs += ", wp::tile_ref(" + V(a) + ", " + A(a) + ")";
        Line("wp::adj_tile_map(" + ElementFn(op, true, true) + ", " + A(op.dst[0]) + refs + ");");
        return;
      }
      case OpKind::kCopy:
        if (!Diff(dt())) return;
        Line("wp::cg_accum(" + A(op.args[0]) + ", " + A(op.dst[0]) + ");");
        if (Mut(op.dst[0])) Line(A(op.dst[0]) + " = wp::cg_zeros<" + CppType(dt()) + ">();");
        return;
      case OpKind::kCall: {
        const BuiltinOverload* b = op.builtin;
        if (b->native == "print" && op.args.size() == 1) {   // Warp's "adj: <adjoint>" line
          Line("wp::adj_print(__ctx, " + V(op.args[0]) + ", " + A(op.args[0]) + ");");
          return;
        }
        if (!b->differentiable()) return;
        // Cooperative CPU blocks: the adjoint of a tile load, store or atomic add touches the
        // arrays' gradients: the leader alone runs it, then hands the tiles' adjoints to every
        // lane (see LaneRoleOf).
        const bool lane_leader = LaneRoleOf(op) != LaneRole::kNone;
        auto lane_begin = [&] {
          if (!lane_leader) return;
          Line("wp::lane_sync(__ctx);");
          Line("if (wp::lane_leads(__ctx)) {");
        };
        auto lane_end = [&] {
          if (!lane_leader) return;
          Line("}");
          for (int a : op.args)
            if (T(a).is_tile() && Diff(T(a))) Line("wp::lane_broadcast(__ctx, " + A(a) + ");");
          Line("wp::lane_sync(__ctx);");
        };
        if (op.dst.empty()) {
          // A builtin without a result whose arguments still get gradients (tile_store: the
          // stored tile's adjoint reads the array's gradient).
          if (!(b->flags & kBuiltinVoidAdjoint)) return;
          bool diff = false;
          for (int v : op.args) diff |= Diff(T(v));
          if (!diff) return;
          lane_begin();
          Line("wp::" + b->adjoint + "(" + Args(op.args) + ", " + Args(op.args, 0, std::string::npos, true) + ");");
          lane_end();
          return;
        }
        if ((b->flags & kBuiltinArrayAccess) && (!Diff(T(op.args.back())) || T(op.args.back()).is_struct())) return;
        bool any = false;
        for (int v : op.dst) any |= Diff(T(v));
        if (!any) return;
        if (b->flags & kBuiltinArrayAccess) {
          int ndim = T(op.args[0]).ndim;
          Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.begin() + 1 + ndim), true);
        }
        // Natives that report launch errors take (ctx, function id, line) in their adjoints too.
        const std::string loc = (b->flags & kBuiltinNeedsLoc)
                                    ? "__ctx, " + std::to_string(f_.function_id) + ", " + std::to_string(line) + ", "
                                    : "";
        lane_begin();
        if (op.dst.size() > 1) {
          Line("wp::" + b->adjoint + "(" + loc + Args(op.args) + ", " + Args(op.dst) + ", " +
               Args(op.args, 0, std::string::npos, true) + ", " + Args(op.dst, 0, std::string::npos, true) + ");");
        } else {
          Line("wp::" + b->adjoint + "(" + loc + Args(op.args) + (op.args.empty() ? "" : ", ") +
               Args(op.args, 0, std::string::npos, true) + (op.args.empty() ? "" : ", ") + A(op.dst[0]) + ");");
        }
        lane_end();
        return;
      }
      case OpKind::kFuncCall: {
        const Function& callee = m_.functions.at(op.callee);
        std::string args = "__ctx, __tid_flat";
        if (!op.args.empty()) args += ", " + Args(op.args) + ", " + Args(op.args, 0, std::string::npos, true);
        if (!op.dst.empty()) args += ", " + Args(op.dst, 0, std::string::npos, true);
        Line("adj_" + callee.cpp_name + "(" + args + ");");
        return;
      }
      case OpKind::kConstruct: {
        if (!Diff(dt()) || op.args.empty()) return;
        std::string adj_args = Args(op.args, 0, std::string::npos, true);
        switch (op.mode) {
          case ConstructMode::kZero: return;
          case ConstructMode::kConcat: Line("wp::cg_adj_concat(" + A(op.dst[0]) + ", " + adj_args + ");"); return;
          case ConstructMode::kFill: Line("wp::cg_adj_fill(" + A(op.dst[0]) + ", " + adj_args + ");"); return;
          case ConstructMode::kConvert:
            if (Diff(T(op.args[0]))) Line("wp::cg_adj_convert(" + A(op.dst[0]) + ", " + adj_args + ");");
            return;
          case ConstructMode::kColumns: Line("wp::cg_adj_from_cols(" + A(op.dst[0]) + ", " + adj_args + ");"); return;
        }
        return;
      }
      case OpKind::kLoad:
        if (op.slot) {   // the element a slot write updates: hand back the slots it keeps
          if (!Diff(dt())) return;
          Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.end()), true);
          Line("wp::cg_adj_slot_load(" + A(op.args[0]) + ", " + A(op.dst[0]) + ", " + Args(op.args, 1) + ");");
          return;
        }
        if (!Diff(dt())) return;
        Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.end()), true);
        if (dt().is_struct()) {   // fieldwise atomic adds (cg_atomic_accum, emitted with the struct)
          Line("wp::cg_adj_load_struct(" + A(op.args[0]) + ", " + A(op.dst[0]) + ", " + Args(op.args, 1) + ");");
          return;
        }
        Line("wp::adj_load(" + A(op.args[0]) + ", " + Args(op.args, 1) + ", " + A(op.dst[0]) + ");");
        return;
      case OpKind::kStore: {
        const Type& vt = T(op.args.back());
        if ((op.slot || vt.is_struct()) && Diff(vt)) {   // see cg_adj_slot_store
          Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.end() - 1), true);
          Line("wp::cg_adj_slot_store(" + A(op.args[0]) + ", " + A(op.args.back()) + ", " +
               Args(op.args, 1, op.args.size() - 1) + ");");
          return;
        }
        if (!Diff(vt) || vt.is_struct()) return;
        Check(op, line, op.args[0], std::vector<int>(op.args.begin() + 1, op.args.end() - 1), true);
        Line("wp::adj_store(" + A(op.args[0]) + ", " + Args(op.args, 1, op.args.size() - 1) + ", " + A(op.args.back()) + ");");
        return;
      }
      case OpKind::kExtract:
        if (!Diff(dt())) return;
        Line("wp::cg_adj_extract(" + A(op.args[0]) + ", " + Args(op.args, 1) + ", " + A(op.dst[0]) + ");");
        return;
      case OpKind::kInsert:
        if (!Diff(dt())) return;
        Line("wp::cg_adj_insert(" + A(op.args[0]) + ", " + Args(op.args, 1, op.args.size() - 1) + ", " + A(op.args.back()) +
             ", " + A(op.dst[0]) + ");");
        return;
      case OpKind::kGetField:
        if (!Diff(dt()) || dt().is_array()) return;
        Line("wp::cg_accum(" + A(op.args[0]) + "." + FieldName(op.text) + ", " + A(op.dst[0]) + ");");
        return;
      case OpKind::kSetField: {
        const Type& ft = T(op.args[1]);
        if (Diff(ft) && !ft.is_array()) Line("wp::cg_accum(" + A(op.args[1]) + ", " + A(op.dst[0]) + "." + FieldName(op.text) + ");");
        Line("{");
        ++indent_;
        Line(CppType(dt()) + " __t = " + A(op.dst[0]) + ";");
        Line("__t." + FieldName(op.text) + " = wp::cg_zeros<" + CppType(ft) + ">();");
        Line("wp::cg_accum(" + A(op.args[0]) + ", __t);");
        --indent_;
        Line("}");
        return;
      }
      case OpKind::kPhi:
        if (!Diff(dt())) return;
        Line("wp::cg_adj_phi(" + V(op.args[0]) + ", " + A(op.args[1]) + ", " + A(op.args[2]) + ", " + A(op.dst[0]) + ");");
        return;
    }
  }

  const Module& m_;
  const Function& f_;
  const CodegenOptions& opt_;
  std::string& out_;
  std::set<int> tid_vars_;   // trusted variant only: the variables holding wp.tid()
  Mode mode_ = Mode::kForward;
  // print() runs in the replay of a backward pass (Warp prints the forward values there, then
  // "adj: ..." in the reverse code), but only in the first replay of the body: not in a
  // replay_ function (called again for every reverse loop iteration) nor in RevLoop's
  // recomputation of a loop's iterations.
  bool print_in_replay_ = false;
  std::string fail_ = "return;";
  int indent_ = 0;
  int last_line_ = -1;
  Region region_;
  bool hoisting_ = false;  // the op being emitted is a load or view (its check may move up)
};

// The fields Warp's struct arithmetic accumulates (its wp.atomic_add scalar set): scalars,
// vectors, matrices, quaternions and transforms of [u]int32, [u]int64, float16, bfloat16,
// float32 and float64, and nested structs. bool and narrow-integer fields, arrays and the rest
// ride along unchanged.
bool StructArithmeticField(const Type& t) {
  if (t.is_struct()) return true;
  if (!(t.is_scalar() || t.is_vector() || t.is_matrix() || t.kind == TypeKind::kQuat ||
        t.kind == TypeKind::kTransform))
    return false;
  switch (t.scalar) {
    case ScalarKind::kInt32: case ScalarKind::kInt64: case ScalarKind::kUInt32: case ScalarKind::kUInt64:
    case ScalarKind::kFloat16: case ScalarKind::kFloat32: case ScalarKind::kFloat64: case ScalarKind::kBFloat16:
      return true;
    default:
      return false;
  }
}

void EmitStructs(const Module& m, std::string* out) {
  if (m.struct_order.empty()) return;
  std::string& o = *out;
  o += "namespace wp {\n";
  for (const auto& name : m.struct_order) {
    const StructInfo& si = m.structs.at(name);
    o += "// @wp.struct " + CommentText(name) + "\nstruct " + si.cpp_name + " {\n";
    for (const auto& f : si.fields) o += "  " + CppType(f.type) + " " + FieldName(f.name) + ";\n";
    o += "};\n";
    o += "WP_FUNC void cg_accum(" + si.cpp_name + "& a, const " + si.cpp_name + "& b) {";
    for (const auto& f : si.fields) o += " cg_accum(a." + FieldName(f.name) + ", b." + FieldName(f.name) + ");";
    o += " }\n";
    if (HasIndexedArrays(Type::Struct(name), m.structs)) {
      o += "WP_FUNC void cg_indexed_adjoint(" + si.cpp_name + "& a, const " + si.cpp_name + "& b) {";
      for (const auto& f : si.fields)
        if (HasIndexedArrays(f.type, m.structs))
          o += " cg_indexed_adjoint(a." + FieldName(f.name) + ", b." + FieldName(f.name) + ");";
      o += " }\n";
    }
    // the adjoint of a load of a struct element: its differentiable fields, atomically
    o += "WP_FUNC void cg_atomic_accum(" + si.cpp_name + "* p, const " + si.cpp_name + "& v) {";
    for (const auto& f : si.fields)
      if (IsDifferentiable(f.type) && !HasArrays(f.type, m.structs))
        o += std::string(f.type.is_struct() ? " cg_atomic_accum(" : " atomic_add_ptr(") + "&p->" + FieldName(f.name) +
             ", v." + FieldName(f.name) + ");";
    o += " (void)p; (void)v; }\n";
    // Warp's struct arithmetic (tiles of structs: t + u, t - u, -t, tile_sum, t[i] += s): field
    // by field over the fields StructArithmeticField names; the others keep a's value.
    const std::string& sn = si.cpp_name;
    for (const char* op : {"add", "sub"}) {
      o += "WP_FUNC " + sn + " struct_" + op + "(const " + sn + "& a, const " + sn + "& b) { " + sn + " r = a;";
      for (const auto& f : si.fields)
        if (StructArithmeticField(f.type))
          o += " r." + FieldName(f.name) + " = " + (f.type.is_struct() ? "struct_" : "") + op + "(a." +
               FieldName(f.name) + ", b." + FieldName(f.name) + ");";
      o += " (void)b; return r; }\n";
    }
    o += "WP_FUNC " + sn + " struct_neg(const " + sn + "& a) { " + sn + " r = a;";
    for (const auto& f : si.fields)
      if (StructArithmeticField(f.type))
        o += std::string(" r.") + FieldName(f.name) + " = " + (f.type.is_struct() ? "struct_neg" : "neg") + "(a." +
             FieldName(f.name) + ");";
    o += " return r; }\n";
    // tile_atomic_add of struct elements: the same fields, each atomically
    o += "WP_FUNC void struct_atomic_add(" + sn + "* p, const " + sn + "& v) {";
    for (const auto& f : si.fields)
      if (StructArithmeticField(f.type))
        o += std::string(f.type.is_struct() ? " struct_atomic_add(" : " atomic_add_ptr(") + "&p->" + FieldName(f.name) +
             ", v." + FieldName(f.name) + ");";
    o += " (void)p; (void)v; }\n";
    o += "WP_FUNC void cg_link(" + si.cpp_name + "& a, const " + si.cpp_name + "& b) {";
    for (const auto& f : si.fields)
      if (HasArrays(f.type, m.structs)) o += " cg_link(a." + FieldName(f.name) + ", b." + FieldName(f.name) + ");";
    o += " (void)a; (void)b; }\n";
  }
  o += "}  // namespace wp\n\n";
}

}  // namespace

Expected<ParamLayout> LayoutParam(const std::string& name, const Type& type, const StructTable& structs) {
  ParamLayout p;
  p.name = name;
  p.type = TypeString(type);
  WEFT_ASSIGN_OR_RETURN(TypeLayout l, LayoutOf(type, structs));
  p.size = l.size;
  p.align = l.align;
  if (type.is_indexed_array()) {
    // Packed as its fields (wp::indexedarray_t): the data array, then one int32 index array per
    // dimension (None where a dimension is not indexed), each validated as an array.
    WEFT_ASSIGN_OR_RETURN(ParamLayout data, LayoutParam("data", Type::Array(type.elem(), type.ndim), structs));
    p.fields.push_back(std::move(data));
    for (int d = 0; d < 4; ++d) {
      WEFT_ASSIGN_OR_RETURN(ParamLayout ix, LayoutParam("indices" + std::to_string(d),
                                                        Type::Array(Type::Int32(), 1), structs));
      ix.offset = 88u * static_cast<uint32_t>(d + 1);
      p.fields.push_back(std::move(ix));
    }
    return p;
  }
  if (type.is_array()) {
    p.is_array = true;
    p.array_dtype = TypeString(type.elem());
    p.array_ndim = type.ndim;
    if (!type.elem().is_any()) {
      WEFT_ASSIGN_OR_RETURN(TypeLayout el, LayoutOf(type.elem(), structs));
      p.array_elem_size = el.size;
    }
  }
  if (type.is_struct()) {
    const StructInfo& si = structs.at(type.struct_name);
    uint32_t off = 0;
    for (const auto& f : si.fields) {
      WEFT_ASSIGN_OR_RETURN(ParamLayout fl, LayoutParam(f.name, f.type, structs));
      off = RoundUp(off, fl.align);
      fl.offset = off;
      off += fl.size;
      p.fields.push_back(std::move(fl));
    }
  }
  return p;
}

namespace {

// Runs one function's emission; an exception (an emitter bug) becomes a located error.
Status Guarded(const Function& f, std::vector<Diagnostic>* diags, const std::function<Status()>& emit) {
  try {
    return emit();
  } catch (const std::exception& e) {
    Diagnostic d;
    d.location = {f.file, static_cast<uint32_t>(f.def_line), 1};
    d.message = std::string("weft cannot generate code for ") + (f.is_kernel ? "kernel '" : "function '") + f.name +
                "' (internal compiler error: " + e.what() + "; please report it)";
    if (diags) diags->push_back(d);
    return InvalidArgument(d.ToString());
  }
}

// The no_adjoint error of f or of a function it calls (directly or not), as text; "" if none.
std::string AdjointRefused(const Module& m, const Function& f) {
  std::set<int> seen;
  std::function<std::string(const Function&)> visit = [&](const Function& fn) -> std::string {
    if (!fn.no_adjoint.message.empty()) return fn.no_adjoint.ToString();
    std::function<std::string(const std::vector<Stmt>&)> walk = [&](const std::vector<Stmt>& stmts) -> std::string {
      for (const auto& s : stmts) {
        std::string r;
        if (s.kind == Stmt::Kind::kOp && s.op.callee >= 0 && seen.insert(s.op.callee).second)
          r = visit(m.functions.at(s.op.callee));
        if (r.empty()) r = walk(s.then_body);
        if (r.empty()) r = walk(s.else_body);
        if (r.empty()) r = walk(s.cond_body);
        if (r.empty()) r = walk(s.body);
        if (!r.empty()) return r;
      }
      return "";
    };
    return walk(fn.body);
  };
  return visit(f);
}

}  // namespace

// Whether any function of the module holds a tile or a tile stack (cooperative CPU blocks
// change nothing for a module without them).
static bool ModuleUsesTiles(const Module& m) {
  for (const auto& f : m.functions)
    for (const auto& v : f.vars)
      if (v.type.is_tile() || v.type.is_tile_stack()) return true;
  return false;
}

Expected<GeneratedModule> EmitCpp(const Module& m, const CodegenOptions& options, std::vector<Diagnostic>* diags) {
  GeneratedModule gm;
  std::string& o = gm.source;
  o += "// Generated by weft codegen (engine/codegen) for the ";
  o += options.target == Target::kCpu ? "CPU" : "CUDA";
  o += " target";
  o += options.enable_backward ? ", forward and backward" : ", forward only";
  o += options.bounds_checks ? ", bounds-checked.\n" : ", without bounds checks.\n";
  o += "#include \"weft.h\"\n#include \"codegen_support.h\"\n\n";
  EmitStructs(m, &o);
  for (const auto& f : m.functions) gm.function_names.push_back(f.file + ":" + f.name);
  if (options.enable_backward) {
    for (const auto& f : m.functions) {
      if (f.no_adjoint.message.empty()) continue;
      if (diags) diags->push_back(f.no_adjoint);
      return InvalidArgument(f.no_adjoint.ToString());
    }
  }

  // Every forward function first, then the replays and adjoints: a func's adjoint may call a
  // function instantiated after it (its custom gradient, which may call the func itself).
  for (const auto& f : m.functions) {
    if (f.is_kernel) continue;
    WEFT_RETURN_IF_ERROR(Guarded(f, diags, [&]() {
      FnEmitter(m, f, options, &o).EmitFunc(FnEmitter::Mode::kForward);
      return Status::Ok();
    }));
  }
  for (const auto& f : m.functions) {
    if (f.is_kernel || !options.enable_backward) continue;
    WEFT_RETURN_IF_ERROR(Guarded(f, diags, [&]() {
      FnEmitter(m, f, options, &o).EmitFunc(FnEmitter::Mode::kReplay);
      FnEmitter(m, f, options, &o).EmitFunc(FnEmitter::Mode::kAdjoint);
      return Status::Ok();
    }));
  }
  for (int ki : m.kernels) {
    const Function& f = m.functions.at(ki);
    WEFT_RETURN_IF_ERROR(Guarded(f, diags, [&]() -> Status {
    KernelLayout kl;
    kl.name = f.name;
    std::string args_struct = "weft_args_" + f.cpp_name;
    const size_t block_start = o.size();
    o += "// argument block of kernel " + CommentText(f.name) + "\nstruct alignas(8) " + args_struct + " {\n";
    uint32_t off = 0, align = 8;
    for (size_t i = 0; i < f.params.size(); ++i) {
      const Type& t = f.vars[f.params[i]].type;
      WEFT_ASSIGN_OR_RETURN(ParamLayout pl, LayoutParam(f.param_names[i], t, m.structs));
      off = RoundUp(off, pl.align);
      pl.offset = off;
      off += pl.size;
      if (pl.align > align) align = pl.align;
      o += "  " + CppType(t) + " p" + std::to_string(i) + ";  // " + CommentText(f.param_names[i]) + ": " + CommentText(TypeString(t)) + " @" +
           std::to_string(pl.offset) + "\n";
      kl.params.push_back(std::move(pl));
    }
    if (f.params.empty()) o += "  wp::int64 _unused;\n";
    kl.args_size = f.params.empty() ? 8 : RoundUp(off, align);
    kl.args_align = align;
    o += "};\n";
    o += "static_assert(sizeof(" + args_struct + ") == " + std::to_string(kl.args_size) +
         ", \"weft: argument block layout mismatch\");\n\n";

    o.replace(block_start, std::string::npos, MapToDefLine(f, o.substr(block_start)));
    std::string fwd = f.cpp_name + "_forward_body", bwd = f.cpp_name + "_backward_body";
    FnEmitter(m, f, options, &o).EmitKernelBody(false, args_struct, fwd);
    if (options.enable_backward) FnEmitter(m, f, options, &o).EmitKernelBody(true, args_struct, bwd);

    const size_t entry_start = o.size();
    std::string target = options.target == Target::kCpu ? "cpu" : "cuda";
    kl.adjoint_refused = AdjointRefused(m, f);
    kl.forward_symbol = "weft_" + MangleIdentifier(f.name) + "_" + target + "_forward";
    if (options.enable_backward) kl.backward_symbol = "weft_" + MangleIdentifier(f.name) + "_" + target + "_backward";
    if (options.target == Target::kCpu) {
      // Lanes only where they can matter: a module without tiles runs one thread per block.
      kl.lanes = options.cpu_lanes > 1 && ModuleUsesTiles(m) ? options.cpu_lanes : 1;
      o += "extern \"C\" void " + kl.forward_symbol +
           "(const wp::launch_context_t* __ctx, const void* __args, wp::int64 __begin, wp::int64 __end) {\n"
           "  const " + args_struct + "& __a = *static_cast<const " + args_struct + "*>(__args);\n"
           "  for (wp::int64 __i = __begin; __i < __end; ++__i) " + fwd + "(__ctx, __a, __i);\n}\n\n";
      if (options.enable_backward)
        o += "extern \"C\" void " + kl.backward_symbol +
             "(const wp::launch_context_t* __ctx, const void* __args, const void* __adj_args, wp::int64 __begin, "
             "wp::int64 __end) {\n"
             "  const " + args_struct + "& __a = *static_cast<const " + args_struct + "*>(__args);\n"
             "  const " + args_struct + "& __adj = *static_cast<const " + args_struct + "*>(__adj_args);\n"
             "  for (wp::int64 __i = __begin; __i < __end; ++__i) " + bwd + "(__ctx, __a, __adj, __i);\n}\n\n";
    } else {
      // Lean (what the module store builds first): one index per thread and an early return;
      // the grid must cover the launch. Grid-stride: any grid, max_blocks allowed (the variant
      // a launch that needs it gets, ModuleStore::WithGridStride). Measured
      // (bench/kernel_variants, saxpy 1e8 on an H200): 385 us lean against 448 us in the loop,
      // whose prologue carries the hoisted invariants of the bounds checks' error paths.
      kl.grid_stride = options.grid_stride;
      std::set<uint32_t> tid_loaded;
      std::vector<uint32_t> prefetched;   // what the forward entry prefetches (trusted variant)
      if (options.bounds_checks) {
        std::set<int> tid_vars;
        CollectTidVars(f.body, &tid_vars);
        std::set<uint32_t> trusted;
        if (!tid_vars.empty()) CollectTidIndexedParams(f, tid_vars, f.body, &trusted, &tid_loaded);
        kl.tid_indexed_params.assign(trusted.begin(), trusted.end());
        // The trusted lean entry prefetches into L2 what the body loads at wp.tid() only after
        // a store (vec3 integration 1e8 on an H200: 98.1% -> 99.7% of a device copy;
        // bench/kernel_variants/integrate_variants.cu). In range: the launch proved p[tid]
        // for every thread, and a 1-D launch's flat index is wp.tid().
        if (options.trust_tid_indices && !options.grid_stride && !tid_vars.empty()) {
          const std::set<uint32_t> late = TidLoadsAfterAStore(f, tid_vars);
          prefetched.assign(late.begin(), late.end());
        }
      }
      auto entry = [&](const std::string& symbol, const std::string& params, const std::string& call,
                       const std::vector<uint32_t>& prefetch) {
        o += "extern \"C\" __global__ void " + symbol + "(" + params + ") {\n";
        if (options.grid_stride) {
          o += "  const wp::int64 __stride = (wp::int64)blockDim.x * gridDim.x;\n"
               "  for (wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x; __i < __ctx.bounds.size; "
               "__i += __stride)\n"
               "    " + call + ";\n";
        } else {
          o += "  const wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;\n"
               "  if (__i >= __ctx.bounds.size) return;\n";
          if (!prefetch.empty()) {
            o += "  if (__ctx.bounds.ndim == 1) {\n";
            for (uint32_t p : prefetch) o += "    wp::cg_prefetch_l2(__args.p" + std::to_string(p) + ", __i);\n";
            o += "  }\n";
          }
          o += "  " + call + ";\n";
        }
        o += "}\n\n";
      };
      const std::string ctx_param = "const WP_GRID_CONSTANT wp::launch_context_t __ctx";
      auto args_param = [&](const char* name) { return "const WP_GRID_CONSTANT " + args_struct + " " + name; };
      entry(kl.forward_symbol, ctx_param + ", " + args_param("__args"), fwd + "(&__ctx, __args, __i)", prefetched);
      if (options.enable_backward)
        entry(kl.backward_symbol, ctx_param + ", " + args_param("__args") + ", " + args_param("__adj_args"),
              bwd + "(&__ctx, __args, __adj_args, __i)", {});
      // The coarsened entry (KernelLayout::coarse_symbol). One element per thread leaves a
      // memory-bound kernel short of the copy rate: too few loads in flight per SM (saxpy 1e8 on
      // an H200: 82% of a device copy unchecked, 101% coarsened by 4 with the prefetches;
      // bench/kernel_variants). Running logical threads one after another in one GPU thread is
      // one of the schedules the launch already allows: they share nothing a thread owns.
      if (options.trust_tid_indices && !options.grid_stride && !tid_loaded.empty() && !ModuleUsesTiles(m)) {
        kl.coarse_symbol = kl.forward_symbol + "_x" + std::to_string(kCoarseFactor);
        for (uint32_t p : tid_loaded) kl.coarse_loaded_bytes += kl.params.at(p).array_elem_size;
        const std::string factor = std::to_string(kCoarseFactor);
        o += "extern \"C\" __global__ void " + kl.coarse_symbol + "(" + ctx_param + ", " + args_param("__args") + ") {\n"
             "  const wp::int64 __n = __ctx.bounds.size;\n"
             "  const wp::int64 __q = (__n + " + factor + " - 1) / " + factor + ";\n"
             "  const wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;\n"
             "  if (__i >= __q) return;\n"
             "#pragma unroll\n"
             "  for (int __k = 1; __k < " + factor + "; ++__k) {\n"
             "    const wp::int64 __j = __i + __k * __q;\n"
             "    if (__j >= __n) break;\n";
        for (uint32_t p : tid_loaded) o += "    wp::cg_prefetch_l2(__args.p" + std::to_string(p) + ", __j);\n";
        o += "  }\n"
             "#pragma unroll 1\n"
             "  for (int __k = 0; __k < " + factor + "; ++__k) {\n"
             "    const wp::int64 __j = __i + __k * __q;\n"
             "    if (__j >= __n) break;\n"
             "    " + fwd + "(&__ctx, __args, __j);\n"
             "  }\n"
             "}\n\n";
      }
    }
    o.replace(entry_start, std::string::npos, MapToDefLine(f, o.substr(entry_start)));
    gm.kernels.push_back(std::move(kl));
    return Status::Ok();
    }));
  }
  return gm;
}

}  // namespace weft::codegen
