// CUDA driver loader: dlopen libcuda.so.1 once, resolve the versioned entry points, cuInit.
#include "engine/jit/cuda/cuda_driver.h"

#include <dlfcn.h>

namespace weft::jit {
namespace {

template <typename Fn>
bool Resolve(void* library, const char* symbol, Fn* out, std::string* missing) {
  *out = reinterpret_cast<Fn>(::dlsym(library, symbol));
  if (!*out) *missing += std::string(missing->empty() ? "" : ", ") + symbol;
  return *out != nullptr;
}

Expected<const CudaDriver*> Load() {
  static CudaDriver driver;
  void* library = ::dlopen("libcuda.so.1", RTLD_NOW | RTLD_LOCAL);
  if (!library) {
    const char* why = ::dlerror();
    return Unavailable(std::string("no CUDA driver (libcuda.so.1): ") + (why ? why : "not found"));
  }
  std::string missing;
  // The _v2 names are what cuda.h's macros select since CUDA 4/11; the plain names are legacy.
  Resolve(library, "cuInit", &driver.Init, &missing);
  Resolve(library, "cuDriverGetVersion", &driver.DriverGetVersion, &missing);
  Resolve(library, "cuDeviceGetCount", &driver.DeviceGetCount, &missing);
  Resolve(library, "cuDeviceGet", &driver.DeviceGet, &missing);
  Resolve(library, "cuDeviceGetAttribute", &driver.DeviceGetAttribute, &missing);
  Resolve(library, "cuDeviceGetName", &driver.DeviceGetName, &missing);
  Resolve(library, "cuDevicePrimaryCtxRetain", &driver.DevicePrimaryCtxRetain, &missing);
  Resolve(library, "cuDevicePrimaryCtxRelease_v2", &driver.DevicePrimaryCtxRelease, &missing);
  Resolve(library, "cuCtxSetCurrent", &driver.CtxSetCurrent, &missing);
  Resolve(library, "cuCtxSynchronize", &driver.CtxSynchronize, &missing);
  Resolve(library, "cuModuleLoadData", &driver.ModuleLoadData, &missing);
  Resolve(library, "cuModuleUnload", &driver.ModuleUnload, &missing);
  Resolve(library, "cuModuleGetFunction", &driver.ModuleGetFunction, &missing);
  Resolve(library, "cuLaunchKernel", &driver.LaunchKernel, &missing);
  Resolve(library, "cuMemAlloc_v2", &driver.MemAlloc, &missing);
  Resolve(library, "cuMemFree_v2", &driver.MemFree, &missing);
  Resolve(library, "cuMemcpyHtoD_v2", &driver.MemcpyHtoD, &missing);
  Resolve(library, "cuMemcpyDtoH_v2", &driver.MemcpyDtoH, &missing);
  Resolve(library, "cuGetErrorName", &driver.GetErrorName, &missing);
  Resolve(library, "cuGetErrorString", &driver.GetErrorString, &missing);
  if (!missing.empty()) return Unavailable("the CUDA driver lacks " + missing);
  WEFT_RETURN_IF_ERROR(driver.Check(driver.Init(0), "cuInit"));
  return &driver;
}

}  // namespace

Expected<const CudaDriver*> CudaDriver::Get() {
  static const Expected<const CudaDriver*> loaded = Load();  // thread-safe, once
  return loaded;
}

Status CudaDriver::Check(CuResult result, const char* what) const {
  if (result == 0) return Status::Ok();
  const char* name = nullptr;
  const char* text = nullptr;
  if (GetErrorName) GetErrorName(result, &name);
  if (GetErrorString) GetErrorString(result, &text);
  return Internal(std::string(what) + ": " + (name ? name : "CUDA error " + std::to_string(result)) +
                  (text ? std::string(" (") + text + ")" : std::string()));
}

Expected<int> CudaDriver::ComputeCapability(int ordinal) const {
  CuDevice device = 0;
  WEFT_RETURN_IF_ERROR(Check(DeviceGet(&device, ordinal), "cuDeviceGet"));
  int major = 0, minor = 0;
  WEFT_RETURN_IF_ERROR(Check(
      DeviceGetAttribute(&major, kCuAttributeComputeCapabilityMajor, device), "cuDeviceGetAttribute"));
  WEFT_RETURN_IF_ERROR(Check(
      DeviceGetAttribute(&minor, kCuAttributeComputeCapabilityMinor, device), "cuDeviceGetAttribute"));
  return major * 10 + minor;
}

}  // namespace weft::jit
