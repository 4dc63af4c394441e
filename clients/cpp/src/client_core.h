// The state one Client and its Arrays share: the gRPC channel and stubs, the session id and
// token (as metadata on every call), the Attach keeper, the queue of pending commands, and
// the cache of mapped shared-memory slabs.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "mapped_slab.h"
#include "session_keeper.h"
#include "weft/client/client.h"
#include "weft/v1/array.grpc.pb.h"
#include "weft/v1/device.grpc.pb.h"
#include "weft/v1/exec.grpc.pb.h"
#include "weft/v1/module.grpc.pb.h"
#include "weft/v1/session.grpc.pb.h"

namespace weft::inline client_v1::detail {

class ClientCore {
 public:
  // Connects, opens a session and starts holding Attach.
  static Expected<std::shared_ptr<ClientCore>> Open(const ConnectOptions& options);
  ~ClientCore();

  // Closes the session (SessionService.Close) and stops Attach. Idempotent.
  Status Close();
  bool closed() const { return closed_.load(); }
  // FAILED_PRECONDITION once closed; every operation checks it first.
  Status CheckOpen() const;

  // A context with `weft-session` (once opened) and `authorization` metadata.
  std::unique_ptr<grpc::ClientContext> NewContext() const;

  const SessionInfo& session() const { return session_; }
  const ConnectOptions& options() const { return options_; }
  bool local() const { return local_; }
  const std::shared_ptr<grpc::Channel>& channel() const { return channel_; }

  v1::SessionService::Stub& sessions() { return *session_stub_; }
  v1::ArrayService::Stub& arrays() { return *array_stub_; }
  v1::DeviceService::Stub& devices() { return *device_stub_; }
  v1::ExecService::Stub& exec() { return *exec_stub_; }
  v1::ModuleService::Stub& modules() { return *module_stub_; }
  SlabCache& slabs() { return slabs_; }

  // Queues a command; sends the queue when it reaches options().max_pending_commands.
  Status Enqueue(Command command);
  // Queues several commands and sends everything.
  Status EnqueueAll(std::vector<Command> commands);
  // Sends the queued commands (one ExecService.Submit).
  Status Flush();
  // Flush, then ExecService.Synchronize: the first error of any command since the last sync.
  Status Synchronize();
  std::string TakeOutput();

  // Frees a handle (flushing first, so queued commands that use it are sent before).
  Status FreeHandle(std::uint64_t handle);

 private:
  explicit ClientCore(const ConnectOptions& options) : options_(options) {}
  Status FlushLocked();   // requires queue_mu_

  ConnectOptions options_;
  std::string token_;
  SessionInfo session_;
  bool local_ = false;
  std::atomic<bool> closed_{false};
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::SessionService::Stub> session_stub_;
  std::unique_ptr<v1::ArrayService::Stub> array_stub_;
  std::unique_ptr<v1::DeviceService::Stub> device_stub_;
  std::unique_ptr<v1::ExecService::Stub> exec_stub_;
  std::unique_ptr<v1::ModuleService::Stub> module_stub_;
  std::unique_ptr<SessionKeeper> keeper_;
  SlabCache slabs_;

  std::mutex queue_mu_;          // held across Submit so batches reach the daemon in order
  std::vector<Command> pending_;
  std::mutex output_mu_;
  std::string output_;
};

}  // namespace weft::client_v1::detail
