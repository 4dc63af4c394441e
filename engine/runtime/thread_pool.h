// The CPU launch pool: persistent workers that run chunks of a parallel loop. Several callers
// (sessions) may run loops at once; each caller also works on its own loop and returns when
// every chunk of it is done. Small loops run inline on the calling thread.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace weft {

class ThreadPool {
 public:
  // `threads` = total parallelism including the caller (0 = all cores). threads-1 workers.
  explicit ThreadPool(int threads = 0);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return size_; }

  // Runs body(begin, end) over disjoint chunks covering [0, n). Loops of at most `inline_below`
  // items run on the calling thread in one call. Chunks are at least `min_chunk` items.
  void ParallelFor(int64_t n, const std::function<void(int64_t, int64_t)>& body,
                   int64_t min_chunk = 64, int64_t inline_below = 1024);

 private:
  struct Job {
    const std::function<void(int64_t, int64_t)>* body = nullptr;
    int64_t n = 0;
    int64_t chunk = 1;
    int64_t chunks = 0;
    std::atomic<int64_t> next{0};
    std::atomic<int64_t> done{0};
    std::mutex mu;
    std::condition_variable cv;
  };
  // Runs chunks of `job` until none is left; returns after finishing at least zero chunks.
  static void Work(Job& job);
  void WorkerLoop();

  int size_ = 1;
  std::vector<std::thread> workers_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::shared_ptr<Job>> jobs_;
  bool stop_ = false;
};

}  // namespace weft
