// SessionService: open/close, the Attach stream whose end reaps the session, daemon stats.
#include <unistd.h>

#include <spdlog/spdlog.h>

#include "server/grpc_status.h"
#include "server/services.h"

namespace weft::server {

grpc::Status SessionServiceImpl::Open(grpc::ServerContext* ctx, const v1::OpenSessionRequest* req,
                                      v1::OpenSessionResponse* resp) {
  Status st = auth_.Authenticate(*ctx);
  if (!st.ok()) {
    spdlog::warn("refused session open from {}: {}", ctx->peer(), st.message());
    return ToGrpc(st);
  }
  SessionOptions o;
  o.client_name = req->client_name().empty() ? ctx->peer() : req->client_name();
  o.client_pid = req->client_pid();
  o.local = CallAuth::IsLocalPeer(*ctx);
  o.principal = CallAuth::Principal(*ctx);
  auto s = auth_.engine().OpenSession(o);
  resp->set_session_id(s->id());
  resp->set_daemon_version(WEFT_VERSION);
  resp->set_local(o.local);
  resp->set_daemon_pid(getpid());
  return grpc::Status::OK;
}

grpc::Status SessionServiceImpl::Attach(grpc::ServerContext* ctx,
                                        grpc::ServerReaderWriter<v1::AttachEvent, v1::AttachRequest>* stream) {
  v1::AttachRequest first;
  if (!stream->Read(&first)) return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "attach: no session id sent");
  std::string id = first.session_id().empty() ? Metadata(*ctx, "weft-session") : first.session_id();
  auto s = auth_.SessionById(*ctx, id);
  if (!s.ok()) return ToGrpc(s.status());
  s->reset();   // do not keep the session alive from here
  v1::AttachEvent hello;
  hello.set_message("attached " + id);
  stream->Write(hello);
  v1::AttachRequest ignored;
  while (stream->Read(&ignored)) {
  }
  // The stream ended: the client closed it or went away. Reap the session if it still exists.
  if (auth_.engine().FindSession(id)) {
    spdlog::info("session {}: attach stream ended ({})", id, ctx->IsCancelled() ? "client gone" : "closed by client");
    (void)auth_.engine().CloseSession(id, /*reaped=*/true);
  }
  return grpc::Status::OK;
}

grpc::Status SessionServiceImpl::Close(grpc::ServerContext* ctx, const v1::CloseSessionRequest* req,
                                       v1::CloseSessionResponse*) {
  std::string id = req->session_id().empty() ? Metadata(*ctx, "weft-session") : req->session_id();
  auto s = auth_.SessionById(*ctx, id);
  if (!s.ok()) return ToGrpc(s.status());
  s->reset();
  Status st = auth_.engine().CloseSession(id);
  if (st.code() == StatusCode::kNotFound) return grpc::Status::OK;   // closed concurrently
  return ToGrpc(st);
}

grpc::Status SessionServiceImpl::Stats(grpc::ServerContext* ctx, const v1::StatsRequest*, v1::StatsResponse* resp) {
  Status st = auth_.Authenticate(*ctx);
  if (!st.ok()) return ToGrpc(st);
  EngineStats e = auth_.engine().Stats();
  resp->set_sessions(e.sessions);
  resp->set_arrays(e.arrays);
  resp->set_array_bytes(e.array_bytes);
  resp->set_cpu_slabs(e.cpu_slabs);
  resp->set_cpu_slab_bytes(e.cpu_slab_bytes);
  resp->set_module_cache_hits(e.module_cache_hits);
  resp->set_module_cache_disk_hits(e.module_cache_disk_hits);
  resp->set_module_cache_misses(e.module_cache_misses);
  resp->set_sessions_opened_total(e.sessions_opened_total);
  resp->set_sessions_reaped_total(e.sessions_reaped_total);
  return grpc::Status::OK;
}

}  // namespace weft::server
