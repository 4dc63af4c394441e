// vec3 particle integration (`v[i] = v[i] + g * dt; x[i] = x[i] + v[i] * dt`, 24 bytes loaded and
// 24 stored per element) in variants timed side by side on one GPU, beside a device copy of the
// same bytes: the body weft generates for its trusted-index variant (load v, store v, load x,
// store x: the x load cannot move above the v store, x and v may overlap, so each thread waits
// for two memory latencies one after the other), the same body after a prefetch of x[i] into L2
// or L1 (no effect on what is computed, whatever overlaps), the loads first (what a compiler may
// do only when x and v cannot overlap), Warp's form (grid-stride loop, int32 shape and strides),
// and plain pointers. Built by bench/kernel_variants/build.sh with the flags weft's NVRTC uses
// (-std=c++17 --fmad=false) and run on the GPU machine (scripts/gpu-run's WEFT_GPU_BENCH).
// Prints one row per variant and size: time per launch (median of 7 rounds), GB/s (48 bytes
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

using vec3 = wp::vec_t<3, wp::float32>;

struct alignas(8) integrate_args {
  wp::array_t<vec3> p0;  // x
  wp::array_t<vec3> p1;  // v
  vec3 p2;               // g
  wp::float32 p3;        // dt
};

#define ENTRY(name) \
  extern "C" __global__ void name(const __grid_constant__ wp::launch_context_t __ctx, const __grid_constant__ integrate_args __args)
#define ONCE(BODY)                                                              \
  const wp::int64 __i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;       \
  if (__i < __ctx.bounds.size) BODY(__args, __i);

// The trusted-index body as weft emits it (its checks proven away), forward.
static inline __device__ void body_generated(const integrate_args& __args, wp::int64 __tid_flat) {
  wp::array_t<vec3> var_0 = __args.p0;
  wp::array_t<vec3> var_1 = __args.p1;
  vec3 var_2 = __args.p2;
  wp::float32 var_3 = __args.p3;
  wp::int32 var_5 = wp::int32(__tid_flat);
  vec3 var_6 = wp::load(var_1, var_5);
  vec3 var_7 = wp::mul(var_2, var_3);
  vec3 var_8 = wp::add(var_6, var_7);
  wp::store(var_1, var_5, var_8);
  vec3 var_9 = wp::load(var_0, var_5);
  vec3 var_10 = wp::mul(var_8, var_3);
  vec3 var_11 = wp::add(var_9, var_10);
  wp::store(var_0, var_5, var_11);
}
static inline __device__ void body_prefetch_l2(const integrate_args& __args, wp::int64 i) {
  wp::cg_prefetch_l2(__args.p0, i);
  body_generated(__args, i);
}
static inline __device__ void body_prefetch_l1(const integrate_args& __args, wp::int64 i) {
  asm volatile("prefetch.global.L1 [%0];" ::"l"(reinterpret_cast<const char*>(__args.p0.data) + i * __args.p0.strides[0]));
  body_generated(__args, i);
}
// Both prefetched: the first load then waits as before, the second finds its line on its way.
static inline __device__ void body_prefetch_both(const integrate_args& __args, wp::int64 i) {
  wp::cg_prefetch_l2(__args.p1, i);
  wp::cg_prefetch_l2(__args.p0, i);
  body_generated(__args, i);
}
static inline __device__ void body_loads_first(const integrate_args& __args, wp::int64 __tid_flat) {
  const wp::int32 i = wp::int32(__tid_flat);
  vec3 v = wp::load(__args.p1, i);
  vec3 x = wp::load(__args.p0, i);
  vec3 vi = wp::add(v, wp::mul(__args.p2, __args.p3));
  wp::store(__args.p1, i, vi);
  wp::store(__args.p0, i, wp::add(x, wp::mul(vi, __args.p3)));
}
ENTRY(generated) { ONCE(body_generated) }
ENTRY(prefetch_l2) { ONCE(body_prefetch_l2) }
ENTRY(prefetch_l1) { ONCE(body_prefetch_l1) }
ENTRY(prefetch_both) { ONCE(body_prefetch_both) }
ENTRY(loads_first) { ONCE(body_loads_first) }

// Warp 1.19's form: a grid-stride loop, arrays with int32 shape and strides, the same order.
extern "C" __global__ void warp_style(wp::int64 n, warp_array_t x, warp_array_t v, vec3 g, float dt) {
  for (wp::int64 i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += (wp::int64)blockDim.x * gridDim.x) {
    vec3* pv = (vec3*)((char*)v.data + (int)i * v.strides[0]);
    vec3 vi = wp::add(*pv, wp::mul(g, dt));
    *pv = vi;
    vec3* px = (vec3*)((char*)x.data + (int)i * x.strides[0]);
    *px = wp::add(*px, wp::mul(vi, dt));
  }
}
extern "C" __global__ void ceiling_restrict(wp::int64 n, float* __restrict__ x, float* __restrict__ v, float gy, float dt) {
  const wp::int64 i = (wp::int64)blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  float v0 = v[3 * i], v1 = v[3 * i + 1], v2 = v[3 * i + 2];
  float x0 = x[3 * i], x1 = x[3 * i + 1], x2 = x[3 * i + 2];
  v1 += gy * dt;
  v[3 * i] = v0, v[3 * i + 1] = v1, v[3 * i + 2] = v2;
  x[3 * i] = x0 + v0 * dt, x[3 * i + 1] = x1 + v1 * dt, x[3 * i + 2] = x2 + v2 * dt;
}

int main(int argc, char** argv) {
  std::vector<long long> sizes = {1000000LL, 10000000LL, 100000000LL};
  if (argc > 1) sizes = {std::atoll(argv[1])};
  std::printf("| n | variant | time per launch (us) | GB/s | of copy rate | max rel. error vs float64 |\n");
  std::printf("| --- | --- | --- | --- | --- | --- |\n");
  const float dt = 1.0f / 60.0f;
  const vec3 g(0.0f, -9.8f, 0.0f);
  for (long long n : sizes) {
    const size_t bytes = size_t(n) * sizeof(vec3);
    std::vector<float> hx(3 * n), hv(3 * n);
    unsigned s = 12345u;
    for (long long i = 0; i < 3 * n; ++i) {
      s = s * 1664525u + 1013904223u;
      hx[i] = float((s >> 8) * (1.0 / 16777216.0) - 0.5) * 1e4f;
      s = s * 1664525u + 1013904223u;
      hv[i] = float((s >> 8) * (1.0 / 16777216.0) - 0.5) * 1e-2f;
    }
    float *x, *v, *copy_dst;
    CHECK(cudaMalloc(&x, bytes));
    CHECK(cudaMalloc(&v, bytes));
    CHECK(cudaMalloc(&copy_dst, 4 * bytes));

    wp::launch_context_t ctx{};
    ctx.bounds.ndim = 1;
    ctx.bounds.shape[0] = n;
    ctx.bounds.size = n;
    integrate_args args{};
    args.p0.data = reinterpret_cast<vec3*>(x);
    args.p0.shape[0] = n;
    args.p0.strides[0] = sizeof(vec3);
    args.p0.ndim = 1;
    args.p1 = args.p0;
    args.p1.data = reinterpret_cast<vec3*>(v);
    args.p2 = g;
    args.p3 = dt;
    warp_array_t wx{x, nullptr, {int(n), 0, 0, 0}, {int(sizeof(vec3)), 0, 0, 0}, 1};
    warp_array_t wv{v, nullptr, {int(n), 0, 0, 0}, {int(sizeof(vec3)), 0, 0, 0}, 1};
    const unsigned grid = unsigned((n + 255) / 256);
    const int reps = n >= 100000000LL ? 10 : n >= 10000000LL ? 50 : 200;

    // Two arrays read and written: a copy of 2 x bytes.
    const double copy_us = time_us([&] {
      CHECK(cudaMemcpyAsync(copy_dst, copy_dst + 6 * n, 2 * bytes, cudaMemcpyDeviceToDevice));
    }, reps);
    const double copy_rate = 4.0 * bytes / (copy_us * 1e-6) / 1e9;
    std::printf("| %lld | device copy (%zu MB read + written) | %.1f | %.0f | 100%% | |\n", n, 4 * bytes / 1000000,
                copy_us, copy_rate);

    struct Variant {
      const char* name;
      void (*run)(unsigned, const wp::launch_context_t&, const integrate_args&, const warp_array_t&,
                  const warp_array_t&, long long);
    };
    using C = const wp::launch_context_t&;
    using A = const integrate_args&;
    using W = const warp_array_t&;
    const Variant variants[] = {
        {"generated trusted-index body, no loop (weft's entry)", [](unsigned gr, C c, A a, W, W, long long) { generated<<<gr, 256>>>(c, a); }},
        {"the same, x[i] prefetched into L2 first", [](unsigned gr, C c, A a, W, W, long long) { prefetch_l2<<<gr, 256>>>(c, a); }},
        {"the same, x[i] prefetched into L1 first", [](unsigned gr, C c, A a, W, W, long long) { prefetch_l1<<<gr, 256>>>(c, a); }},
        {"the same, v[i] and x[i] prefetched into L2 first", [](unsigned gr, C c, A a, W, W, long long) { prefetch_both<<<gr, 256>>>(c, a); }},
        {"loads first (only when x and v do not overlap)", [](unsigned gr, C c, A a, W, W, long long) { loads_first<<<gr, 256>>>(c, a); }},
        {"Warp's form: grid-stride loop, int32 strides", [](unsigned gr, C, A a, W wx, W wv, long long n) { warp_style<<<gr, 256>>>(n, wx, wv, a.p2, a.p3); }},
        {"ceiling: plain __restrict__ pointers, loads first", [](unsigned gr, C, A a, W wx, W wv, long long n) { ceiling_restrict<<<gr, 256>>>(n, wx.data, wv.data, a.p2[1], a.p3); }},
    };
    for (const Variant& var : variants) {
      CHECK(cudaMemcpy(x, hx.data(), bytes, cudaMemcpyHostToDevice));
      CHECK(cudaMemcpy(v, hv.data(), bytes, cudaMemcpyHostToDevice));
      var.run(grid, ctx, args, wx, wv, n);   // one step: checked against float64 below
      CHECK(cudaGetLastError());
      std::vector<float> ox(3 * n), ov(3 * n);
      CHECK(cudaMemcpy(ox.data(), x, bytes, cudaMemcpyDeviceToHost));
      CHECK(cudaMemcpy(ov.data(), v, bytes, cudaMemcpyDeviceToHost));
      double max_rel = 0;
      const double dt64 = double(dt);
      for (long long i = 0; i < 3 * n; ++i) {
        const double vr = double(hv[i]) + (i % 3 == 1 ? -9.8 * dt64 : 0.0);
        const double xr = double(hx[i]) + vr * dt64;
        max_rel = std::max(max_rel, std::fabs(double(ov[i]) - vr) / std::max(std::fabs(vr), 1e-3));
        max_rel = std::max(max_rel, std::fabs(double(ox[i]) - xr) / std::max(std::fabs(xr), 1e-3));
      }
      const double us = time_us([&] { var.run(grid, ctx, args, wx, wv, n); }, reps);
      CHECK(cudaGetLastError());
      const double rate = 4.0 * bytes / (us * 1e-6) / 1e9;
      std::printf("| %lld | %s | %.1f | %.0f | %.1f%% | %.1e |\n", n, var.name, us, rate, 100.0 * rate / copy_rate,
                  max_rel);
    }
    CHECK(cudaFree(x));
    CHECK(cudaFree(v));
    CHECK(cudaFree(copy_dst));
  }
  return 0;
}
