// The devices a daemon can see: the CPU (model from /proc/cpuinfo, memory from sysinfo, pool
// threads) and CUDA GPUs through the driver loaded with dlopen("libcuda.so.1") when present.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace weft {

struct DeviceInfo {
  std::string name;          // "cpu", "cuda:0"
  std::string kind;          // "cpu" or "cuda"
  std::string description;   // CPU model / GPU product name
  uint64_t total_memory = 0;
  uint64_t free_memory = 0;
  int32_t compute_capability_major = 0;
  int32_t compute_capability_minor = 0;
  int32_t cores = 0;         // CPU pool threads / GPU SMs
  int32_t max_shared_memory_per_block = 0;   // GPUs: the opt-in maximum, bytes; CPU: 0
  bool compute_supported = false;  // arrays and launches work on it (CPU: yes; CUDA: not yet)
};

// The CPU device; `pool_threads` is reported as cores.
DeviceInfo QueryCpuDevice(int pool_threads);
// Every CUDA device the driver reports; empty when there is no driver or no GPU.
std::vector<DeviceInfo> QueryCudaDevices();
// The CUDA toolchain this daemon runs with: the driver's version (cuDriverGetVersion, e.g. 13000;
// 0 without a driver), NVRTC's "major.minor" (empty without NVRTC) and the architectures
// (kCudaArchs entries, e.g. 90) it compiles for (wp.get_cuda_driver_version,
// wp.get_cuda_toolkit_version, wp.get_cuda_supported_archs).
struct CudaToolchainInfo {
  int32_t driver_version = 0;
  std::string nvrtc_version;
  std::vector<int32_t> archs;
};
CudaToolchainInfo QueryCudaToolchain();
// Physical memory + swap, bytes (the absurd-size bound for allocations).
uint64_t PhysicalMemoryAndSwap();

}  // namespace weft
