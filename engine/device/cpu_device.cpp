// CpuDevice: memcpy/memset on shared memory, strided fill/copy (array_view), launches through
// RunCpuLaunch under the watchdog.
#include "engine/device/cpu_device.h"

#include <cstdio>
#include <cstring>

#include "engine/runtime/cpu_launch.h"
#include "engine/runtime/session.h"

namespace weft {

CpuDevice::CpuDevice(ThreadPool& pool, LaunchWatchdog* watchdog, CpuDeviceOptions options)
    : pool_(pool), watchdog_(watchdog), options_(options), slabs_(options.slabs) {}

Status CpuDevice::Upload(Session&, const MemoryBlock& dst, uint64_t offset, const void* src, uint64_t n) {
  if (n) std::memcpy(static_cast<char*>(dst.data) + offset, src, n);
  return Status::Ok();
}

Status CpuDevice::Download(Session&, const MemoryBlock& src, uint64_t offset, void* dst, uint64_t n) {
  if (n) std::memcpy(dst, static_cast<const char*>(src.data) + offset, n);
  return Status::Ok();
}

Status CpuDevice::CopyBlock(Session&, const MemoryBlock& dst, const MemoryBlock& src, uint64_t n) {
  if (n) std::memcpy(dst.data, src.data, n);
  return Status::Ok();
}

Status CpuDevice::Fill(Session& s, const ArrayView& dst, const std::string& value) {
  return FillView(dst, value, s.cancel_flag());
}

Status CpuDevice::Copy(Session& s, const ArrayView& dst, const ArrayView& src) {
  return CopyView(dst, src, s.cancel_flag());
}

Status CpuDevice::Launch(Session& s, const KernelLaunch& l, std::string* output) {
  CpuLaunch launch;
  launch.module = l.module.get();
  launch.kernel = l.kernel;
  launch.dim = l.dim;
  launch.args = l.args;
  launch.adj_args = l.adj_args;
  launch.block_dim = l.block_dim;
  launch.print_capacity = options_.print_capacity;
  std::shared_ptr<geometry::LaunchTable> geometry = s.geometry().TableFor("cpu");   // alive for the launch
  if (geometry) launch.geometry = &geometry->table;
  if (!watchdog_) return RunCpuLaunch(pool_, launch, output);
  LaunchWatchdog::Watch watch(*watchdog_, s.cancel_flag(), options_.launch_time_limit_s);
  launch.cancel = watch.word();
  Status st = RunCpuLaunch(pool_, launch, output);
  if (st.code() != StatusCode::kCancelled) return st;
  const std::string kernel = "kernel '" + l.kernel->layout.name + "'" + (l.adj_args ? " (adjoint)" : "");
  if (watch.reason() == LaunchWatchdog::Reason::kTimeLimit) {
    char limit[32];
    std::snprintf(limit, sizeof(limit), "%g", options_.launch_time_limit_s);
    return Status(StatusCode::kDeadlineExceeded, kernel + " ran longer than the launch time limit of " + limit +
                                                     " s (weftd --launch-time-limit) and was stopped");
  }
  return Status(StatusCode::kCancelled, kernel + " was stopped: its session was closed");
}

}  // namespace weft
