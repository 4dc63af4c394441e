// Reaps sessions that were opened but never attached: a thread that, every quarter of the
// attach timeout (at most once a second), closes every session no Attach stream claimed
// within the timeout (Engine::ReapUnattachedSessions). Stops with the daemon.
#pragma once

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "engine/runtime/engine.h"

namespace weft::server {

class SessionReaper {
 public:
  SessionReaper(Engine& engine, double attach_timeout_s);
  ~SessionReaper();   // Stop()
  void Stop();

 private:
  void Loop();
  Engine& engine_;
  std::chrono::steady_clock::duration timeout_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace weft::server
