// LaunchWatchdog: the registry of running launches and the thread that cancels them.
#include "engine/runtime/launch_watchdog.h"

#include <algorithm>

namespace weft {

LaunchWatchdog::LaunchWatchdog() : thread_([this] { Loop(); }) {}

LaunchWatchdog::~LaunchWatchdog() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  thread_.join();
}

LaunchWatchdog::Watch::Watch(LaunchWatchdog& dog, const std::atomic<bool>* session_cancel, double time_limit_s)
    : dog_(dog), session_cancel_(session_cancel) {
  if (time_limit_s > 0) {
    has_deadline_ = true;
    deadline_ = std::chrono::steady_clock::now() +
                std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                    std::chrono::duration<double>(time_limit_s));
  }
  if (session_cancel_ && session_cancel_->load()) {
    reason_ = Reason::kSessionCancelled;
    __atomic_store_n(&word_, 1, __ATOMIC_RELAXED);
  }
  bool wake;
  {
    std::lock_guard<std::mutex> lock(dog_.mu_);
    dog_.watches_.push_back(this);
    wake = dog_.idle_;   // a thread between ticks sees this watch at its next tick
  }
  if (wake) dog_.cv_.notify_all();
}

LaunchWatchdog::Watch::~Watch() {
  std::lock_guard<std::mutex> lock(dog_.mu_);
  auto it = std::find(dog_.watches_.begin(), dog_.watches_.end(), this);
  if (it != dog_.watches_.end()) dog_.watches_.erase(it);
}

LaunchWatchdog::Reason LaunchWatchdog::Watch::reason() const {
  std::lock_guard<std::mutex> lock(dog_.mu_);
  return reason_;
}

void LaunchWatchdog::Loop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!stop_) {
    if (watches_.empty()) {
      idle_ = true;
      cv_.wait(lock, [&] { return stop_ || !watches_.empty(); });
      idle_ = false;
      continue;
    }
    const auto now = std::chrono::steady_clock::now();
    for (Watch* w : watches_) {
      if (w->reason_ != Reason::kNone) continue;
      Reason r = Reason::kNone;
      if (w->session_cancel_ && w->session_cancel_->load()) r = Reason::kSessionCancelled;
      else if (w->has_deadline_ && now >= w->deadline_) r = Reason::kTimeLimit;
      if (r == Reason::kNone) continue;
      w->reason_ = r;
      __atomic_store_n(&w->word_, 1, __ATOMIC_RELAXED);
    }
    cv_.wait_for(lock, kTick);
  }
}

}  // namespace weft
