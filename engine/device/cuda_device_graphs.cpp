// CUDA graphs of a session's commands (GraphCommand, docs/graphs.md). Owns CudaDevice::Graph
// and capture on the session's stream: BeginCapture starts stream capture (relaxed mode: the
// daemon's other threads keep serving their sessions), the command executor queues the graph's
// launches, fills and copies as usual (each launch then writes errors into the capture's own
// slots), EndCapture instantiates the graph. LaunchGraph queues one cuGraphLaunch, then copies
// the graph's error slots into the stream's free ones and clears them, and appends the graph's
// launches to the stream's pending list: a replayed launch's error (bounds, a trap) reads back at
// the next synchronize with its kernel name and the client's file:line, as any launch's.
#include <cstring>

#include "engine/device/cuda_device.h"
#include "engine/runtime/session.h"

namespace weft {

class CudaDevice::Graph {
 public:
  Graph(CudaDevice* device, uint64_t generation) : device_(device), generation_(generation) {}
  Graph(const Graph&) = delete;
  Graph& operator=(const Graph&) = delete;
  ~Graph() {
    // After a reset the context that held them is gone (and the graph with it).
    if (device_->lost() || device_->generation_.load() != generation_) return;
    std::shared_lock<std::shared_mutex> reset(device_->reset_mu_);
    if (!device_->MakeCurrent().ok()) return;
    const jit::CudaDriver* d = device_->driver_;
    if (exec) d->GraphExecDestroy(exec);
    if (graph) d->GraphDestroy(graph);
    if (slots) d->MemFree(slots);
  }

  CudaDevice* device_;
  uint64_t generation_;
  std::string session_id;
  jit::CuGraph graph = nullptr;
  jit::CuGraphExec exec = nullptr;
  jit::CuDevicePtr slots = 0;      // one launch_error_t per launch, zero between replays
  std::vector<Pending> launches;   // slot = index
};

bool CudaDevice::GraphsSupported() const {
  return driver_->StreamBeginCapture && driver_->StreamEndCapture && driver_->GraphInstantiate &&
         driver_->GraphLaunch && driver_->GraphExecDestroy && driver_->GraphDestroy;
}

Status CudaDevice::BeginCapture(Session& s) {
  if (!GraphsSupported()) return FailedPrecondition(name_ + ": the CUDA driver has no graph capture");
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  if (st->capture) return FailedPrecondition("a graph is already being captured on this stream");
  auto capture = std::make_unique<Stream::Capture>();
  const size_t bytes = kErrorSlots * sizeof(wp::launch_error_t);
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemAlloc(&capture->slots, bytes), "cuMemAlloc (graph error slots)"));
  // Zeroed on the stream before the capture starts (an operation of the stream, not the graph).
  Status st_ok = driver_->Check(driver_->MemsetD8Async(capture->slots, 0, bytes, st->stream), "cuMemsetD8Async");
  if (st_ok.ok())
    st_ok = driver_->Check(driver_->StreamBeginCapture(st->stream, jit::kCuStreamCaptureModeRelaxed),
                           "cuStreamBeginCapture");
  if (!st_ok.ok()) {
    driver_->MemFree(capture->slots);
    return st_ok;
  }
  st->capture = std::move(capture);
  return Status::Ok();
}

Expected<std::shared_ptr<CudaDevice::Graph>> CudaDevice::EndCapture(Session& s, bool keep) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  Stream* st = FindStream(s.id());
  if (!st || !st->capture) return FailedPrecondition("no graph is being captured on this stream");
  std::unique_ptr<Stream::Capture> capture = std::move(st->capture);
  auto g = std::make_shared<Graph>(this, st->generation);
  g->session_id = s.id();
  g->slots = capture->slots;   // freed by the Graph from here on
  g->launches = std::move(capture->launches);
  Status ended = driver_->Check(driver_->StreamEndCapture(st->stream, &g->graph), "cuStreamEndCapture");
  if (!capture->refused.empty()) return FailedPrecondition("graph capture: " + capture->refused);
  if (!keep) return FailedPrecondition("graph capture abandoned");
  if (!ended.ok()) return FailedPrecondition("graph capture: " + ended.message());
  if (!g->graph) return FailedPrecondition("graph capture: the driver returned no graph");
  Status made = driver_->Check(driver_->GraphInstantiate(&g->exec, g->graph, 0), "cuGraphInstantiateWithFlags");
  if (!made.ok()) return FailedPrecondition("graph capture: " + made.message());
  return g;
}

Status CudaDevice::LaunchGraph(Session& s, Graph& g) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  if (g.device_ != this || g.session_id != s.id())
    return InvalidArgument("graph captured by another session or on another device");
  if (g.generation_ != generation_.load())
    return FailedPrecondition(name_ + " was reset since this graph was captured: capture it again");
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  if (st->capture) return FailedPrecondition("a graph cannot be launched while one is being captured");
  const size_t n = g.launches.size();
  WEFT_RETURN_IF_ERROR(MakeRoom(s, *st, n));
  {
    TimedSpan timed(*this, *st, kTimingGraph, "graph launch");
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->GraphLaunch(g.exec, st->stream), "cuGraphLaunch"));
  }
  if (n == 0) return Status::Ok();
  const size_t bytes = n * sizeof(wp::launch_error_t);
  const jit::CuDevicePtr dst = st->errors + st->pending.size() * sizeof(wp::launch_error_t);
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemcpyDtoDAsync(dst, g.slots, bytes, st->stream),
                                      "cuMemcpyDtoDAsync (graph launch errors)"));
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemsetD8Async(g.slots, 0, bytes, st->stream), "cuMemsetD8Async"));
  st->pending.insert(st->pending.end(), g.launches.begin(), g.launches.end());
  return Status::Ok();
}

}  // namespace weft
