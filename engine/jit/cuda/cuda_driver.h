// The CUDA driver API, loaded with dlopen("libcuda.so.1") on first use, so one weft build runs on
// machines with and without a GPU. Owns: the function table (the few entry points the CUDA
// backend needs: init, devices, primary contexts, modules, launches, memory) and turning CUresult
// codes into Status. Carries no CUDA headers: handles are opaque, types match cuda.h's ABI.
#pragma once

#include <cstddef>
#include <string>

#include "engine/core/status.h"

namespace weft::jit {

using CuResult = int;             // CUresult; 0 = CUDA_SUCCESS
using CuDevice = int;             // CUdevice
using CuContext = struct CUctx_st*;
using CuModule = struct CUmod_st*;
using CuFunction = struct CUfunc_st*;
using CuStream = struct CUstream_st*;
using CuDevicePtr = unsigned long long;  // CUdeviceptr (64-bit)

struct CudaDriver {
  // The loaded driver, initialised (cuInit(0) done). Unavailable when libcuda is absent or
  // cuInit fails (no GPU, no permission); the answer is computed once.
  static Expected<const CudaDriver*> Get();

  CuResult (*Init)(unsigned flags) = nullptr;
  CuResult (*DriverGetVersion)(int* version) = nullptr;
  CuResult (*DeviceGetCount)(int* count) = nullptr;
  CuResult (*DeviceGet)(CuDevice* device, int ordinal) = nullptr;
  CuResult (*DeviceGetAttribute)(int* value, int attribute, CuDevice device) = nullptr;
  CuResult (*DeviceGetName)(char* name, int length, CuDevice device) = nullptr;
  CuResult (*DevicePrimaryCtxRetain)(CuContext* context, CuDevice device) = nullptr;
  CuResult (*DevicePrimaryCtxRelease)(CuDevice device) = nullptr;
  CuResult (*CtxSetCurrent)(CuContext context) = nullptr;
  CuResult (*CtxSynchronize)() = nullptr;
  CuResult (*ModuleLoadData)(CuModule* module, const void* image) = nullptr;
  CuResult (*ModuleUnload)(CuModule module) = nullptr;
  CuResult (*ModuleGetFunction)(CuFunction* function, CuModule module, const char* name) = nullptr;
  CuResult (*LaunchKernel)(CuFunction f, unsigned grid_x, unsigned grid_y, unsigned grid_z,
                           unsigned block_x, unsigned block_y, unsigned block_z,
                           unsigned shared_bytes, CuStream stream, void** params,
                           void** extra) = nullptr;
  CuResult (*MemAlloc)(CuDevicePtr* pointer, size_t bytes) = nullptr;
  CuResult (*MemFree)(CuDevicePtr pointer) = nullptr;
  CuResult (*MemcpyHtoD)(CuDevicePtr dst, const void* src, size_t bytes) = nullptr;
  CuResult (*MemcpyDtoH)(void* dst, CuDevicePtr src, size_t bytes) = nullptr;
  CuResult (*GetErrorName)(CuResult result, const char** name) = nullptr;
  CuResult (*GetErrorString)(CuResult result, const char** text) = nullptr;

  // Ok for CUDA_SUCCESS; otherwise Internal("<what>: CUDA_ERROR_X (text)").
  Status Check(CuResult result, const char* what) const;
  // sm_XY as XY*10+Y (e.g. 90 for an H100), or a Status.
  Expected<int> ComputeCapability(int ordinal) const;
};

// Device attribute numbers used above (cuda.h's CUdevice_attribute values).
constexpr int kCuAttributeComputeCapabilityMajor = 75;
constexpr int kCuAttributeComputeCapabilityMinor = 76;

}  // namespace weft::jit
