// saxpy kernel variants timed side by side on one GPU: the kernel weft generated before
// __grid_constant__ (its entry loop and bounds-checked body, copied from WEFT_DUMP_IR output of
// `y[i] = a * x[i] + y[i]`), and variants that each change one thing (no grid-stride loop, as
// weft's grid_stride=False; the error report out of line, with and without __grid_constant__
// parameters; no checks; a lean kernel with int32 shape and strides), beside a device copy of
// the same bytes; and (2026-11-28) the body weft generates with `wp.tid()` as emitted under the
// entry forms (the loop, none, a loop calling the body, once then a loop: docs/cuda.md, "The
// H200, 2026-11-28 later"); and (2026-11-29) ceilings outside Warp's model of one element per
// thread (float4, four elements per thread with the loads first) and coarsened entries (the
// unchecked body for 2, 4 or 8 logical threads per GPU thread, the later ones prefetched into L1
// or L2, or run statement by statement in lockstep: docs/cuda.md "Coarsened launches"). Built by bench/kernel_variants/build.sh with the flags weft's NVRTC uses
// (-std=c++17 --fmad=false) and run on the GPU machine (scripts/gpu-run's WEFT_GPU_BENCH).
// Prints one row per variant and size: time per launch (median of 7 rounds), GB/s (12 bytes
// per element), share of the copy rate, and the max error against a float64 reference.
#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "weft.h"
#include "codegen_support.h"
#include "variant_common.h"

struct alignas(8) saxpy_args {
  wp::array_t<wp::float32> p0;  // x
  wp::array_t<wp::float32> p1;  // y
  wp::float32 p2;               // a
};

// The body weft generates (forward, bounds-checked), as emitted.
static inline __device__ void saxpy_body(const wp::launch_context_t* __ctx, const saxpy_args& __args,
                                         wp::int64 __tid_flat) {
  wp::array_t<wp::float32> var_0 = __args.p0;
  wp::array_t<wp::float32> var_1 = __args.p1;
  wp::float32 var_2 = __args.p2;
  wp::int32 var_4 = wp::int32(__tid_flat);
  if (!wp::cg_check(__ctx, 0, 5, 0, "x", var_0, var_4, 0, 0, 0, 1)) return;
  if (!wp::cg_check(__ctx, 0, 5, 1, "y", var_1, var_4, 0, 0, 0, 1)) return;
  wp::float32 var_5 = wp::load(var_0, var_4);
  wp::float32 var_6 = wp::mul(var_2, var_5);
  wp::float32 var_7 = wp::load(var_1, var_4);
  wp::float32 var_8 = wp::add(var_6, var_7);
  wp::store(var_1, var_4, var_8);
}

// The failure path of a check, out of line: the hot path keeps only compares and a branch.
template <typename T>
__device__ __noinline__ void report_check_failure(const wp::launch_context_t* ctx, wp::int32 line, wp::int32 param,
                                                  const char* name, const wp::array_t<T>& a, wp::int64 i) {
  const wp::int64 idx[wp::ARRAY_MAX_DIMS] = {i, 0, 0, 0};
  wp::report_error(ctx, a.data ? wp::LAUNCH_OUT_OF_BOUNDS : wp::LAUNCH_NULL_ARRAY, 0, line, param, 1, idx, a.shape, name);
}
template <typename T>
static inline __device__ bool check_cold(const wp::launch_context_t* ctx, wp::int32 line, wp::int32 param, const char* name,
                                         const wp::array_t<T>& a, wp::int64 i) {
  if (ctx->flags & wp::LAUNCH_FLAG_NO_BOUNDS_CHECK) return true;
  if (a.data != nullptr && wp::in_range(i, a.shape[0])) return true;
  report_check_failure(ctx, line, param, name, a, i);
  return false;
}
static inline __device__ void saxpy_body_cold(const wp::launch_context_t* __ctx, const saxpy_args& __args,
                                              wp::int64 __tid_flat) {
  wp::int32 i = wp::int32(__tid_flat);
  if (!check_cold(__ctx, 5, 0, "x", __args.p0, i)) return;
  if (!check_cold(__ctx, 5, 1, "y", __args.p1, i)) return;
  wp::float32 x = wp::load(__args.p0, i);
  wp::float32 y = wp::load(__args.p1, i);
  wp::store(__args.p1, i, wp::add(wp::mul(__args.p2, x), y));
}
static inline __device__ void saxpy_body_unchecked(const saxpy_args& __args, wp::int64 __tid_flat) {
  wp::int32 i = wp::int32(__tid_flat);
  wp::float32 x = wp::load(__args.p0, i);
  wp::float32 y = wp::load(__args.p1, i);
  wp::store(__args.p1, i, wp::add(wp::mul(__args.p2, x), y));
}

#define GRID_STRIDE_LOOP(BODY)                                                                                     \
  for (wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x; __i < __ctx.bounds.size;                 \
       __i += (wp::int64)blockDim.x * gridDim.x)                                                                   \
  BODY

extern "C" __global__ void weft_now(wp::launch_context_t __ctx, saxpy_args __args) {
  GRID_STRIDE_LOOP(saxpy_body(&__ctx, __args, __i);)
}
extern "C" __global__ void no_loop(wp::launch_context_t __ctx, saxpy_args __args) {
  const wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  if (__i < __ctx.bounds.size) saxpy_body(&__ctx, __args, __i);
}
extern "C" __global__ void cold_report(wp::launch_context_t __ctx, saxpy_args __args) {
  GRID_STRIDE_LOOP(saxpy_body_cold(&__ctx, __args, __i);)
}
extern "C" __global__ void cold_report_no_loop(wp::launch_context_t __ctx, saxpy_args __args) {
  const wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  if (__i < __ctx.bounds.size) saxpy_body_cold(&__ctx, __args, __i);
}
// The grid-stride entry as weft generated it from 2026-11-25 (its grid-stride variant still
// does): __grid_constant__ parameters, the stride computed once before the loop; and the two
// halves of that change alone.
extern "C" __global__ void gc_hoisted_stride(const __grid_constant__ wp::launch_context_t __ctx,
                                             const __grid_constant__ saxpy_args __args) {
  const wp::int64 __stride = (wp::int64)blockDim.x * gridDim.x;
  for (wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x; __i < __ctx.bounds.size; __i += __stride)
    saxpy_body(&__ctx, __args, __i);
}
extern "C" __global__ void gc_only(const __grid_constant__ wp::launch_context_t __ctx,
                                   const __grid_constant__ saxpy_args __args) {
  GRID_STRIDE_LOOP(saxpy_body(&__ctx, __args, __i);)
}
extern "C" __global__ void hoisted_stride_only(wp::launch_context_t __ctx, saxpy_args __args) {
  const wp::int64 __stride = (wp::int64)blockDim.x * gridDim.x;
  for (wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x; __i < __ctx.bounds.size; __i += __stride)
    saxpy_body(&__ctx, __args, __i);
}
// One entry for both cases: a grid that covers the launch runs the body once per thread without a
// loop; a smaller grid (max_blocks) strides.
extern "C" __global__ void once_or_loop(wp::launch_context_t __ctx, saxpy_args __args) {
  wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  const wp::int64 __stride = (wp::int64)blockDim.x * gridDim.x;
  if (__stride >= __ctx.bounds.size) {
    if (__i < __ctx.bounds.size) saxpy_body(&__ctx, __args, __i);
    return;
  }
  for (; __i < __ctx.bounds.size; __i += __stride) saxpy_body(&__ctx, __args, __i);
}
// One loop, left after the first pass when the grid covers the launch (the body inlined once).
extern "C" __global__ void loop_break_once(wp::launch_context_t __ctx, saxpy_args __args) {
  wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  const wp::int64 __stride = (wp::int64)blockDim.x * gridDim.x;
  const bool __once = __stride >= __ctx.bounds.size;
  if (__i >= __ctx.bounds.size) return;
  do {
    saxpy_body(&__ctx, __args, __i);
    if (__once) break;
    __i += __stride;
  } while (__i < __ctx.bounds.size);
}
extern "C" __global__ void no_loop_unchecked(wp::launch_context_t __ctx, saxpy_args __args) {
  const wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  if (__i < __ctx.bounds.size) saxpy_body_unchecked(__args, __i);
}
// The same out-of-line report with the parameters __grid_constant__ (what weft's entries use):
// the pointers point into the parameter space, nothing is copied.
extern "C" __global__ void cold_report_grid_constant(const __grid_constant__ wp::launch_context_t __ctx,
                                                     const __grid_constant__ saxpy_args __args) {
  GRID_STRIDE_LOOP(saxpy_body_cold(&__ctx, __args, __i);)
}
extern "C" __global__ void unchecked(wp::launch_context_t __ctx, saxpy_args __args) {
  GRID_STRIDE_LOOP(saxpy_body_unchecked(__args, __i);)
}

// A lean kernel over arrays with int32 shape and strides (Warp's array_t layout), unchecked.
extern "C" __global__ void warp_style(wp::int64 n, warp_array_t x, warp_array_t y, float a) {
  const wp::int64 i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  float* px = (float*)((char*)x.data + (int)i * x.strides[0]);
  float* py = (float*)((char*)y.data + (int)i * y.strides[0]);
  *py = a * *px + *py;
}

// The first tid component with the multi-dimensional division out of line (a call, so nothing
// of it is hoisted). Measured slower in the loop and the same without it: not adopted.
__device__ __noinline__ wp::int64 tid_first_nd(const wp::launch_bounds_t* b, wp::int64 flat) {
  const wp::int64 inner = (b->shape[1] > 0 ? b->shape[1] : 1) * (b->shape[2] > 0 ? b->shape[2] : 1) *
                          (b->shape[3] > 0 ? b->shape[3] : 1);
  return flat / inner;
}

// The body weft generates (2026-11-28, WEFT_DUMP_IR of `i = wp.tid(); y[i] = a * x[i] + y[i]`):
// the tid unravelled (dead here) and its first component through cg_tid_first, whose
// multi-dimensional divisor (a product of the launch's inner extents) the compiler hoists into
// every thread's prologue in a loop; kDivisorOutOfLine: through tid_first_nd instead.
template <bool kDivisorOutOfLine>
static inline __device__ void gen_body_as(const wp::launch_context_t* __ctx, const saxpy_args& __args,
                                          wp::int64 __tid_flat) {
  wp::int64 __tid[4];
  wp::cg_unravel(__ctx->bounds, __tid_flat, __tid);
  (void)__tid;
  wp::array_t<wp::float32> var_0 = __args.p0;
  wp::array_t<wp::float32> var_1 = __args.p1;
  wp::float32 var_2 = __args.p2;
  const wp::int64 tid0 = !kDivisorOutOfLine ? wp::cg_tid_first(__ctx, __tid_flat)
                         : __ctx->bounds.ndim <= 1 ? __tid_flat
                                                   : tid_first_nd(&__ctx->bounds, __tid_flat);
  wp::int32 var_4 = wp::int32(tid0);
  if (!wp::cg_check(__ctx, 0, 6, 0, "x", var_0, var_4, 0, 0, 0, 1)) return;
  if (!wp::cg_check(__ctx, 0, 6, 1, "y", var_1, var_4, 0, 0, 0, 1)) return;
  wp::float32 var_5 = wp::load(var_0, var_4);
  wp::float32 var_6 = wp::mul(var_2, var_5);
  wp::float32 var_7 = wp::load(var_1, var_4);
  wp::float32 var_8 = wp::add(var_6, var_7);
  wp::store(var_1, var_4, var_8);
}
static inline __device__ void gen_body(const wp::launch_context_t* c, const saxpy_args& a, wp::int64 i) {
  gen_body_as<false>(c, a, i);
}
static inline __device__ void gen_body_tidfast(const wp::launch_context_t* c, const saxpy_args& a, wp::int64 i) {
  gen_body_as<true>(c, a, i);
}
#define GC_ENTRY(name) \
  extern "C" __global__ void name(const __grid_constant__ wp::launch_context_t __ctx, const __grid_constant__ saxpy_args __args)
#define GC_LOOP(BODY)                                                                                             \
  const wp::int64 __stride = (wp::int64)blockDim.x * gridDim.x;                                                  \
  for (wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x; __i < __ctx.bounds.size; __i += __stride) \
    BODY(&__ctx, __args, __i);
#define GC_NO_LOOP(BODY)                                                   \
  const wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x; \
  if (__i < __ctx.bounds.size) BODY(&__ctx, __args, __i);
// A grid that covers the launch (always, unless max_blocks) runs each thread once: the loop's
// back edge is taken only when it does not, so loop-invariant work of the body's error paths
// need not be hoisted above the first pass.
#define GC_ONCE_THEN_LOOP(BODY)                                                         \
  wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;                    \
  const wp::int64 __stride = (wp::int64)blockDim.x * gridDim.x;                        \
  if (__i >= __ctx.bounds.size) return;                                                \
  BODY(&__ctx, __args, __i);                                                           \
  if (__stride >= __ctx.bounds.size) return;                                           \
  for (__i += __stride; __i < __ctx.bounds.size; __i += __stride) BODY(&__ctx, __args, __i);
// The loop calls the body out of line: nothing of the body is hoisted into the loop's prologue.
static __device__ __noinline__ void gen_body_call(const wp::launch_context_t* __ctx, const saxpy_args* __args,
                                                  wp::int64 __tid_flat) {
  gen_body_tidfast(__ctx, *__args, __tid_flat);
}
static inline __device__ void gen_body_called(const wp::launch_context_t* __ctx, const saxpy_args& __args,
                                              wp::int64 __tid_flat) {
  gen_body_call(__ctx, &__args, __tid_flat);
}
GC_ENTRY(gen_loop_calls_body) { GC_LOOP(gen_body_called) }
GC_ENTRY(gen_now) { GC_LOOP(gen_body) }
GC_ENTRY(gen_now_no_loop) { GC_NO_LOOP(gen_body) }
GC_ENTRY(gen_tidfast) { GC_LOOP(gen_body_tidfast) }
GC_ENTRY(gen_tidfast_no_loop) { GC_NO_LOOP(gen_body_tidfast) }
GC_ENTRY(gen_tidfast_once_then_loop) { GC_ONCE_THEN_LOOP(gen_body_tidfast) }

// Ceilings (2026-11-29): what this GPU gives saxpy when the program may leave Warp's model of
// one thread per element. Plain pointers, no checks; n a multiple of 4.
extern "C" __global__ void ceiling_scalar(long long n, const float* __restrict__ x, float* __restrict__ y, float a) {
  const long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) y[i] = a * x[i] + y[i];
}
// Loads that bypass nothing but mark the data as streamed (evict-first).
extern "C" __global__ void ceiling_streaming(long long n, const float* __restrict__ x, float* __restrict__ y, float a) {
  const long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) __stcs(y + i, a * __ldcs(x + i) + __ldcs(y + i));
}
// Four elements per thread, each a quarter of the array apart (coalesced), all loads first.
extern "C" __global__ void ceiling_ilp4(long long n, const float* __restrict__ x, float* __restrict__ y, float a) {
  const long long q = n / 4;
  const long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= q) return;
  float xv[4], yv[4];
#pragma unroll
  for (int k = 0; k < 4; ++k) { xv[k] = x[i + k * q]; yv[k] = y[i + k * q]; }
#pragma unroll
  for (int k = 0; k < 4; ++k) y[i + k * q] = a * xv[k] + yv[k];
}
// 16-byte loads and stores: four consecutive elements per thread.
extern "C" __global__ void ceiling_float4(long long n, const float4* __restrict__ x, float4* __restrict__ y, float a) {
  const long long i = (long long)blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n / 4) return;
  const float4 xv = x[i];
  float4 yv = y[i];
  yv.x = a * xv.x + yv.x;
  yv.y = a * xv.y + yv.y;
  yv.z = a * xv.z + yv.z;
  yv.w = a * xv.w + yv.w;
  y[i] = yv;
}

// Coarsened entries (2026-11-29): each thread runs the unchecked generated body for K logical
// threads a K-th of the launch apart (i, i+Q, ... : coalesced per copy), first prefetching what
// the later copies' tid-indexed arrays hold at their index, so that their loads are in flight
// together: an entry-level change that leaves the body's statements as they are.
template <int K, bool kL1>
static inline __device__ void coarse_prefetch(const wp::launch_context_t& __ctx, const saxpy_args& __args) {
  const wp::int64 n = __ctx.bounds.size;
  const wp::int64 q = (n + K - 1) / K;
  const wp::int64 i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= q) return;
#pragma unroll
  for (int k = 1; k < K; ++k) {
    const wp::int64 j = i + k * q;
    if (j < n) {
      const char* px = (const char*)__args.p0.data + j * __args.p0.strides[0];
      const char* py = (const char*)__args.p1.data + j * __args.p1.strides[0];
      if (kL1) {
        asm volatile("prefetch.global.L1 [%0];" ::"l"(px));
        asm volatile("prefetch.global.L1 [%0];" ::"l"(py));
      } else {
        asm volatile("prefetch.global.L2 [%0];" ::"l"(px));
        asm volatile("prefetch.global.L2 [%0];" ::"l"(py));
      }
    }
  }
#pragma unroll
  for (int k = 0; k < K; ++k) {
    const wp::int64 j = i + k * q;
    if (j < n) saxpy_body_unchecked(__args, j);
  }
}
GC_ENTRY(coarse_l2_k2) { coarse_prefetch<2, false>(__ctx, __args); }
GC_ENTRY(coarse_l2_k4) { coarse_prefetch<4, false>(__ctx, __args); }
GC_ENTRY(coarse_l1_k4) { coarse_prefetch<4, true>(__ctx, __args); }
GC_ENTRY(coarse_l2_k8) { coarse_prefetch<8, false>(__ctx, __args); }
// Lockstep: the unchecked body's statements each run for the K copies before the next statement
// (what a coarsening code generator would emit): all loads of the K copies come first.
template <int K>
static inline __device__ void coarse_lockstep(const wp::launch_context_t& __ctx, const saxpy_args& __args) {
  const wp::int64 n = __ctx.bounds.size;
  const wp::int64 q = (n + K - 1) / K;
  const wp::int64 i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= q) return;
  if (i + (K - 1) * q >= n) {   // the tail: one copy after the other
    for (int k = 0; k < K; ++k)
      if (i + k * q < n) saxpy_body_unchecked(__args, i + k * q);
    return;
  }
  wp::int32 t[K];
  wp::float32 xv[K], yv[K];
#pragma unroll
  for (int k = 0; k < K; ++k) t[k] = wp::int32(i + k * q);
#pragma unroll
  for (int k = 0; k < K; ++k) xv[k] = wp::load(__args.p0, t[k]);
#pragma unroll
  for (int k = 0; k < K; ++k) yv[k] = wp::load(__args.p1, t[k]);
#pragma unroll
  for (int k = 0; k < K; ++k) wp::store(__args.p1, t[k], wp::add(wp::mul(__args.p2, xv[k]), yv[k]));
}
GC_ENTRY(lockstep_k2) { coarse_lockstep<2>(__ctx, __args); }
GC_ENTRY(lockstep_k4) { coarse_lockstep<4>(__ctx, __args); }

int main(int argc, char** argv) {
  std::vector<long long> sizes = {10000000LL, 100000000LL};
  if (argc > 1) sizes = {std::atoll(argv[1])};
  std::printf("| n | variant | time per launch (us) | GB/s | of copy rate | max rel. error vs float64 |\n");
  std::printf("| --- | --- | --- | --- | --- | --- |\n");
  for (long long n : sizes) {
    const size_t bytes = size_t(n) * sizeof(float);
    std::vector<float> hx(n), hy(n);
    unsigned s = 12345u;
    for (long long i = 0; i < n; ++i) {
      s = s * 1664525u + 1013904223u;
      hx[i] = float((s >> 8) * (1.0 / 16777216.0) - 0.5) * 1e3f;
      s = s * 1664525u + 1013904223u;
      hy[i] = float((s >> 8) * (1.0 / 16777216.0) - 0.5) * 1e-3f;
    }
    float *x, *y, *copy_dst;
    wp::launch_error_t* err;
    CHECK(cudaMalloc(&x, bytes));
    CHECK(cudaMalloc(&y, bytes));
    CHECK(cudaMalloc(&copy_dst, 2 * bytes));
    CHECK(cudaMalloc(&err, sizeof(wp::launch_error_t)));
    CHECK(cudaMemset(err, 0, sizeof(wp::launch_error_t)));
    CHECK(cudaMemcpy(x, hx.data(), bytes, cudaMemcpyHostToDevice));

    wp::launch_context_t ctx{};
    ctx.bounds.ndim = 1;
    ctx.bounds.shape[0] = n;
    ctx.bounds.size = n;
    ctx.error = err;
    saxpy_args args{};
    args.p0.data = x;
    args.p0.shape[0] = n;
    args.p0.strides[0] = 4;
    args.p0.ndim = 1;
    args.p1 = args.p0;
    args.p1.data = y;
    args.p2 = 1.75f;
    warp_array_t wx{x, nullptr, {int(n), 0, 0, 0}, {4, 0, 0, 0}, 1};
    warp_array_t wy{y, nullptr, {int(n), 0, 0, 0}, {4, 0, 0, 0}, 1};
    const unsigned grid = unsigned((n + 255) / 256);
    const int reps = n >= 100000000LL ? 20 : 100;

    const double copy_us = time_us([&] { CHECK(cudaMemcpyAsync(copy_dst, copy_dst + n, bytes, cudaMemcpyDeviceToDevice)); }, reps);
    const double copy_rate = 2.0 * bytes / (copy_us * 1e-6) / 1e9;   // read + write
    std::printf("| %lld | device copy (%zu MB read + written) | %.1f | %.0f | 100%% | |\n", n, 2 * bytes / 1000000, copy_us, copy_rate);

    struct Variant {
      const char* name;
      void (*run)(unsigned, const wp::launch_context_t&, const saxpy_args&, const warp_array_t&, const warp_array_t&, long long);
    };
    const Variant variants[] = {
        {"generated body in the grid-stride loop (the max_blocks variant)", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { gen_now<<<g, 256>>>(c, a); }},
        {"generated body, no loop (the default entry)", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { gen_now_no_loop<<<g, 256>>>(c, a); }},
        {"loop, checks, 1-D tid fast path", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { gen_tidfast<<<g, 256>>>(c, a); }},
        {"no loop, checks, 1-D tid fast path", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { gen_tidfast_no_loop<<<g, 256>>>(c, a); }},
        {"loop calling the body out of line, checks, 1-D tid fast path", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { gen_loop_calls_body<<<g, 256>>>(c, a); }},
        {"once then loop, checks, 1-D tid fast path", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { gen_tidfast_once_then_loop<<<g, 256>>>(c, a); }},
        {"grid-stride loop, checks inline (generated before)", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { weft_now<<<g, 256>>>(c, a); }},
        {"grid-stride loop, __grid_constant__, stride hoisted (the entry of 2026-11-25)", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { gc_hoisted_stride<<<g, 256>>>(c, a); }},
        {"grid-stride loop, __grid_constant__ only", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { gc_only<<<g, 256>>>(c, a); }},
        {"grid-stride loop, stride hoisted only", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { hoisted_stride_only<<<g, 256>>>(c, a); }},
        {"no loop (if i < n), checks inline (grid_stride=False)", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { no_loop<<<g, 256>>>(c, a); }},
        {"one entry: once when the grid covers, else loop", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { once_or_loop<<<g, 256>>>(c, a); }},
        {"one loop, left after one pass when the grid covers", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { loop_break_once<<<g, 256>>>(c, a); }},
        {"no loop, no checks", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { no_loop_unchecked<<<g, 256>>>(c, a); }},
        {"loop, error report out of line (parameters copied to local memory)", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { cold_report<<<g, 256>>>(c, a); }},
        {"loop, error report out of line, parameters __grid_constant__", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { cold_report_grid_constant<<<g, 256>>>(c, a); }},
        {"no loop, error report out of line", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { cold_report_no_loop<<<g, 256>>>(c, a); }},
        {"loop, no checks", [](unsigned g, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long) { unchecked<<<g, 256>>>(c, a); }},
        {"coarsened x2, later copies prefetched to L2, no checks", [](unsigned, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long n) { coarse_l2_k2<<<unsigned(((n + 2 - 1) / 2 + 255) / 256), 256>>>(c, a); }},
        {"coarsened x4, later copies prefetched to L2, no checks", [](unsigned, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long n) { coarse_l2_k4<<<unsigned(((n + 4 - 1) / 4 + 255) / 256), 256>>>(c, a); }},
        {"coarsened x4, later copies prefetched to L1, no checks", [](unsigned, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long n) { coarse_l1_k4<<<unsigned(((n + 4 - 1) / 4 + 255) / 256), 256>>>(c, a); }},
        {"coarsened x8, later copies prefetched to L2, no checks", [](unsigned, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long n) { coarse_l2_k8<<<unsigned(((n + 8 - 1) / 8 + 255) / 256), 256>>>(c, a); }},
        {"coarsened x2, statements in lockstep, no checks", [](unsigned, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long n) { lockstep_k2<<<unsigned(((n + 2 - 1) / 2 + 255) / 256), 256>>>(c, a); }},
        {"coarsened x4, statements in lockstep, no checks", [](unsigned, const wp::launch_context_t& c, const saxpy_args& a, const warp_array_t&, const warp_array_t&, long long n) { lockstep_k4<<<unsigned(((n + 4 - 1) / 4 + 255) / 256), 256>>>(c, a); }},
        {"ceiling: plain pointers, one element per thread", [](unsigned, const wp::launch_context_t&, const saxpy_args& a, const warp_array_t& wx, const warp_array_t& wy, long long n) { ceiling_scalar<<<unsigned((n + 255) / 256), 256>>>(n, wx.data, wy.data, a.p2); }},
        {"ceiling: one element per thread, streaming loads/stores", [](unsigned, const wp::launch_context_t&, const saxpy_args& a, const warp_array_t& wx, const warp_array_t& wy, long long n) { ceiling_streaming<<<unsigned((n + 255) / 256), 256>>>(n, wx.data, wy.data, a.p2); }},
        {"ceiling: four elements per thread a quarter apart, loads first", [](unsigned, const wp::launch_context_t&, const saxpy_args& a, const warp_array_t& wx, const warp_array_t& wy, long long n) { ceiling_ilp4<<<unsigned((n / 4 + 255) / 256), 256>>>(n, wx.data, wy.data, a.p2); }},
        {"ceiling: float4 loads and stores", [](unsigned, const wp::launch_context_t&, const saxpy_args& a, const warp_array_t& wx, const warp_array_t& wy, long long n) { ceiling_float4<<<unsigned((n / 4 + 255) / 256), 256>>>(n, reinterpret_cast<const float4*>(wx.data), reinterpret_cast<float4*>(wy.data), a.p2); }},
        {"lean, no checks, int32 shape and strides", [](unsigned g, const wp::launch_context_t&, const saxpy_args& a, const warp_array_t& wx, const warp_array_t& wy, long long n) { warp_style<<<g, 256>>>(n, wx, wy, a.p2); }},
    };
    for (const Variant& v : variants) {
      CHECK(cudaMemcpy(y, hy.data(), bytes, cudaMemcpyHostToDevice));
      v.run(grid, ctx, args, wx, wy, n);   // one launch: checked against float64 below
      CHECK(cudaGetLastError());
      std::vector<float> out(n);
      CHECK(cudaMemcpy(out.data(), y, bytes, cudaMemcpyDeviceToHost));
      double max_rel = 0;
      for (long long i = 0; i < n; ++i) {
        const double ref = 1.75 * double(hx[i]) + double(hy[i]);
        max_rel = std::max(max_rel, std::fabs(double(out[i]) - ref) / std::max(std::fabs(ref), 1e-30));
      }
      const double us = time_us([&] { v.run(grid, ctx, args, wx, wy, n); }, reps);
      CHECK(cudaGetLastError());
      const double rate = 3.0 * bytes / (us * 1e-6) / 1e9;
      std::printf("| %lld | %s | %.1f | %.0f | %.1f%% | %.1e |\n", n, v.name, us, rate, 100.0 * rate / copy_rate, max_rel);
    }
    wp::launch_error_t herr{};
    CHECK(cudaMemcpy(&herr, err, sizeof(herr), cudaMemcpyDeviceToHost));
    if (herr.kind != 0) std::printf("unexpected launch error kind %d\n", herr.kind);
    CHECK(cudaFree(x));
    CHECK(cudaFree(y));
    CHECK(cudaFree(copy_dst));
    CHECK(cudaFree(err));
  }
  return 0;
}
