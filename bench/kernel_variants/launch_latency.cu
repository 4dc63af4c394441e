// What one empty-kernel launch costs the driver on this machine, outside any daemon or Python:
// the time of the cuLaunchKernel call alone and of launch + wait, for the ways weftd could
// issue it (stream kind, cuCtxSetCurrent before each launch, parameter size, another thread of
// the process polling the driver meanwhile, the wait by cuStreamQuery polling or by
// cuStreamSynchronize). Medians of `iters` launches per case, microseconds. Built by build.sh
// (CUDA runtime static, libcuda loaded by the runtime); run on a GPU machine.
#include <cuda.h>
#include <cuda_runtime.h>
#include <sched.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <vector>

#define CU_CHECK(call)                                                            \
  do {                                                                            \
    CUresult e_ = (call);                                                         \
    if (e_ != CUDA_SUCCESS) {                                                     \
      std::fprintf(stderr, "%s:%d: CUDA driver error %d\n", __FILE__, __LINE__, e_); \
      std::exit(1);                                                               \
    }                                                                             \
  } while (0)

struct Context128 {   // about the size of weft's launch_context_t
  unsigned long long words[16];
};

extern "C" __global__ void empty_small(int) {}
extern "C" __global__ void empty_weft_like(Context128 ctx, void* args) {
  if (ctx.words[0] == 12345 && args == nullptr) asm volatile("trap;");
}

namespace {

double NowUs() {
  return std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

enum class Wait { kQuery, kSynchronize, kNone };

struct Case {
  const char* name;
  bool nonblocking = true;
  bool set_current = false;
  bool weft_params = true;
  bool poller = false;
  Wait wait = Wait::kQuery;
};

void Run(const Case& c, CUcontext ctx, CUfunction small, CUfunction weft_like, int iters) {
  CUstream stream = nullptr;
  if (c.nonblocking) CU_CHECK(cuStreamCreate(&stream, CU_STREAM_NON_BLOCKING));
  CUstream other = nullptr;
  CU_CHECK(cuStreamCreate(&other, CU_STREAM_NON_BLOCKING));
  std::atomic<bool> stop{false};
  std::thread poller;
  if (c.poller) {
    poller = std::thread([&] {
      CU_CHECK(cuCtxSetCurrent(ctx));
      while (!stop.load(std::memory_order_relaxed)) {
        (void)cuStreamQuery(other);
        sched_yield();
      }
    });
  }
  Context128 params{};
  void* args = nullptr;
  int small_arg = 0;
  void* weft_list[] = {&params, &args};
  void* small_list[] = {&small_arg};
  std::vector<double> launch_us, total_us;
  for (int i = 0; i < iters + 200; ++i) {
    const double t0 = NowUs();
    if (c.set_current) CU_CHECK(cuCtxSetCurrent(ctx));
    CU_CHECK(cuLaunchKernel(c.weft_params ? weft_like : small, 1, 1, 1, 256, 1, 1, 0, stream,
                            c.weft_params ? weft_list : small_list, nullptr));
    const double t1 = NowUs();
    if (c.wait == Wait::kQuery) {
      CUresult r;
      while ((r = cuStreamQuery(stream)) == CUDA_ERROR_NOT_READY) sched_yield();
      CU_CHECK(r);
    } else if (c.wait == Wait::kSynchronize) {
      CU_CHECK(cuStreamSynchronize(stream));
    }
    const double t2 = NowUs();
    if (i >= 200) {
      launch_us.push_back(t1 - t0);
      total_us.push_back(t2 - t0);
    }
  }
  if (c.wait == Wait::kNone) CU_CHECK(cuStreamSynchronize(stream));
  stop = true;
  if (poller.joinable()) poller.join();
  std::printf("%-58s launch %6.2f us   launch+wait %6.2f us\n", c.name, Median(launch_us),
              c.wait == Wait::kNone ? 0.0 : Median(total_us));
  if (stream) CU_CHECK(cuStreamDestroy(stream));
  CU_CHECK(cuStreamDestroy(other));
}

}  // namespace

int main(int argc, char** argv) {
  const int iters = argc > 1 ? std::atoi(argv[1]) : 5000;
  if (cudaFree(nullptr) != cudaSuccess) {   // creates the runtime's (primary) context
    std::fprintf(stderr, "no CUDA device\n");
    return 1;
  }
  CUcontext ctx = nullptr;
  CU_CHECK(cuCtxGetCurrent(&ctx));
  cudaFunction_t f_small = nullptr, f_weft = nullptr;
  if (cudaGetFuncBySymbol(&f_small, reinterpret_cast<const void*>(empty_small)) != cudaSuccess ||
      cudaGetFuncBySymbol(&f_weft, reinterpret_cast<const void*>(empty_weft_like)) != cudaSuccess) {
    std::fprintf(stderr, "cudaGetFuncBySymbol failed\n");
    return 1;
  }
  CUfunction small = reinterpret_cast<CUfunction>(f_small);
  CUfunction weft_like = reinterpret_cast<CUfunction>(f_weft);
  std::printf("empty kernel, 1 block of 256 threads, medians of %d launches\n", iters);
  const Case cases[] = {
      {"non-blocking stream, weft-sized params, query poll"},
      {"  + cuCtxSetCurrent before each launch", true, true},
      {"  + another thread polling cuStreamQuery", true, false, true, true},
      {"  wait by cuStreamSynchronize", true, false, true, false, Wait::kSynchronize},
      {"  small params (one int)", true, false, false},
      {"legacy default stream, small params, cuStreamSynchronize", false, false, false, false, Wait::kSynchronize},
      {"non-blocking stream, weft-sized params, no wait (batched)", true, false, true, false, Wait::kNone},
      {"non-blocking stream, weft-sized params, query poll (again)"},
  };
  for (const Case& c : cases) Run(c, ctx, small, weft_like, iters);
  return 0;
}
