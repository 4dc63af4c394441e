// SerialQueue: a worker thread draining an ordered task queue.
#include "engine/runtime/serial_queue.h"

namespace weft {

SerialQueue::SerialQueue() = default;

SerialQueue::~SerialQueue() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void SerialQueue::Post(std::function<void()> task) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    tasks_.push_back(std::move(task));
    if (!thread_.joinable()) thread_ = std::thread([this] { Loop(); });
  }
  cv_.notify_one();
}

void SerialQueue::WaitIdle() {
  std::unique_lock<std::mutex> lock(mu_);
  idle_cv_.wait(lock, [&] { return tasks_.empty() && !running_task_; });
}

void SerialQueue::RunAndWait(std::function<void()> task) {
  {
    std::unique_lock<std::mutex> lock(mu_);
    if (!tasks_.empty() || running_task_) {
      tasks_.push_back(std::move(task));
      if (!thread_.joinable()) thread_ = std::thread([this] { Loop(); });
      cv_.notify_one();
      idle_cv_.wait(lock, [&] { return tasks_.empty() && !running_task_; });
      return;
    }
    running_task_ = true;   // the worker starts nothing while this runs here
  }
  RunClaimed(std::move(task));
}

bool SerialQueue::RunHereOrPost(std::function<void()> task) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!tasks_.empty() || running_task_) {
      tasks_.push_back(std::move(task));
      if (!thread_.joinable()) thread_ = std::thread([this] { Loop(); });
      cv_.notify_one();
      return false;
    }
    running_task_ = true;   // the worker starts nothing while this runs here
  }
  RunClaimed(std::move(task));
  return true;
}

void SerialQueue::RunClaimed(std::function<void()> task) {
  task();
  task = nullptr;   // release captured references before the queue counts as idle
  {
    std::lock_guard<std::mutex> lock(mu_);
    running_task_ = false;
    if (tasks_.empty()) idle_cv_.notify_all();
  }
  cv_.notify_one();   // tasks posted meanwhile
}

uint64_t SerialQueue::pending() const {
  std::lock_guard<std::mutex> lock(mu_);
  return tasks_.size() + (running_task_ ? 1 : 0);
}

void SerialQueue::Loop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    cv_.wait(lock, [&] { return stop_ || (!tasks_.empty() && !running_task_); });
    if (tasks_.empty() || running_task_) {
      if (stop_) return;
      continue;
    }
    auto task = std::move(tasks_.front());
    tasks_.pop_front();
    running_task_ = true;
    lock.unlock();
    task();
    task = nullptr;   // release captured references outside the lock
    lock.lock();
    running_task_ = false;
    if (tasks_.empty()) idle_cv_.notify_all();
  }
}

}  // namespace weft
