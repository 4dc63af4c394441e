// SessionService: open (bound to the caller's principal, limited per principal), close, the
// Attach stream (one per session) whose end reaps the session, daemon stats.
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
  auto peer = auth_.LocalPeer(*ctx);
  // Names and pids a client claims are for people reading logs; the kernel's pid wins locally.
  o.client_name = req->client_name().substr(0, 256);
  if (o.client_name.empty()) o.client_name = ctx->peer();
  o.client_pid = peer ? peer->pid : req->client_pid();
  o.local = peer.has_value();
  o.principal = auth_.Principal(*ctx);
  auto s = auth_.engine().OpenClientSession(o);
  if (!s.ok()) {
    spdlog::warn("refused session open from {}: {}", o.principal, s.status().message());
    return ToGrpc(s.status());
  }
  resp->set_session_id((*s)->id());
  resp->set_daemon_version(WEFT_VERSION);
  resp->set_local(o.local);
  resp->set_daemon_pid(getpid());
  return grpc::Status::OK;
}

// The first Attach of a session claims it; when that stream ends the session is reaped. A
// second Attach (a hijack attempt, or a confused client) is refused and changes nothing.
grpc::Status SessionServiceImpl::Attach(grpc::ServerContext* ctx,
                                        grpc::ServerReaderWriter<v1::AttachEvent, v1::AttachRequest>* stream) {
  v1::AttachRequest first;
  if (!stream->Read(&first)) return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "attach: no session id sent");
  std::string id = first.session_id().empty() ? Metadata(*ctx, "weft-session") : first.session_id();
  auto found = auth_.SessionById(*ctx, id);
  if (!found.ok()) return ToGrpc(found.status());
  std::shared_ptr<Session> s = std::move(found).value();
  if (!s->ClaimAttach())
    return ToGrpc(FailedPrecondition("session " + s->label() + " already has an Attach stream; a session is attached once"));
  const std::string label = s->label();
  std::weak_ptr<Session> watched = s;
  s.reset();   // do not keep the session alive from here
  v1::AttachEvent hello;
  hello.set_message("attached " + label);
  stream->Write(hello);
  v1::AttachRequest ignored;
  while (stream->Read(&ignored)) {
  }
  // The stream ended: the client closed it or went away. Reap the session if it still exists
  // (the same session object: ids are never reused, but check the object anyway).
  if (auto still = watched.lock(); still && auth_.engine().FindSession(id) == still) {
    spdlog::info("session {}: attach stream ended ({})", label, ctx->IsCancelled() ? "client gone" : "closed by client");
    still.reset();
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
