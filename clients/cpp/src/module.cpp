// Kernel modules from C++: ModuleDef helpers and Client::Compile (ModuleService.Compile).
#include "weft/client/module.h"

#include "client_core.h"
#include "rpc_status.h"

namespace weft {
inline namespace client_v1 {

ModuleDef& ModuleDef::AddKernel(std::string kernel_name, std::string kernel_source,
                                std::vector<std::string> names, std::vector<std::string> types) {
  FunctionDef f;
  f.name = std::move(kernel_name);
  f.source = std::move(kernel_source);
  f.param_names = std::move(names);
  f.param_types = std::move(types);
  functions.push_back(std::move(f));
  return *this;
}

ModuleDef& ModuleDef::AddConstant(std::string symbol, std::string type, std::string literal) {
  symbols.push_back(SymbolDef{std::move(symbol), SymbolDef::Kind::kConstant, std::move(literal),
                              std::move(type)});
  return *this;
}

namespace {

void ToProto(const ModuleDef& in, v1::ModuleSource* out) {
  out->set_name(in.name);
  for (const auto& f : in.functions) {
    auto* p = out->add_functions();
    p->set_name(f.name);
    p->set_source(f.source);
    p->set_file(f.file);
    p->set_first_line(f.first_line);
    p->set_is_kernel(f.is_kernel);
    for (const auto& t : f.param_types) p->add_param_types(t);
    for (const auto& n : f.param_names) p->add_param_names(n);
    p->set_return_type(f.return_type);
    p->set_key(f.key.empty() ? in.name + "." + f.name : f.key);
  }
  for (const auto& alias : in.warp_aliases) {
    auto* s = out->add_symbols();
    s->set_name(alias);
    s->set_builtin_module("warp");
  }
  for (const auto& sym : in.symbols) {
    auto* s = out->add_symbols();
    s->set_name(sym.name);
    switch (sym.kind) {
      case SymbolDef::Kind::kBuiltinModule: s->set_builtin_module(sym.value); break;
      case SymbolDef::Kind::kFunction: s->set_function(sym.value); break;
      case SymbolDef::Kind::kType: s->set_type(sym.value); break;
      case SymbolDef::Kind::kConstant:
        s->mutable_constant()->set_type(sym.constant_type);
        s->mutable_constant()->set_value(sym.value);
        break;
    }
  }
  for (const auto& st : in.structs) {
    auto* d = out->add_structs();
    d->set_name(st.name);
    for (const auto& f : st.fields) {
      auto* pf = d->add_fields();
      pf->set_name(f.name);
      pf->set_type(f.type);
    }
  }
  for (const auto& [k, v] : in.options) (*out->mutable_options())[k] = v;
}

}  // namespace

Expected<CompiledModule> Client::Compile(const ModuleDef& module, const std::string& device) {
  if (!core_) return FailedPrecondition("weft::Client is not connected");
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  v1::CompileRequest request;
  ToProto(module, request.mutable_module());
  request.set_device(device);
  v1::CompileResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->modules().Compile(context.get(), request, &response), "ModuleService.Compile"));
  CompiledModule out;
  out.module_id = response.module_id();
  out.cache_hit = response.cache_hit();
  out.compile_ms = response.compile_ms();
  for (const auto& k : response.kernels()) {
    KernelInfo info;
    info.name = k.name();
    info.args_size = k.args_size();
    for (const auto& p : k.params())
      info.params.push_back(KernelParamInfo{p.name(), p.type(), p.offset(), p.size()});
    out.kernels.push_back(std::move(info));
  }
  for (const auto& d : response.diagnostics()) {
    if (d.severity() == v1::Diagnostic::ERROR) continue;
    out.warnings.push_back(d.location().file() + ":" + std::to_string(d.location().line()) +
                           ": " + d.message());
  }
  return out;
}

}  // namespace client_v1
}  // namespace weft
