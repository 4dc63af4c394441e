// SessionReaper: the periodic sweep for sessions without an Attach stream.
#include "server/session_reaper.h"

#include <algorithm>

namespace weft::server {

SessionReaper::SessionReaper(Engine& engine, double attach_timeout_s)
    : engine_(engine),
      timeout_(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
          std::chrono::duration<double>(attach_timeout_s))),
      thread_([this] { Loop(); }) {}

SessionReaper::~SessionReaper() { Stop(); }

void SessionReaper::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void SessionReaper::Loop() {
  const auto period = std::min<std::chrono::steady_clock::duration>(timeout_ / 4, std::chrono::seconds(1));
  std::unique_lock<std::mutex> lock(mu_);
  while (!cv_.wait_for(lock, period, [&] { return stop_; })) {
    lock.unlock();
    engine_.ReapUnattachedSessions(timeout_);
    lock.lock();
  }
}

}  // namespace weft::server
