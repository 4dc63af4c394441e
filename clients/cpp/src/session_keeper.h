// Holds SessionService.Attach open on a background thread for the life of the session: when
// this process dies the stream breaks and the daemon frees everything the session owned.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <memory>
#include <string>
#include <thread>

#include "weft/client/status.h"
#include "weft/v1/session.grpc.pb.h"

namespace weft::inline client_v1::detail {

class SessionKeeper {
 public:
  // Starts the stream; `context` carries the session metadata and is owned by the keeper.
  SessionKeeper(v1::SessionService::Stub* stub, std::unique_ptr<grpc::ClientContext> context,
                std::string session_id);
  ~SessionKeeper();   // Stop()
  SessionKeeper(const SessionKeeper&) = delete;
  SessionKeeper& operator=(const SessionKeeper&) = delete;

  // Waits until the daemon has claimed the stream for the session (its first event, "attached
  // #<label>"): from then on this process's death reaps the session at once. An error when the
  // stream ended first (the daemon refused it or is gone) or nothing came within `timeout`.
  Status WaitAttached(std::chrono::milliseconds timeout);
  // Cancels the stream and joins the thread. Idempotent.
  void Stop();
  // False once the stream has ended (daemon gone, session closed or Stop()).
  bool attached() const { return attached_.load(); }
  // Messages the daemon sent on the stream, in order (e.g. a shutdown notice).
  std::string last_event() const;

 private:
  void Run(v1::SessionService::Stub* stub, std::string session_id);

  std::unique_ptr<grpc::ClientContext> context_;
  std::atomic<bool> attached_{true};
  mutable std::mutex mu_;
  std::string last_event_;
  bool hello_seen_ = false;   // under mu_
  bool ended_ = false;        // under mu_
  std::string end_message_;   // under mu_: the stream's final status when it ended
  std::condition_variable cv_;
  std::thread thread_;
};

}  // namespace weft::client_v1::detail
