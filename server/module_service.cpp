// ModuleService: compile a module through the engine: for a device (loaded, with a module id),
// or compile-only for a CUDA architecture (cuda_arch: the CUBIN report, no GPU needed); and
// the properties of a compiled kernel as loaded on a GPU.
#include <spdlog/spdlog.h>

#include "engine/codegen/emit_text.h"
#include "server/grpc_status.h"
#include "server/proto_convert.h"
#include "server/services.h"

namespace weft::server {

namespace {
constexpr size_t kDiagnosticsTrailerMaxBytes = 4096;
}  // namespace

grpc::Status ModuleServiceImpl::Compile(grpc::ServerContext* ctx, const v1::CompileRequest* req,
                                        v1::CompileResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  CompileReport report;
  // The status with the error diagnostics that its message does not already carry. The
  // diagnostics (with their kinds) also travel in a binary trailer, as a CompileResponse: a
  // failed call delivers no response message. Left out when large (the status message carries
  // their text either way).
  auto failed = [&](const Status& status) {
    if (resp->diagnostics_size() > 0 && resp->ByteSizeLong() <= kDiagnosticsTrailerMaxBytes)
      ctx->AddTrailingMetadata("weft-compile-diagnostics-bin", resp->SerializeAsString());
    std::string msg = status.message();
    for (const auto& d : report.diagnostics) {
      if (d.severity != Diagnostic::Severity::kError) continue;
      std::string text = d.ToString();
      if (msg.find(text) == std::string::npos) msg += "\n" + text;
    }
    return ToGrpc(Status(status.code(), msg));
  };
  if (req->cuda_arch() != 0) {
    const std::string& device = req->device();
    const bool cuda_n = device.size() > 5 && device.size() <= 9 && device.rfind("cuda:", 0) == 0 &&
                        device.find_first_not_of("0123456789", 5) == std::string::npos;
    if (!device.empty() && device != "cuda" && !cuda_n)
      return ToGrpc(InvalidArgument("cuda_arch compiles for a CUDA device; device must be empty, \"cuda\" or "
                                    "\"cuda:N\", not '" + codegen::CommentText(device.substr(0, 64)) + "'"));
    if (req->cuda_arch() > 1000)
      return ToGrpc(InvalidArgument("unknown CUDA architecture " + std::to_string(req->cuda_arch())));
    auto c = auth_.engine().CompileForArch(**s, FromProto(req->module()), static_cast<int>(req->cuda_arch()), &report);
    for (const auto& d : report.diagnostics) ToProto(d, resp->add_diagnostics());
    if (!c.ok()) return failed(c.status());
    auto* cuda = resp->mutable_cuda();
    cuda->set_arch(static_cast<uint32_t>(c->arch));
    cuda->set_binary_size(c->image.size());
    cuda->set_nvrtc_version(c->nvrtc_version);
    for (const auto& k : c->kernels) {
      auto* r = cuda->add_kernels();
      r->set_kernel(k.kernel);
      r->set_adjoint(k.adjoint);
      r->set_symbol(k.symbol);
      r->set_registers(k.registers);
      r->set_code_bytes(k.code_bytes);
      r->set_shared_bytes(k.shared_bytes);
      r->set_local_bytes(k.local_bytes);
      r->set_const_bytes(k.const_bytes);
    }
    if (req->return_binary()) cuda->set_binary(std::move(c->image));
    resp->set_cache_hit(report.cache_hit || report.disk_hit);
    resp->set_compile_ms(report.compile_ms);
    return grpc::Status::OK;
  }
  auto m = auth_.engine().Compile(**s, FromProto(req->module()), req->device(), &report);
  for (const auto& d : report.diagnostics) ToProto(d, resp->add_diagnostics());
  if (!m.ok()) return failed(m.status());
  const LoadedModule& mod = **m;
  resp->set_module_id(mod.id);
  for (const auto& k : mod.kernels) {
    auto* ki = resp->add_kernels();
    ki->set_name(k.layout.name);
    ki->set_args_size(k.layout.args_size);
    ki->set_adjoint_refused(k.layout.adjoint_refused);
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

grpc::Status ModuleServiceImpl::KernelProperties(grpc::ServerContext* ctx, const v1::KernelPropertiesRequest* req,
                                                 v1::KernelPropertiesResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  auto p = auth_.engine().KernelPropertiesOf(**s, req->module_id(), req->kernel(), req->device());
  if (!p.ok()) return ToGrpc(p.status());
  resp->set_register_count(p->register_count);
  resp->set_local_memory_size(p->local_memory_size);
  resp->set_shared_memory_size(p->shared_memory_size);
  resp->set_max_threads_per_block(p->max_threads_per_block);
  resp->set_suggested_block_size(p->suggested_block_size);
  resp->set_min_grid_size(p->min_grid_size);
  return grpc::Status::OK;
}

}  // namespace weft::server
