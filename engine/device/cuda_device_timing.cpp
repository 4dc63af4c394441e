// CUDA activity timing on a CudaDevice (wp.timing_begin / wp.timing_end, docs/cuda.md "Activity
// timing"): a session's filter per GPU, the pair of events recorded around each timed operation
// on the session's stream (TimedSpan), and their collection into elapsed times once the stream
// is idle. Events are the daemon's own (with timing), reused from one collection to the next;
// a stream keeps at most kMaxTimedActivities records, so a client cannot make the daemon hold
// events without bound by timing forever.
#include "engine/device/cuda_device.h"
#include "engine/runtime/session.h"

namespace weft {

Status CudaDevice::SetTiming(Session& s, uint32_t filter) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  Stream* st = nullptr;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (filter) timing_filters_[s.id()] = filter;
    else timing_filters_.erase(s.id());
    auto it = streams_.find(s.id());
    if (it != streams_.end()) st = it->second.get();
  }
  if (st == nullptr) return Status::Ok();   // a stream made later takes the filter
  st->timing_filter.store(filter);
  if (filter) {   // a new BEGIN: what an earlier one recorded is discarded
    std::lock_guard<std::mutex> lock(st->timing_mu);
    RecycleTimingLocked(*st);
    st->timing_dropped = 0;
  }
  return Status::Ok();
}

void CudaDevice::TakeTiming(Session& s, std::vector<TimedActivity>* out, uint64_t* dropped, bool keep) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  Stream* st = FindStream(s.id());
  if (st == nullptr) return;
  std::lock_guard<std::mutex> lock(st->timing_mu);
  if (keep && !st->timed.empty() && MakeCurrent().ok()) {
    for (const Stream::Timed& t : st->timed) {
      float ms = 0;
      // Both events completed (the stream is idle); a pair the driver cannot measure (a reset
      // in between) is reported as not timed.
      if (driver_->EventElapsedTime(&ms, t.start, t.end) == 0) {
        out->push_back(TimedActivity{name_, t.name, t.filter, static_cast<double>(ms)});
      } else {
        ++st->timing_dropped;
      }
    }
  }
  if (keep) *dropped += st->timing_dropped;
  st->timing_dropped = 0;
  RecycleTimingLocked(*st);
}

jit::CuEvent CudaDevice::TimingEventLocked(Stream& st) {
  if (!st.spare_events.empty()) {
    jit::CuEvent e = st.spare_events.back();
    st.spare_events.pop_back();
    return e;
  }
  jit::CuEvent e = nullptr;
  if (driver_->EventCreate(&e, 0) != 0) return nullptr;   // CU_EVENT_DEFAULT: with timing
  return e;
}

void CudaDevice::RecycleTimingLocked(Stream& st) {
  for (const Stream::Timed& t : st.timed) {
    for (jit::CuEvent e : {t.start, t.end}) {
      if (st.spare_events.size() < kSpareTimingEvents) st.spare_events.push_back(e);
      else driver_->EventDestroy(e);
    }
  }
  st.timed.clear();
}

CudaDevice::TimedSpan::TimedSpan(CudaDevice& device, Stream& st, uint32_t filter, const char* name,
                                 const std::string& suffix)
    : device_(device), st_(st) {
  if ((st.timing_filter.load(std::memory_order_relaxed) & filter) == 0 || st.capture) return;
  std::lock_guard<std::mutex> lock(st.timing_mu);
  if (st.timed.size() >= kMaxTimedActivities) {
    ++st.timing_dropped;
    return;
  }
  jit::CuEvent start = device.TimingEventLocked(st);
  jit::CuEvent end = start ? device.TimingEventLocked(st) : nullptr;
  if (start && end && device.driver_->EventRecord(start, st.stream) == 0) {
    record_ = Stream::Timed{std::string(name) + suffix, filter, start, end};
    return;
  }
  ++st.timing_dropped;   // the driver refused an event: this operation runs untimed
  for (jit::CuEvent e : {start, end})
    if (e) st.spare_events.push_back(e);
}

CudaDevice::TimedSpan::~TimedSpan() {
  if (record_.start == nullptr) return;
  std::lock_guard<std::mutex> lock(st_.timing_mu);
  if (device_.driver_->EventRecord(record_.end, st_.stream) == 0) {
    st_.timed.push_back(std::move(record_));
    return;
  }
  ++st_.timing_dropped;
  st_.spare_events.push_back(record_.start);
  st_.spare_events.push_back(record_.end);
}

// ---- timing events of a session ----

Status CudaDevice::RecordTimedEvent(Session& s, uint64_t id) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  const uint64_t gen = generation_.load();
  std::lock_guard<std::mutex> lock(timed_events_mu_);
  auto& events = timed_events_[s.id()];
  auto it = events.find(id);
  if (it == events.end() || it->second.generation != gen) {   // new, or its context was reset
    if (it == events.end() && events.size() >= kTimedEventsPerSession)
      return ResourceExhausted("the session holds " + std::to_string(events.size()) + " timing events on " + name_ +
                               ", the limit (a wp.Event is released when it is collected)");
    jit::CuEvent e = nullptr;
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->EventCreate(&e, 0), "cuEventCreate"));
    it = events.insert_or_assign(id, TimedEvent{e, gen}).first;
  }
  return driver_->Check(driver_->EventRecord(it->second.event, st->stream), "cuEventRecord");
}

void CudaDevice::DestroyTimedEvent(Session& s, uint64_t id) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  std::lock_guard<std::mutex> lock(timed_events_mu_);
  auto session = timed_events_.find(s.id());
  if (session == timed_events_.end()) return;
  auto it = session->second.find(id);
  if (it == session->second.end()) return;
  if (it->second.generation == generation_.load() && MakeCurrent().ok()) driver_->EventDestroy(it->second.event);
  session->second.erase(it);
}

Expected<double> CudaDevice::TimedEventElapsed(Session& s, uint64_t start_id, uint64_t end_id) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  std::lock_guard<std::mutex> lock(timed_events_mu_);
  auto session = timed_events_.find(s.id());
  const uint64_t gen = generation_.load();
  jit::CuEvent events[2] = {nullptr, nullptr};
  const uint64_t ids[2] = {start_id, end_id};
  for (int i = 0; i < 2; ++i) {
    const TimedEvent* e = nullptr;
    if (session != timed_events_.end()) {
      auto it = session->second.find(ids[i]);
      if (it != session->second.end()) e = &it->second;
    }
    if (e == nullptr)
      return NotFound("timing event " + std::to_string(ids[i]) + " was never recorded on " + name_ +
                      " in this session (or was released)");
    if (e->generation != gen)
      return FailedPrecondition(name_ + " was reset since timing event " + std::to_string(ids[i]) +
                                " was recorded: record it again");
    events[i] = e->event;
  }
  float ms = 0;
  const jit::CuResult r = driver_->EventElapsedTime(&ms, events[0], events[1]);
  if (r == jit::kCuErrorNotReady)
    return FailedPrecondition("timing event " + std::to_string(end_id) + " is recorded after work that has not "
                              "finished (recorded again by another thread?)");
  WEFT_RETURN_IF_ERROR(driver_->Check(r, "cuEventElapsedTime"));
  return static_cast<double>(ms);
}

size_t CudaDevice::TimedEventCount() const {
  std::lock_guard<std::mutex> lock(timed_events_mu_);
  size_t n = 0;
  for (const auto& [id, events] : timed_events_) n += events.size();
  return n;
}

void CudaDevice::ForgetTimedEvents(const std::string& session_id) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  std::lock_guard<std::mutex> lock(timed_events_mu_);
  auto session = timed_events_.find(session_id);
  if (session == timed_events_.end()) return;
  const uint64_t gen = generation_.load();
  bool current = false;
  for (const auto& [id, e] : session->second) {
    if (e.generation != gen) continue;
    if (!current) current = MakeCurrent().ok();
    if (current) driver_->EventDestroy(e.event);
  }
  timed_events_.erase(session);
}

}  // namespace weft
