// The native library compiles for the GPU: NVRTC (loaded with dlopen, so the test binary has no
// link dependency on CUDA; skipped when libnvrtc is absent) compiles a kernel that instantiates
// every header's builtins and adjoints (scalars for float32, float64 and float16; the rest for
// float32) to sm_90 code, with no GPU and no driver.
#include <dlfcn.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

#ifndef WEFT_NATIVE_DIR
#define WEFT_NATIVE_DIR "engine/native"
#endif

namespace {

typedef int nvrtcResult;  // NVRTC_SUCCESS == 0
typedef struct _nvrtcProgram* nvrtcProgram;

struct Nvrtc {
  void* lib = nullptr;
  nvrtcResult (*create)(nvrtcProgram*, const char*, const char*, int, const char* const*, const char* const*) = nullptr;
  nvrtcResult (*compile)(nvrtcProgram, int, const char* const*) = nullptr;
  nvrtcResult (*log_size)(nvrtcProgram, size_t*) = nullptr;
  nvrtcResult (*log)(nvrtcProgram, char*) = nullptr;
  nvrtcResult (*cubin_size)(nvrtcProgram, size_t*) = nullptr;
  nvrtcResult (*destroy)(nvrtcProgram*) = nullptr;

  bool Load() {
    for (const char* name : {"libnvrtc.so", "libnvrtc.so.13", "/usr/local/cuda/lib64/libnvrtc.so", "/usr/local/cuda/lib64/libnvrtc.so.13"}) {
      lib = dlopen(name, RTLD_NOW | RTLD_LOCAL);
      if (lib) break;
    }
    if (!lib) return false;
    create = reinterpret_cast<decltype(create)>(dlsym(lib, "nvrtcCreateProgram"));
    compile = reinterpret_cast<decltype(compile)>(dlsym(lib, "nvrtcCompileProgram"));
    log_size = reinterpret_cast<decltype(log_size)>(dlsym(lib, "nvrtcGetProgramLogSize"));
    log = reinterpret_cast<decltype(log)>(dlsym(lib, "nvrtcGetProgramLog"));
    cubin_size = reinterpret_cast<decltype(cubin_size)>(dlsym(lib, "nvrtcGetCUBINSize"));
    destroy = reinterpret_cast<decltype(destroy)>(dlsym(lib, "nvrtcDestroyProgram"));
    return create && compile && log_size && log && cubin_size && destroy;
  }
};

// Instantiates the library for one float type T (the kernel below calls it for float32,
// float64 and half where the builtin supports it).
const char* kKernelSource = R"CUDA(
#include "weft.h"

// Inside namespace wp, unqualified names find wp's overloads first (as generated code, which
// qualifies every call with wp::, does).
namespace wp {
namespace check {

template <typename T>
__device__ void scalar_family(T a, T b, T* out) {
  T r = add(a, b);
  r = add(r, sub(a, b)); r = add(r, mul(a, b)); r = add(r, div(a, b)); r = add(r, mod(a, b));
  r = add(r, floordiv(a, b)); r = add(r, pow(a, b)); r = add(r, min(a, b)); r = add(r, max(a, b));
  r = add(r, clamp(a, b, r)); r = add(r, abs(a)); r = add(r, sign(a)); r = add(r, step(a)); r = add(r, nonzero(a));
  r = add(r, sin(a)); r = add(r, cos(a)); r = add(r, tan(a)); r = add(r, asin(a)); r = add(r, acos(a));
  r = add(r, atan(a)); r = add(r, atan2(a, b)); r = add(r, sinh(a)); r = add(r, cosh(a)); r = add(r, tanh(a));
  r = add(r, sqrt(a)); r = add(r, cbrt(a)); r = add(r, log(a)); r = add(r, log2(a)); r = add(r, log10(a));
  r = add(r, exp(a)); r = add(r, erf(a)); r = add(r, erfc(a)); r = add(r, erfinv(a)); r = add(r, erfcinv(a));
  r = add(r, floor(a)); r = add(r, ceil(a)); r = add(r, round(a)); r = add(r, rint(a)); r = add(r, trunc(a));
  r = add(r, frac(a)); r = add(r, degrees(a)); r = add(r, radians(a)); r = add(r, copysign(a, b));
  r = add(r, lerp(a, b, r)); r = add(r, smoothstep(a, b, r)); r = add(r, where(isnan(a) || isinf(b) || !isfinite(r), a, b));
  T ga = T(0), gb = T(0), gc = T(0);
  adj_add(a, b, ga, gb, r); adj_sub(a, b, ga, gb, r); adj_mul(a, b, ga, gb, r); adj_div(a, b, ga, gb, r);
  adj_mod(a, b, ga, gb, r); adj_pow(a, b, ga, gb, r); adj_min(a, b, ga, gb, r); adj_max(a, b, ga, gb, r);
  adj_clamp(a, b, r, ga, gb, gc, r); adj_abs(a, ga, r); adj_sin(a, ga, r); adj_cos(a, ga, r); adj_tan(a, ga, r);
  adj_asin(a, ga, r); adj_acos(a, ga, r); adj_atan(a, ga, r); adj_atan2(a, b, ga, gb, r); adj_sinh(a, ga, r);
  adj_cosh(a, ga, r); adj_tanh(a, ga, r); adj_sqrt(a, ga, r); adj_cbrt(a, ga, r); adj_log(a, ga, r);
  adj_log2(a, ga, r); adj_log10(a, ga, r); adj_exp(a, ga, r); adj_erf(a, ga, r); adj_erfc(a, ga, r);
  adj_erfinv(a, ga, r); adj_erfcinv(a, ga, r); adj_lerp(a, b, r, ga, gb, gc, r); adj_smoothstep(a, b, r, ga, gb, gc, r);
  adj_copysign(a, b, ga, gb, r); adj_degrees(a, ga, r); adj_frac(a, ga, r); adj_floor(a, ga, r);
  out[0] = add(r, add(ga, add(gb, gc)));
}

template <typename T>
__device__ void linalg_family(T s, T* out) {
  vec_t<3, T> a(s, T(1), T(2)), b(T(3)), g3;
  vec_t<4, T> c(s, s, s, s), g4;
  mat_t<3, 3, T> m(a, b, a), n = identity<3, T>(), gm;
  mat_t<4, 4, T> m4 = identity<4, T>(), gm4;
  mat_t<2, 2, T> m2(s, T(1), T(2), s), gm2;
  quat_t<T> q = normalize(quat_t<T>(s, T(1), T(2), T(3))), gq;
  transform_t<T> t(a, q), gt;
  vec_t<6, T> sv(a, b), gsv;
  T gs = T(0);
  vec_t<3, T> v = add(cross(a, b), mul(normalize(a), length(b)));
  v = add(v, mul(m, v)); v = add(v, mul(v, m)); v = add(v, cw_mul(v, b)); v = add(v, div(v, s));
  v = add(v, quat_rotate(q, v)); v = add(v, quat_rotate_inv(q, v)); v = add(v, transform_point(t, v));
  v = add(v, transform_vector(t, v)); v = add(v, transform_point(m4, v)); v = add(v, spatial_top(spatial_cross(sv, sv)));
  v = add(v, get_diag(add(inverse(m), mul(transpose(m), m)))); v = add(v, lerp(a, b, s)); v = add(v, min(a, b));
  mat_t<3, 3, T> u, vv, qq, rr;
  vec_t<3, T> sig, d, axis;
  svd3(m, u, sig, vv); qr3(m, qq, rr); eig3(m, qq, d);
  vec_t<2, T> sig2; mat_t<2, 2, T> u2, v2; svd2(m2, u2, sig2, v2);
  T angle;
  quat_to_axis_angle(q, axis, angle);
  quat_t<T> q2 = mul(quat_slerp(q, quat_rpy(s, s, s), s), quat_from_matrix(quat_to_matrix(q)));
  q2 = add(q2, quat_from_axis_angle(axis, angle)); q2 = add(q2, quat_inverse(q2)); q2 = add(q2, quat_from_matrix(m4));
  transform_t<T> t2 = transform_multiply(t, transform_inverse(t));
  mat_t<6, 6, T> sa = spatial_adjoint(m, n);
  adj_cross(a, b, g3, g3, v); adj_normalize(a, g3, v); adj_length(a, g3, s); adj_dot(c, c, g4, g4, s);
  adj_mul(m, v, gm, g3, v); adj_mul(m, n, gm, gm, n); adj_inverse(m, gm, n); adj_determinant(m4, gm4, s);
  adj_determinant(m2, gm2, s); adj_transpose(m, gm, n); adj_quat_rotate(q, a, gq, g3, v);
  adj_quat_rotate_inv(q, a, gq, g3, v); adj_quat_to_matrix(q, gq, m); adj_quat_from_matrix(m, gm, q);
  adj_quat_slerp(q, q2, s, gq, gq, gs, q); adj_quat_rpy(s, s, s, gs, gs, gs, q); adj_quat_from_axis_angle(axis, angle, g3, gs, q);
  adj_quat_to_axis_angle(q, axis, angle, gq, g3, gs); adj_transform_point(t, a, gt, g3, v);
  adj_transform_multiply(t, t2, gt, gt, t); adj_transform_inverse(t, gt, t2); adj_spatial_cross(sv, sv, gsv, gsv, sv);
  adj_spatial_cross_dual(sv, sv, gsv, gsv, sv); adj_svd3(m, u, sig, vv, gm, u, sig, vv); adj_qr3(m, qq, rr, gm, qq, rr);
  adj_eig3(m, qq, d, gm, qq, d); adj_extract(m, 1, 2, gm, gs, gs, s);
  out[1] = add(add(add(add(dot(v, g3), trace(gm)), ddot(gm4, m4)), dot(q2, gq)), add(sa.data[1][1], t2.p.c[0]));
  out[2] = add(add(length(gsv), trace(gm2)), add(sig2.c[0], gs));
}

__device__ void body(launch_context_t& ctx, int64 i, array_t<float> af, array_t<double> ad, array_t<half> ah,
                     array_t<int8> ai8, array_t<int64> ai64, array_t<vec_t<3, float>> av, array_t<mat_t<3, 3, double>> am) {
  if (!bounds_ok(af, i)) {
    report_out_of_bounds(&ctx, 0, 1, 0, af, 1, i);
    return;
  }
  float* p = checked_address(&ctx, 0, 2, 0, af, i);
  if (!p) return;
  scalar_family<float32>(*p, 2.0f, p);
  scalar_family<float64>(load(ad, i), 2.0, address(ad, i));
  scalar_family<half>(load(ah, i), half(2.0f), address(ah, i));
  linalg_family<float32>(*p, p);
  // (float64 linear algebra is the same templates; the host tests run it. Leaving it out here
  // halves the compile time of this test.)
  int32 n = add(int32(3), floordiv(int32(7), int32(-2)));
  n = bit_xor(lshift(n, int32(3)), rshift(n, int32(1)));
  atomic_add(af, 0, 1.0f); atomic_sub(ad, 0, 1.0); atomic_add(ah, 0, half(1.0f)); atomic_max(ah, 0, half(3.0f));
  atomic_add(ai8, 0, int8(1)); atomic_min(ai8, 0, int8(-1)); atomic_cas(ai8, 0, int8(0), int8(1)); atomic_exch(ai8, 1, int8(4));
  atomic_add(ai64, 0, int64(n)); atomic_min(ai64, 0, int64(-5)); atomic_max(ai64, 0, int64(5)); atomic_or(ai64, 0, int64(1));
  atomic_add(av, 0, vec_t<3, float>(1.0f)); atomic_max(av, 0, vec_t<3, float>(2.0f)); atomic_add(am, 0, identity<3, double>());
  atomic_min(af, 0, -1.0f); atomic_max(ad, 0, 4.0); atomic_exch(af, 1, 2.0f); atomic_cas(ad, 1, 0.0, 1.0);
  float gf = 0.0f; int32 gi = 0;
  adj_atomic_add(af, 0, 1.0f, af, gi, gf, 0.0f); adj_atomic_max(af, 0, 1.0f, af, gi, gf, 0.0f);
  adj_load(af, i, gf); adj_store(af, i, gf);
  uint32 state = rand_init(int32(i), 7);
  float r = randf(state) + randn(state) + float(randi(state, 0, 10)) + float(poisson(state, 20.0f)) + float(poisson(state, 2.0f));
  r += length(sample_unit_sphere(state)) + length(sample_unit_disk(state)) + length(sample_unit_hemisphere(state));
  r += length(sample_unit_sphere_surface(state)) + length(sample_unit_ring(state)) + length(sample_unit_cube(state));
  r += length(sample_unit_square(state)) + length(sample_triangle(state)) + float(sample_cdf(state, af));
  r += noise(state, r) + noise(state, vec_t<2, float>(r)) + noise(state, vec_t<3, float>(r)) + noise(state, vec_t<4, float>(r));
  r += pnoise(state, r, 4) + pnoise(state, vec_t<3, float>(r), 2, 3, 4) + length(curlnoise(state, vec_t<3, float>(r), 2u, 2.0f, 0.5f));
  r += length(curlnoise(state, vec_t<2, float>(r), 2u, 2.0f, 0.5f));
  print(&ctx, r); print(&ctx, vec_t<3, float>(r)); print(&ctx, identity<3, double>()); print(&ctx, transform_identity<float>());
  printf(&ctx, "%d %f\n", n, r);
  expect_eq_at(&ctx, 0, 3, n, int32(0)); expect_near(&ctx, r, 1.0f, 0.1f); expect_neq(&ctx, vec_t<2, float>(r), vec_t<2, float>(0.0f));
  store(af, i, r + float(n) + float(lower_bound(af, 0.5f)));
}

}  // namespace check
}  // namespace wp

extern "C" __global__ void weft_nvrtc_check(wp::launch_context_t ctx, wp::array_t<float> af, wp::array_t<double> ad,
                                             wp::array_t<wp::half> ah, wp::array_t<wp::int8> ai8, wp::array_t<wp::int64> ai64,
                                             wp::array_t<wp::vec_t<3, float>> av, wp::array_t<wp::mat_t<3, 3, double>> am) {
  wp::int64 i = blockIdx.x * (wp::int64)blockDim.x + threadIdx.x;
  wp::check::body(ctx, i, af, ad, ah, ai8, ai64, av, am);
}
)CUDA";

TEST(NativeNvrtc, WeftHeaderCompilesForSm90) {
  Nvrtc nvrtc;
  if (!nvrtc.Load()) GTEST_SKIP() << "libnvrtc not found";
  nvrtcProgram prog = nullptr;
  ASSERT_EQ(nvrtc.create(&prog, kKernelSource, "native_check.cu", 0, nullptr, nullptr), 0);
  std::string include = std::string("-I") + WEFT_NATIVE_DIR;
  const char* options[] = {"--gpu-architecture=sm_90", "-std=c++17", include.c_str()};
  nvrtcResult result = nvrtc.compile(prog, 3, options);
  size_t n = 0;
  nvrtc.log_size(prog, &n);
  std::vector<char> log(n + 1, '\0');
  nvrtc.log(prog, log.data());
  EXPECT_EQ(result, 0) << log.data();
  // No warnings either: the log of a clean compile is empty.
  EXPECT_EQ(std::string(log.data()).find("warning"), std::string::npos) << log.data();
  if (result == 0) {
    size_t cubin = 0;
    EXPECT_EQ(nvrtc.cubin_size(prog, &cubin), 0);
    EXPECT_GT(cubin, 1000u);
  }
  nvrtc.destroy(&prog);
}

}  // namespace
