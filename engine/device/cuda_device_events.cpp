// Cross-process stream ordering on a CudaDevice: interprocess CUDA events of a client process
// (cuIpcGetEventHandle bytes) opened per session, waited on by the session's stream or recorded
// on it, so that a framework stream in the client and the session's stream in the daemon order
// their work on the GPU without a host-side synchronize (docs/interop.md, "Ordering"); and who
// may use a handle (its first session, or the sessions of that one's principal once shared).
#include <algorithm>
#include <cstring>

#include "engine/device/cuda_device.h"
#include "engine/runtime/session.h"

namespace weft {

Expected<jit::CuEvent> CudaDevice::OpenEventLocked(const Session& s, const std::string& handle, bool share) {
  const std::string& session_id = s.id();
  auto owner = event_owner_.find(handle);
  if (owner != event_owner_.end() && owner->second.session_id != session_id) {
    if (!owner->second.shared || owner->second.principal != s.options().principal)
      return PermissionDenied("this CUDA IPC event handle (" + IpcHandlePrefix(handle) +
                              "...) is used by another session; a session orders work with events of its own "
                              "client process, or with interprocess events (wp.Event(interprocess=True)) that "
                              "a session of the same principal shared");
  } else if (owner != event_owner_.end() && share) {
    owner->second.shared = true;
  }
  const uint64_t gen = generation_.load();
  auto& list = ipc_events_[session_id];
  auto it = std::find_if(list.begin(), list.end(), [&](const OpenedEvent& e) { return e.handle == handle; });
  if (it != list.end()) {
    OpenedEvent e = *it;
    list.erase(it);
    if (e.generation == gen) {          // most recently used last
      list.push_back(e);
      return e.event;
    }
    // opened before a device reset: the event went with the old context
  }
  jit::CuIpcEventHandle h{};
  std::memcpy(h.reserved, handle.data(), sizeof(h.reserved));
  jit::CuEvent ev = nullptr;
  jit::CuResult r = driver_->IpcOpenEventHandle(&ev, h);
  if (r != 0 || ev == nullptr)
    return InvalidArgument("the CUDA IPC event handle (" + IpcHandlePrefix(handle) + "...) could not be opened on " + name_ +
                           " (" + driver_->ErrorName(r) +
                           "): not the handle of a live interprocess event (cudaEventInterprocess | "
                           "cudaEventDisableTiming) of a process on this machine");
  if (list.size() >= kEventsPerSession) {
    const OpenedEvent& old = list.front();
    if (old.generation == gen) driver_->EventDestroy(old.event);
    ForgetOwnerLocked(session_id, old.handle);
    list.erase(list.begin());
  }
  list.push_back(OpenedEvent{handle, ev, gen});
  if (owner == event_owner_.end()) event_owner_[handle] = EventOwner{session_id, s.options().principal, share};
  return ev;
}

void CudaDevice::ForgetOwnerLocked(const std::string& session_id, const std::string& handle) {
  auto owner = event_owner_.find(handle);
  if (owner != event_owner_.end() && owner->second.session_id == session_id) event_owner_.erase(owner);
}

Status CudaDevice::IpcEvent(Session& s, const std::string& handle, EventUse use) {
  if (handle.size() != sizeof(jit::CuIpcEventHandle))
    return InvalidArgument("a CUDA IPC event handle has " + std::to_string(sizeof(jit::CuIpcEventHandle)) +
                           " bytes, got " + std::to_string(handle.size()));
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  std::lock_guard<std::mutex> lock(events_mu_);
  WEFT_ASSIGN_OR_RETURN(jit::CuEvent ev, OpenEventLocked(s, handle, use == EventUse::kShare));
  if (use == EventUse::kShare) return Status::Ok();
  const bool record = use == EventUse::kRecord;
  jit::CuResult r = record ? driver_->EventRecord(ev, st->stream) : driver_->StreamWaitEvent(st->stream, ev, 0);
  if (r == 0) return Status::Ok();
  if (jit::IsStickyCudaError(r)) return driver_->Check(r, record ? "cuEventRecord" : "cuStreamWaitEvent");
  return InvalidArgument(std::string("the CUDA IPC event (") + IpcHandlePrefix(handle) + "...) could not be " +
                         (record ? "recorded on " : "waited on by ") + "the session's stream on " + name_ + " (" +
                         driver_->ErrorName(r) + "): an event of another GPU's context?");
}

size_t CudaDevice::IpcEventCount() const {
  std::lock_guard<std::mutex> lock(events_mu_);
  size_t n = 0;
  for (const auto& [id, list] : ipc_events_) n += list.size();
  return n;
}

void CudaDevice::ForgetEvents(const std::string& session_id) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);   // not during a device reset
  std::lock_guard<std::mutex> lock(events_mu_);
  auto it = ipc_events_.find(session_id);
  if (it == ipc_events_.end()) return;
  const uint64_t gen = generation_.load();
  bool current = false;
  for (const OpenedEvent& e : it->second) {
    if (e.generation == gen) {
      if (!current) {
        (void)MakeCurrent();
        current = true;
      }
      driver_->EventDestroy(e.event);
    }
    ForgetOwnerLocked(session_id, e.handle);
  }
  ipc_events_.erase(it);
}

}  // namespace weft
