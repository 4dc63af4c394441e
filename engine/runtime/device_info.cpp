// Device queries: /proc/cpuinfo + sysinfo for the CPU, the CUDA driver API through dlopen.
#include "engine/runtime/device_info.h"

#include <dlfcn.h>
#include <sys/sysinfo.h>

#include <fstream>
#include <mutex>

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

namespace {

// The few driver entry points the device list needs (CUDA driver API, ABI-stable).
struct CudaDriver {
  using InitFn = int (*)(unsigned);
  using CountFn = int (*)(int*);
  using GetFn = int (*)(int*, int);
  using NameFn = int (*)(char*, int, int);
  using TotalMemFn = int (*)(size_t*, int);
  using AttrFn = int (*)(int*, int, int);
  using CtxCreateFn = int (*)(void**, unsigned, int);
  using CtxDestroyFn = int (*)(void*);
  using MemInfoFn = int (*)(size_t*, size_t*);
  using PrimaryRetainFn = int (*)(void**, int);
  using PrimaryReleaseFn = int (*)(int);
  using CtxSetFn = int (*)(void*);
  void* lib = nullptr;
  InitFn init = nullptr;
  CountFn count = nullptr;
  GetFn get = nullptr;
  NameFn name = nullptr;
  TotalMemFn total_mem = nullptr;
  AttrFn attr = nullptr;
  MemInfoFn mem_info = nullptr;
  PrimaryRetainFn retain = nullptr;
  PrimaryReleaseFn release = nullptr;
  CtxSetFn set_current = nullptr;
  bool ok = false;
};

const CudaDriver& Driver() {
  static CudaDriver d;
  static std::once_flag once;
  std::call_once(once, [] {
    d.lib = dlopen("libcuda.so.1", RTLD_NOW | RTLD_LOCAL);
    if (!d.lib) return;
    d.init = reinterpret_cast<CudaDriver::InitFn>(dlsym(d.lib, "cuInit"));
    d.count = reinterpret_cast<CudaDriver::CountFn>(dlsym(d.lib, "cuDeviceGetCount"));
    d.get = reinterpret_cast<CudaDriver::GetFn>(dlsym(d.lib, "cuDeviceGet"));
    d.name = reinterpret_cast<CudaDriver::NameFn>(dlsym(d.lib, "cuDeviceGetName"));
    d.total_mem = reinterpret_cast<CudaDriver::TotalMemFn>(dlsym(d.lib, "cuDeviceTotalMem_v2"));
    d.attr = reinterpret_cast<CudaDriver::AttrFn>(dlsym(d.lib, "cuDeviceGetAttribute"));
    d.mem_info = reinterpret_cast<CudaDriver::MemInfoFn>(dlsym(d.lib, "cuMemGetInfo_v2"));
    d.retain = reinterpret_cast<CudaDriver::PrimaryRetainFn>(dlsym(d.lib, "cuDevicePrimaryCtxRetain"));
    d.release = reinterpret_cast<CudaDriver::PrimaryReleaseFn>(dlsym(d.lib, "cuDevicePrimaryCtxRelease_v2"));
    d.set_current = reinterpret_cast<CudaDriver::CtxSetFn>(dlsym(d.lib, "cuCtxSetCurrent"));
    d.ok = d.init && d.count && d.get && d.name && d.total_mem && d.attr && d.init(0) == 0;
  });
  return d;
}

constexpr int kAttrMultiprocessorCount = 16;
constexpr int kAttrComputeCapabilityMajor = 75;
constexpr int kAttrComputeCapabilityMinor = 76;

}  // namespace

std::vector<DeviceInfo> QueryCudaDevices() {
  std::vector<DeviceInfo> out;
  const CudaDriver& d = Driver();
  if (!d.ok) return out;
  int n = 0;
  if (d.count(&n) != 0) return out;
  for (int i = 0; i < n; ++i) {
    int dev = 0;
    if (d.get(&dev, i) != 0) continue;
    DeviceInfo info;
    info.name = "cuda:" + std::to_string(i);
    info.kind = "cuda";
    char name[256] = {0};
    d.name(name, sizeof(name) - 1, dev);
    info.description = name;
    size_t total = 0;
    d.total_mem(&total, dev);
    info.total_memory = total;
    info.free_memory = total;
    d.attr(&info.compute_capability_major, kAttrComputeCapabilityMajor, dev);
    d.attr(&info.compute_capability_minor, kAttrComputeCapabilityMinor, dev);
    d.attr(&info.cores, kAttrMultiprocessorCount, dev);
    // Free memory needs a context: use the device's primary context (shared, cheap once made).
    if (d.retain && d.set_current && d.mem_info) {
      void* ctx = nullptr;
      if (d.retain(&ctx, dev) == 0) {
        if (d.set_current(ctx) == 0) {
          size_t free_b = 0, total_b = 0;
          if (d.mem_info(&free_b, &total_b) == 0) info.free_memory = free_b;
          d.set_current(nullptr);
        }
        // Keep the primary context retained: releasing the last reference destroys it, and
        // recreating it costs far more than the query.
      }
    }
    out.push_back(std::move(info));
  }
  return out;
}

}  // namespace weft
