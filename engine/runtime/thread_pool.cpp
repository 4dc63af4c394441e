// ThreadPool: shared job queue, atomic chunk claiming, caller participation.
#include "engine/runtime/thread_pool.h"

#include <algorithm>

namespace weft {

ThreadPool::ThreadPool(int threads) {
  if (threads <= 0) threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  size_ = threads;
  for (int i = 1; i < threads; ++i) workers_.emplace_back([this] { WorkerLoop(); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  for (auto& t : workers_) t.join();
}

void ThreadPool::Work(Job& job) {
  while (true) {
    int64_t c = job.next.fetch_add(1, std::memory_order_relaxed);
    if (c >= job.chunks) return;
    int64_t b = c * job.chunk;
    int64_t e = std::min(job.n, b + job.chunk);
    (*job.body)(b, e);
    if (job.done.fetch_add(1, std::memory_order_acq_rel) + 1 == job.chunks) {
      std::lock_guard<std::mutex> lock(job.mu);
      job.cv.notify_all();
    }
  }
}

void ThreadPool::WorkerLoop() {
  while (true) {
    std::shared_ptr<Job> job;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
      if (stop_) return;
      job = jobs_.front();
      // Drop the job from the queue once every chunk has been claimed.
      if (job->next.load(std::memory_order_relaxed) >= job->chunks) {
        jobs_.pop_front();
        continue;
      }
    }
    Work(*job);
    std::lock_guard<std::mutex> lock(mu_);
    if (!jobs_.empty() && jobs_.front() == job) jobs_.pop_front();
  }
}

void ThreadPool::ParallelFor(int64_t n, const std::function<void(int64_t, int64_t)>& body,
                             int64_t min_chunk, int64_t inline_below) {
  if (n <= 0) return;
  if (size_ == 1 || n <= inline_below) {
    body(0, n);
    return;
  }
  auto job = std::make_shared<Job>();
  job->body = &body;
  job->n = n;
  // About 4 chunks per thread for balance, never smaller than min_chunk.
  int64_t target = static_cast<int64_t>(size_) * 4;
  job->chunk = std::max<int64_t>(std::max<int64_t>(min_chunk, 1), (n + target - 1) / target);
  job->chunks = (n + job->chunk - 1) / job->chunk;
  {
    std::lock_guard<std::mutex> lock(mu_);
    jobs_.push_back(job);
  }
  cv_.notify_all();
  Work(*job);
  std::unique_lock<std::mutex> lock(job->mu);
  job->cv.wait(lock, [&] { return job->done.load(std::memory_order_acquire) == job->chunks; });
  std::lock_guard<std::mutex> qlock(mu_);
  auto it = std::find(jobs_.begin(), jobs_.end(), job);
  if (it != jobs_.end()) jobs_.erase(it);
}

}  // namespace weft
