// SessionReaper: the reaps of detached sessions, queued, and the periodic sweep for sessions
// without an Attach stream.
#include "server/session_reaper.h"

#include <algorithm>
#include <utility>
#include <vector>

#include <spdlog/spdlog.h>

namespace weft::server {

SessionReaper::SessionReaper(Engine& engine, double attach_timeout_s)
    : engine_(engine),
      timeout_(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
          std::chrono::duration<double>(attach_timeout_s))),
      thread_([this] { Loop(); }) {}

SessionReaper::~SessionReaper() { Stop(); }

void SessionReaper::ReapDetached(std::string id, std::weak_ptr<Session> watched, bool client_gone) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stop_) return;
    detached_.push_back(Detached{std::move(id), std::move(watched), client_gone});
  }
  cv_.notify_all();
}

void SessionReaper::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  JoinClosings(/*all=*/true);
}

void SessionReaper::JoinClosings(bool all) {
  for (auto it = closing_.begin(); it != closing_.end();) {
    if (all || it->done->load()) {
      it->thread.join();
      it = closing_.erase(it);
    } else {
      ++it;
    }
  }
}

// Ids are never reused, but the object is compared anyway: a session closed by its client and
// a new one can never be confused.
void SessionReaper::Reap(const Detached& d) {
  auto still = d.watched.lock();
  if (!still || engine_.FindSession(d.id) != still) return;   // closed meanwhile
  spdlog::info("session {}: attach stream ended ({})", still->label(),
               d.client_gone ? "client gone" : "closed by client");
  still.reset();
  (void)engine_.CloseSession(d.id, /*reaped=*/true);
}

void SessionReaper::Loop() {
  const auto period = std::min<std::chrono::steady_clock::duration>(timeout_ / 4, std::chrono::seconds(1));
  auto next_sweep = std::chrono::steady_clock::now() + period;
  std::unique_lock<std::mutex> lock(mu_);
  while (!stop_) {
    cv_.wait_until(lock, next_sweep, [&] { return stop_ || !detached_.empty(); });
    if (stop_) break;
    std::deque<Detached> batch;
    batch.swap(detached_);
    lock.unlock();
    for (auto& d : batch) {
      auto done = std::make_shared<std::atomic<bool>>(false);
      closing_.push_back(Closing{std::thread([this, d = std::move(d), done] {
                                   Reap(d);
                                   done->store(true);
                                 }),
                                 done});
    }
    JoinClosings(/*all=*/false);
    if (std::chrono::steady_clock::now() >= next_sweep) {
      engine_.ReapUnattachedSessions(timeout_);
      next_sweep = std::chrono::steady_clock::now() + period;
    }
    lock.lock();
  }
}

}  // namespace weft::server
