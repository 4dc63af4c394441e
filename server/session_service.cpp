// SessionService: open (bound to the caller's principal, limited per principal), close, the
// Attach stream (one per session, on the callback API: no thread while it waits) whose end
// reaps the session, daemon stats.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <mutex>
#include <string>

#include <grpcpp/create_channel.h>
#include <spdlog/spdlog.h>

#include "server/fast_lane.h"
#include "server/grpc_status.h"
#include "server/session_hosts.h"
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
  const bool unchecked = req->unchecked() && routing_.unchecked_hosts;
  if ((unchecked || routing_.isolate) && hosts_ && o.local) {
    // An unchecked session (every local session with --isolate-sessions) runs in a process of
    // its own: start it and send the client there.
    auto host = hosts_->Start(o.principal);
    if (!host.ok()) {
      spdlog::warn("refused {} session of {}: {}", unchecked ? "unchecked" : "isolated", o.principal,
                   host.status().message());
      return ToGrpc(host.status());
    }
    resp->set_session_host(*host);
    resp->set_daemon_version(WEFT_VERSION);
    resp->set_daemon_pid(getpid());
    return grpc::Status::OK;
  }
  if (routing_.device_hosts && hosts_ && o.local && !unchecked) {
    // Under --device-hosts a checked local session runs in the process of its device.
    auto device = SessionDevice(req->device());
    if (!device.ok()) return ToGrpc(device.status());
    auto host = hosts_->StartForDevice(*device);
    if (!host.ok()) {
      spdlog::warn("refused session of {} on {}: {}", o.principal, *device, host.status().message());
      return ToGrpc(host.status());
    }
    resp->set_session_host(*host);
    resp->set_session_device(*device);
    resp->set_daemon_version(WEFT_VERSION);
    resp->set_daemon_pid(getpid());
    return grpc::Status::OK;
  }
  if (routing_.single_session && session_opened_.exchange(true))
    return ToGrpc(FailedPrecondition("this weftd is a session host and serves one session, already opened"));
  auto s = auth_.engine().OpenClientSession(o);
  if (!s.ok() && routing_.single_session) session_opened_ = false;   // the host's one session is still to come
  if (!s.ok()) {
    spdlog::warn("refused session open from {}: {}", o.principal, s.status().message());
    return ToGrpc(s.status());
  }
  resp->set_session_id((*s)->id());
  resp->set_daemon_version(WEFT_VERSION);
  resp->set_local(o.local);
  resp->set_daemon_pid(getpid());
  if (fast_lane_ && o.local) {
    resp->set_fast_lane_path(fast_lane_->path());
    resp->set_fast_lane_secret(fast_lane_->NewSecret((*s)->id(), o.principal));
  }
  return grpc::Status::OK;
}

Expected<std::string> SessionServiceImpl::SessionDevice(const std::string& asked) {
  // The name is the client's: checked against the daemon's devices before it is used or shown.
  std::vector<std::string> gpus;
  for (const DeviceInfo& d : auth_.engine().ListDevices())
    if (d.kind == "cuda" && d.compute_supported) gpus.push_back(d.name);
  if (asked.empty()) return gpus.empty() ? std::string("cpu") : gpus.front();
  if (asked == "cpu") return asked;
  if (asked == "cuda") {
    if (gpus.empty()) return InvalidArgument("session device 'cuda': this daemon has no GPU it can compute on");
    return gpus[cuda_turn_.fetch_add(1) % gpus.size()];
  }
  for (const std::string& g : gpus)
    if (asked == g) return asked;
  const bool printable = asked.size() <= 32 && std::all_of(asked.begin(), asked.end(), [](char c) {
                           return c >= 0x21 && c <= 0x7e && c != '\'' && c != '\\';
                         });
  return InvalidArgument("session device " + (printable ? "'" + asked + "'" : std::string("(not a device name)")) +
                         ": expected \"cpu\", \"cuda\" or one of this daemon's GPUs (" +
                         std::to_string(gpus.size()) + " usable)");
}

namespace {

// One Attach stream. The first message names the session; the first Attach of a session claims
// it and, when that stream ends (the client closed it or went away), the session is reaped. A
// second Attach (a hijack attempt, or a confused client) is refused and changes nothing.
// Reactions run on gRPC's callback threads and never block: the reap is queued to the
// SessionReaper. OnReadDone and OnWriteDone may run at once; mu_ orders the end of the stream.
class AttachReactor final : public grpc::ServerBidiReactor<v1::AttachRequest, v1::AttachEvent> {
 public:
  AttachReactor(grpc::CallbackServerContext* ctx, const CallAuth& auth, SessionReaper& reaper)
      : ctx_(ctx), auth_(auth), reaper_(reaper) {
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!claimed_) {
      if (!ok) return Finish(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "attach: no session id sent"));
      Claim();
      return;
    }
    if (ok) {   // later messages mean nothing; keep reading until the stream ends
      StartRead(&request_);
      return;
    }
    reaper_.ReapDetached(id_, watched_, ctx_->IsCancelled());
    bool finish_now;
    {
      std::lock_guard<std::mutex> lock(mu_);
      finish_after_write_ = writing_;
      finish_now = !writing_;
    }
    if (finish_now) Finish(grpc::Status::OK);
  }

  void OnWriteDone(bool) override {
    bool finish_now;
    {
      std::lock_guard<std::mutex> lock(mu_);
      writing_ = false;
      finish_now = finish_after_write_;
    }
    if (finish_now) Finish(grpc::Status::OK);
  }

  void OnDone() override { delete this; }

 private:
  void Claim() {
    id_ = request_.session_id().empty() ? Metadata(*ctx_, "weft-session") : request_.session_id();
    auto found = auth_.SessionById(*ctx_, id_);
    if (!found.ok()) return Finish(ToGrpc(found.status()));
    std::shared_ptr<Session> s = std::move(found).value();
    if (!s->ClaimAttach())
      return Finish(ToGrpc(FailedPrecondition("session " + s->label() +
                                              " already has an Attach stream; a session is attached once")));
    claimed_ = true;
    watched_ = s;   // weak: the stream does not keep the session alive
    hello_.set_message("attached " + s->label());
    {
      std::lock_guard<std::mutex> lock(mu_);
      writing_ = true;
    }
    StartWrite(&hello_);
    StartRead(&request_);
  }

  grpc::CallbackServerContext* ctx_;
  const CallAuth& auth_;
  SessionReaper& reaper_;
  v1::AttachRequest request_;
  v1::AttachEvent hello_;
  bool claimed_ = false;   // only touched by OnReadDone (reads are sequential)
  std::string id_;
  std::weak_ptr<Session> watched_;
  std::mutex mu_;
  bool writing_ = false;
  bool finish_after_write_ = false;
};

}  // namespace

grpc::ServerBidiReactor<v1::AttachRequest, v1::AttachEvent>* SessionServiceImpl::Attach(grpc::CallbackServerContext* ctx) {
  return new AttachReactor(ctx, auth_, reaper_);
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

void SessionServiceImpl::AddDeviceHostStats(v1::StatsResponse* resp) const {
  // Under --device-hosts the sessions live in the hosts: the daemon's view adds theirs (a host
  // that does not answer within a second is left out, and its sessions with it).
  for (const std::string& socket : hosts_->DeviceHostSockets()) {
    auto channel = grpc::CreateChannel("unix:" + socket, grpc::InsecureChannelCredentials());
    auto stub = v1::SessionService::NewStub(channel);
    grpc::ClientContext cctx;
    cctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(1));
    v1::StatsResponse h;
    const grpc::Status got = stub->Stats(&cctx, v1::StatsRequest(), &h);
    if (!got.ok()) {
      spdlog::debug("stats of the device host at {}: {}", socket, got.error_message());
      continue;
    }
    resp->set_sessions(resp->sessions() + h.sessions());
    resp->set_arrays(resp->arrays() + h.arrays());
    resp->set_array_bytes(resp->array_bytes() + h.array_bytes());
    resp->set_cpu_slabs(resp->cpu_slabs() + h.cpu_slabs());
    resp->set_cpu_slab_bytes(resp->cpu_slab_bytes() + h.cpu_slab_bytes());
    resp->set_module_cache_hits(resp->module_cache_hits() + h.module_cache_hits());
    resp->set_module_cache_disk_hits(resp->module_cache_disk_hits() + h.module_cache_disk_hits());
    resp->set_module_cache_misses(resp->module_cache_misses() + h.module_cache_misses());
    resp->set_sessions_opened_total(resp->sessions_opened_total() + h.sessions_opened_total());
    resp->set_sessions_reaped_total(resp->sessions_reaped_total() + h.sessions_reaped_total());
    resp->set_gpu_slabs(resp->gpu_slabs() + h.gpu_slabs());
    resp->set_gpu_slab_bytes(resp->gpu_slab_bytes() + h.gpu_slab_bytes());
    resp->set_gpu_resets(resp->gpu_resets() + h.gpu_resets());
    resp->set_last_gpu_reset_ms(std::max(resp->last_gpu_reset_ms(), h.last_gpu_reset_ms()));
    resp->set_gpu_coarsened_launches(resp->gpu_coarsened_launches() + h.gpu_coarsened_launches());
    resp->set_commands_run_total(resp->commands_run_total() + h.commands_run_total());
    resp->set_command_run_seconds(resp->command_run_seconds() + h.command_run_seconds());
  }
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
  resp->set_gpu_slabs(e.gpu_slabs);
  resp->set_gpu_slab_bytes(e.gpu_slab_bytes);
  resp->set_gpu_resets(e.gpu_resets);
  resp->set_last_gpu_reset_ms(e.last_gpu_reset_ms);
  resp->set_gpu_coarsened_launches(e.gpu_coarsened_launches);
  resp->set_commands_run_total(e.commands_run_total);
  resp->set_command_run_seconds(e.command_run_seconds);
  if (hosts_) {
    resp->set_session_hosts(hosts_->alive());
    resp->set_session_hosts_started_total(hosts_->started_total());
    AddDeviceHostStats(resp);
  }
  // The calling session's placement, when the call names one.
  if (auto s = auth_.SessionOf(*ctx); s.ok()) resp->set_cuda_placement(auth_.engine().CudaPlacement(**s));
  return grpc::Status::OK;
}

}  // namespace weft::server
