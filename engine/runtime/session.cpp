// Session: held arrays, first-error bookkeeping and print output.
#include "engine/runtime/session.h"

#include <vector>

namespace weft {

std::shared_ptr<Allocation> Session::Find(uint64_t handle) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = arrays_.find(handle);
  return it == arrays_.end() ? nullptr : it->second;
}

void Session::Hold(const std::shared_ptr<Allocation>& a) {
  std::lock_guard<std::mutex> lock(mu_);
  arrays_[a->handle] = a;
  if (a->grad && !arrays_.count(a->grad->handle)) {
    arrays_[a->grad->handle] = a->grad;
    grad_owner_[a->grad->handle] = a->handle;
    owned_grads_.emplace(a->handle, a->grad->handle);
  }
}

bool Session::Release(uint64_t handle) {
  std::vector<std::shared_ptr<Allocation>> drop;   // freed after the lock is let go
  std::lock_guard<std::mutex> lock(mu_);
  auto it = arrays_.find(handle);
  if (it == arrays_.end()) return false;
  if (grad_owner_.count(handle)) return true;   // a gradient lives as long as its array
  auto [first, last] = owned_grads_.equal_range(handle);
  for (auto g = first; g != last; ++g) {
    auto held = arrays_.find(g->second);
    if (held != arrays_.end()) {
      drop.push_back(std::move(held->second));
      arrays_.erase(held);
    }
    grad_owner_.erase(g->second);
  }
  owned_grads_.erase(first, last);
  drop.push_back(std::move(it->second));
  arrays_.erase(it);
  return true;
}

void Session::ReplaceGrad(const std::shared_ptr<Allocation>& a, std::shared_ptr<Allocation> g) {
  std::shared_ptr<Allocation> old;   // dropped after the lock is let go
  std::lock_guard<std::mutex> lock(mu_);
  old = std::move(a->grad);
  a->grad = std::move(g);
}

bool Session::Holds(uint64_t handle) const {
  std::lock_guard<std::mutex> lock(mu_);
  return arrays_.count(handle) != 0;
}

size_t Session::array_count() const {
  std::lock_guard<std::mutex> lock(mu_);
  return arrays_.size();
}

void Session::ReleaseAll() {
  graphs.clear();   // they hold arrays
  std::unordered_map<uint64_t, std::shared_ptr<Allocation>> drop;
  {
    std::lock_guard<std::mutex> lock(mu_);
    drop.swap(arrays_);
    grad_owner_.clear();
    owned_grads_.clear();
  }
  geometry_.Clear();   // objects hold arrays too
}

bool Session::failed() const {
  std::lock_guard<std::mutex> lock(mu_);
  return !error_.ok();
}

void Session::Fail(const Status& s, const SourceLocation& origin) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!error_.ok()) {
    ++skipped_;
    return;
  }
  error_ = s;
  error_origin_ = origin;
}

void Session::CountSkipped() {
  std::lock_guard<std::mutex> lock(mu_);
  ++skipped_;
}

void Session::AppendOutput(const std::string& text) {
  std::lock_guard<std::mutex> lock(mu_);
  if (output_.size() < (16u << 20)) output_ += text;
}

void Session::SetTimingResult(std::vector<TimedActivity> timing, uint64_t dropped) {
  std::lock_guard<std::mutex> lock(mu_);
  timing_ended_ = true;
  timing_ = std::move(timing);
  timing_dropped_ = dropped;
}

Session::SyncResult Session::TakeResult() {
  std::lock_guard<std::mutex> lock(mu_);
  SyncResult r;
  r.error = error_;
  if (!error_.ok() && skipped_ > 0)
    r.error = Status(error_.code(), error_.message() + " (" + std::to_string(skipped_) +
                                        " later command(s) were skipped)");
  r.origin = error_origin_;
  r.output.swap(output_);
  r.timing_ended = timing_ended_;
  r.timing.swap(timing_);
  r.timing_dropped = timing_dropped_;
  timing_ended_ = false;
  timing_.clear();
  timing_dropped_ = 0;
  error_ = Status::Ok();
  error_origin_ = {};
  skipped_ = 0;
  return r;
}

}  // namespace weft
