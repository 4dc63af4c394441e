// SessionReaper: the thread that closes sessions whose client is gone. It reaps (1) sessions
// whose Attach stream ended, queued by the Attach reactor so that the close (cancel, wait for
// the session's executor, release its arrays) never runs on a gRPC thread; each such close
// runs on a short-lived thread of its own, so one slow close never delays another, and (2) every
// quarter of the attach timeout (at most once a second), sessions no Attach stream claimed
// within the timeout (Engine::ReapUnattachedSessions). Stops with the daemon.
#pragma once

#include <chrono>
#include <condition_variable>
#include <atomic>
#include <deque>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "engine/runtime/engine.h"

namespace weft::server {

class SessionReaper {
 public:
  SessionReaper(Engine& engine, double attach_timeout_s);
  ~SessionReaper();   // Stop()
  // Queues the reap of session `id` after its Attach stream ended; it is closed (as reaped)
  // only if it is still the object `watched` (it may have been closed by its client meanwhile).
  // `client_gone`: the stream broke rather than being closed by the client (for the log).
  void ReapDetached(std::string id, std::weak_ptr<Session> watched, bool client_gone);
  // Stops the thread; reaps still queued are left to the engine's own close of every session.
  void Stop();

 private:
  struct Detached {
    std::string id;
    std::weak_ptr<Session> watched;
    bool client_gone = false;
  };
  struct Closing {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  void Loop();
  void Reap(const Detached& d);
  void JoinClosings(bool all);
  Engine& engine_;
  std::chrono::steady_clock::duration timeout_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::deque<Detached> detached_;
  std::list<Closing> closing_;   // only touched by the reaper's thread (and Stop after it)
  std::thread thread_;   // last: starts when everything above is initialised
};

}  // namespace weft::server
