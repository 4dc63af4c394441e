// Whether a CUDA process gets a usable context back after a sticky kernel fault: launches a
// kernel that writes to an illegal address (`illegal`, default) or executes `trap` (`trap`),
// then tries the same primary context, cuDevicePrimaryCtxReset + retain, and a new
// non-primary context (cuCtxCreate), each proved by an allocation, a memset and a
// synchronize. docs/cuda.md ("Fault containment and recovery") quotes its output on the lent
// H200. Build: bash bench/fault_probe/build.sh; run on the GPU machine:
// ./build/fault_probe/fault_probe [illegal|trap].
#include <cuda.h>
#include <stdio.h>
#include <string.h>

static const char* error_name(CUresult r) {
  const char* s = 0;
  cuGetErrorName(r, &s);
  return s ? s : "?";
}

static const char* kPtx =
    ".version 7.0\n.target sm_50\n.address_size 64\n"
    ".visible .entry write_to(.param .u64 p) { .reg .u64 %a; ld.param.u64 %a, [p]; st.global.u32 [%a], 1; ret; }\n"
    ".visible .entry trap_now() { trap; ret; }\n";

// Allocation, memset and synchronize in the current context; 1 when all three succeed.
static int prove(const char* what) {
  CUdeviceptr p = 0;
  CUresult a = cuMemAlloc(&p, 1 << 20);
  CUresult m = a == CUDA_SUCCESS ? cuMemsetD8(p, 7, 1 << 20) : a;
  CUresult s = cuCtxSynchronize();
  printf("  %-32s alloc=%s memset=%s sync=%s\n", what, error_name(a), error_name(m), error_name(s));
  if (p) cuMemFree(p);
  return a == CUDA_SUCCESS && m == CUDA_SUCCESS && s == CUDA_SUCCESS;
}

int main(int argc, char** argv) {
  const int trap = argc > 1 && strcmp(argv[1], "trap") == 0;
  CUdevice dev;
  CUcontext primary, again, fresh;
  CUmodule mod;
  CUfunction f;
  if (cuInit(0) != CUDA_SUCCESS || cuDeviceGet(&dev, 0) != CUDA_SUCCESS) {
    printf("no CUDA device\n");
    return 1;
  }
  printf("retain: %s\n", error_name(cuDevicePrimaryCtxRetain(&primary, dev)));
  cuCtxSetCurrent(primary);
  printf("load: %s\n", error_name(cuModuleLoadData(&mod, kPtx)));
  cuModuleGetFunction(&f, mod, trap ? "trap_now" : "write_to");
  CUdeviceptr illegal = 16;
  void* args[] = {&illegal};
  printf("launch (%s): %s\n", trap ? "trap" : "illegal address",
         error_name(cuLaunchKernel(f, 1, 1, 1, 1, 1, 1, 0, 0, trap ? 0 : args, 0)));
  printf("synchronize after the fault: %s\n", error_name(cuCtxSynchronize()));
  prove("the same primary context");
  cuDevicePrimaryCtxRelease(dev);
  printf("primary context reset: %s\n", error_name(cuDevicePrimaryCtxReset(dev)));
  CUresult r = cuDevicePrimaryCtxRetain(&again, dev);
  printf("retain after the reset: %s\n", error_name(r));
  if (r == CUDA_SUCCESS && cuCtxSetCurrent(again) == CUDA_SUCCESS) prove("the primary context, reset");
  r = cuCtxCreate(&fresh, NULL, 0, dev);
  printf("cuCtxCreate: %s\n", error_name(r));
  if (r == CUDA_SUCCESS && cuCtxSetCurrent(fresh) == CUDA_SUCCESS) prove("a new non-primary context");
  return 0;
}
