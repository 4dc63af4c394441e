// engine/native array access, atomics, launch error reports, print and expect, on the host:
// strided addressing and views, bounds tests, first-error-wins reports under contention, atomics
// hammered from several threads against the exact expected totals (integers, float, double,
// half, vectors, 8/16-bit types), the adjoints of loads/stores/atomics, the print buffer
// (no interleaving, overflow), and expect_* messages.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "engine/native/host_symbols.h"
#include "engine/native/weft.h"

// The daemon exports this for JIT code; the test binary defines it the same way (weak, so a
// definition elsewhere in the test binary wins without a clash).
extern "C" __attribute__((weak)) int weft_host_snprintf(char* buf, unsigned long size, const char* fmt, ...) {
  va_list args;
  va_start(args, fmt);
  int n = std::vsnprintf(buf, size, fmt, args);
  va_end(args);
  return n;
}

namespace {

template <typename T>
wp::array_t<T> MakeArray(std::vector<T>& storage, std::vector<wp::int64> shape, std::vector<wp::int64> strides = {}) {
  wp::array_t<T> a{};
  a.data = storage.data();
  a.ndim = (wp::int32)shape.size();
  wp::int64 stride = sizeof(T);
  for (int d = (int)shape.size() - 1; d >= 0; --d) {
    a.shape[d] = shape[d];
    a.strides[d] = strides.empty() ? stride : strides[d];
    stride *= shape[d];
  }
  return a;
}

TEST(NativeArray, StridedAddressingAndViews) {
  std::vector<float> buf(24);
  for (int i = 0; i < 24; ++i) buf[i] = (float)i;
  auto a = MakeArray(buf, {2, 3, 4});
  EXPECT_EQ(wp::load(a, 1, 2, 3), 23.0f);
  EXPECT_EQ(wp::load(a, 0, 1, 0), 4.0f);
  wp::store(a, 1, 0, 1, 100.0);  // value converts to the element type
  EXPECT_EQ(buf[13], 100.0f);
  auto v = wp::view(a, 1);
  EXPECT_EQ(v.ndim, 2);
  EXPECT_EQ(v.shape[0], 3);
  EXPECT_EQ(wp::load(v, 2, 3), 23.0f);
  EXPECT_EQ(wp::load(wp::view(a, 1, 2), 1), 21.0f);
  // A transposed view through strides: element (i, j) of the 4x6 transpose of a 6x4 array.
  std::vector<float> m(24);
  for (int i = 0; i < 24; ++i) m[i] = (float)i;
  auto t = MakeArray(m, {4, 6}, {4, 16});
  EXPECT_EQ(wp::load(t, 3, 5), m[5 * 4 + 3]);
  // Every-other-element view.
  auto every2 = MakeArray(m, {12}, {8});
  EXPECT_EQ(wp::load(every2, 11), 22.0f);
  EXPECT_EQ(wp::len(a), 2);
}

TEST(NativeArray, BoundsAndReports) {
  std::vector<int> buf(12);
  auto a = MakeArray(buf, {3, 4});
  EXPECT_TRUE(wp::bounds_ok(a, 2, 3));
  EXPECT_FALSE(wp::bounds_ok(a, 3, 0));
  EXPECT_FALSE(wp::bounds_ok(a, 0, -1));
  EXPECT_FALSE(wp::bounds_ok(a, -9223372036854775807LL - 1, 0));
  wp::array_t<int> none{};
  EXPECT_FALSE(wp::bounds_ok(none, 0));

  wp::launch_error_t err{};
  wp::launch_context_t ctx{};
  ctx.error = &err;
  EXPECT_FALSE(wp::launch_failed(&ctx));
  EXPECT_NE(wp::checked_address(&ctx, 2, 17, 1, a, 1, 1), nullptr);
  EXPECT_EQ(err.kind, wp::LAUNCH_OK);
  EXPECT_EQ(wp::checked_address(&ctx, 2, 17, 1, a, 1, 4), nullptr);
  EXPECT_EQ(err.kind, wp::LAUNCH_OUT_OF_BOUNDS);
  EXPECT_EQ(err.line, 17);
  EXPECT_EQ(err.function_id, 2);
  EXPECT_EQ(err.array_param, 1);
  EXPECT_EQ(err.ndim, 2);
  EXPECT_EQ(err.index[1], 4);
  EXPECT_EQ(err.shape[0], 3);
  EXPECT_EQ(err.shape[1], 4);
  EXPECT_TRUE(wp::launch_failed(&ctx));
  // Later errors do not overwrite the first.
  EXPECT_EQ(wp::checked_address(&ctx, 5, 99, 0, none, 0), nullptr);
  EXPECT_EQ(err.line, 17);
  // A None array is its own kind.
  wp::launch_error_t err2{};
  ctx.error = &err2;
  wp::checked_address(&ctx, 0, 3, 4, none, 0);
  EXPECT_EQ(err2.kind, wp::LAUNCH_NULL_ARRAY);
  // The no-bounds-check flag skips the test.
  wp::launch_error_t err3{};
  ctx.error = &err3;
  ctx.flags = wp::LAUNCH_FLAG_NO_BOUNDS_CHECK;
  EXPECT_EQ(wp::checked_address(&ctx, 0, 3, 0, a, 0, 5), wp::address(a, 0, 5));
  EXPECT_EQ(err3.kind, wp::LAUNCH_OK);
}

TEST(NativeArray, FirstErrorWinsUnderContention) {
  for (int round = 0; round < 20; ++round) {
    wp::launch_error_t err{};
    wp::launch_context_t ctx{};
    ctx.error = &err;
    std::vector<int> buf(4);
    auto a = MakeArray(buf, {4});
    std::vector<std::thread> threads;
    for (int t = 0; t < 8; ++t)
      threads.emplace_back([&, t] { wp::report_out_of_bounds(&ctx, t, 100 + t, t, a, 1, 1000 + t); });
    for (auto& th : threads) th.join();
    // Exactly one writer: all fields come from the same thread.
    int t = err.function_id;
    ASSERT_GE(t, 0);
    ASSERT_LT(t, 8);
    EXPECT_EQ(err.line, 100 + t);
    EXPECT_EQ(err.array_param, t);
    EXPECT_EQ(err.index[0], 1000 + t);
  }
}

template <typename T, typename Fn>
void Hammer(int threads, int per_thread, Fn fn) {
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      for (int i = 0; i < per_thread; ++i) fn(t, i);
    });
  for (auto& th : pool) th.join();
}

TEST(NativeAtomic, ConcurrentTotalsAreExact) {
  const int kThreads = 8, kIters = 20000;
  std::vector<wp::int32> ib(2);
  auto ia = MakeArray(ib, {2});
  std::vector<float> fb(1);
  auto fa = MakeArray(fb, {1});
  std::vector<double> db(1);
  auto da = MakeArray(db, {1});
  std::vector<wp::int64> lb(1);
  auto la = MakeArray(lb, {1});
  std::vector<wp::uint8> bb(4);
  auto ba = MakeArray(bb, {4});
  std::vector<wp::int16> sb(2);
  auto sa = MakeArray(sb, {2});
  std::vector<wp::vec_t<3, float>> vb(1);
  auto va = MakeArray(vb, {1});
  Hammer<int>(kThreads, kIters, [&](int t, int i) {
    wp::atomic_add(ia, 0, 1);
    wp::atomic_sub(ia, 1, 2);
    wp::atomic_add(fa, 0, 0.5f);  // exact in float32 up to 2^24
    wp::atomic_add(da, 0, 0.25);
    wp::atomic_add(la, 0, (wp::int64)1 << 33);
    wp::atomic_add(ba, t % 4, 1);        // wraps mod 256, neighbours untouched
    wp::atomic_add(sa, 1, (wp::int16)1);  // 16-bit
    wp::atomic_add(va, 0, wp::vec_t<3, float>(1.0f, 2.0f, -1.0f));
  });
  const int n = kThreads * kIters;
  EXPECT_EQ(ib[0], n);
  EXPECT_EQ(ib[1], -2 * n);
  EXPECT_EQ(fb[0], 0.5f * n);
  EXPECT_EQ(db[0], 0.25 * n);
  EXPECT_EQ(lb[0], (wp::int64)n << 33);
  for (int k = 0; k < 4; ++k) EXPECT_EQ(bb[k], (wp::uint8)((kThreads / 4) * kIters % 256)) << k;
  EXPECT_EQ(sb[0], 0);
  EXPECT_EQ(sb[1], (wp::int16)n);
  EXPECT_EQ(vb[0], (wp::vec_t<3, float>(1.0f * n, 2.0f * n, -1.0f * n)));

  // min / max from every thread: the extreme wins; returns are old values.
  std::vector<float> mb = {0.0f, 0.0f};
  auto ma = MakeArray(mb, {2});
  std::vector<wp::int32> imb = {0, 0};
  auto ima = MakeArray(imb, {2});
  Hammer<int>(kThreads, 1000, [&](int t, int i) {
    float v = (float)(t * 1000 + i) - 3000.0f;
    wp::atomic_min(ma, 0, v);
    wp::atomic_max(ma, 1, v);
    wp::atomic_min(ima, 0, (wp::int32)v);
    wp::atomic_max(ima, 1, (wp::int32)v);
  });
  EXPECT_EQ(mb[0], -3000.0f);
  EXPECT_EQ(mb[1], 4999.0f);
  EXPECT_EQ(imb[0], -3000);
  EXPECT_EQ(imb[1], 4999);

  // cas as a lock-free counter: every increment lands exactly once.
  std::vector<wp::int32> cb = {0};
  auto ca = MakeArray(cb, {1});
  Hammer<int>(kThreads, 5000, [&](int, int) {
    for (;;) {
      wp::int32 old = wp::load(ca, 0);
      if (wp::atomic_cas(ca, 0, old, old + 1) == old) break;
    }
  });
  EXPECT_EQ(cb[0], kThreads * 5000);
}

TEST(NativeAtomic, ReturnValuesAndOddTypes) {
  std::vector<float> fb = {1.5f};
  auto fa = MakeArray(fb, {1});
  EXPECT_EQ(wp::atomic_add(fa, 0, 2.0f), 1.5f);
  EXPECT_EQ(wp::atomic_exch(fa, 0, -1.0f), 3.5f);
  EXPECT_EQ(wp::atomic_cas(fa, 0, 7.0f, 9.0f), -1.0f);  // no match: unchanged
  EXPECT_EQ(fb[0], -1.0f);
  EXPECT_EQ(wp::atomic_cas(fa, 0, -1.0f, 9.0f), -1.0f);
  EXPECT_EQ(fb[0], 9.0f);
  std::vector<wp::half> hb = {wp::half(1.0f)};
  auto ha = MakeArray(hb, {1});
  EXPECT_EQ(float(wp::atomic_add(ha, 0, wp::half(0.5f))), 1.0f);
  EXPECT_EQ(float(hb[0]), 1.5f);
  EXPECT_EQ(float(wp::atomic_max(ha, 0, wp::half(4.0f))), 1.5f);
  EXPECT_EQ(float(hb[0]), 4.0f);
  std::vector<wp::uint32> ub = {0xf0u};
  auto ua = MakeArray(ub, {1});
  EXPECT_EQ(wp::atomic_or(ua, 0, 0x0fu), 0xf0u);
  EXPECT_EQ(wp::atomic_and(ua, 0, 0x3cu), 0xffu);
  EXPECT_EQ(wp::atomic_xor(ua, 0, 0xffu), 0x3cu);
  EXPECT_EQ(ub[0], 0xc3u);
  // NaN never wins a min/max.
  std::vector<float> nb = {1.0f};
  auto na = MakeArray(nb, {1});
  wp::atomic_min(na, 0, NAN);
  wp::atomic_max(na, 0, NAN);
  EXPECT_EQ(nb[0], 1.0f);
  // A NaN slot takes the value (fmin/fmax, Warp); the old value is returned.
  nb[0] = NAN;
  EXPECT_TRUE(std::isnan(wp::atomic_min(na, 0, -2.0f)));
  EXPECT_EQ(nb[0], -2.0f);
  nb[0] = NAN;
  EXPECT_TRUE(std::isnan(wp::atomic_max(na, 0, 3.0f)));
  EXPECT_EQ(nb[0], 3.0f);
  // 2-4 index forms.
  std::vector<double> d4(16);
  auto a4 = MakeArray(d4, {2, 2, 2, 2});
  wp::atomic_add(a4, 1, 0, 1, 1, 3.0);
  EXPECT_EQ(d4[8 + 2 + 1], 3.0);
  wp::mat_t<2, 2, float> mm(1.0f, 2.0f, 3.0f, 4.0f);
  std::vector<wp::mat_t<2, 2, float>> mb(1);
  auto ma = MakeArray(mb, {1});
  wp::atomic_add(ma, 0, mm);
  wp::atomic_add(ma, 0, mm);
  EXPECT_EQ(mb[0], wp::mul(mm, 2.0f));
}

TEST(NativeAtomic, Adjoints) {
  std::vector<double> data = {1.0, 5.0, 3.0}, grad = {0.5, 2.0, -1.0};
  auto a = MakeArray(data, {3});
  auto g = MakeArray(grad, {3});
  double adj_v = 0;
  int ai = 0;
  wp::adj_atomic_add(a, 1, 4.0, g, ai, adj_v, 0.0);
  EXPECT_EQ(adj_v, 2.0);
  wp::adj_atomic_sub(a, 2, 4.0, g, ai, adj_v, 0.0);
  EXPECT_EQ(adj_v, 3.0);
  adj_v = 0;
  wp::adj_atomic_max(a, 1, 5.0, g, ai, adj_v, 0.0);  // the element holds 5: this value won
  EXPECT_EQ(adj_v, 2.0);
  wp::adj_atomic_min(a, 1, 7.0, g, ai, adj_v, 0.0);  // lost: nothing
  EXPECT_EQ(adj_v, 2.0);
  wp::array_t<double> none{};
  wp::adj_atomic_add(a, 1, 4.0, none, ai, adj_v, 0.0);  // no gradient array: nothing
  EXPECT_EQ(adj_v, 2.0);
  // Loads scatter into the gradient (atomically), stores gather from it.
  wp::adj_load(g, 0, 1.5);
  EXPECT_EQ(grad[0], 2.0);
  adj_v = 0;
  wp::adj_store(g, 2, adj_v);
  EXPECT_EQ(adj_v, -1.0);
  std::vector<double> acc(1);
  auto acc_a = MakeArray(acc, {1});
  Hammer<int>(8, 1000, [&](int, int) { wp::adj_load(acc_a, 0, 1.0); });
  EXPECT_EQ(acc[0], 8000.0);
  EXPECT_EQ(wp::grad_of(a).data, nullptr);
}

TEST(NativeRandom, MatchesWarpStreamAndDistributions) {
  // The PCG hash itself (values from the published constants, computed by hand in 64-bit).
  auto ref_pcg = [](uint32_t s) {
    uint32_t b = (uint32_t)((uint64_t)s * 747796405u + 2891336453u);
    uint32_t c = (uint32_t)((uint64_t)(((b >> ((b >> 28u) + 4u)) ^ b)) * 277803737u);
    return (c >> 22u) ^ c;
  };
  for (uint32_t s : {0u, 1u, 42u, 0xffffffffu}) EXPECT_EQ(wp::rand_pcg(s), ref_pcg(s));
  EXPECT_EQ(wp::rand_init(7), ref_pcg(7));
  EXPECT_EQ(wp::rand_init(7, 3), ref_pcg(7 + ref_pcg(3)));
  wp::uint32 st = wp::rand_init(123);
  wp::uint32 expect_state = ref_pcg(ref_pcg(123));
  float f = wp::randf(st);
  EXPECT_EQ(st, expect_state);
  EXPECT_EQ(f, (float)(expect_state >> 8) / 16777216.0f);

  const int n = 200000;
  double sum = 0, sum2 = 0, nsum = 0, nsum2 = 0, nsum4 = 0;
  int hist[10] = {};
  wp::uint32 s = wp::rand_init(2024);
  for (int i = 0; i < n; ++i) {
    float u = wp::randf(s);
    ASSERT_GE(u, 0.0f);
    ASSERT_LT(u, 1.0f);
    sum += u;
    sum2 += u * u;
    hist[(int)(u * 10)]++;
    double z = wp::randn(s);
    nsum += z;
    nsum2 += z * z;
    nsum4 += z * z * z * z;
    int k = wp::randi(s, -3, 5);
    ASSERT_GE(k, -3);
    ASSERT_LT(k, 5);
  }
  EXPECT_NEAR(sum / n, 0.5, 0.005);
  EXPECT_NEAR(sum2 / n, 1.0 / 3, 0.005);
  for (int b = 0; b < 10; ++b) EXPECT_NEAR(hist[b], n / 10, 5 * std::sqrt(n / 10.0)) << b;
  EXPECT_NEAR(nsum / n, 0.0, 0.01);
  EXPECT_NEAR(nsum2 / n, 1.0, 0.02);
  EXPECT_NEAR(nsum4 / n, 3.0, 0.1);
  EXPECT_EQ(wp::randi(s, 4, 4), 4);  // empty range: no division by zero

  // Samplers land in their sets with the right mean radius.
  double disk_r2 = 0, ball_r3 = 0, sphere_z = 0, hemi_z = 0;
  for (int i = 0; i < 50000; ++i) {
    auto ring = wp::sample_unit_ring(s);
    ASSERT_NEAR(wp::length(ring), 1.0f, 1e-5f);
    auto disk = wp::sample_unit_disk(s);
    ASSERT_LE(wp::length(disk), 1.0f + 1e-6f);
    disk_r2 += wp::length_sq(disk);
    auto sph = wp::sample_unit_sphere_surface(s);
    ASSERT_NEAR(wp::length(sph), 1.0f, 1e-5f);
    sphere_z += sph.c[2];
    auto ball = wp::sample_unit_sphere(s);
    ASSERT_LE(wp::length(ball), 1.0f + 1e-5f);
    ball_r3 += std::pow(wp::length(ball), 3.0);
    auto hs = wp::sample_unit_hemisphere_surface(s);
    ASSERT_GE(hs.c[2], 0.0f);
    hemi_z += hs.c[2];
    auto hb = wp::sample_unit_hemisphere(s);
    ASSERT_GE(hb.c[2], 0.0f);
    auto sq = wp::sample_unit_square(s);
    ASSERT_LE(std::fabs(sq.c[0]), 0.5f);
    auto cube = wp::sample_unit_cube(s);
    ASSERT_LE(std::fabs(cube.c[2]), 0.5f);
    auto tri = wp::sample_triangle(s);
    ASSERT_GE(tri.c[0], 0.0f);
    ASSERT_GE(tri.c[1], 0.0f);
    ASSERT_LE(tri.c[0] + tri.c[1], 1.0f + 1e-6f);
  }
  EXPECT_NEAR(disk_r2 / 50000, 0.5, 0.01);   // E[r^2] of a uniform disk
  EXPECT_NEAR(ball_r3 / 50000, 0.5, 0.01);   // E[r^3] of a uniform ball
  EXPECT_NEAR(sphere_z / 50000, 0.0, 0.01);
  EXPECT_NEAR(hemi_z / 50000, 0.5, 0.01);    // E[z] on the upper hemisphere

  // Poisson: mean and variance equal lambda, small (multiplication) and large (PTRS) branches.
  for (float lam : {0.5f, 4.0f, 30.0f, 1000.0f}) {
    double m = 0, m2 = 0;
    const int k = 40000;
    for (int i = 0; i < k; ++i) {
      double x = wp::poisson(s, lam);
      m += x;
      m2 += x * x;
    }
    m /= k;
    double var = m2 / k - m * m;
    EXPECT_NEAR(m, lam, 5 * std::sqrt(lam / k)) << lam;
    EXPECT_NEAR(var / lam, 1.0, 0.05) << lam;
  }
  EXPECT_EQ(wp::poisson(s, 0.0f), 0u);
  EXPECT_EQ(wp::poisson(s, NAN), 0u);
  EXPECT_EQ(wp::poisson(s, INFINITY), 4294967295u);  // terminates
  EXPECT_NEAR(wp::poisson(s, 2e9f), 2e9, 5 * std::sqrt(2e9));

  // sample_cdf / lower_bound.
  std::vector<float> cdf = {0.1f, 0.4f, 1.0f};
  auto ca = MakeArray(cdf, {3});
  int counts[3] = {};
  for (int i = 0; i < 30000; ++i) counts[wp::sample_cdf(s, ca)]++;
  EXPECT_NEAR(counts[0] / 30000.0, 0.1, 0.01);
  EXPECT_NEAR(counts[1] / 30000.0, 0.3, 0.01);
  EXPECT_EQ(wp::lower_bound(ca, 0.4f), 1);
  EXPECT_EQ(wp::lower_bound(ca, 2.0f), 2);               // past the last: end - 1 (Warp)
  EXPECT_EQ(wp::lower_bound(ca, 1, 3, 0.0f), 1);
  EXPECT_EQ(wp::lower_bound(ca, -5, 100, 2.0f), 2);  // range clamped to the array
  wp::array_t<float> none{};
  EXPECT_EQ(wp::lower_bound(none, 0.5f), 0);
  EXPECT_EQ(wp::sample_cdf(s, none), 0);
}

TEST(NativeNoise, ValuesGradientsAndPeriods) {
  wp::uint32 seed = wp::rand_init(5);
  double mn = 1e9, mx = -1e9;
  for (int i = 0; i < 2000; ++i) {
    float x = 0.37f * i - 300.0f;
    wp::vec_t<2, float> p2(x, 0.61f * i);
    wp::vec_t<3, float> p3(x, 0.23f * i, -0.11f * i);
    float v = wp::noise(seed, p3);
    mn = std::min(mn, (double)v);
    mx = std::max(mx, (double)v);
    ASSERT_TRUE(std::isfinite(v));
    ASSERT_LE(std::fabs(wp::noise(seed, x)), 1.0f);
    ASSERT_LE(std::fabs(wp::noise(seed, p2)), 1.5f);
    ASSERT_LE(std::fabs(wp::noise(seed, wp::vec_t<4, float>(x, 1.0f, 2.0f, 3.0f))), 2.0f);
    // Periodic in each dimension on non-negative coordinates (Warp wraps the lattice index with
    // C's remainder, which keeps negative indices negative).
    float ax = std::fabs(x);
    wp::vec_t<2, float> ap2(ax, 0.61f * i);
    EXPECT_NEAR(wp::pnoise(seed, ax, 8), wp::pnoise(seed, ax + 8.0f, 8), 2e-4f);
    EXPECT_NEAR(wp::pnoise(seed, ap2, 4, 6), wp::pnoise(seed, wp::add(ap2, wp::vec_t<2, float>(4.0f, 6.0f)), 4, 6), 2e-4f);
  }
  EXPECT_LT(mn, -0.2);
  EXPECT_GT(mx, 0.2);
  // Non-finite and huge inputs: NaN out for NaN/inf, finite for huge (the lattice wraps).
  EXPECT_TRUE(std::isnan(wp::noise(seed, NAN)));
  EXPECT_TRUE(std::isnan(wp::noise(seed, wp::vec_t<3, float>(INFINITY, 0.0f, 0.0f))));
  EXPECT_TRUE(std::isfinite(wp::noise(seed, wp::vec_t<2, float>(3e30f, -1e20f))));
  // Zero at lattice points, continuous, deterministic per seed, different across seeds.
  EXPECT_EQ(wp::noise(seed, 3.0f), 0.0f);
  EXPECT_NEAR(wp::noise(seed, 2.5f), wp::noise(seed, 2.5f + 1e-5f), 1e-4f);
  EXPECT_NE(wp::noise(seed, 2.5f), wp::noise(wp::rand_init(6), 2.5f));
  // The analytic gradient used by curlnoise matches finite differences.
  float p[3] = {0.3f, 1.7f, -2.2f}, g[3];
  wp::noise_gradient<3>(seed, wp::noise_cell<3>(p, nullptr), g);
  for (int k = 0; k < 3; ++k) {
    wp::vec_t<3, float> pp(p[0], p[1], p[2]), pm(p[0], p[1], p[2]);
    pp.c[k] += 1e-3f;
    pm.c[k] -= 1e-3f;
    float num = (wp::noise(seed, pp) - wp::noise(seed, pm)) / 2e-3f;
    EXPECT_NEAR(g[k], num, 2e-3f) << k;
  }
  // The Hessian (used by curlnoise's adjoint) matches finite differences of the gradient.
  float h[3][3];
  wp::noise_hessian<3>(seed, wp::noise_cell<3>(p, nullptr), h);
  for (int k = 0; k < 3; ++k) {
    float pp[3] = {p[0], p[1], p[2]}, pm[3] = {p[0], p[1], p[2]}, gp[3], gm[3];
    pp[k] += 1e-3f;
    pm[k] -= 1e-3f;
    wp::noise_gradient<3>(seed, wp::noise_cell<3>(pp, nullptr), gp);
    wp::noise_gradient<3>(seed, wp::noise_cell<3>(pm, nullptr), gm);
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(h[j][k], (gp[j] - gm[j]) / 2e-3f, 2e-2f) << j << k;
  }
  // Curl noise is divergence-free: the trace of its (central-difference) Jacobian is tiny
  // compared with the Jacobian itself.
  auto div_and_norm = [&](wp::vec_t<3, float> q, float* jac_norm) {
    const float h = 3e-3f;
    float d = 0, n2 = 0;
    for (int k = 0; k < 3; ++k) {
      auto qp = q, qm = q;
      qp.c[k] += h;
      qm.c[k] -= h;
      auto dc = wp::div(wp::sub(wp::curlnoise(seed, qp, 2u, 2.0f, 0.5f), wp::curlnoise(seed, qm, 2u, 2.0f, 0.5f)), 2 * h);
      d += dc.c[k];
      n2 += wp::length_sq(dc);
    }
    *jac_norm = std::sqrt(n2);
    return d;
  };
  for (int i = 0; i < 20; ++i) {
    wp::vec_t<3, float> q(0.13f * i, 0.71f * i + 0.2f, -0.37f * i);
    float jn;
    float d = div_and_norm(q, &jn);
    EXPECT_LT(std::fabs(d), 0.01f * jn + 1e-3f) << i;
    EXPECT_GT(wp::length(wp::curlnoise(seed, q, 1u, 2.0f, 0.5f)) + wp::length(wp::curlnoise(seed, wp::add(q, wp::vec_t<3, float>(0.5f)), 1u, 2.0f, 0.5f)), 0.0f);
    auto c2 = wp::curlnoise(seed, wp::vec_t<2, float>(0.3f * i, 0.1f), 3u, 2.0f, 0.5f);
    ASSERT_TRUE(wp::isfinite(c2));
  }
}

std::string PrintBufferText(const wp::print_buffer_t& pb) {
  return std::string(pb.data, pb.used < pb.capacity ? pb.used : pb.capacity);
}

TEST(NativePrint, ValuesAndBuffer) {
  std::vector<char> storage(4096);
  wp::print_buffer_t pb{storage.data(), storage.size(), 0};
  wp::launch_context_t ctx{};
  ctx.print = &pb;
  wp::print(&ctx, 1.5f);
  wp::print(&ctx, wp::int32(-7));
  wp::print(&ctx, true);
  wp::print(&ctx, wp::vec_t<3, float>(1.0f, 2.5f, -3.0f));
  wp::print(&ctx, wp::mat_t<2, 2, double>(1.0, 2.0, 3.0, 4.0));
  wp::print(&ctx, wp::quat_t<float>(0.0f, 0.0f, 0.0f, 1.0f));
  wp::print(&ctx, wp::transform_identity<float>());
  wp::print(&ctx, wp::half(0.25f));
  wp::print(&ctx, wp::uint64(18446744073709551615ull));
  wp::printf(&ctx, "x=%d y=%.2f ok\n", 3, 0.5f);
  EXPECT_EQ(PrintBufferText(pb),
            "1.5\n-7\nTrue\n1 2.5 -3 \n1 2 \n3 4 \n0 0 0 1\n(0 0 0) (0 0 0 1)\n0.25\n18446744073709551615\nx=3 y=0.50 ok\n");
}

// The reverse code of print(): Warp's "adj: " lines (components without a trailing space, a
// matrix's later rows indented under the first; values without a printed form: the placeholder).
TEST(NativePrint, AdjointLines) {
  std::vector<char> storage(4096);
  wp::print_buffer_t pb{storage.data(), storage.size(), 0};
  wp::launch_context_t ctx{};
  ctx.print = &pb;
  wp::adj_print(&ctx, 17.0f, 42.0f);
  wp::adj_print(&ctx, wp::vec_t<3, float>(0.0f, 1.0f, 2.0f), wp::vec_t<3, float>(2.0f, 1.0f, 0.0f));
  wp::adj_print(&ctx, wp::mat_t<2, 2, float>(0.0f, 1.0f, 2.0f, 3.0f), wp::mat_t<2, 2, float>(3.0f, 2.0f, 1.0f, 0.0f));
  wp::adj_print(&ctx, true, false);
  wp::array_t<float> a{};
  wp::adj_print(&ctx, a, a);
  EXPECT_EQ(PrintBufferText(pb),
            "adj: 42\nadj: 2 1 0\nadj: 3 2\n     1 0\nadj: False\nadj: <type without print implementation>\n");
}

// wp::printf formats only what the compiler emits for its argument types; anything else
// (a conversion that reads memory or writes, a type mismatch, a count mismatch) is replaced by
// a fixed message instead of reaching snprintf.
TEST(NativePrint, PrintfRefusesFormatsThatDoNotMatchTheArguments) {
  std::vector<char> storage(4096);
  wp::print_buffer_t pb{storage.data(), storage.size(), 0};
  wp::launch_context_t ctx{};
  ctx.print = &pb;
  wp::printf(&ctx, "%p %p\n", wp::int64(1), wp::int64(2));
  wp::printf(&ctx, "%s\n", wp::int64(0x41414141));
  wp::printf(&ctx, "%n\n", wp::int32(0));
  wp::printf(&ctx, "%*d\n", wp::int32(5), wp::int32(1));
  wp::printf(&ctx, "%d\n", 1.5f);             // int conversion, float argument
  wp::printf(&ctx, "%f\n", wp::int32(1));     // float conversion, int argument
  wp::printf(&ctx, "%d\n", wp::int64(7));     // 64-bit argument needs %lld
  wp::printf(&ctx, "%d %d\n", wp::int32(1));  // too few arguments
  wp::printf(&ctx, "%d\n", wp::int32(1), wp::int32(2));  // too many
  wp::printf(&ctx, "100%\n");
  const std::string rejected = "[weft: wp.printf format rejected]\n";
  std::string expected;
  for (int i = 0; i < 10; ++i) expected += rejected;
  EXPECT_EQ(PrintBufferText(pb), expected);
  pb.used = 0;
  wp::printf(&ctx, "%+05d|%-4x|%lld|%.3e|%G|%o|100%%|%llu\n", wp::int32(7), wp::uint32(255), wp::int64(-5), 1500.0,
             wp::half(0.5f), wp::uint8(8), wp::uint64(18446744073709551615ull));
  EXPECT_EQ(PrintBufferText(pb), "+0007|ff  |-5|1.500e+03|0.5|10|100%|18446744073709551615\n");
}

TEST(NativePrint, ThreadsDoNotInterleaveAndOverflowIsBounded) {
  std::vector<char> storage(1 << 20);
  wp::print_buffer_t pb{storage.data(), storage.size(), 0};
  wp::launch_context_t ctx{};
  ctx.print = &pb;
  Hammer<int>(8, 500, [&](int t, int i) { wp::printf(&ctx, "thread %d line %d ....................\n", t, i); });
  std::string text = PrintBufferText(pb);
  size_t lines = 0, pos = 0;
  while (pos < text.size()) {
    size_t nl = text.find('\n', pos);
    ASSERT_NE(nl, std::string::npos);
    std::string line = text.substr(pos, nl - pos);
    int t, i;
    ASSERT_EQ(std::sscanf(line.c_str(), "thread %d line %d", &t, &i), 2) << line;
    ASSERT_EQ(line.size(), line.find('.') + 20) << line;
    ++lines;
    pos = nl + 1;
  }
  EXPECT_EQ(lines, 4000u);
  // A small buffer: writes past the end are dropped, never overrun.
  std::vector<char> small(40 + 16, 'Z');
  wp::print_buffer_t spb{small.data(), 40, 0};
  ctx.print = &spb;
  for (int i = 0; i < 10; ++i) wp::printf(&ctx, "%d: 0123456789\n", i);
  EXPECT_GT(spb.used, spb.capacity);
  for (int i = 40; i < 56; ++i) EXPECT_EQ(small[i], 'Z');
  // No print buffer, no context: nothing happens.
  wp::print(nullptr, 1.0f);
  wp::launch_context_t bare{};
  wp::print(&bare, 1.0f);
}

TEST(NativeExpect, FailuresReportValuesAndLine) {
  wp::launch_error_t err{};
  wp::launch_context_t ctx{};
  ctx.error = &err;
  wp::expect_eq_at(&ctx, 1, 42, 3, 3);
  wp::expect_near_at(&ctx, 1, 43, 1.0f, 1.05f, 0.1f);
  wp::expect_neq_at(&ctx, 1, 44, wp::vec_t<2, float>(1.0f, 2.0f), wp::vec_t<2, float>(1.0f, 3.0f));
  EXPECT_EQ(err.kind, wp::LAUNCH_OK);
  wp::expect_eq_at(&ctx, 3, 45, wp::vec_t<3, float>(1.0f, 2.0f, 3.0f), wp::vec_t<3, float>(1.0f, 2.0f, 4.0f));
  EXPECT_EQ(err.kind, wp::LAUNCH_EXPECT_FAILED);
  EXPECT_EQ(err.line, 45);
  EXPECT_EQ(err.function_id, 3);
  EXPECT_STREQ(err.message, "expect_eq(1 2 3, 1 2 4)");
  wp::launch_error_t err2{};
  ctx.error = &err2;
  wp::expect_near(&ctx, 1.0, 2.0, 0.5);
  EXPECT_EQ(err2.kind, wp::LAUNCH_EXPECT_FAILED);
  EXPECT_STREQ(err2.message, "expect_near(1, 2)");
  wp::launch_error_t err3{};
  ctx.error = &err3;
  wp::expect_near(&ctx, NAN, 1.0f, 10.0f);  // NaN never passes
  EXPECT_EQ(err3.kind, wp::LAUNCH_EXPECT_FAILED);
}

TEST(NativeHostSymbols, ExportsSnprintf) {
  auto symbols = weft::native::HostSymbols();
  ASSERT_EQ(symbols.count("weft_host_snprintf"), 1u);
  auto fn = reinterpret_cast<int (*)(char*, unsigned long, const char*, ...)>(symbols["weft_host_snprintf"]);
  char buf[32];
  EXPECT_EQ(fn(buf, sizeof(buf), "%d-%s", 12, "ab"), 5);
  EXPECT_STREQ(buf, "12-ab");
}

}  // namespace
