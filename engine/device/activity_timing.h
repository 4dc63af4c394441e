// CUDA activity timing (wp.timing_begin / wp.timing_end): the kinds of GPU operation a session
// may ask to time (Warp's TIMING_* bits), one timed operation as a synchronize reports it, and
// the bound on how many one session's stream keeps. The events themselves live with the
// session's stream in CudaDevice (cuda_device_timing.cpp).
#pragma once

#include <cstdint>
#include <string>

namespace weft {

// Warp's values (warp.TIMING_KERNEL ...): a client sends them as they are.
constexpr uint32_t kTimingKernel = 1;          // the client's kernels, forward and backward
constexpr uint32_t kTimingKernelBuiltin = 2;   // the daemon's own kernels (strided copy and fill, sort, geometry)
constexpr uint32_t kTimingMemcpy = 4;
constexpr uint32_t kTimingMemset = 8;
constexpr uint32_t kTimingGraph = 16;

// Timed operations one session's stream on one GPU keeps until a synchronize collects them
// (two events each); past it operations run untimed and are counted as dropped.
constexpr uint64_t kMaxTimedActivities = 1 << 16;

struct TimedActivity {
  std::string device;   // "cuda:N"
  std::string name;     // "forward kernel NAME", "memcpy HtoD", "memset", "graph launch", ...
  uint32_t filter = 0;  // its kTiming* bit
  double elapsed_ms = 0;
};

}  // namespace weft
