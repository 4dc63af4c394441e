// Semantic analysis, module and statement level: symbol tables, struct resolution, function
// instantiation (kernels, funcs, generic funcs per argument types), and lowering of
// statements to the structured SSA IR (assignments, if/elif/else with phi merges, for/while
// with loop-carried slots, break/continue/return as flags guarding the rest of a block).
#include <cstdio>
#include <exception>

#include "engine/codegen/emit_text.h"
#include "engine/sema/check_impl.h"

namespace weft::sema {

// The atomic builtin an augmented assignment on an array element becomes (+ - & | ^).
static const char* AtomicBuiltinOf(ast::BinaryOperator op) {
  switch (op) {
    case ast::BinaryOperator::kAdd: return "atomic_add";
    case ast::BinaryOperator::kSub: return "atomic_sub";
    case ast::BinaryOperator::kBitAnd: return "atomic_and";
    case ast::BinaryOperator::kBitOr: return "atomic_or";
    default: return "atomic_xor";
  }
}


Checker::Checker(const ModuleSource& module, const std::vector<ParsedFunction>& parsed,
                 std::vector<Diagnostic>* diags)
    : src_(module), parsed_(parsed), diags_(diags), lanes_(CpuLanesOption(module)) {
  for (const auto& s : module.symbols) symbols_.emplace(s.name, &s);
  for (const auto& p : parsed) by_key_[p.source->key.empty() ? p.source->name : p.source->key] = &p;
}

Status Checker::Error(const SourceLocation& loc, const std::string& msg) { return ErrorOf("", loc, msg); }

Status Checker::ErrorOf(const char* kind, const SourceLocation& loc, const std::string& msg) {
  Diagnostic d;
  d.message = msg;
  d.kind = kind;
  d.location = loc;
  if (st_ && loc.line > 0) {
    int rel = static_cast<int>(loc.line) - st_->fn.def_line;
    if (rel >= 0 && rel < static_cast<int>(st_->source_lines.size())) d.source_line = st_->source_lines[rel];
  }
  if (diags_) diags_->push_back(d);
  return InvalidArgument(d.ToString());
}

Expected<Module> Checker::Run() {
  // The geometry query structs (defined by engine/native, never emitted) come first; client
  // structs may not take their names, nor hold them.
  if (lanes_ < 1) {
    SourceLocation loc;
    loc.file = src_.name;
    return Error(loc, "module option cpu_block_dim must be an integer from 1 to 1024, got '" +
                          src_.options.at("cpu_block_dim").substr(0, 16) + "'");
  }
  const StructTable& geometry = GeometryStructs();
  for (const auto& [name, info] : geometry) module_.structs[name] = info;
  auto uses_geometry = [&](const Type& t) {
    const Type* e = t.is_array() ? &t.elem() : &t;
    return e->is_struct() && geometry.count(e->struct_name) != 0;
  };
  // Structs: resolve field types (order: dependencies first).
  for (const auto& sd : src_.structs) {
    if (geometry.count(sd.name)) {
      SourceLocation loc;
      loc.file = sd.name;
      return Error(loc, "struct name '" + sd.name + "' is reserved for a geometry query type");
    }
    StructInfo info;
    info.name = sd.name;
    info.cpp_name = StructCppName(sd.name);
    for (const auto& f : sd.fields) {
      auto t = ParseType(f.type);
      if (!t.ok()) {
        SourceLocation loc;
        loc.file = sd.name;
        return Error(loc, "struct " + sd.name + " field '" + f.name + "': " + t.status().message());
      }
      if (uses_geometry(*t)) {
        SourceLocation loc;
        loc.file = sd.name;
        return Error(loc, "struct " + sd.name + " field '" + f.name + "': a geometry query cannot be a struct field");
      }
      if (ContainsAny(*t)) {
        SourceLocation loc;
        loc.file = sd.name;
        return Error(loc, "struct " + sd.name + " field '" + f.name + "': a struct field needs a concrete type, not the "
                              "generic " + TypeString(*t));
      }
      info.fields.push_back({f.name, *t});
    }
    module_.structs[sd.name] = std::move(info);
  }
  std::set<std::string> placed;
  std::function<Status(const std::string&, int)> place = [&](const std::string& name, int depth) -> Status {
    if (placed.count(name)) return Status::Ok();
    auto it = module_.structs.find(name);
    if (it == module_.structs.end() || depth > 64) {
      SourceLocation loc;
      loc.file = name;
      return Error(loc, "unknown or recursive struct '" + name + "'");
    }
    for (const auto& f : it->second.fields) {
      const Type* t = &f.type;
      if (t->is_array()) t = &t->elem();
      if (t->is_struct()) WEFT_RETURN_IF_ERROR(place(t->struct_name, depth + 1));
    }
    placed.insert(name);
    module_.struct_order.push_back(name);
    return Status::Ok();
  };
  for (const auto& sd : src_.structs) {
    auto s = place(sd.name, 0);
    if (!s.ok()) return s;
  }

  bool failed = false;
  for (const auto& p : parsed_) {
    if (!p.source->is_kernel) continue;
    std::vector<Type> types;
    bool bad = false;
    for (size_t i = 0; i < p.source->param_types.size(); ++i) {
      auto t = ParseType(p.source->param_types[i]);
      if (!t.ok() || ContainsAny(*t) || uses_geometry(*t)) {
        SourceLocation loc{p.source->file, p.source->first_line, 1};
        (void)Error(loc, "kernel '" + p.source->name + "' parameter " + std::to_string(i) + ": " +
                             (!t.ok() ? t.status().message()
                                      : uses_geometry(*t) ? "a geometry query cannot be a kernel parameter (pass the object's id, a uint64)"
                                                          : "kernel parameters need concrete types, not 'any'"));
        bad = true;
        break;
      }
      types.push_back(*t);
    }
    if (bad) {
      failed = true;
      continue;
    }
    SourceLocation def_loc{p.source->file, p.source->first_line, 1};
    Expected<int> idx = Internal("not compiled");
    try {
      idx = InstantiateFunction(p, types, def_loc);
    } catch (const std::exception& e) {
      st_ = nullptr;
      in_progress_.clear();
      idx = Error(def_loc, "weft cannot compile kernel '" + p.source->name + "' (internal compiler error: " + e.what() +
                               "; please report it)");
    }
    if (!idx.ok()) {
      failed = true;
      continue;
    }
    module_.kernels.push_back(*idx);
  }
  if (failed) return InvalidArgument("the module has errors");
  return std::move(module_);
}

namespace {

// Warp's words (ValueError) for a value that does not fit the slice it is assigned to: a vector
// slice takes a vector of its length and scalar type, a 2-D matrix slice a matrix of its shape.
std::string SliceAssignMismatch(const Type& value, const Type& slice) {
  const std::string dtype = ScalarName(slice.scalar);
  if (slice.is_vector()) {
    const std::string length = std::to_string(slice.rows);
    if (!value.is_vector())
      return "The provided value is expected to be a vector of length " + length + ", with dtype " + dtype + ".";
    if (value.scalar != slice.scalar)
      return "The provided vector is expected to be of length " + length + " with dtype " + dtype + ".";
    return "The length of the provided vector (" + std::to_string(value.rows) +
           ") isn't compatible with the given slice (expected " + length + ").";
  }
  const std::string shape = "(" + std::to_string(slice.rows) + ", " + std::to_string(slice.cols) + ")";
  if (!value.is_matrix())
    return "The provided value is expected to be a matrix of shape " + shape + ", with dtype " + dtype + ".";
  if (value.scalar != slice.scalar)
    return "The provided matrix is expected to be of shape " + shape + " with dtype " + dtype + ".";
  return "The shape of the provided matrix ((" + std::to_string(value.rows) + ", " + std::to_string(value.cols) +
         ")) isn't compatible with the given slice (expected " + shape + ").";
}

std::vector<std::string> SplitLines(const std::string& s) {
  std::vector<std::string> out;
  size_t b = 0;
  for (size_t i = 0; i <= s.size(); ++i) {
    if (i == s.size() || s[i] == '\n') {
      out.push_back(s.substr(b, i - b));
      b = i + 1;
    }
  }
  return out;
}

}  // namespace

// grad_of_params >= 0: pf is the gradient function (wp.func_grad) of a func with that many
// parameters; its first parameters are the func's, the rest its return values' adjoints.
bool ContainsArrays(const Type& t, const StructTable& structs) {
  if (t.is_array()) return true;
  if (t.is_tuple()) {
    for (const auto& e : t.sub)
      if (ContainsArrays(e, structs)) return true;
    return false;
  }
  if (!t.is_struct()) return false;
  auto it = structs.find(t.struct_name);
  if (it == structs.end()) return false;
  for (const auto& f : it->second.fields)
    if (ContainsArrays(f.type, structs)) return true;
  return false;
}

bool ArrayOfArrays(const Type& t, const StructTable& structs) {
  if (t.is_array()) return !t.is_fixed_array() && ContainsArrays(t.elem(), structs);
  if (t.is_tuple()) {
    for (const auto& e : t.sub)
      if (ArrayOfArrays(e, structs)) return true;
    return false;
  }
  if (!t.is_struct()) return false;
  auto it = structs.find(t.struct_name);
  if (it == structs.end()) return false;
  for (const auto& f : it->second.fields)
    if (ArrayOfArrays(f.type, structs)) return true;
  return false;
}

Expected<int> Checker::InstantiateFunction(const ParsedFunction& pf, const std::vector<Type>& param_types,
                                           const SourceLocation& call_loc, int grad_of_params) {
  const FunctionSource& fs = *pf.source;
  std::string key = fs.key.empty() ? fs.name : fs.key;
  std::string inst = key + "(";
  for (const auto& t : param_types) inst += TypeString(t) + ";";
  inst += ")";
  if (auto it = instances_.find(inst); it != instances_.end()) return it->second;
  if (in_progress_.count(inst)) return Error(call_loc, "recursive call of '" + fs.name + "' is not supported");
  in_progress_.insert(inst);

  FnState state;
  FnState* saved = st_;
  st_ = &state;
  // Restores the caller's state when an exception unwinds through here (see LowerStmt).
  struct UnwindGuard {
    Checker* c;
    FnState* saved;
    std::string inst;
    ~UnwindGuard() {
      if (std::uncaught_exceptions() > 0) {
        c->st_ = saved;
        c->in_progress_.erase(inst);
      }
    }
  } unwind_guard{this, saved, inst};
  Function& fn = state.fn;
  fn.name = fs.name;
  fn.key = inst;
  fn.file = fs.file;
  fn.def_line = static_cast<int>(fs.first_line);
  fn.is_kernel = fs.is_kernel;
  state.parsed = &pf;
  state.source_lines = SplitLines(fs.source);
  state.block = &fn.body;
  state.line = fn.def_line;

  auto finish_error = [&](Status s) -> Status {
    st_ = saved;
    in_progress_.erase(inst);
    return s;
  };

  const auto& params = pf.def->params;
  if (params.size() != param_types.size())
    return finish_error(Error(pf.def->loc, "'" + fs.name + "' takes " + std::to_string(params.size()) +
                                               " parameters but " + std::to_string(param_types.size()) +
                                               " types were given"));
  std::vector<int> param_vars(params.size(), -1);   // the variable each plain parameter starts as
  for (size_t i = 0; i < params.size(); ++i) {
    const Type& t = param_types[i];
    const Type& base = t.is_array() ? t.elem() : t;
    if (base.is_struct() && !module_.structs.count(base.struct_name))
      return finish_error(Error(params[i].loc, "unknown struct type '" + base.struct_name + "'"));
    if (ArrayOfArrays(t, module_.structs))
      return finish_error(Error(params[i].loc, "'" + params[i].name + "': arrays whose elements hold arrays (structs with "
                                               "array or indexed-array members) cannot be kernel or func parameters: an "
                                               "array inside array memory would be an address written by the client"));
    if (t.is_function()) {
      // A wp.Function parameter: each target is its own instantiation; no runtime parameter.
      Value fv;
      const std::string& target = t.struct_name;
      if (target.rfind("func:", 0) == 0) fv.kind = Value::Kind::kFunc, fv.name = target.substr(5);
      else if (target.rfind("builtin:", 0) == 0) fv.kind = Value::Kind::kBuiltin, fv.name = target.substr(8);
      else return finish_error(Error(params[i].loc, "'" + params[i].name + "' needs a function argument"));
      state.func_scope[params[i].name] = fv;
      continue;
    }
    if (t.is_tuple()) {
      // A tuple parameter: one parameter per element; the name stands for the tuple.
      if (fs.is_kernel) return finish_error(Error(params[i].loc, "kernel parameters cannot be tuples"));
      Value tv;
      tv.kind = Value::Kind::kTuple;
      for (size_t k = 0; k < t.sub.size(); ++k) {
        int v = NewVar(t.sub[k], params[i].name + "_" + std::to_string(k));
        fn.vars[v].is_param = true;
        fn.params.push_back(v);
        fn.param_names.push_back(params[i].name + "_" + std::to_string(k));
        tv.elems.push_back(Value::OfVar(v));
      }
      state.tuple_scope[params[i].name] = std::move(tv);
      continue;
    }
    int v = NewVar(t, params[i].name);
    fn.vars[v].is_param = true;
    fn.params.push_back(v);
    fn.param_names.push_back(params[i].name);
    state.scope[params[i].name] = v;
    param_vars[i] = v;
    if (fs.is_kernel && (t.is_array() || t.is_struct())) state.array_param[v] = static_cast<int>(i);
  }
  if (grad_of_params >= 0) {
    // The gradient function returns one adjoint slot per differentiable parameter of the
    // forward func; `wp.adjoint[x] += ...` updates the slot of x.
    // An array parameter's wp.adjoint[a] is its gradient array, which the gradient function
    // takes as an extra parameter after its own (elements are updated in place).
    for (int i = 0; i < grad_of_params && i < static_cast<int>(params.size()); ++i) {
      const Type& t = param_types[i];
      if (!t.is_array() || t.is_fixed_array()) continue;
      int v = NewVar(t, "adj_" + params[i].name);
      fn.vars[v].is_param = true;
      fn.params.push_back(v);
      fn.param_names.push_back("adj_" + params[i].name);
      fn.grad_array_of_param.push_back(i);
      state.adjoint_slots[params[i].name] = v;
    }
    for (int i = 0; i < grad_of_params && i < static_cast<int>(params.size()); ++i) {
      const Type& t = param_types[i];
      if (!IsDifferentiable(t) || (t.is_struct() && ContainsArrays(t, module_.structs))) continue;
      int slot = NewVar(t, "adj_" + params[i].name, true);
      fn.returns.push_back(t);
      fn.return_slots.push_back(slot);
      fn.grad_of_param.push_back(i);
      state.adjoint_slots[params[i].name] = slot;
      Stmt z;
      z.op.kind = OpKind::kConstruct;
      z.op.mode = ConstructMode::kZero;
      z.op.dst.push_back(slot);
      Push(std::move(z));
    }
  } else if (!fs.is_kernel && !fs.return_type.empty() && fs.return_type != "void" && fs.return_type != "None") {
    auto rt = ParseType(fs.return_type);
    if (!rt.ok()) return finish_error(Error(pf.def->loc, "return type: " + rt.status().message()));
    if (ContainsAny(*rt)) {
      state.return_patterns = rt->is_tuple() ? rt->sub : std::vector<Type>{*rt};
    } else if (rt->is_tuple()) fn.returns = rt->sub;
    else fn.returns.push_back(*rt);
    for (const auto& t : fn.returns) fn.return_slots.push_back(NewVar(t, "ret", true));
  }
  fn.return_flag = NewVar(Type::Bool(), "returned", true);
  {
    Stmt init;
    init.op.kind = OpKind::kConst;
    init.op.dst.push_back(fn.return_flag);
    init.op.text = "false";
    Push(std::move(init));
  }

  CountAssignedNames(pf.def->body, &state.assign_counts);
  CollectTileViewBases(pf.def->body, &state.view_bases);
  std::set<std::string> rebound;   // names plainly assigned (not updated in place) in the body
  CollectReboundNames(pf.def->body, &rebound);
  Status s = LowerBlock(pf.def->body);
  if (!s.ok()) return finish_error(s);
  // wp.ref[T] parameters: their final values are returned after the function's own (the
  // binding at the end of the body is the value on every path: statements after a return
  // are guarded by its flag), and the caller writes them back to its arguments.
  for (size_t i = 0; i < params.size() && i < fs.param_types.size(); ++i) {
    std::string inner;
    if (!RefTypeInner(fs.param_types[i], &inner)) {
      // A tile or tile stack the body assigns (`t += ...`, a push) is a reference too (Warp
      // passes tiles by reference): its final value goes back to the caller's variable.
      // A parameter the body rebinds (`t = t * 2.0`) is a local from there on, as in Python.
      const Type& t = param_types[i];
      auto cur = state.scope.find(params[i].name);
      if (fs.is_kernel || !(t.is_tile() || t.is_tile_stack()) || cur == state.scope.end() ||
          cur->second == param_vars[i] || TypeOf(cur->second) != t || rebound.count(params[i].name))
        continue;
      int slot = NewVar(t, "ref_" + params[i].name, true);
      EmitCopy(slot, cur->second);
      fn.returns.push_back(t);
      fn.return_slots.push_back(slot);
      fn.ref_params.push_back(static_cast<int>(i));
      continue;
    }
    if (fs.is_kernel) return finish_error(Error(params[i].loc, "kernel parameters cannot be wp.ref[T]"));
    if (grad_of_params >= 0)
      return finish_error(Error(params[i].loc, "a gradient function (wp.func_grad) cannot take wp.ref[T] parameters"));
    auto cur = state.scope.find(params[i].name);
    if (cur == state.scope.end() || param_types[i].is_function() || param_types[i].is_tuple())
      return finish_error(Error(params[i].loc, "wp.ref parameter '" + params[i].name + "' must hold a single value"));
    if (TypeOf(cur->second) != param_types[i])
      return finish_error(Error(params[i].loc, "wp.ref parameter '" + params[i].name + "' changes type from " +
                                                   TypeString(param_types[i]) + " to " + TypeString(TypeOf(cur->second))));
    int slot = NewVar(param_types[i], "ref_" + params[i].name, true);
    EmitCopy(slot, cur->second);
    fn.returns.push_back(param_types[i]);
    fn.return_slots.push_back(slot);
    fn.ref_params.push_back(static_cast<int>(i));
  }
  if (fn.is_kernel && !fn.return_slots.empty())
    return finish_error(Error(pf.def->loc, "kernels cannot return a value"));
  if (!fn.is_kernel && fn.returns.empty() && !fs.return_type.empty() && fs.return_type != "void" &&
      fs.return_type != "None")
    return finish_error(Error(pf.def->loc, "'" + fs.name + "' declares a return type but never returns"));

  // Tiles and fixed-size arrays live in the thread's memory (the CPU thread's stack): bounded,
  // with the funcs this one calls.
  {
    int64_t own = 0, callees = 0;
    for (const auto& v : fn.vars) {
      if (!v.type.is_tile() && !v.type.is_fixed_array()) continue;
      auto layout = LayoutOf(v.type.elem(), module_.structs);
      int64_t n = layout.ok() ? layout->size : 8;
      for (int e : v.type.fixed_shape) n *= e;
      own += 2 * n;
    }
    std::function<void(const std::vector<Stmt>&)> walk = [&](const std::vector<Stmt>& stmts) {
      for (const auto& s : stmts) {
        if (s.kind == Stmt::Kind::kOp && s.op.callee >= 0 && s.op.callee < static_cast<int>(module_.functions.size()))
          callees = std::max(callees, module_.functions[s.op.callee].local_value_bytes);
        walk(s.then_body);
        walk(s.else_body);
        walk(s.cond_body);
        walk(s.body);
      }
    };
    walk(fn.body);
    fn.local_value_bytes = own + callees;
    if (fn.local_value_bytes > kMaxLocalValueBytes)
      return finish_error(Error(pf.def->loc, "the tiles and fixed-size arrays of '" + fs.name + "' and the funcs it calls take " +
                                                 std::to_string(fn.local_value_bytes) + " bytes of the thread's memory, "
                                                 "adjoints included (at most " + std::to_string(kMaxLocalValueBytes) + ")"));
    if (fn.is_kernel && lanes_ > 1 && fn.local_value_bytes * lanes_ > kMaxLaneBlockValueBytes)
      return finish_error(Error(pf.def->loc, "with cooperative CPU blocks of " + std::to_string(lanes_) + " threads, the tiles "
                                                 "and fixed-size arrays of '" + fs.name + "' take " +
                                                 std::to_string(fn.local_value_bytes) + " bytes per thread, " +
                                                 std::to_string(fn.local_value_bytes * lanes_) + " per block (at most " +
                                                 std::to_string(kMaxLaneBlockValueBytes) + "): use a smaller block_dim or "
                                                 "smaller tiles"));
  }

  st_ = saved;
  in_progress_.erase(inst);
  fn.function_id = static_cast<int>(module_.functions.size());
  fn.cpp_name = (fn.is_kernel ? "weft_kernel_" : "weft_func_") + codegen::MangleIdentifier(fs.name) + "_" +
                std::to_string(fn.function_id);
  const std::vector<Type> returns = fn.returns;
  int index = static_cast<int>(module_.functions.size());
  module_.functions.push_back(std::move(fn));
  instances_[inst] = index;

  // A custom gradient (wp.func_grad) of this func: instantiated with the func's parameter
  // types followed by its return types (the adjoints of the results), after the func itself,
  // so that the gradient may call the func (Warp's adj_sigmoid calling sigmoid). Codegen
  // emits every forward function before any adjoint, so the func's adjoint sees it.
  if (!fs.is_kernel && grad_of_params < 0) {
    auto g = by_key_.find(key + "__custom_grad");
    if (g != by_key_.end()) {
      std::vector<Type> gtypes = param_types;
      for (const auto& t : returns) gtypes.push_back(t);
      if (g->second->def->params.size() != gtypes.size())
        return Error(g->second->def->loc, "the gradient of '" + fs.name + "' must take its " +
                                              std::to_string(param_types.size()) + " parameters and " +
                                              std::to_string(returns.size()) + " adjoint(s) of its return value(s)");
      auto gi = InstantiateFunction(*g->second, gtypes, g->second->def->loc, static_cast<int>(param_types.size()));
      if (!gi.ok()) return gi.status();
      module_.functions[index].custom_grad = *gi;
    }
    // A custom replay (wp.func_replay): same parameters and results as the func; the func's
    // replay twin calls it (it runs with its side effects: recomputing is its job).
    auto r = by_key_.find(key + "__custom_replay");
    if (r != by_key_.end()) {
      if (r->second->def->params.size() != param_types.size())
        return Error(r->second->def->loc, "the replay function of '" + fs.name + "' must take its " +
                                              std::to_string(param_types.size()) + " parameters");
      auto ri = InstantiateFunction(*r->second, param_types, r->second->def->loc);
      if (!ri.ok()) return ri.status();
      if (module_.functions[*ri].returns != returns)
        return Error(r->second->def->loc, "the replay function of '" + fs.name +
                                              "' must return what the func returns");
      module_.functions[index].custom_replay = *ri;
      if (module_.functions[*ri].may_fail) module_.functions[index].may_fail = true;
    }
  }
  return index;
}

// ---------------------------------------------------------------------------------------
// Emission helpers
// ---------------------------------------------------------------------------------------

int Checker::NewVar(const Type& t, const std::string& hint, bool is_mutable) {
  Var v;
  v.id = static_cast<int>(st_->fn.vars.size());
  v.type = t;
  v.hint = hint;
  v.is_mutable = is_mutable;
  st_->fn.vars.push_back(v);
  return v.id;
}

void Checker::Push(Stmt s) {
  s.line = st_->line;
  st_->block->push_back(std::move(s));
}

int Checker::EmitOp(OpKind kind, const Type& dst_type, std::vector<int> args, std::string text) {
  Stmt s;
  s.op.kind = kind;
  s.op.args = std::move(args);
  s.op.text = std::move(text);
  int d = -1;
  if (!dst_type.is_void()) {
    d = NewVar(dst_type);
    s.op.dst.push_back(d);
  }
  Push(std::move(s));
  return d;
}

int Checker::EmitConst(const Type& t, const std::string& cpp_text) { return EmitOp(OpKind::kConst, t, {}, cpp_text); }

int Checker::EmitRaw(const Type& t, const std::string& text, std::vector<int> args) {
  return EmitOp(OpKind::kRaw, t, std::move(args), text);
}

void Checker::EmitCopy(int dst, int src) {
  Stmt s;
  s.op.kind = OpKind::kCopy;
  s.op.dst.push_back(dst);
  s.op.args.push_back(src);
  Push(std::move(s));
}

// ---------------------------------------------------------------------------------------
// Statements
// ---------------------------------------------------------------------------------------

bool Checker::MayExit(const ast::Stmt& s, bool nested_loop) const {
  switch (s.kind) {
    case ast::StmtKind::kBreak:
    case ast::StmtKind::kContinue: return !nested_loop;
    case ast::StmtKind::kReturn: return true;
    case ast::StmtKind::kIf: {
      const auto& i = static_cast<const ast::If&>(s);
      for (const auto& c : i.body)
        if (MayExit(*c, nested_loop)) return true;
      for (const auto& c : i.orelse)
        if (MayExit(*c, nested_loop)) return true;
      return false;
    }
    case ast::StmtKind::kFor:
      for (const auto& c : static_cast<const ast::For&>(s).body)
        if (MayExit(*c, true)) return true;
      return false;
    case ast::StmtKind::kWhile:
      for (const auto& c : static_cast<const ast::While&>(s).body)
        if (MayExit(*c, true)) return true;
      return false;
    default: return false;
  }
}

// A bool var that is true while no break/continue/return has happened (in this loop body).
int Checker::ExitFlagsGuard() {
  std::vector<int> flags{st_->fn.return_flag};
  if (!st_->loops.empty()) {
    flags.push_back(st_->loops.back().break_flag);
    flags.push_back(st_->loops.back().continue_flag);
  }
  std::string text = "!(";
  for (size_t i = 0; i < flags.size(); ++i) text += (i ? " || $" : "$") + std::to_string(i);
  return EmitRaw(Type::Bool(), text + ")", flags);
}

Status Checker::LowerBlock(const ast::StmtList& stmts, size_t from) {
  for (size_t i = from; i < stmts.size(); ++i) {
    WEFT_RETURN_IF_ERROR(LowerStmt(*stmts[i]));
    if (i + 1 < stmts.size() && MayExit(*stmts[i], false)) {
      st_->line = static_cast<int>(stmts[i + 1]->loc.line);
      int go = ExitFlagsGuard();
      return LowerIf(go, [&]() { return LowerBlock(stmts, i + 1); }, nullptr);
    }
  }
  return Status::Ok();
}

Status Checker::BindLocal(const std::string& name, int var, const SourceLocation& loc) {
  auto it = st_->scope.find(name);
  // In the function's own block (not inside an if, for or while) a name may be bound again to
  // a value of another type, as in Warp: straight-line code has no path to merge. Inside a
  // compound statement a variable keeps one type.
  if (it != st_->scope.end() && TypeOf(it->second) != TypeOf(var) && st_->block != &st_->fn.body)
    return Error(loc, "'" + name + "' has type " + TypeString(TypeOf(it->second)) + "; cannot assign a value of type " +
                          TypeString(TypeOf(var)) + " inside a branch or loop (a variable keeps one type there, as in Warp)");
  if (it != st_->scope.end() && TypeOf(it->second) != TypeOf(var)) st_->literal_locals.erase(name);
  if (st_->fn.vars[var].is_mutable) {  // never alias a slot that changes later
    int copy = NewVar(TypeOf(var), name);
    EmitCopy(copy, var);
    var = copy;
  }
  if (st_->fn.vars[var].hint.empty()) st_->fn.vars[var].hint = name;
  auto ap = st_->array_param.find(var);
  (void)ap;
  st_->scope[name] = var;
  return Status::Ok();
}

// A bug of the checker (an exception: std::out_of_range, bad_alloc, ...) must never reach
// the user without a location: it becomes an error at the statement being lowered.
namespace {
// Tuple / function bindings changed by a compound statement: same elements / target, or not.
bool SameBinding(const Value& a, const Value& b) {
  if (a.kind != b.kind || a.name != b.name || a.elems.size() != b.elems.size()) return false;
  for (size_t i = 0; i < a.elems.size(); ++i)
    if (a.elems[i].var != b.elems[i].var) return false;
  return true;
}
void MarkPathBound(const std::map<std::string, Value>& before, std::map<std::string, Value>* after,
                   std::set<std::string>* path_bound) {
  for (auto it = after->begin(); it != after->end();) {
    auto b = before.find(it->first);
    if (b == before.end() || !SameBinding(b->second, it->second)) {
      path_bound->insert(it->first);
      it = after->erase(it);
    } else {
      ++it;
    }
  }
}
}  // namespace

Status Checker::LowerStmt(const ast::Stmt& s) {
  st_->line = static_cast<int>(s.loc.line);
  if (s.kind == ast::StmtKind::kIf || s.kind == ast::StmtKind::kFor || s.kind == ast::StmtKind::kWhile) {
    const auto tuples = st_->tuple_scope;
    const auto funcs = st_->func_scope;
    const auto aliases = st_->tile_aliases;
    Status r = LowerStmt2(s);
    if (st_) {
      MarkPathBound(tuples, &st_->tuple_scope, &st_->path_bound);
      MarkPathBound(funcs, &st_->func_scope, &st_->path_bound);
      // a view bound on one path only is a plain value after the statement
      for (auto it = st_->tile_aliases.begin(); it != st_->tile_aliases.end();) {
        auto before = aliases.find(it->first);
        if (before == aliases.end() || !(before->second == it->second)) it = st_->tile_aliases.erase(it);
        else ++it;
      }
    }
    return r;
  }
  return LowerStmt2(s);
}

Status Checker::LowerStmt2(const ast::Stmt& s) {
  try {
    return LowerStmtUnguarded(s);
  } catch (const std::exception& e) {
    return Error(s.loc, std::string("weft cannot compile this statement (internal compiler error: ") + e.what() +
                            "; please report it)");
  }
}

Status Checker::LowerStmtUnguarded(const ast::Stmt& s) {
  switch (s.kind) {
    case ast::StmtKind::kFunctionDef: return Error(s.loc, "nested function definitions are not supported in kernels");
    case ast::StmtKind::kAssign: {
      const auto& a = static_cast<const ast::Assign&>(s);
      last_tile_view_.result = -1;
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*a.value));
      const auto view = last_tile_view_;
      for (const auto& t : a.targets) WEFT_RETURN_IF_ERROR(LowerAssignTo(*t, v));
      // `row = t[i]`, `v = wp.tile_view(t, ...)`: the name aliases the view of the tile local
      const ast::Name* base = ViewedTileName(*a.value);
      if (base && a.targets.size() == 1 && v.kind == Value::Kind::kVar && v.var == view.result) {
        const auto* n = ast::As<ast::Name>(a.targets[0].get());
        auto b = st_->scope.find(base->id);
        const bool base_is_view = st_->tile_aliases.count(base->id) > 0;
        if (n && n->id != base->id && b != st_->scope.end() && (b->second == view.base || base_is_view))
          st_->tile_aliases[n->id] = TileAlias{base->id, TypeOf(v.var), view.region};
      }
      // `x = 0` (an untyped literal; Warp's constant local, not a place wp.ref can take)
      const ast::Expr* lit = a.value.get();
      if (const auto* u = ast::As<ast::UnaryOp>(lit); u && u->op == ast::UnaryOperator::kMinus) lit = u->operand.get();
      const auto* c = ast::As<ast::Constant>(lit);
      const bool untyped = c && (c->type == ast::Constant::Type::kInt || c->type == ast::Constant::Type::kFloat);
      for (const auto& t : a.targets)
        if (const auto* n = ast::As<ast::Name>(t.get())) {
          if (untyped) st_->untyped_literal_names[n->id] = ExprText(*a.value);
          else st_->untyped_literal_names.erase(n->id);
        }
      return Status::Ok();
    }
    case ast::StmtKind::kAnnAssign: {
      const auto& a = static_cast<const ast::AnnAssign&>(s);
      WEFT_ASSIGN_OR_RETURN(Type t, EvalTypeExpr(*a.annotation));
      if (!a.value) {
        int v = NewVar(t);
        Stmt z;
        z.op.kind = OpKind::kConstruct;
        z.op.mode = ConstructMode::kZero;
        z.op.dst.push_back(v);
        Push(std::move(z));
        return LowerAssignTo(*a.target, Value::OfVar(v));
      }
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*a.value));
      WEFT_ASSIGN_OR_RETURN(int c, Coerce(v, t, a.value->loc, "the annotated value"));
      return LowerAssignTo(*a.target, Value::OfVar(c));
    }
    case ast::StmtKind::kAugAssign: {
      const auto& a = static_cast<const ast::AugAssign&>(s);
      if (const auto* n = ast::As<ast::Name>(a.target.get())) st_->untyped_literal_names.erase(n->id);
      // arr[i][j] op= v, arr[i].x op= v: a component of an array element (Warp's composite-slot
      // atomics), for the same operators; see LowerComponentAtomic.
      {
        WEFT_ASSIGN_OR_RETURN(bool lowered, LowerComponentAtomic(a));
        if (lowered) return Status::Ok();
      }
      // arr[i] += v / -= v are atomic adds (Warp's rule), so parallel threads may accumulate;
      // &=, |=, ^= on integer elements (scalars, integer vectors/matrices) are atomic and/or/xor.
      const bool bitwise_op = a.op == ast::BinaryOperator::kBitAnd || a.op == ast::BinaryOperator::kBitOr ||
                              a.op == ast::BinaryOperator::kBitXor;
      bool struct_tile_element = false;   // t[i] op= s on a tile of structs
      bool tile_element = false;          // t[i] op= s
      if (const auto* sub = ast::As<ast::Subscript>(a.target.get())) {
        WEFT_ASSIGN_OR_RETURN(Value base, Eval(*sub->value));
        if (base.kind == Value::Kind::kVar && TypeOf(base.var).is_tile()) {   // t[i, j] += v only (Warp)
          tile_element = true;
          struct_tile_element = TypeOf(base.var).elem().is_struct();
          if (struct_tile_element && bitwise_op)
            return ErrorOf("type", a.loc, "Tile bitwise inplace operators do not support Warp struct tile elements");
          bool any_slice = false;
          for (const auto& e : sub->indices) any_slice |= ast::As<ast::Slice>(e.get()) != nullptr;
          if (any_slice || static_cast<int>(sub->indices.size()) != TypeOf(base.var).ndim)
            return ErrorOf("value", a.loc, "Compound assignment to a tile view is not supported: write t[...] = t[...] " +
                                               std::string("+ v, or update the whole tile"));
        }
        const bool bitwise = bitwise_op;
        const bool integer_elem = base.kind == Value::Kind::kVar && TypeOf(base.var).is_array() &&
                                  (TypeOf(base.var).elem().is_scalar() || TypeOf(base.var).elem().is_vector() ||
                                   TypeOf(base.var).elem().is_matrix()) &&
                                  IsInt(TypeOf(base.var).elem().scalar);
        if (base.kind == Value::Kind::kVar && TypeOf(base.var).is_array() &&
            (a.op == ast::BinaryOperator::kAdd || a.op == ast::BinaryOperator::kSub || (bitwise && integer_elem))) {
          const Type at = TypeOf(base.var);
          if (static_cast<int>(sub->indices.size()) != at.ndim)
            return Error(a.loc, "array '" + ExprText(*sub->value) + "' has " + std::to_string(at.ndim) +
                                    " dimensions but " + std::to_string(sub->indices.size()) + " indices were given");
          std::vector<Value> args{base};
          WEFT_RETURN_IF_ERROR(EvalSlotIndices(sub->indices, &args));
          WEFT_ASSIGN_OR_RETURN(Value val, Eval(*a.value));
          WEFT_ASSIGN_OR_RETURN(int cv, Coerce(val, at.elem(), a.value->loc,
                                               bitwise ? "the value combined with the array element"
                                                       : "the value added to the array"));
          args.push_back(Value::OfVar(cv));
          WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin(AtomicBuiltinOf(a.op), std::move(args), a.loc, ArrayParamOf(base.var),
                                                                 ExprText(*sub->value)));
          (void)r;
          return Status::Ok();
        }
      }
      ast::BinOp synthetic;
      synthetic.loc = a.loc;
      synthetic.op = a.op;
      // Evaluate `target op value` without re-parsing: borrow the nodes through a non-owning view.
      store_target_ = true;   // the target's array subscripts are element writes
      Expected<Value> lhs_or = Eval(*a.target);
      store_target_ = false;
      WEFT_ASSIGN_OR_RETURN(Value lhs, std::move(lhs_or));
      WEFT_ASSIGN_OR_RETURN(Value rhs, Eval(*a.value));
      if (bitwise_op && lhs.kind == Value::Kind::kVar && TypeOf(lhs.var).is_tile() && TypeOf(lhs.var).elem().is_struct())
        return ErrorOf("type", a.loc, "Tile bitwise inplace operators do not support Warp struct tile elements");
      static const std::map<ast::BinaryOperator, std::string> kNames = {
          {ast::BinaryOperator::kAdd, "add"},        {ast::BinaryOperator::kSub, "sub"},
          {ast::BinaryOperator::kMul, "mul"},        {ast::BinaryOperator::kMatMul, "mul"},
          {ast::BinaryOperator::kDiv, "div"},        {ast::BinaryOperator::kFloorDiv, "floordiv"},
          {ast::BinaryOperator::kMod, "mod"},        {ast::BinaryOperator::kPow, "pow"},
          {ast::BinaryOperator::kLShift, "lshift"},  {ast::BinaryOperator::kRShift, "rshift"},
          {ast::BinaryOperator::kBitOr, "bit_or"},   {ast::BinaryOperator::kBitXor, "bit_xor"},
          {ast::BinaryOperator::kBitAnd, "bit_and"},
      };
      const bool saved_struct_arithmetic = struct_arithmetic_;
      struct_arithmetic_ = struct_tile_element;
      Expected<Value> r_or = ResolveAndEmitBuiltin(kNames.at(a.op), {lhs, rhs}, a.loc);
      struct_arithmetic_ = saved_struct_arithmetic;
      WEFT_ASSIGN_OR_RETURN(Value r, std::move(r_or));
      if (r.kind == Value::Kind::kVar && lhs.kind == Value::Kind::kVar && TypeOf(r.var) != TypeOf(lhs.var))
        return Error(a.loc, std::string("'") + ast::Spelling(a.op) + "=' would change the type of '" +
                                ExprText(*a.target) + "' from " + TypeString(TypeOf(lhs.var)) + " to " +
                                TypeString(TypeOf(r.var)));
      slot_store_emitted_ = false;
      if (const auto* n = ast::As<ast::Name>(a.target.get());
          n && r.kind == Value::Kind::kVar && (st_->tile_aliases.count(n->id) || TypeOf(r.var).is_tile()))
        write_through_ = true;   // `t += x` on a tile updates it in place (its views see it)
      if (lanes_ > 1 && tile_element &&
          (a.op == ast::BinaryOperator::kAdd || a.op == ast::BinaryOperator::kSub || bitwise_op)) {
        lane_update_.active = true;   // combine every lane's v (TileUpdate)
        lane_update_.op = a.op;
        lane_update_.value = rhs;
      }
      Status assigned = LowerAssignTo(*a.target, r);
      lane_update_.active = false;
      WEFT_RETURN_IF_ERROR(assigned);
      // `a[i].x *= v` (any operator but + - & | ^) on a differentiable slot of an array element:
      // its adjoint would need the slot's value before the update, which the replay no longer
      // has. Warp refuses it when the module generates adjoints; so does weft.
      const bool passes_gradient = a.op == ast::BinaryOperator::kAdd || a.op == ast::BinaryOperator::kSub ||
                                   a.op == ast::BinaryOperator::kBitAnd || a.op == ast::BinaryOperator::kBitOr ||
                                   a.op == ast::BinaryOperator::kBitXor;
      if (slot_store_emitted_ && !passes_gradient && r.kind == Value::Kind::kVar && IsDifferentiable(TypeOf(r.var)) &&
          st_->fn.no_adjoint.message.empty()) {
        Diagnostic& d = st_->fn.no_adjoint;
        d.location = a.loc;
        d.message = "Differentiable composite slot augmented assignments with this operator are not supported with "
                    "backward code generation enabled ('" + ExprText(*a.target) + " " + ast::Spelling(a.op) +
                    "= ...'). Write the result to a separate array, or use enable_backward=False for "
                    "forward-only code.";
        int rel = static_cast<int>(a.loc.line) - st_->fn.def_line;
        if (rel >= 0 && rel < static_cast<int>(st_->source_lines.size())) d.source_line = st_->source_lines[rel];
      }
      return Status::Ok();
    }
    case ast::StmtKind::kIf: {
      const auto& i = static_cast<const ast::If&>(s);
      WEFT_ASSIGN_OR_RETURN(int c, EvalCond(*i.test));
      return LowerIf(c, [&]() { return LowerBlock(i.body); },
                     i.orelse.empty() ? std::function<Status()>() : [&]() { return LowerBlock(i.orelse); });
    }
    case ast::StmtKind::kFor: return LowerFor(static_cast<const ast::For&>(s));
    case ast::StmtKind::kWhile: return LowerWhile(static_cast<const ast::While&>(s));
    case ast::StmtKind::kBreak:
    case ast::StmtKind::kContinue: {
      if (st_->loops.empty())
        return Error(s.loc, std::string("'") + (s.kind == ast::StmtKind::kBreak ? "break" : "continue") +
                                "' outside a loop");
      int flag = s.kind == ast::StmtKind::kBreak ? st_->loops.back().break_flag : st_->loops.back().continue_flag;
      Stmt set;
      set.op.kind = OpKind::kConst;
      set.op.dst.push_back(flag);
      set.op.text = "true";
      Push(std::move(set));
      return Status::Ok();
    }
    case ast::StmtKind::kReturn: return LowerReturn(static_cast<const ast::Return&>(s));
    case ast::StmtKind::kExprStmt: {
      const auto& e = static_cast<const ast::ExprStmt&>(s);
      if (ast::As<ast::Constant>(e.value.get())) return Status::Ok();  // stray docstring / literal
      WEFT_ASSIGN_OR_RETURN(Value v, Eval(*e.value));
      (void)v;
      return Status::Ok();
    }
    case ast::StmtKind::kPass: return Status::Ok();
    case ast::StmtKind::kAssert: {
      // Warp checks asserts only in debug builds; weft type-checks the test and emits nothing.
      const auto& a = static_cast<const ast::Assert&>(s);
      WEFT_ASSIGN_OR_RETURN(int c, EvalCond(*a.test));
      (void)c;
      return Status::Ok();
    }
  }
  return Error(s.loc, "unsupported statement");
}

Status Checker::LowerAssignTo(const ast::Expr& target, Value value) {
  const SourceLocation& loc = target.loc;
  const bool slot_store = slot_store_;   // `value` is an element updated by a component write
  slot_store_ = false;
  const bool write_through = write_through_;   // an update in place (see write_through_)
  write_through_ = false;
  // The base of a component or field write: an array element loaded there is a slot load.
  auto eval_slot_base = [&](const ast::Expr& e) {
    slot_target_ = true;
    Expected<Value> v = Eval(e);
    slot_target_ = false;
    return v;
  };
  // Lowers the write of `updated` (the base with one component or field replaced).
  auto assign_updated = [&](const ast::Expr& e, int updated) {
    slot_store_ = true;
    write_through_ = true;
    return LowerAssignTo(e, Value::OfVar(updated));
  };
  if (const auto* n = ast::As<ast::Name>(&target)) {
    if (auto alias = st_->tile_aliases.find(n->id); alias != st_->tile_aliases.end()) {
      const TileAlias a = alias->second;
      if (write_through && value.kind == Value::Kind::kVar && TypeOf(value.var) == a.view)
        return WriteThroughAlias(n->id, a, value.var, loc);
      st_->tile_aliases.erase(alias);   // rebound: no longer a view
    }
    if (value.kind == Value::Kind::kTuple) {
      // A tuple value (Warp's tuples): the name stands for its elements (len(), t[i], unpacking,
      // passing to a func's tuple or Any parameter).
      if (st_->scope.count(n->id))
        return Error(loc, "'" + n->id + "' holds a single value; it cannot be rebound to a tuple");
      Value t;
      t.kind = Value::Kind::kTuple;
      for (const Value& e : value.elems) {
        if (e.kind != Value::Kind::kVar || TypeOf(e.var).is_void())
          return Error(loc, "a tuple assigned to '" + n->id + "' must hold runtime values");
        Value x = e;
        if (st_->fn.vars[e.var].is_mutable) {
          int copy = NewVar(TypeOf(e.var), n->id);
          EmitCopy(copy, e.var);
          x = Value::OfVar(copy);
        }
        t.elems.push_back(x);
      }
      st_->tuple_scope[n->id] = std::move(t);
      st_->path_bound.erase(n->id);
      return Status::Ok();
    }
    if (value.kind == Value::Kind::kFunc || value.kind == Value::Kind::kBuiltin || value.kind == Value::Kind::kType) {
      if (st_->scope.count(n->id))
        return Error(loc, "'" + n->id + "' holds a value; it cannot be rebound to a " +
                              (value.kind == Value::Kind::kType ? "type" : "function"));
      st_->func_scope[n->id] = value;
      st_->path_bound.erase(n->id);
      return Status::Ok();
    }
    if (value.kind != Value::Kind::kVar) {
      return Error(loc, "'" + n->id + "' cannot hold " +
                            (value.kind == Value::Kind::kType ? "a type" : std::string("this value")) +
                            " (only runtime values can be assigned)");
    }
    if (TypeOf(value.var).is_void()) return Error(loc, "cannot assign the result of a function that returns nothing");
    // An assigned literal takes its default type (int32 / float32); keep the var. A name
    // assigned only once, from a numeric literal, stays usable as that literal where Warp
    // takes constants (typed constructors, constant integer indices and slice bounds).
    if (!write_through) {
      // A tile rebound with `=`: the names viewing it keep viewing the tile they were bound to,
      // now as values of their own (Python names; Warp's views keep their storage).
      for (auto it = st_->tile_aliases.begin(); it != st_->tile_aliases.end();) {
        if (it->second.base != n->id) {
          ++it;
          continue;
        }
        const std::string viewer = it->first;
        const TileAlias dep = it->second;
        WEFT_ASSIGN_OR_RETURN(Value now, ViewOfAlias(dep, loc));
        WEFT_RETURN_IF_ERROR(BindLocal(viewer, now.var, loc));
        it = st_->tile_aliases.find(viewer);
        it = st_->tile_aliases.erase(it);
      }
    }
    WEFT_RETURN_IF_ERROR(BindLocal(n->id, value.var, loc));
    auto count = st_->assign_counts.find(n->id);
    if (value.literal && count != st_->assign_counts.end() && count->second == 1)
      st_->literal_locals[n->id] = {st_->scope[n->id], value.literal_text};
    return Status::Ok();
  }
  if (const auto* t = ast::As<ast::Tuple>(&target)) {
    if (value.kind == Value::Kind::kVar && value.name == "__tid") {  // i, j = wp.tid()
      if (t->elts.size() > 4) return Error(loc, "wp.tid() has at most 4 dimensions");
      for (size_t k = 0; k < t->elts.size(); ++k) {
        int v = EmitRaw(Type::Int32(), "wp::int32(__tid[" + std::to_string(k) + "])", {});
        WEFT_RETURN_IF_ERROR(LowerAssignTo(*t->elts[k], Value::OfVar(v)));
      }
      return Status::Ok();
    }
    if (value.kind != Value::Kind::kTuple)
      return Error(loc, "cannot unpack a single value into " + std::to_string(t->elts.size()) + " names");
    if (value.elems.size() != t->elts.size())
      return Error(loc, "cannot unpack " + std::to_string(value.elems.size()) + " values into " +
                            std::to_string(t->elts.size()) + " targets");
    for (size_t i = 0; i < t->elts.size(); ++i) WEFT_RETURN_IF_ERROR(LowerAssignTo(*t->elts[i], value.elems[i]));
    return Status::Ok();
  }
  if (value.kind != Value::Kind::kVar) return Error(loc, "only runtime values can be stored");
  struct StoreTarget {   // the target's own subscripts are element writes (index reads reset it)
    bool* flag;
    bool saved;
    ~StoreTarget() { *flag = saved; }
  } store_guard{&store_target_, store_target_};
  store_target_ = true;
  if (const auto* sub = ast::As<ast::Subscript>(&target)) {
    WEFT_ASSIGN_OR_RETURN(Value base, eval_slot_base(*sub->value));
    if (base.kind == Value::Kind::kBuiltin && base.name == "adjoint")  // wp.adjoint[x] = ...
      return AssignAdjoint(*sub, value);
    if (base.kind != Value::Kind::kVar) return Error(loc, "cannot assign to an element of '" + ExprText(*sub->value) + "'");
    const Type bt = TypeOf(base.var);
    if (bt.is_tile()) {   // t[i, j] = v, t[i] = row, t[a:b, :] = block
      WEFT_ASSIGN_OR_RETURN(int updated, TileUpdate(*sub, base, value));
      return assign_updated(*sub->value, updated);
    }
    SliceRegion region;
    if (!bt.is_array()) {
      WEFT_ASSIGN_OR_RETURN(bool sliced, SliceRegionOf(*sub, bt, &region));
      if (sliced) {
        // v[a:b] = w, m[i, a:b] = w, m[a:b, c:d] = n: component by component (Extract + Insert,
        // so the adjoint flows through each component)
        const Type vt = TypeOf(value.var);
        if (vt != region.shape) return ErrorOf("value", loc, SliceAssignMismatch(vt, region.shape));
        const bool matrix_value = region.shape.is_matrix();
        int updated = base.var;
        for (size_t k = 0; k < region.components.size(); ++k) {
          std::vector<int> src{value.var};
          if (matrix_value) {
            src.push_back(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(k / region.shape.cols) + ")"));
            src.push_back(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(k % region.shape.cols) + ")"));
          } else {
            src.push_back(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(k) + ")"));
          }
          int x = EmitOp(OpKind::kExtract, Type::Scalar(bt.scalar), src);
          std::vector<int> args{updated};
          args.insert(args.end(), region.components[k].begin(), region.components[k].end());
          args.push_back(x);
          updated = EmitOp(OpKind::kInsert, bt, args);
        }
        return assign_updated(*sub->value, updated);
      }
    }
    WEFT_ASSIGN_OR_RETURN(std::vector<int> idx, EvalIndices(sub->indices, bt.is_array()));
    if (bt.is_array()) {
      if (static_cast<int>(idx.size()) != bt.ndim)
        return Error(loc, "array '" + ExprText(*sub->value) + "' has " + std::to_string(bt.ndim) +
                              " dimensions but " + std::to_string(idx.size()) + " indices were given");
      WEFT_ASSIGN_OR_RETURN(int v, Coerce(value, bt.elem(), loc, "the value stored into '" + ExprText(*sub->value) + "'"));
      Stmt s;
      s.op.kind = OpKind::kStore;
      s.op.args.push_back(base.var);
      for (int i : idx) s.op.args.push_back(i);
      s.op.args.push_back(v);
      s.op.array_param = ArrayParamOf(base.var);
      s.op.array_name = ExprText(*sub->value);
      s.op.slot = slot_store;
      slot_store_emitted_ |= slot_store;
      Push(std::move(s));
      st_->fn.may_fail = true;
      return Status::Ok();
    }
    Type comp;
    if (bt.is_vector() || bt.kind == TypeKind::kQuat || bt.kind == TypeKind::kTransform) {
      if (idx.size() != 1) return Error(loc, TypeString(bt) + " takes one index");
      comp = Type::Scalar(bt.scalar);
    } else if (bt.is_matrix()) {
      if (idx.size() == 2) comp = Type::Scalar(bt.scalar);
      else if (idx.size() == 1) comp = Type::Vector(bt.cols, bt.scalar);
      else return Error(loc, "a matrix takes one (row) or two indices");
    } else {
      return Error(loc, "cannot assign to an element of a value of type " + TypeString(bt));
    }
    for (int i : idx)
      if (!TypeOf(i).is_scalar() || !IsInt(TypeOf(i).scalar)) return Error(loc, "component indices must be integers");
    if (TypeOf(value.var).kind != comp.kind)   // Warp's TypeError for a composite slot write
      return ErrorOf("type", loc, "Composite slot assignment expects value of type `" + TypeString(comp) + "`, got `" +
                                      TypeString(TypeOf(value.var)) + "`");
    WEFT_ASSIGN_OR_RETURN(int v, Coerce(value, comp, loc, "the component value"));
    std::vector<int> args{base.var};
    for (int i : idx) args.push_back(i);
    args.push_back(v);
    int updated = EmitOp(OpKind::kInsert, bt, args);
    return assign_updated(*sub->value, updated);
  }
  if (const auto* at = ast::As<ast::Attribute>(&target)) {
    WEFT_ASSIGN_OR_RETURN(Value base, eval_slot_base(*at->value));
    if (base.kind != Value::Kind::kVar) return Error(loc, "cannot assign to '" + ExprText(target) + "'");
    const Type bt = TypeOf(base.var);
    if (bt.is_struct()) {
      const StructInfo& si = module_.structs.at(bt.struct_name);
      int fi = -1;
      const StructField* f = si.Find(at->attr, &fi);
      if (!f) return Error(at->attr_loc, "struct " + bt.struct_name + " has no field '" + at->attr + "'");
      WEFT_ASSIGN_OR_RETURN(int v, Coerce(value, f->type, loc, "the value of field '" + at->attr + "'"));
      int updated = EmitOp(OpKind::kSetField, bt, {base.var, v}, at->attr);
      st_->block->back().op.field_index = fi;
      if (ArrayParamOf(base.var) >= 0) st_->array_param[updated] = ArrayParamOf(base.var);
      return assign_updated(*at->value, updated);
    }
    if (bt.is_vector() || bt.kind == TypeKind::kQuat) {
      static const std::string kXYZW = "xyzw";
      size_t k = at->attr.size() == 1 ? kXYZW.find(at->attr[0]) : std::string::npos;
      if (k == std::string::npos || static_cast<int>(k) >= bt.component_count())
        return ErrorOf("attribute", at->attr_loc, "`" + at->attr + "` is not an attribute of '" + ExprText(*at->value) +
                                                      "' (" + TypeString(bt) + ")");
      if (!TypeOf(value.var).is_scalar())   // Warp's TypeError for a composite slot write
        return ErrorOf("type", loc, "Composite slot assignment expects value of type `" +
                                        TypeString(Type::Scalar(bt.scalar)) + "`, got `" + TypeString(TypeOf(value.var)) + "`");
      WEFT_ASSIGN_OR_RETURN(int v, Coerce(value, Type::Scalar(bt.scalar), loc, "the component value"));
      int ki = EmitConst(Type::Int32(), "wp::int32(" + std::to_string(k) + ")");
      int updated = EmitOp(OpKind::kInsert, bt, {base.var, ki, v});
      return assign_updated(*at->value, updated);
    }
    if (bt.kind == TypeKind::kTransform && (at->attr == "p" || at->attr == "q")) {
      // t.p = v / t.q = r: the translation's 3 or the rotation's 4 components, one by one
      // (component writes, with their adjoints).
      bool p = at->attr == "p";
      Type part = p ? Type::Vector(3, bt.scalar) : Type::Quat(bt.scalar);
      WEFT_ASSIGN_OR_RETURN(int v, Coerce(value, part, loc, p ? "the translation" : "the rotation"));
      int updated = base.var;
      for (int k = 0; k < (p ? 3 : 4); ++k) {
        int src = EmitConst(Type::Int32(), "wp::int32(" + std::to_string(k) + ")");
        int x = EmitOp(OpKind::kExtract, Type::Scalar(bt.scalar), {v, src});
        int dst = EmitConst(Type::Int32(), "wp::int32(" + std::to_string(p ? k : 3 + k) + ")");
        updated = EmitOp(OpKind::kInsert, bt, {updated, dst, x});
      }
      return assign_updated(*at->value, updated);
    }
    return Error(loc, "cannot assign to attribute '" + at->attr + "' of a value of type " + TypeString(bt));
  }
  return Error(loc, "cannot assign to this expression");
}

// The indices of an array element an atomic update writes, appended to `out` (Warp's
// TypeError for a float index).
Status Checker::EvalSlotIndices(const ast::ExprList& indices, std::vector<Value>* out) {
  for (const auto& ix : indices) {
    WEFT_ASSIGN_OR_RETURN(Value iv, Eval(*ix));
    if (iv.kind == Value::Kind::kVar && TypeOf(iv.var).is_scalar() && !IsInt(TypeOf(iv.var).scalar))
      return ErrorOf("type", ix->loc, "Array slot write indices must be integers, got `" +
                                          TypeString(TypeOf(iv.var)) + "`");
    out->push_back(iv);
  }
  return Status::Ok();
}

// `arr[i][j] += v`, `arr[i].x -= v`, `m_arr[i][r] &= row` (a component or a matrix row of an
// array element; arr may be wp.adjoint[a] or a struct's array field): one atomic on the whole
// element whose value is the operator's identity (zero, or all bits set for &=) with `v` in
// that component, so threads updating the same component of one element do not race (a plain
// read-modify-write would lose updates on a GPU). The adjoint flows through the insert: `v`
// gets the element gradient's component. Only 32/64-bit scalars (the widths with hardware
// atomics); other element types keep the read-modify-write. Returns false when `a` is not such
// an update.
Expected<bool> Checker::LowerComponentAtomic(const ast::AugAssign& a) {
  const bool bitwise = a.op == ast::BinaryOperator::kBitAnd || a.op == ast::BinaryOperator::kBitOr ||
                       a.op == ast::BinaryOperator::kBitXor;
  if (a.op != ast::BinaryOperator::kAdd && a.op != ast::BinaryOperator::kSub && !bitwise) return false;
  const ast::Subscript* element = nullptr;      // arr[i]
  const ast::ExprList* component = nullptr;     // [j] or [r, c]
  int attr_index = -1;                          // .x .y .z .w
  if (const auto* s1 = ast::As<ast::Subscript>(a.target.get())) {
    element = ast::As<ast::Subscript>(s1->value.get());
    component = &s1->indices;
  } else if (const auto* at = ast::As<ast::Attribute>(a.target.get())) {
    static const std::string kXYZW = "xyzw";
    element = ast::As<ast::Subscript>(at->value.get());
    if (at->attr.size() == 1 && kXYZW.find(at->attr[0]) != std::string::npos)
      attr_index = static_cast<int>(kXYZW.find(at->attr[0]));
    else
      element = nullptr;
  }
  if (element == nullptr) return false;
  WEFT_ASSIGN_OR_RETURN(Value arr, Eval(*element->value));
  if (arr.kind != Value::Kind::kVar || !TypeOf(arr.var).is_array()) return false;
  const Type at = TypeOf(arr.var);
  const Type et = at.elem();
  if (static_cast<int>(element->indices.size()) != at.ndim) return false;   // the generic path reports it
  if (!(et.is_vector() || et.is_matrix() || et.kind == TypeKind::kQuat)) return false;
  const ScalarKind sk = et.scalar;
  const int width = ScalarSize(sk);
  if (sk == ScalarKind::kBool || (width != 4 && width != 8) || (bitwise && !IsInt(sk))) return false;
  Type comp;
  size_t n_idx = attr_index >= 0 ? 1 : component->size();
  if (et.is_matrix()) {
    if (attr_index >= 0) return false;
    if (n_idx == 1) comp = Type::Vector(et.cols, sk);
    else if (n_idx == 2) comp = Type::Scalar(sk);
    else return false;
  } else {
    if (n_idx != 1) return false;
    if (attr_index >= et.component_count()) return false;
    comp = Type::Scalar(sk);
  }
  std::vector<Value> args{arr};
  WEFT_RETURN_IF_ERROR(EvalSlotIndices(element->indices, &args));
  std::vector<int> slot;
  if (attr_index >= 0) {
    slot.push_back(EmitConst(Type::Int32(), "wp::int32(" + std::to_string(attr_index) + ")"));
  } else {
    WEFT_ASSIGN_OR_RETURN(slot, EvalIndices(*component, false));
    for (int i : slot)
      if (!TypeOf(i).is_scalar() || !IsInt(TypeOf(i).scalar)) return Error(a.loc, "component indices must be integers");
  }
  WEFT_ASSIGN_OR_RETURN(Value val, Eval(*a.value));
  if (val.kind != Value::Kind::kVar || TypeOf(val.var).kind != comp.kind)   // Warp's TypeError
    return ErrorOf("type", a.loc, "Composite slot assignment expects value of type `" + TypeString(comp) + "`, got `" +
                                      (val.kind == Value::Kind::kVar ? TypeString(TypeOf(val.var)) : std::string("?")) + "`");
  WEFT_ASSIGN_OR_RETURN(int v, Coerce(val, comp, a.value->loc, "the component value"));
  const std::string identity = a.op == ast::BinaryOperator::kBitAnd
                                   ? CppType(et) + "((" + CppType(Type::Scalar(sk)) + ")~(" + CppType(Type::Scalar(sk)) + ")0)"
                                   : CppType(et) + "()";
  std::vector<int> insert{EmitConst(et, identity)};
  insert.insert(insert.end(), slot.begin(), slot.end());
  insert.push_back(v);
  args.push_back(Value::OfVar(EmitOp(OpKind::kInsert, et, insert)));
  WEFT_ASSIGN_OR_RETURN(Value r, ResolveAndEmitBuiltin(AtomicBuiltinOf(a.op), std::move(args), a.loc, ArrayParamOf(arr.var),
                                                         ExprText(*element->value)));
  (void)r;
  return true;
}

Status Checker::LowerIf(int cond, const std::function<Status()>& then_fn, const std::function<Status()>& else_fn) {
  Stmt s;
  s.kind = Stmt::Kind::kIf;
  s.cond = cond;
  s.line = st_->line;
  std::map<std::string, int> before = st_->scope;
  std::vector<Stmt>* outer = st_->block;
  int line = st_->line;

  st_->block = &s.then_body;
  Status ts = then_fn();
  std::map<std::string, int> then_scope = st_->scope;
  st_->scope = before;
  Status es = Status::Ok();
  if (ts.ok() && else_fn) {
    st_->block = &s.else_body;
    es = else_fn();
  }
  std::map<std::string, int> else_scope = st_->scope;
  st_->block = outer;
  st_->line = line;
  if (!ts.ok()) return ts;
  if (!es.ok()) return es;
  outer->push_back(std::move(s));

  std::set<std::string> names;
  for (const auto& [n, v] : then_scope) names.insert(n);
  for (const auto& [n, v] : else_scope) names.insert(n);
  std::map<std::string, int> merged;
  for (const auto& n : names) {
    auto t = then_scope.find(n);
    auto e = else_scope.find(n);
    if (t != then_scope.end() && e != else_scope.end()) {
      if (t->second == e->second) {
        merged[n] = t->second;
        continue;
      }
      if (TypeOf(t->second) != TypeOf(e->second)) {
        SourceLocation loc{st_->fn.file, static_cast<uint32_t>(line), 0};
        return Error(loc, "'" + n + "' has type " + TypeString(TypeOf(t->second)) + " in one branch and " +
                              TypeString(TypeOf(e->second)) + " in the other");
      }
      int phi = EmitOp(OpKind::kPhi, TypeOf(t->second), {cond, t->second, e->second});
      st_->fn.vars[phi].hint = n;
      int ap = ArrayParamOf(t->second);
      if (ap >= 0 && ap == ArrayParamOf(e->second)) st_->array_param[phi] = ap;
      merged[n] = phi;
    } else {
      merged[n] = t != then_scope.end() ? t->second : e->second;  // defined on one path only
    }
  }
  st_->scope = std::move(merged);
  return Status::Ok();
}

void CollectReboundNames(const ast::StmtList& body, std::set<std::string>* out) {
  std::function<void(const ast::Expr&)> target = [&](const ast::Expr& t) {
    if (const auto* n = ast::As<ast::Name>(&t)) out->insert(n->id);
    else if (const auto* tu = ast::As<ast::Tuple>(&t))
      for (const auto& e : tu->elts) target(*e);
  };
  for (const auto& sp : body) {
    const ast::Stmt& s = *sp;
    switch (s.kind) {
      case ast::StmtKind::kAssign:
        for (const auto& t : static_cast<const ast::Assign&>(s).targets) target(*t);
        break;
      case ast::StmtKind::kAnnAssign: target(*static_cast<const ast::AnnAssign&>(s).target); break;
      case ast::StmtKind::kIf:
        CollectReboundNames(static_cast<const ast::If&>(s).body, out);
        CollectReboundNames(static_cast<const ast::If&>(s).orelse, out);
        break;
      case ast::StmtKind::kFor:
        target(*static_cast<const ast::For&>(s).target);
        CollectReboundNames(static_cast<const ast::For&>(s).body, out);
        break;
      case ast::StmtKind::kWhile: CollectReboundNames(static_cast<const ast::While&>(s).body, out); break;
      default: break;
    }
  }
}

const ast::Name* ViewedTileName(const ast::Expr& value) {
  const ast::Expr* viewed = nullptr;
  if (const auto* sub = ast::As<ast::Subscript>(&value)) viewed = sub->value.get();
  if (const auto* call = ast::As<ast::Call>(&value); call && !call->args.empty()) {
    const auto* fa = ast::As<ast::Attribute>(call->func.get());
    const auto* fn = ast::As<ast::Name>(call->func.get());
    if ((fa && fa->attr == "tile_view") || (fn && fn->id == "tile_view")) viewed = call->args[0].get();
  }
  return viewed ? ast::As<ast::Name>(viewed) : nullptr;
}

void CollectTileViewBases(const ast::StmtList& body, std::map<std::string, std::set<std::string>>* out) {
  for (const auto& sp : body) {
    const ast::Stmt& s = *sp;
    if (s.kind == ast::StmtKind::kAssign) {
      const auto& a = static_cast<const ast::Assign&>(s);
      const ast::Name* base = ViewedTileName(*a.value);
      if (base)
        for (const auto& t : a.targets)
          if (const auto* n = ast::As<ast::Name>(t.get()); n && n->id != base->id) (*out)[n->id].insert(base->id);
    } else if (s.kind == ast::StmtKind::kIf) {
      CollectTileViewBases(static_cast<const ast::If&>(s).body, out);
      CollectTileViewBases(static_cast<const ast::If&>(s).orelse, out);
    } else if (s.kind == ast::StmtKind::kFor) {
      CollectTileViewBases(static_cast<const ast::For&>(s).body, out);
    } else if (s.kind == ast::StmtKind::kWhile) {
      CollectTileViewBases(static_cast<const ast::While&>(s).body, out);
    }
  }
}

void CollectAssignedNames(const ast::StmtList& stmts, std::set<std::string>* out) {
  std::map<std::string, int> counts;
  CountAssignedNames(stmts, &counts);
  for (const auto& [name, n] : counts) out->insert(name);
}

namespace {
// A name passed as an argument to a builtin that writes its arguments (query iterators,
// out-parameter forms: `while wp.hash_grid_query_next(q, index)`, `if wp.mesh_query_point(m,
// p, d, inside, face, u, v)`, or the call as a statement or assigned value) is assigned by that
// call: it is never a literal-valued local, even where it is read before the call in a loop.
void CountNamesWrittenByCall(const ast::Expr* e, std::map<std::string, int>* out) {
  if (e == nullptr) return;
  if (const auto* u = ast::As<ast::UnaryOp>(e)) return CountNamesWrittenByCall(u->operand.get(), out);
  const auto* call = ast::As<ast::Call>(e);
  if (call == nullptr) return;
  std::string name;
  if (const auto* n = ast::As<ast::Name>(call->func.get())) name = n->id;
  else if (const auto* a = ast::As<ast::Attribute>(call->func.get())) name = a->attr;
  if (const auto* written = TileWrittenArgs(name)) {   // tile forms that assign to arguments
    for (const auto& arg : *written) {
      const ast::Expr* target = TileWrittenTarget(*call, arg);
      while (target && !ast::As<ast::Name>(target)) {
        if (const auto* sub = ast::As<ast::Subscript>(target)) target = sub->value.get();
        else if (const auto* at = ast::As<ast::Attribute>(target)) target = at->value.get();
        else target = nullptr;
      }
      if (target) ++(*out)[ast::As<ast::Name>(target)->id];
    }
    return;
  }
  bool writes = false;
  for (const auto* o : BuiltinRegistry::Get().Overloads(name)) writes = writes || (o->flags & kBuiltinWritesArgs);
  if (!writes) return;
  for (const auto& arg : call->args)
    if (const auto* n = ast::As<ast::Name>(arg.get())) ++(*out)[n->id];
}
}  // namespace

void CountAssignedNames(const ast::StmtList& stmts, std::map<std::string, int>* out) {
  std::function<void(const ast::Expr&)> target = [&](const ast::Expr& t) {
    if (const auto* n = ast::As<ast::Name>(&t)) ++(*out)[n->id];
    else if (const auto* tu = ast::As<ast::Tuple>(&t)) {
      for (const auto& e : tu->elts) target(*e);
    } else if (const auto* s = ast::As<ast::Subscript>(&t)) target(*s->value);
    else if (const auto* a = ast::As<ast::Attribute>(&t)) target(*a->value);
  };
  for (const auto& sp : stmts) {
    const ast::Stmt& s = *sp;
    switch (s.kind) {
      case ast::StmtKind::kAssign:
        for (const auto& t : static_cast<const ast::Assign&>(s).targets) target(*t);
        CountNamesWrittenByCall(static_cast<const ast::Assign&>(s).value.get(), out);
        break;
      case ast::StmtKind::kExprStmt: CountNamesWrittenByCall(static_cast<const ast::ExprStmt&>(s).value.get(), out); break;
      case ast::StmtKind::kAnnAssign: target(*static_cast<const ast::AnnAssign&>(s).target); break;
      case ast::StmtKind::kAugAssign: target(*static_cast<const ast::AugAssign&>(s).target); break;
      case ast::StmtKind::kIf:
        CountNamesWrittenByCall(static_cast<const ast::If&>(s).test.get(), out);
        CountAssignedNames(static_cast<const ast::If&>(s).body, out);
        CountAssignedNames(static_cast<const ast::If&>(s).orelse, out);
        break;
      case ast::StmtKind::kFor:
        target(*static_cast<const ast::For&>(s).target);
        CountAssignedNames(static_cast<const ast::For&>(s).body, out);
        break;
      case ast::StmtKind::kWhile:
        CountNamesWrittenByCall(static_cast<const ast::While&>(s).test.get(), out);
        CountAssignedNames(static_cast<const ast::While&>(s).body, out);
        break;
      default: break;
    }
  }
}

namespace {

// Shared loop scaffolding: carried slots before the body, flags, loop-back values after.
struct LoopBuilder {
  Checker* c;
  Stmt loop;
  std::vector<std::pair<std::string, int>> carried;  // name, slot

  Status Begin(const ast::StmtList& body) {
    std::set<std::string> assigned;
    CollectAssignedNames(body, &assigned);
    auto* st = c->st_;
    // writing through a tile view assigns the tile it views (and what that views)
    for (bool grew = true; grew;) {
      grew = false;
      for (const auto& n : std::set<std::string>(assigned)) {
        auto v = st->view_bases.find(n);
        if (v == st->view_bases.end()) continue;
        for (const auto& b : v->second) grew |= assigned.insert(b).second;
      }
    }
    for (const auto& n : assigned) {
      auto it = st->scope.find(n);
      if (it == st->scope.end()) continue;
      int init = it->second;
      if (c->TypeOf(init).is_array()) continue;  // arrays are handles; element writes do not rebind
      int slot = c->NewVar(c->TypeOf(init), n, true);
      c->EmitCopy(slot, init);
      it->second = slot;
      int ap = c->ArrayParamOf(init);
      if (ap >= 0) st->array_param[slot] = ap;
      carried.emplace_back(n, slot);
      loop.carried.push_back({slot, init, -1});
    }
    loop.kind = Stmt::Kind::kLoop;
    loop.line = st->line;
    loop.break_flag = c->NewVar(Type::Bool(), "brk", true);
    loop.continue_flag = c->NewVar(Type::Bool(), "cont", true);
    loop.return_flag = st->fn.return_flag;
    loop.counter = c->NewVar(Type::Scalar(ScalarKind::kInt64), "trips", true);
    return Status::Ok();
  }

  Status Body(const ast::StmtList& body) {
    auto* st = c->st_;
    std::vector<Stmt>* outer = st->block;
    st->block = &loop.body;
    st->loops.push_back({loop.break_flag, loop.continue_flag});
    Status s = c->LowerBlock(body);
    if (s.ok()) {
      for (size_t i = 0; i < carried.size(); ++i) {
        int next = st->scope.at(carried[i].first);
        if (c->TypeOf(next) != c->TypeOf(carried[i].second)) {
          s = c->Error({st->fn.file, static_cast<uint32_t>(loop.line), 0},
                       "'" + carried[i].first + "' changes type inside the loop");
          break;
        }
        if (next != carried[i].second && st->fn.vars[next].is_mutable) {  // keep loop-back copies parallel
          int tmp = c->NewVar(c->TypeOf(next), carried[i].first);
          c->EmitCopy(tmp, next);
          next = tmp;
        }
        loop.carried[i].next = next;
      }
    }
    st->loops.pop_back();
    st->block = outer;
    if (!s.ok()) return s;
    for (const auto& [n, slot] : carried) st->scope[n] = slot;
    st->block->push_back(std::move(loop));
    return Status::Ok();
  }
};

}  // namespace

Status Checker::LowerFor(const ast::For& s) {
  const auto* tn = ast::As<ast::Name>(s.target.get());
  if (!tn) return Error(s.target->loc, "a for loop needs a single name as its target: for i in range(...)");
  const auto* call = ast::As<ast::Call>(s.iter.get());
  const auto* fname = call ? ast::As<ast::Name>(call->func.get()) : nullptr;
  // reversed(range(...)): the same values, last first (Python's semantics)
  bool reversed = false;
  if (fname && fname->id == "reversed" && !st_->scope.count("reversed") && call->args.size() == 1 &&
      call->keywords.empty()) {
    reversed = true;
    call = ast::As<ast::Call>(call->args[0].get());
    fname = call ? ast::As<ast::Name>(call->func.get()) : nullptr;
  }
  if (!reversed && !(call && fname && fname->id == "range" && !st_->scope.count("range"))) {
    // for index in wp.hash_grid_query(...) / wp.bvh_query_*(...) / wp.mesh_query_aabb(...),
    // or over a query held in a variable:
    // index = 0; while <query>_next(q, index): body
    WEFT_ASSIGN_OR_RETURN(Value qv, Eval(*s.iter));
    const char* next = nullptr;
    if (qv.kind == Value::Kind::kVar && TypeOf(qv.var).is_struct()) {
      const std::string& n = TypeOf(qv.var).struct_name;
      if (n == "HashGridQuery") next = "hash_grid_query_next";
      else if (n == "BvhQuery") next = "bvh_query_next";
      else if (n == "MeshQueryAABB") next = "mesh_query_aabb_next";
    }
    if (!next)
      return Error(s.iter->loc, "for loops iterate over range(...), reversed(range(...)) or a geometry query "
                                "(hash_grid_query, bvh_query_aabb/ray, mesh_query_aabb)");
    auto prev = st_->scope.find(tn->id);
    if (prev != st_->scope.end() && TypeOf(prev->second) != Type::Int32())
      return Error(s.target->loc, "loop variable '" + tn->id + "' already has type " + TypeString(TypeOf(prev->second)));
    int index = NewVar(Type::Int32(), tn->id, true);
    {
      Stmt zero;
      zero.op.kind = OpKind::kConst;
      zero.op.dst.push_back(index);
      zero.op.text = "(wp::int32)0";
      Push(std::move(zero));
    }
    st_->scope[tn->id] = index;
    LoopBuilder lb{this, {}, {}};
    WEFT_RETURN_IF_ERROR(lb.Begin(s.body));
    lb.loop.is_while = true;
    std::vector<Stmt>* outer = st_->block;
    st_->block = &lb.loop.cond_body;
    auto c = ResolveAndEmitBuiltin(next, {Value::OfVar(qv.var), Value::OfVar(index)}, s.iter->loc);
    st_->block = outer;
    if (!c.ok()) return c.status();
    lb.loop.cond = c->var;
    return lb.Body(s.body);
  }
  if (!fname || fname->id != "range" || st_->scope.count("range"))
    return Error(s.iter->loc, "for loops iterate over range(...) or reversed(range(...)) only");
  if (call->args.empty() || call->args.size() > 3 || !call->keywords.empty())
    return Error(s.iter->loc, "range() takes 1 to 3 positional arguments");
  std::vector<Value> vals;
  for (const auto& a : call->args) {
    WEFT_ASSIGN_OR_RETURN(Value v, Eval(*a));
    if (v.kind != Value::Kind::kVar || !TypeOf(v.var).is_scalar() || !IsInt(TypeOf(v.var).scalar))
      return Error(a->loc, "range() arguments must be integers, got " +
                               (v.kind == Value::Kind::kVar ? TypeString(TypeOf(v.var)) : std::string("a non-value")));
    vals.push_back(v);
  }
  Type it = Type::Int32();
  for (const auto& v : vals)
    if (!v.literal) {
      it = TypeOf(v.var);
      break;
    }
  std::vector<int> vars;
  for (const auto& v : vals) {
    WEFT_ASSIGN_OR_RETURN(int c, Coerce(v, it, s.iter->loc, "range() argument"));
    vars.push_back(c);
  }
  int start, end, step;
  if (vars.size() == 1) {
    start = EmitConst(it, "(" + CppType(it) + ")0");
    end = vars[0];
    step = EmitConst(it, "(" + CppType(it) + ")1");
  } else {
    start = vars[0];
    end = vars[1];
    step = vars.size() == 3 ? vars[2] : EmitConst(it, "(" + CppType(it) + ")1");
  }
  if (reversed) {
    // n = len(range(start, end, step)); reversed: range(start + (n-1)*step, start - step, -step)
    // (n == 0: start - step twice, no iteration). A zero step iterates nothing.
    int n = EmitRaw(it,
                    "(($2) > 0 ? (($1) > ($0) ? (($1) - ($0) + ($2) - 1) / ($2) : 0)"
                    " : (($2) < 0 ? (($0) > ($1) ? (($0) - ($1) - ($2) - 1) / (0 - ($2)) : 0) : 0))",
                    {start, end, step});
    int last = EmitRaw(it, "(($0) > 0 ? ($1) + (($0) - 1) * ($2) : ($1) - ($2))", {n, start, step});
    end = EmitRaw(it, "(($0) - ($1))", {start, step});
    step = EmitRaw(it, "(0 - ($0))", {step});
    start = last;
  }
  LoopBuilder lb{this, {}, {}};
  WEFT_RETURN_IF_ERROR(lb.Begin(s.body));
  lb.loop.start = start;
  lb.loop.end = end;
  lb.loop.step = step;
  lb.loop.iter = NewVar(it, tn->id, true);
  auto prev = st_->scope.find(tn->id);
  if (prev != st_->scope.end() && TypeOf(prev->second) != it)
    return Error(s.target->loc, "loop variable '" + tn->id + "' already has type " + TypeString(TypeOf(prev->second)));
  const int before = prev != st_->scope.end() ? prev->second : start;
  st_->scope[tn->id] = lb.loop.iter;
  // A loop over constant bounds: its variable may appear in wp.static(...) (Warp unrolls such
  // a loop and evaluates the expression per iteration; weft evaluates it per iteration at
  // run time, to the same value).
  bool constant_range = true;
  for (const auto& v : vals) constant_range = constant_range && v.literal;
  const bool was_static = st_->static_loop_vars.count(tn->id) != 0;
  if (constant_range) st_->static_loop_vars.insert(tn->id);
  else st_->static_loop_vars.erase(tn->id);
  const int iter = lb.loop.iter, brk = lb.loop.break_flag;
  Status body = lb.Body(s.body);
  if (was_static) st_->static_loop_vars.insert(tn->id);
  else st_->static_loop_vars.erase(tn->id);
  WEFT_RETURN_IF_ERROR(body);
  // After the loop the name holds the last value it took (Python's rule): the value at a
  // break, else the last one iterated (the counter has gone one step past it), or its value
  // before the loop when the loop did not run.
  st_->scope[tn->id] = EmitRaw(it, "($0 ? $1 : ($1 != $2 ? ($1 - $3) : $4))", {brk, iter, start, step, before});
  return Status::Ok();
}

Status Checker::LowerWhile(const ast::While& s) {
  LoopBuilder lb{this, {}, {}};
  WEFT_RETURN_IF_ERROR(lb.Begin(s.body));
  lb.loop.is_while = true;
  std::vector<Stmt>* outer = st_->block;
  st_->block = &lb.loop.cond_body;
  auto c = EvalCond(*s.test);
  st_->block = outer;
  if (!c.ok()) return c.status();
  lb.loop.cond = *c;
  return lb.Body(s.body);
}

Status Checker::LowerReturn(const ast::Return& s) {
  Function& fn = st_->fn;
  std::vector<Value> vals;
  if (s.value) {
    WEFT_ASSIGN_OR_RETURN(Value v, Eval(*s.value));
    if (v.kind == Value::Kind::kTuple) vals = v.elems;
    else vals.push_back(v);
    for (const auto& x : vals)
      if (x.kind != Value::Kind::kVar || TypeOf(x.var).is_void())
        return Error(s.value->loc, "return values must be runtime values");
  }
  if (fn.is_kernel && !vals.empty()) return Error(s.loc, "kernels cannot return a value");
  if (!fn.is_kernel) {
    if (fn.return_slots.empty() && !vals.empty()) {
      const auto& patterns = st_->return_patterns;
      if (!patterns.empty()) {
        bool fits = patterns.size() == vals.size();
        for (size_t i = 0; fits && i < vals.size(); ++i) fits = GenericAccepts(patterns[i], TypeOf(vals[i].var));
        if (!fits) {
          std::string want, got;
          for (size_t i = 0; i < patterns.size(); ++i) want += (i ? ", " : "") + TypeString(patterns[i]);
          for (size_t i = 0; i < vals.size(); ++i) got += (i ? ", " : "") + TypeString(TypeOf(vals[i].var));
          return Error(s.loc, "'" + fn.name + "' is annotated to return " + want + " but returns " + got);
        }
      }
      for (const auto& x : vals) {
        fn.returns.push_back(TypeOf(x.var));
        fn.return_slots.push_back(NewVar(TypeOf(x.var), "ret", true));
      }
      // Earlier bare `return`s in a value-returning function are caught at codegen time as
      // default values; Warp rejects them, so do we.
      if (st_->has_bare_return) return Error(s.loc, "'" + fn.name + "' returns a value here but not on every path");
    }
    if (vals.empty() && !fn.return_slots.empty() && st_->adjoint_slots.empty())
      return Error(s.loc, "'" + fn.name + "' must return " + std::to_string(fn.returns.size()) + " value(s)");
    if (!st_->adjoint_slots.empty() && !vals.empty())
      return Error(s.loc, "a gradient function (wp.func_grad) sets wp.adjoint[...] and returns no value");
    if (vals.empty()) st_->has_bare_return = true;
    if (vals.size() != fn.return_slots.size() && st_->adjoint_slots.empty())
      return Error(s.loc, "'" + fn.name + "' returns " + std::to_string(fn.returns.size()) + " value(s) elsewhere, " +
                              std::to_string(vals.size()) + " here");
    for (size_t i = 0; i < vals.size(); ++i) {
      const Type have = TypeOf(vals[i].var);
      if (have.is_fixed_array() && fn.returns[i].is_array() && !fn.returns[i].is_fixed_array()) {
        std::string elem = TypeString(fn.returns[i].elem());
        return Error(s.loc, "The function `" + fn.name + "` returns a fixed-size array whereas it has its return type "
                            "annotated as `Array[" + elem + "]`.");
      }
      WEFT_ASSIGN_OR_RETURN(int v, Coerce(vals[i], fn.returns[i], s.value->loc, "the return value"));
      EmitCopy(fn.return_slots[i], v);
    }
  }
  Stmt set;
  set.op.kind = OpKind::kConst;
  set.op.dst.push_back(fn.return_flag);
  set.op.text = "true";
  Push(std::move(set));
  return Status::Ok();
}

Expected<Module> Check(const ModuleSource& module, const std::vector<ParsedFunction>& parsed,
                       std::vector<Diagnostic>* diags) {
  Checker c(module, parsed, diags);
  return c.Run();
}

}  // namespace weft::sema
