// Runs one kernel launch (forward or adjoint) on the CPU thread pool: builds the launch context
// (bounds, error slot, print buffer, cancel word), partitions the grid (checking the cancel
// word between chunks of threads), and turns a kernel-reported error
// into a Status naming the kernel, the array parameter, the index, the shape and file:line.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/native/geometry_abi.h"
#include "engine/native/launch_abi.h"
#include "engine/runtime/launch_args.h"
#include "engine/runtime/module_store.h"
#include "engine/runtime/thread_pool.h"

namespace weft {

struct CpuLaunch {
  const LoadedModule* module = nullptr;
  const LoadedKernel* kernel = nullptr;
  std::vector<int64_t> dim;
  const PackedArgs* args = nullptr;
  const PackedArgs* adj_args = nullptr;   // non-null: run cpu_backward
  bool bounds_checks = true;
  uint64_t print_capacity = 1 << 20;
  // The launch's cancel word (a LaunchWatchdog::Watch's), or null. Kernels poll it in loops
  // and RunCpuLaunch checks it before every kCancelChunk threads.
  const int32_t* cancel = nullptr;
  // The session's geometry objects on the CPU (null: none).
  const wp::geometry_table_t* geometry = nullptr;
  // The launch's block_dim (0: not given). A kernel compiled with lanes (KernelLayout::lanes >
  // 1) must be launched with that block_dim and runs its blocks as fibers (cpu_lanes.h).
  uint32_t block_dim = 0;
};

// Threads run between two checks of the cancel word.
constexpr int64_t kCancelChunk = 1 << 14;

// Checks dim (1..4 extents, each >= 0, product < 2^62).
Status CheckLaunchDim(const std::vector<int64_t>& dim);
// The launch bounds of a checked dim (CheckLaunchDim first), shared by every device's launch.
Expected<wp::launch_bounds_t> LaunchBoundsOf(const std::vector<int64_t>& dim);

// A kernel-reported error as the Status clients see (kernel, function, array, index, shape,
// file:line); used by every device.
Status FormatLaunchError(const LoadedModule& module, const LoadedKernel& kernel, bool adjoint,
                         const wp::launch_error_t& e);

// Runs the launch; appends kernel print output to *output. CANCELLED ("launch cancelled")
// when the cancel word was set (threads after that point did not run).
Status RunCpuLaunch(ThreadPool& pool, const CpuLaunch& launch, std::string* output);

}  // namespace weft
