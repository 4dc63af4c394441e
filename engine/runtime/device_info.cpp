// Device queries: /proc/cpuinfo + sysinfo for the CPU, the CUDA driver API through the one loader (engine/device/cuda_driver).
#include "engine/runtime/device_info.h"

#include <sys/sysinfo.h>

#include <fstream>
#include <mutex>

#include "engine/device/cuda_driver.h"
#include "engine/runtime/module_store.h"
#if WEFT_WITH_CUDA
#include "engine/jit/cuda/nvrtc_compiler.h"
#endif

namespace weft {

uint64_t PhysicalMemoryAndSwap() {
  struct sysinfo si {};
  if (sysinfo(&si) != 0) return ~0ull;
  return (static_cast<uint64_t>(si.totalram) + si.totalswap) * si.mem_unit;
}

DeviceInfo QueryCpuDevice(int pool_threads) {
  DeviceInfo d;
  d.name = "cpu";
  d.kind = "cpu";
  std::ifstream f("/proc/cpuinfo");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("model name", 0) == 0) {
      auto p = line.find(':');
      if (p != std::string::npos) d.description = line.substr(p + 2);
      break;
    }
  }
  if (d.description.empty()) d.description = "CPU";
  struct sysinfo si {};
  if (sysinfo(&si) == 0) {
    d.total_memory = static_cast<uint64_t>(si.totalram) * si.mem_unit;
    d.free_memory = (static_cast<uint64_t>(si.freeram) + si.bufferram) * si.mem_unit;
  }
  d.cores = pool_threads;
  d.compute_supported = true;
  return d;
}

std::vector<DeviceInfo> QueryCudaDevices() {
  std::vector<DeviceInfo> out;
  auto loaded = jit::CudaDriver::Get();
  if (!loaded.ok()) return out;
  const jit::CudaDriver& d = **loaded;
  int n = 0;
  if (d.DeviceGetCount(&n) != 0) return out;
  for (int i = 0; i < n; ++i) {
    jit::CuDevice dev = 0;
    if (d.DeviceGet(&dev, i) != 0) continue;
    DeviceInfo info;
    info.name = "cuda:" + std::to_string(i);
    info.kind = "cuda";
    char name[256] = {0};
    d.DeviceGetName(name, sizeof(name) - 1, dev);
    info.description = name;
    size_t total = 0;
    d.DeviceTotalMem(&total, dev);
    info.total_memory = total;
    info.free_memory = total;
    d.DeviceGetAttribute(&info.compute_capability_major, jit::kCuAttributeComputeCapabilityMajor, dev);
    d.DeviceGetAttribute(&info.compute_capability_minor, jit::kCuAttributeComputeCapabilityMinor, dev);
    d.DeviceGetAttribute(&info.cores, jit::kCuAttributeMultiprocessorCount, dev);
    d.DeviceGetAttribute(&info.max_shared_memory_per_block, jit::kCuAttributeMaxSharedMemoryPerBlockOptin, dev);
    // Free memory needs a context: the device's primary context, retained for the query and
    // released after it (the CUDA device holds its own reference; a device reset must be able to
    // drop every reference of the daemon).
    jit::CuContext ctx = nullptr;
    if (d.DevicePrimaryCtxRetain(&ctx, dev) == 0) {
      if (d.CtxSetCurrent(ctx) == 0) {
        size_t free_b = 0, total_b = 0;
        if (d.MemGetInfo(&free_b, &total_b) == 0) info.free_memory = free_b;
        d.CtxSetCurrent(nullptr);
      }
      d.DevicePrimaryCtxRelease(dev);
    }
    out.push_back(std::move(info));
  }
  return out;
}

CudaToolchainInfo QueryCudaToolchain() {
  CudaToolchainInfo info;
  auto loaded = jit::CudaDriver::Get();
  if (loaded.ok() && (*loaded)->DriverGetVersion) {
    int version = 0;
    if ((*loaded)->DriverGetVersion(&version) == 0) info.driver_version = version;
  }
#if WEFT_WITH_CUDA
  if (auto version = jit::NvrtcVersion(); version.ok()) info.nvrtc_version = *version;
  for (int arch : kCudaArchs)
    if (jit::NvrtcSupportsArch(arch)) info.archs.push_back(arch);
#endif
  return info;
}

}  // namespace weft
