// The one CUDA driver API loader of the daemon: dlopen("libcuda.so.1") on first use, so one weft
// build runs on machines with and without a GPU (no driver = no CUDA devices). Owns: the
// function table (every entry point the CUDA device, the device list and the tests use) and
// turning CUresult codes into Status. Carries no CUDA headers: handles are opaque, types and
// constants match cuda.h's ABI.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "engine/core/status.h"

namespace weft::jit {

using CuResult = int;             // CUresult; 0 = CUDA_SUCCESS
using CuDevice = int;             // CUdevice
using CuContext = struct CUctx_st*;
using CuModule = struct CUmod_st*;
using CuFunction = struct CUfunc_st*;
using CuStream = struct CUstream_st*;
using CuEvent = struct CUevent_st*;
using CuDevicePtr = unsigned long long;  // CUdeviceptr (64-bit)
using CuGraph = struct CUgraph_st*;
using CuGraphExec = struct CUgraphExec_st*;

// CUipcMemHandle: 64 opaque bytes.
struct CuIpcMemHandle {
  char reserved[64];
};

// CUipcEventHandle: 64 opaque bytes.
struct CuIpcEventHandle {
  char reserved[64];
};

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
  CuResult (*DeviceTotalMem)(size_t* bytes, CuDevice device) = nullptr;
  CuResult (*DevicePrimaryCtxRetain)(CuContext* context, CuDevice device) = nullptr;
  CuResult (*DevicePrimaryCtxRelease)(CuDevice device) = nullptr;
  CuResult (*DevicePrimaryCtxReset)(CuDevice device) = nullptr;
  CuResult (*CtxSetCurrent)(CuContext context) = nullptr;
  CuResult (*CtxSynchronize)() = nullptr;
  CuResult (*MemGetInfo)(size_t* free_bytes, size_t* total_bytes) = nullptr;
  CuResult (*ModuleLoadData)(CuModule* module, const void* image) = nullptr;
  CuResult (*ModuleUnload)(CuModule module) = nullptr;
  CuResult (*ModuleGetFunction)(CuFunction* function, CuModule module, const char* name) = nullptr;
  CuResult (*FuncGetAttribute)(int* value, int attribute, CuFunction function) = nullptr;
  CuResult (*LaunchKernel)(CuFunction f, unsigned grid_x, unsigned grid_y, unsigned grid_z,
                           unsigned block_x, unsigned block_y, unsigned block_z,
                           unsigned shared_bytes, CuStream stream, void** params,
                           void** extra) = nullptr;
  CuResult (*MemAlloc)(CuDevicePtr* pointer, size_t bytes) = nullptr;
  CuResult (*MemFree)(CuDevicePtr pointer) = nullptr;
  CuResult (*MemcpyHtoD)(CuDevicePtr dst, const void* src, size_t bytes) = nullptr;
  CuResult (*MemcpyDtoH)(void* dst, CuDevicePtr src, size_t bytes) = nullptr;
  CuResult (*MemcpyDtoD)(CuDevicePtr dst, CuDevicePtr src, size_t bytes) = nullptr;
  CuResult (*MemcpyHtoDAsync)(CuDevicePtr dst, const void* src, size_t bytes, CuStream stream) = nullptr;
  CuResult (*MemcpyDtoHAsync)(void* dst, CuDevicePtr src, size_t bytes, CuStream stream) = nullptr;
  CuResult (*MemcpyDtoDAsync)(CuDevicePtr dst, CuDevicePtr src, size_t bytes, CuStream stream) = nullptr;
  CuResult (*MemcpyPeerAsync)(CuDevicePtr dst, CuContext dst_ctx, CuDevicePtr src, CuContext src_ctx,
                              size_t bytes, CuStream stream) = nullptr;
  CuResult (*MemsetD8Async)(CuDevicePtr dst, unsigned char value, size_t n, CuStream stream) = nullptr;
  CuResult (*MemsetD16Async)(CuDevicePtr dst, unsigned short value, size_t n, CuStream stream) = nullptr;
  CuResult (*MemsetD32Async)(CuDevicePtr dst, unsigned value, size_t n, CuStream stream) = nullptr;
  CuResult (*StreamCreate)(CuStream* stream, unsigned flags) = nullptr;
  CuResult (*StreamDestroy)(CuStream stream) = nullptr;
  CuResult (*StreamSynchronize)(CuStream stream) = nullptr;
  CuResult (*StreamQuery)(CuStream stream) = nullptr;
  CuResult (*MemHostAlloc)(void** pointer, size_t bytes, unsigned flags) = nullptr;
  CuResult (*MemFreeHost)(void* pointer) = nullptr;
  CuResult (*MemHostRegister)(void* pointer, size_t bytes, unsigned flags) = nullptr;
  CuResult (*MemHostUnregister)(void* pointer) = nullptr;
  CuResult (*MemHostGetDevicePointer)(CuDevicePtr* device_pointer, void* host, unsigned flags) = nullptr;
  CuResult (*IpcGetMemHandle)(CuIpcMemHandle* handle, CuDevicePtr pointer) = nullptr;
  // Importing another process's allocation (engine/device/cuda_import.h).
  CuResult (*IpcOpenMemHandle)(CuDevicePtr* pointer, CuIpcMemHandle handle, unsigned flags) = nullptr;
  CuResult (*IpcCloseMemHandle)(CuDevicePtr pointer) = nullptr;
  // Interprocess events of a client process (engine/device/cuda_device_events.cpp).
  CuResult (*IpcOpenEventHandle)(CuEvent* event, CuIpcEventHandle handle) = nullptr;
  CuResult (*EventRecord)(CuEvent event, CuStream stream) = nullptr;
  CuResult (*StreamWaitEvent)(CuStream stream, CuEvent event, unsigned flags) = nullptr;
  CuResult (*EventDestroy)(CuEvent event) = nullptr;
  // Activity timing (cuda_device_timing.cpp): events of the daemon's own, with timing.
  CuResult (*EventCreate)(CuEvent* event, unsigned flags) = nullptr;
  CuResult (*EventElapsedTime)(float* ms, CuEvent start, CuEvent end) = nullptr;
  // Occupancy (wp.get_suggested_block_size); null when the driver lacks it.
  CuResult (*OccupancyMaxPotentialBlockSize)(int* min_grid_size, int* block_size, CuFunction f,
                                             size_t (*shared_for_block)(int), size_t shared_bytes,
                                             int block_size_limit) = nullptr;
  // Stream memory operations (ordering without a round trip, cuda_device_values.cpp); null when
  // the driver lacks them.
  CuResult (*StreamWaitValue64)(CuStream stream, CuDevicePtr address, uint64_t value, unsigned flags) = nullptr;
  CuResult (*StreamWriteValue64)(CuStream stream, CuDevicePtr address, uint64_t value, unsigned flags) = nullptr;
  // A host function run by the driver once the stream reaches it (cuda_device.cpp's signalled
  // wait); null when the driver lacks it (the wait then polls with sleeps).
  CuResult (*LaunchHostFunc)(CuStream stream, void (*fn)(void*), void* user_data) = nullptr;
  // Graph capture of a session's stream (cuda_device_graphs.cpp); null when the driver lacks them.
  CuResult (*StreamBeginCapture)(CuStream stream, int mode) = nullptr;
  CuResult (*StreamEndCapture)(CuStream stream, CuGraph* graph) = nullptr;
  CuResult (*GraphInstantiate)(CuGraphExec* exec, CuGraph graph, unsigned long long flags) = nullptr;
  CuResult (*GraphLaunch)(CuGraphExec exec, CuStream stream) = nullptr;
  CuResult (*GraphExecDestroy)(CuGraphExec exec) = nullptr;
  CuResult (*GraphDestroy)(CuGraph graph) = nullptr;
  CuResult (*MemGetAddressRange)(CuDevicePtr* base, size_t* size, CuDevicePtr pointer) = nullptr;
  CuResult (*PointerGetAttribute)(void* data, int attribute, CuDevicePtr pointer) = nullptr;
  CuResult (*GetErrorName)(CuResult result, const char** name) = nullptr;
  CuResult (*GetErrorString)(CuResult result, const char** text) = nullptr;

  // Ok for CUDA_SUCCESS; otherwise Internal("<what>: CUDA_ERROR_X (text)").
  Status Check(CuResult result, const char* what) const;
  // "CUDA_ERROR_X" for a result code.
  std::string ErrorName(CuResult result) const;
  // sm_XY as XY*10+Y (e.g. 90 for an H100), or a Status.
  Expected<int> ComputeCapability(int ordinal) const;
};

// Device attribute numbers used above (cuda.h's CUdevice_attribute values).
constexpr int kCuAttributeMultiprocessorCount = 16;
constexpr int kCuAttributeMaxThreadsPerMultiprocessor = 39;
constexpr int kCuAttributeMaxSharedMemoryPerBlockOptin = 97;
constexpr int kCuAttributeComputeCapabilityMajor = 75;
constexpr int kCuAttributeComputeCapabilityMinor = 76;
constexpr int kCuAttributeCanUse64BitStreamMemOps = 122;
// cuStreamWaitValue64 flags: wait until (int64_t)(*address - value) >= 0.
constexpr unsigned kCuStreamWaitValueGeq = 0;
// cuStreamBeginCapture mode: CU_STREAM_CAPTURE_MODE_RELAXED (other threads of the daemon keep
// serving their sessions while one session's stream captures).
constexpr int kCuStreamCaptureModeRelaxed = 2;
// cuIpcOpenMemHandle flags.
constexpr unsigned kCuIpcMemLazyEnablePeerAccess = 1;
// CUpointer_attribute values.
constexpr int kCuPointerAttributeDeviceOrdinal = 9;
// CUresult values the IPC import reports by name.
constexpr CuResult kCuErrorAlreadyMapped = 208;
// CUfunction_attribute values.
constexpr int kCuFuncAttributeNumRegs = 4;
// cuStreamCreate flags, cuStreamQuery's "still running".
constexpr unsigned kCuStreamNonBlocking = 1;
// cuMemHostAlloc flags: CU_MEMHOSTALLOC_PORTABLE | CU_MEMHOSTALLOC_DEVICEMAP.
constexpr unsigned kCuMemHostAllocMapped = 0x01 | 0x02;
constexpr CuResult kCuErrorNotReady = 600;
// Errors after which the context is unusable (sticky): the device must be reset.
bool IsStickyCudaError(CuResult result);

}  // namespace weft::jit
