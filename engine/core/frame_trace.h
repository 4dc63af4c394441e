// Optional timing of the work one thread does for one request (WEFT_LANE_TRACE): the engine
// adds the time it spent waiting for a GPU stream at a synchronize and launching GPU kernels,
// and the fast lane reads it after serving a frame. Off (one branch on a cached flag) unless
// the variable is set.
#pragma once

#include <chrono>
#include <cstdint>

namespace weft::frame_trace {

// Whether WEFT_LANE_TRACE is set (read once).
bool Enabled();

// What the engine recorded on this thread since the last Reset.
struct Phases {
  int64_t device_sync_ns = 0;   // in Device::Synchronize (queueing the read-back, waiting, draining)
  int64_t stream_wait_ns = 0;   // of that, polling the stream until it was idle
  int64_t stream_polls = 0;     // cuStreamQuery calls
  int64_t stream_blocks = 0;    // waits that blocked until the stream's host function signalled
  int64_t gpu_launch_ns = 0;    // in CudaDevice::Launch (checks, look-ups, the driver call)
  int64_t driver_launch_ns = 0; // of that, in cuLaunchKernel
};
Phases& Current();   // thread-local
inline void Reset() { Current() = Phases{}; }

inline int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace weft::frame_trace
