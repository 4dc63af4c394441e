// ModuleService: compile a module through the engine's ModuleStore.
#include <spdlog/spdlog.h>

#include "server/grpc_status.h"
#include "server/proto_convert.h"
#include "server/services.h"

namespace weft::server {

grpc::Status ModuleServiceImpl::Compile(grpc::ServerContext* ctx, const v1::CompileRequest* req,
                                        v1::CompileResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  CompileReport report;
  auto m = auth_.engine().Compile(**s, FromProto(req->module()), req->device(), &report);
  for (const auto& d : report.diagnostics) ToProto(d, resp->add_diagnostics());
  if (!m.ok()) {
    std::string msg = m.status().message();
    for (const auto& d : report.diagnostics) {
      if (d.severity != Diagnostic::Severity::kError) continue;
      std::string text = d.ToString();
      if (msg.find(text) == std::string::npos) msg += "\n" + text;
    }
    return ToGrpc(Status(m.status().code(), msg));
  }
  const LoadedModule& mod = **m;
  resp->set_module_id(mod.id);
  for (const auto& k : mod.kernels) {
    auto* ki = resp->add_kernels();
    ki->set_name(k.layout.name);
    ki->set_args_size(k.layout.args_size);
    for (const auto& p : k.layout.params) {
      auto* kp = ki->add_params();
      kp->set_name(p.name);
      kp->set_type(p.type);
      kp->set_offset(p.offset);
      kp->set_size(p.size);
    }
  }
  resp->set_cache_hit(report.cache_hit || report.disk_hit);
  resp->set_compile_ms(report.compile_ms);
  return grpc::Status::OK;
}

}  // namespace weft::server
