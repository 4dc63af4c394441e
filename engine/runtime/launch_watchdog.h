// Stops launches that must not run on. Every running CPU launch registers its cancel word (the
// int32 its kernel polls through wp::launch_context_t::cancel, and the launch loop checks per
// chunk of threads) together with its session's cancel flag and its time limit; one thread
// sets the word when the session is cancelled or the limit passes, and records why.
// The thread wakes every kTick while launches are registered and sleeps otherwise; a new watch
// wakes it only from that sleep (short launches in a row cost no thread switch each).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

namespace weft {

class LaunchWatchdog {
 public:
  static constexpr std::chrono::milliseconds kTick{10};
  enum class Reason { kNone, kSessionCancelled, kTimeLimit };

  LaunchWatchdog();
  ~LaunchWatchdog();
  LaunchWatchdog(const LaunchWatchdog&) = delete;
  LaunchWatchdog& operator=(const LaunchWatchdog&) = delete;

  // One launch, watched while this object lives. `session_cancel` may be null; a time limit
  // of 0 means none.
  class Watch {
   public:
    Watch(LaunchWatchdog& dog, const std::atomic<bool>* session_cancel, double time_limit_s);
    ~Watch();
    Watch(const Watch&) = delete;
    Watch& operator=(const Watch&) = delete;
    const int32_t* word() const { return &word_; }
    // Why the word was set (kNone while it is not).
    Reason reason() const;

   private:
    friend class LaunchWatchdog;
    LaunchWatchdog& dog_;
    const std::atomic<bool>* session_cancel_;
    bool has_deadline_ = false;
    std::chrono::steady_clock::time_point deadline_;
    int32_t word_ = 0;   // written with __atomic_store_n, read by kernels with __atomic_load_n
    Reason reason_ = Reason::kNone;   // guarded by dog_.mu_
  };

 private:
  void Loop();
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<Watch*> watches_;
  bool stop_ = false;
  bool idle_ = false;   // the thread waits for a first watch (not for its next tick)
  std::thread thread_;
};

}  // namespace weft
