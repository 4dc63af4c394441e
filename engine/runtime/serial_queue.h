// A session's executor: one thread that runs posted tasks in order, started by the first Post
// (a session that never posts work costs no thread). WaitIdle blocks until every
// task posted before it has finished. RunAndWait runs a task after everything posted before it
// and returns when it is done: on the calling thread when the queue is idle (no thread hand-off,
// the sync-point fast path), else posted and waited for. Tasks never overlap either way.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>

namespace weft {

class SerialQueue {
 public:
  SerialQueue();
  ~SerialQueue();   // runs what is queued, then stops
  SerialQueue(const SerialQueue&) = delete;
  SerialQueue& operator=(const SerialQueue&) = delete;

  void Post(std::function<void()> task);
  void WaitIdle();
  void RunAndWait(std::function<void()> task);
  // Runs `task` on the calling thread when nothing is queued or running (no thread switch),
  // else queues it behind the others and returns at once. Returns whether it ran here.
  bool RunHereOrPost(std::function<void()> task);
  uint64_t pending() const;

 private:
  void Loop();
  // Runs `task` on the calling thread, which set running_task_ under the lock, then clears it.
  void RunClaimed(std::function<void()> task);
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::condition_variable idle_cv_;
  std::deque<std::function<void()>> tasks_;
  bool running_task_ = false;
  bool stop_ = false;
  std::thread thread_;
};

}  // namespace weft
