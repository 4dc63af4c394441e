// The gRPC services of weftd: thin adapters from protobuf to Engine calls, one .cpp each.
// Each resolves the caller (CallAuth), converts, calls the engine, converts back; engine
// Status values become grpc::Status only through ToGrpc.
#pragma once

#include <atomic>

#include "server/call_auth.h"
#include "server/session_reaper.h"
#include "weft/v1/array.grpc.pb.h"
#include "weft/v1/device.grpc.pb.h"
#include "weft/v1/exec.grpc.pb.h"
#include "weft/v1/geometry.grpc.pb.h"
#include "weft/v1/module.grpc.pb.h"
#include "weft/v1/session.grpc.pb.h"

namespace weft::server {

class FastLane;       // server/fast_lane.h
class SessionHosts;   // server/session_hosts.h

// Attach is served on gRPC's callback API: an attached session's stream waits without holding
// a thread (a sync-API stream would hold one of gRPC's server threads for the session's whole
// life); the other methods are synchronous.
// Where SessionService.Open sends a session.
struct SessionRouting {
  bool single_session = false;   // this weftd is a session host; a second Open is refused
  bool unchecked_hosts = false;  // an unchecked local session goes to a host (--allow-unchecked)
  bool isolate = false;          // every local session goes to a host (--isolate-sessions)
  bool device_hosts = false;     // a checked local session goes to its device's host (--device-hosts)
};

class SessionServiceImpl final : public v1::SessionService::WithCallbackMethod_Attach<v1::SessionService::Service> {
 public:
  using Routing = SessionRouting;
  // `hosts`: the processes sessions run in (null: every session opens here).
  SessionServiceImpl(const CallAuth& auth, SessionReaper& reaper, FastLane* fast_lane = nullptr,
                     SessionHosts* hosts = nullptr, Routing routing = {})
      : auth_(auth), reaper_(reaper), fast_lane_(fast_lane), hosts_(hosts), routing_(routing) {}
  grpc::Status Open(grpc::ServerContext* ctx, const v1::OpenSessionRequest* req, v1::OpenSessionResponse* resp) override;
  grpc::ServerBidiReactor<v1::AttachRequest, v1::AttachEvent>* Attach(grpc::CallbackServerContext* ctx) override;
  grpc::Status Close(grpc::ServerContext* ctx, const v1::CloseSessionRequest* req, v1::CloseSessionResponse* resp) override;
  grpc::Status Stats(grpc::ServerContext* ctx, const v1::StatsRequest* req, v1::StatsResponse* resp) override;
 private:
  // The device whose host a session opened with `asked` (OpenSessionRequest.device) goes to:
  // "" = the first GPU that computes, else "cpu"; "cuda" = the GPUs in turn; InvalidArgument
  // for anything that is not one of the daemon's devices.
  Expected<std::string> SessionDevice(const std::string& asked);
  // Adds the stats of the device hosts alive now to the daemon's own (--device-hosts).
  void AddDeviceHostStats(v1::StatsResponse* resp) const;
  const CallAuth& auth_;
  SessionReaper& reaper_;
  FastLane* fast_lane_;   // null: no fast lane (the Open response then names none)
  SessionHosts* hosts_;
  const Routing routing_;
  std::atomic<bool> session_opened_{false};
  std::atomic<uint64_t> cuda_turn_{0};   // sessions opened on "cuda" go to the GPUs in turn
};

class ArrayServiceImpl final : public v1::ArrayService::Service {
 public:
  explicit ArrayServiceImpl(const CallAuth& auth) : auth_(auth) {}
  grpc::Status Create(grpc::ServerContext* ctx, const v1::CreateArrayRequest* req, v1::CreateArrayResponse* resp) override;
  grpc::Status Free(grpc::ServerContext* ctx, const v1::FreeArrayRequest* req, v1::FreeArrayResponse* resp) override;
  grpc::Status Describe(grpc::ServerContext* ctx, const v1::DescribeArrayRequest* req, v1::DescribeArrayResponse* resp) override;
  grpc::Status Read(grpc::ServerContext* ctx, const v1::ReadArrayRequest* req,
                    grpc::ServerWriter<v1::ArrayChunk>* writer) override;
  grpc::Status Write(grpc::ServerContext* ctx, grpc::ServerReader<v1::WriteArrayRequest>* reader,
                     v1::WriteArrayResponse* resp) override;
  grpc::Status Export(grpc::ServerContext* ctx, const v1::ExportArrayRequest* req, v1::ExportArrayResponse* resp) override;
  grpc::Status Import(grpc::ServerContext* ctx, const v1::ImportArrayRequest* req, v1::ImportArrayResponse* resp) override;
  grpc::Status ImportCuda(grpc::ServerContext* ctx, const v1::ImportCudaRequest* req,
                          v1::ImportCudaResponse* resp) override;
 private:
  const CallAuth& auth_;
};

// The bodies of ExecService.Submit and Synchronize for a session already resolved and
// authorized: the gRPC methods and the fast lane (fast_lane.h) both call these, so a frame is
// checked exactly as a call is.
// `run_here_when_idle`: an asynchronous batch runs on the calling thread when the session's
// executor is idle (Engine::Submit; the fast lane's connection thread).
Status ExecSubmit(Engine& engine, Session& s, const v1::SubmitRequest& req, v1::SubmitResponse* resp,
                  bool run_here_when_idle = false);
void ExecSynchronize(Engine& engine, Session& s, v1::SynchronizeResponse* resp);

// The bodies of ArrayService.Create, Free and Describe for a session already resolved and
// authorized (the gRPC methods and the fast lane).
Status ArrayCreate(Engine& engine, Session& s, const v1::CreateArrayRequest& req, v1::CreateArrayResponse* resp);
// At most kMaxFreeHandles handles in FreeArrayRequest.handles (a request's work is bounded).
inline constexpr int kMaxFreeHandles = 65536;
Status ArrayFree(Engine& engine, Session& s, const v1::FreeArrayRequest& req);
Status ArrayDescribe(Engine& engine, Session& s, const v1::DescribeArrayRequest& req, v1::DescribeArrayResponse* resp);
Status ArrayImportCuda(Engine& engine, Session& s, const v1::ImportCudaRequest& req, v1::ImportCudaResponse* resp);
// The body of GeometryService.Call (the gRPC method and the fast lane).
Status GeometryCall(Engine& engine, Session& s, const v1::GeometryRequest& req, v1::GeometryResponse* resp);

class ExecServiceImpl final : public v1::ExecService::Service {
 public:
  explicit ExecServiceImpl(const CallAuth& auth) : auth_(auth) {}
  grpc::Status Submit(grpc::ServerContext* ctx, const v1::SubmitRequest* req, v1::SubmitResponse* resp) override;
  grpc::Status Synchronize(grpc::ServerContext* ctx, const v1::SynchronizeRequest* req,
                           v1::SynchronizeResponse* resp) override;
  grpc::Status EventElapsed(grpc::ServerContext* ctx, const v1::EventElapsedRequest* req,
                            v1::EventElapsedResponse* resp) override;
 private:
  const CallAuth& auth_;
};

class ModuleServiceImpl final : public v1::ModuleService::Service {
 public:
  explicit ModuleServiceImpl(const CallAuth& auth) : auth_(auth) {}
  grpc::Status Compile(grpc::ServerContext* ctx, const v1::CompileRequest* req, v1::CompileResponse* resp) override;
  grpc::Status KernelProperties(grpc::ServerContext* ctx, const v1::KernelPropertiesRequest* req,
                                v1::KernelPropertiesResponse* resp) override;
 private:
  const CallAuth& auth_;
};

class GeometryServiceImpl final : public v1::GeometryService::Service {
 public:
  explicit GeometryServiceImpl(const CallAuth& auth) : auth_(auth) {}
  grpc::Status Call(grpc::ServerContext* ctx, const v1::GeometryRequest* req, v1::GeometryResponse* resp) override;

 private:
  const CallAuth& auth_;
};

class DeviceServiceImpl final : public v1::DeviceService::Service {
 public:
  explicit DeviceServiceImpl(const CallAuth& auth) : auth_(auth) {}
  grpc::Status List(grpc::ServerContext* ctx, const v1::ListDevicesRequest* req, v1::ListDevicesResponse* resp) override;
 private:
  const CallAuth& auth_;
};

}  // namespace weft::server
