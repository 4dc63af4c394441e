// CUDA driver loader: dlopen libcuda.so.1 once, resolve the versioned entry points, cuInit.
// (device_info.cpp lists devices through it; the CUDA device and module_store use it.)
#include "engine/device/cuda_driver.h"

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
  Resolve(library, "cuDeviceTotalMem_v2", &driver.DeviceTotalMem, &missing);
  Resolve(library, "cuDevicePrimaryCtxRelease_v2", &driver.DevicePrimaryCtxRelease, &missing);
  Resolve(library, "cuDevicePrimaryCtxReset_v2", &driver.DevicePrimaryCtxReset, &missing);
  Resolve(library, "cuMemGetInfo_v2", &driver.MemGetInfo, &missing);
  Resolve(library, "cuFuncGetAttribute", &driver.FuncGetAttribute, &missing);
  Resolve(library, "cuMemcpyDtoD_v2", &driver.MemcpyDtoD, &missing);
  Resolve(library, "cuMemcpyHtoDAsync_v2", &driver.MemcpyHtoDAsync, &missing);
  Resolve(library, "cuMemcpyDtoHAsync_v2", &driver.MemcpyDtoHAsync, &missing);
  Resolve(library, "cuMemcpyDtoDAsync_v2", &driver.MemcpyDtoDAsync, &missing);
  Resolve(library, "cuMemcpyPeerAsync", &driver.MemcpyPeerAsync, &missing);
  Resolve(library, "cuMemsetD8Async", &driver.MemsetD8Async, &missing);
  Resolve(library, "cuMemsetD16Async", &driver.MemsetD16Async, &missing);
  Resolve(library, "cuMemsetD32Async", &driver.MemsetD32Async, &missing);
  Resolve(library, "cuStreamCreate", &driver.StreamCreate, &missing);
  Resolve(library, "cuStreamDestroy_v2", &driver.StreamDestroy, &missing);
  Resolve(library, "cuStreamSynchronize", &driver.StreamSynchronize, &missing);
  Resolve(library, "cuStreamQuery", &driver.StreamQuery, &missing);
  Resolve(library, "cuMemHostAlloc", &driver.MemHostAlloc, &missing);
  Resolve(library, "cuMemFreeHost", &driver.MemFreeHost, &missing);
  Resolve(library, "cuMemHostRegister_v2", &driver.MemHostRegister, &missing);
  Resolve(library, "cuMemHostUnregister", &driver.MemHostUnregister, &missing);
  Resolve(library, "cuMemHostGetDevicePointer_v2", &driver.MemHostGetDevicePointer, &missing);
  Resolve(library, "cuIpcGetMemHandle", &driver.IpcGetMemHandle, &missing);
  Resolve(library, "cuIpcOpenMemHandle_v2", &driver.IpcOpenMemHandle, &missing);
  Resolve(library, "cuIpcCloseMemHandle", &driver.IpcCloseMemHandle, &missing);
  Resolve(library, "cuIpcOpenEventHandle", &driver.IpcOpenEventHandle, &missing);
  Resolve(library, "cuEventRecord", &driver.EventRecord, &missing);
  Resolve(library, "cuStreamWaitEvent", &driver.StreamWaitEvent, &missing);
  Resolve(library, "cuEventDestroy_v2", &driver.EventDestroy, &missing);
  Resolve(library, "cuEventCreate", &driver.EventCreate, &missing);
  Resolve(library, "cuMemGetAddressRange_v2", &driver.MemGetAddressRange, &missing);
  Resolve(library, "cuPointerGetAttribute", &driver.PointerGetAttribute, &missing);
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
  // cuEventElapsedTime_v2 (CUDA 12.8+) and the older entry take the same arguments.
  std::string no_v2;
  Resolve(library, "cuEventElapsedTime_v2", &driver.EventElapsedTime, &no_v2);
  if (!driver.EventElapsedTime) Resolve(library, "cuEventElapsedTime", &driver.EventElapsedTime, &missing);
  if (!missing.empty()) return Unavailable("the CUDA driver lacks " + missing);
  // Optional (stream memory operations, CUDA 12+): without them the client orders by events.
  std::string optional_missing;
  Resolve(library, "cuStreamWaitValue64_v2", &driver.StreamWaitValue64, &optional_missing);
  Resolve(library, "cuStreamWriteValue64_v2", &driver.StreamWriteValue64, &optional_missing);
  Resolve(library, "cuLaunchHostFunc", &driver.LaunchHostFunc, &optional_missing);
  Resolve(library, "cuOccupancyMaxPotentialBlockSize", &driver.OccupancyMaxPotentialBlockSize, &optional_missing);
  // Optional (graphs): without them a graph is replayed command by command.
  Resolve(library, "cuStreamBeginCapture_v2", &driver.StreamBeginCapture, &optional_missing);
  Resolve(library, "cuStreamEndCapture", &driver.StreamEndCapture, &optional_missing);
  Resolve(library, "cuGraphInstantiateWithFlags", &driver.GraphInstantiate, &optional_missing);
  Resolve(library, "cuGraphLaunch", &driver.GraphLaunch, &optional_missing);
  Resolve(library, "cuGraphExecDestroy", &driver.GraphExecDestroy, &optional_missing);
  Resolve(library, "cuGraphDestroy", &driver.GraphDestroy, &optional_missing);
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

std::string CudaDriver::ErrorName(CuResult result) const {
  const char* name = nullptr;
  if (GetErrorName) GetErrorName(result, &name);
  return name ? std::string(name) : "CUDA error " + std::to_string(result);
}

bool IsStickyCudaError(CuResult result) {
  switch (result) {
    case 700:   // CUDA_ERROR_ILLEGAL_ADDRESS
    case 702:   // CUDA_ERROR_LAUNCH_TIMEOUT
    case 710:   // CUDA_ERROR_ASSERT
    case 714:   // CUDA_ERROR_HARDWARE_STACK_ERROR
    case 715:   // CUDA_ERROR_ILLEGAL_INSTRUCTION
    case 716:   // CUDA_ERROR_MISALIGNED_ADDRESS
    case 717:   // CUDA_ERROR_INVALID_ADDRESS_SPACE
    case 718:   // CUDA_ERROR_INVALID_PC
    case 719:   // CUDA_ERROR_LAUNCH_FAILED (a __trap)
    case 999:   // CUDA_ERROR_UNKNOWN
      return true;
    default:
      return false;
  }
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
