// ExecService: ordered command batches, synchronization, and the time between timing events.
#include <spdlog/spdlog.h>

#include "server/grpc_status.h"
#include "server/proto_convert.h"
#include "server/services.h"

namespace weft::server {

namespace {

// A session's sync result (first error, origin, kernel output, timed GPU operations) as a SynchronizeResponse. In a
// session or device host, an error with a GPU lost to a fault ends the session (the driver keeps
// that error for the life of the process): the response says so, and the client opens a new one.
void FillSync(Engine& engine, Session::SyncResult& r, v1::SynchronizeResponse* resp) {
  if (!r.error.ok()) {
    if (engine.options().device_host && engine.AnyGpuLost()) {
      resp->set_session_ended(true);
      resp->set_error(r.error.message() +
                      "; this session ran in the process of its device's sessions (a device host: weftd "
                      "--device-hosts), which ends now with every session of that device: the daemon and the "
                      "sessions of other devices were not touched; a new session gets a fresh process and GPU "
                      "context (the Python client opens one on its next call)");
    } else if (engine.options().session_host && engine.AnyGpuLost()) {
      resp->set_session_ended(true);
      resp->set_error(r.error.message() +
                      "; this unchecked session ran in a process of its own (a session host), which ends with it: "
                      "the daemon and its other sessions were not touched; a new session gets a fresh GPU context "
                      "(the Python client opens one on its next call)");
    } else {
      resp->set_error(r.error.message());
    }
    resp->set_error_code(static_cast<int32_t>(r.error.code()));
    ToProto(r.origin, resp->mutable_error_origin());
  }
  resp->set_output(std::move(r.output));
  if (r.timing_ended) {
    resp->set_timing_ended(true);
    resp->set_timing_dropped(r.timing_dropped);
    for (TimedActivity& t : r.timing) {
      v1::TimedActivity* out = resp->add_timing();
      out->set_device(std::move(t.device));
      out->set_name(std::move(t.name));
      out->set_filter(t.filter);
      out->set_elapsed_ms(t.elapsed_ms);
    }
  }
}

}  // namespace

Status ExecSubmit(Engine& engine, Session& s, const v1::SubmitRequest& req, v1::SubmitResponse* resp,
                  bool run_here_when_idle) {
  std::vector<Command> commands;
  commands.reserve(req.commands_size());
  for (int i = 0; i < req.commands_size(); ++i) {
    auto c = FromProto(req.commands(i), static_cast<size_t>(i));
    if (!c.ok()) return c.status();   // nothing queued
    commands.push_back(std::move(c).value());
  }
  const uint64_t n = commands.size();
  if (req.synchronize()) {
    auto r = engine.SubmitAndSynchronize(s, std::move(commands));
    if (!r.ok()) return r.status();
    resp->set_queued(n);
    FillSync(engine, *r, resp->mutable_sync());
    return Status::Ok();
  }
  if (req.run()) {
    auto r = engine.SubmitAndRun(s, std::move(commands));
    if (!r.ok()) return r.status();
    resp->set_queued(n);
    if (r->has_value()) FillSync(engine, **r, resp->mutable_sync());
    return Status::Ok();
  }
  auto r = engine.Submit(s, std::move(commands), run_here_when_idle);
  if (!r.ok()) return r.status();
  resp->set_queued(*r);
  return Status::Ok();
}

void ExecSynchronize(Engine& engine, Session& s, v1::SynchronizeResponse* resp) {
  Session::SyncResult r = engine.Synchronize(s);
  FillSync(engine, r, resp);
}

grpc::Status ExecServiceImpl::Submit(grpc::ServerContext* ctx, const v1::SubmitRequest* req, v1::SubmitResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  return ToGrpc(ExecSubmit(auth_.engine(), **s, *req, resp));
}

grpc::Status ExecServiceImpl::Synchronize(grpc::ServerContext* ctx, const v1::SynchronizeRequest*,
                                          v1::SynchronizeResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  ExecSynchronize(auth_.engine(), **s, resp);
  return grpc::Status::OK;
}

grpc::Status ExecServiceImpl::EventElapsed(grpc::ServerContext* ctx, const v1::EventElapsedRequest* req,
                                           v1::EventElapsedResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  auto ms = auth_.engine().EventElapsed(**s, req->device(), req->start_id(), req->end_id());
  if (!ms.ok()) return ToGrpc(ms.status());
  resp->set_elapsed_ms(*ms);
  return grpc::Status::OK;
}

}  // namespace weft::server
