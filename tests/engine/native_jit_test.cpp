// The native library under the daemon's own CPU JIT (clang 19, -nostdinc, PCH of weft.h): a
// hand-written module calls builtins from every family and the results match the same headers
// compiled by g++ into this test; print output reaches the launch's print buffer through the
// weft_host_snprintf host symbol; atomics from JIT code are exact under concurrent calls;
// out-of-bounds accesses are reported and not performed.
#if defined(WEFT_WITH_CPU_JIT)

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "engine/jit/cpu/cpu_jit.h"
#include "engine/native/host_symbols.h"
#include "engine/native/weft.h"

namespace {

using Fn = void (*)(const wp::launch_context_t*, const void*, wp::int64, wp::int64);

// Every family once; results go to out[0..kOut). The host computes the same with g++.
#define WEFT_NATIVE_JIT_BODY                                                                                   \
  wp::vec_t<3, double> a(x, 2.0 * x, -0.5), b(0.3, -1.0, x * x);                                              \
  wp::mat_t<3, 3, double> m(a, b, wp::cross(a, b));                                                           \
  wp::quat_t<double> q = wp::normalize(wp::quat_t<double>(x, 0.2, -0.4, 0.9));                                \
  wp::transform_t<double> t(a, q);                                                                            \
  wp::mat_t<3, 3, double> u, v;                                                                               \
  wp::vec_t<3, double> s;                                                                                     \
  wp::svd3(m, u, s, v);                                                                                       \
  wp::uint32 state = wp::rand_init(7, (wp::int32)i);                                                          \
  out[0] = wp::sin(x) + wp::erfinv(0.5 * x) + wp::pow(x, 1.5) + wp::atan2(x, -1.0);                           \
  out[1] = wp::determinant(wp::inverse(m)) + wp::length(wp::normalize(a)) + wp::trace(wp::mul(m, m));         \
  out[2] = wp::dot(wp::quat_rotate(q, b), wp::transform_point(wp::transform_inverse(t), a));                  \
  out[3] = s.c[0] + s.c[1] + s.c[2] + wp::dot(wp::quat_slerp(q, wp::quat_rpy(x, 0.1, 0.2), 0.3), q);           \
  out[4] = (double)wp::randf(state) + (double)wp::randn(state) + (double)wp::poisson(state, 12.0f);           \
  out[5] = (double)wp::noise(state, wp::vec_t<3, float>((float)x, 0.5f, 1.5f)) +                              \
           (double)wp::floordiv(wp::int32(-7), wp::int32(2)) + (double)wp::div(wp::int32(5), wp::int32(0)) +  \
           (double)(float)wp::add(wp::half((float)x), wp::half(0.125f));                                      \
  double ga = 0, gb = 0;                                                                                      \
  wp::adj_pow(x, 1.5, ga, gb, 1.0);                                                                           \
  wp::mat_t<3, 3, double> gm;                                                                                 \
  wp::adj_inverse(m, gm, wp::identity<3, double>());                                                          \
  out[6] = ga + gb + wp::ddot(gm, gm);

constexpr int kOut = 7;

void HostBody(double x, wp::int64 i, double* out) { WEFT_NATIVE_JIT_BODY }

#define WEFT_STR2(...) #__VA_ARGS__
#define WEFT_STR(...) WEFT_STR2(__VA_ARGS__)

std::string ModuleSource() {
  std::string body = WEFT_STR(WEFT_NATIVE_JIT_BODY);
  return std::string(R"(#include "weft.h"
struct values_args { wp::array_t<double> x; wp::array_t<double> out; };
extern "C" void weft_values_cpu_forward(const wp::launch_context_t* ctx, const void* args, wp::int64 begin, wp::int64 end) {
  const values_args& p = *(const values_args*)args;
  for (wp::int64 i = begin; i < end; ++i) {
    double x = wp::load(p.x, i);
    double* out = wp::address(p.out, i, 0);
)") + body + R"(
  }
}
struct atomics_args { wp::array_t<float> f; wp::array_t<wp::int64> n; wp::array_t<wp::vec_t<3, double>> v; };
extern "C" void weft_atomics_cpu_forward(const wp::launch_context_t* ctx, const void* args, wp::int64 begin, wp::int64 end) {
  const atomics_args& p = *(const atomics_args*)args;
  for (wp::int64 i = begin; i < end; ++i) {
    wp::atomic_add(p.f, 0, 0.5f);
    wp::atomic_add(p.n, 0, wp::int64(3));
    wp::atomic_max(p.n, 1, i);
    wp::atomic_sub(p.v, 0, wp::vec_t<3, double>(1.0, 0.5, 0.25));
  }
}
struct print_args { wp::array_t<float> a; };
extern "C" void weft_print_cpu_forward(const wp::launch_context_t* ctx, const void* args, wp::int64 begin, wp::int64 end) {
  const print_args& p = *(const print_args*)args;
  for (wp::int64 i = begin; i < end; ++i) {
    float* e = wp::checked_address(ctx, 0, 12, 0, p.a, i);
    if (!e) return;
    *e = 1.0f;
    wp::print(ctx, wp::vec_t<2, float>((float)i, 0.5f));
    wp::printf(ctx, "i=%d\n", (int)i);
    wp::expect_eq_at(ctx, 0, 13, (int)i, 0);
  }
}
)";
}

template <typename T>
wp::array_t<T> Array(T* data, std::vector<wp::int64> shape) {
  wp::array_t<T> a{};
  a.data = data;
  a.ndim = (wp::int32)shape.size();
  wp::int64 stride = sizeof(T);
  for (int d = (int)shape.size() - 1; d >= 0; --d) {
    a.shape[d] = shape[d];
    a.strides[d] = stride;
    stride *= shape[d];
  }
  return a;
}

class NativeJit : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    weft::jit::CpuJitOptions options;
    options.include_dirs = {WEFT_NATIVE_DIR};
    options.pch_dir = std::filesystem::temp_directory_path().string();
    options.host_symbols = weft::native::HostSymbols();
    auto jit = weft::jit::CpuJit::Create(options);
    ASSERT_TRUE(jit.ok()) << jit.status().ToString();
    jit_ = std::move(*jit).release();
    auto object = jit_->Compile(ModuleSource(), "native_jit_module.cpp");
    ASSERT_TRUE(object.ok()) << object.status().ToString();
    auto code = jit_->Load(*object, "native_jit_module");
    ASSERT_TRUE(code.ok()) << code.status().ToString();
    code_ = new std::shared_ptr<weft::jit::CpuCode>(*code);
  }
  static void TearDownTestSuite() {
    delete code_;
    delete jit_;
    code_ = nullptr;
    jit_ = nullptr;
  }
  Fn Lookup(const char* name) {
    auto fn = (*code_)->Lookup(name);
    EXPECT_TRUE(fn.ok()) << fn.status().ToString();
    return fn.ok() ? reinterpret_cast<Fn>(*fn) : nullptr;
  }
  static weft::jit::CpuJit* jit_;
  static std::shared_ptr<weft::jit::CpuCode>* code_;
};
weft::jit::CpuJit* NativeJit::jit_ = nullptr;
std::shared_ptr<weft::jit::CpuCode>* NativeJit::code_ = nullptr;

TEST_F(NativeJit, SameResultsAsTheHostCompiler) {
  ASSERT_NE(code_, nullptr);
  EXPECT_TRUE(jit_->has_pch());
  Fn fn = Lookup("weft_values_cpu_forward");
  ASSERT_NE(fn, nullptr);
  const int n = 64;
  std::vector<double> xs(n), out(n * kOut), ref(n * kOut);
  for (int i = 0; i < n; ++i) xs[i] = 0.05 + 0.03 * i;
  struct {
    wp::array_t<double> x, out;
  } args{Array(xs.data(), {n}), Array(out.data(), {n, kOut})};
  wp::launch_context_t ctx{};
  fn(&ctx, &args, 0, n);
  for (int i = 0; i < n; ++i) HostBody(xs[i], i, &ref[i * kOut]);
  for (int i = 0; i < n * kOut; ++i) {
    ASSERT_TRUE(std::isfinite(ref[i])) << i;
    // Same headers, same IEEE operations (no FMA contraction in either): agreement to rounding.
    EXPECT_NEAR(out[i], ref[i], 1e-12 * (1 + std::fabs(ref[i]))) << "x[" << i / kOut << "] out[" << i % kOut << "]";
  }
}

TEST_F(NativeJit, AtomicsAreExactAcrossThreads) {
  ASSERT_NE(code_, nullptr);
  Fn fn = Lookup("weft_atomics_cpu_forward");
  ASSERT_NE(fn, nullptr);
  float f = 0;
  wp::int64 nn[2] = {0, -1};
  wp::vec_t<3, double> v;
  struct {
    wp::array_t<float> f;
    wp::array_t<wp::int64> n;
    wp::array_t<wp::vec_t<3, double>> v;
  } args{Array(&f, {1}), Array(nn, {2}), Array(&v, {1})};
  wp::launch_context_t ctx{};
  const int kThreads = 8, kPer = 10000;
  std::vector<std::thread> pool;
  for (int t = 0; t < kThreads; ++t) pool.emplace_back([&, t] { fn(&ctx, &args, t * kPer, (t + 1) * kPer); });
  for (auto& th : pool) th.join();
  EXPECT_EQ(f, 0.5f * kThreads * kPer);
  EXPECT_EQ(nn[0], 3LL * kThreads * kPer);
  EXPECT_EQ(nn[1], kThreads * kPer - 1);
  EXPECT_EQ(v, (wp::vec_t<3, double>(-1.0 * kThreads * kPer, -0.5 * kThreads * kPer, -0.25 * kThreads * kPer)));
}

TEST_F(NativeJit, PrintExpectAndBoundsReports) {
  ASSERT_NE(code_, nullptr);
  Fn fn = Lookup("weft_print_cpu_forward");
  ASSERT_NE(fn, nullptr);
  float data[3] = {0, 0, 0};
  struct {
    wp::array_t<float> a;
  } args{Array(data, {3})};
  std::vector<char> buf(1024);
  wp::print_buffer_t pb{buf.data(), buf.size(), 0};
  wp::launch_error_t err{};
  wp::launch_context_t ctx{};
  ctx.print = &pb;
  ctx.error = &err;
  fn(&ctx, &args, 0, 2);
  EXPECT_EQ(std::string(buf.data(), pb.used), "0 0.5 \ni=0\n1 0.5 \ni=1\n");
  EXPECT_EQ(err.kind, wp::LAUNCH_EXPECT_FAILED);
  EXPECT_EQ(err.line, 13);
  EXPECT_STREQ(err.message, "expect_eq(1, 0)");
  // Index 3 is out of bounds: reported (first error wins, so use a fresh slot), not written.
  wp::launch_error_t err2{};
  ctx.error = &err2;
  float guard[4] = {0, 0, 0, -7};
  args.a = Array(guard, {3});
  fn(&ctx, &args, 3, 4);
  EXPECT_EQ(err2.kind, wp::LAUNCH_OUT_OF_BOUNDS);
  EXPECT_EQ(err2.line, 12);
  EXPECT_EQ(err2.index[0], 3);
  EXPECT_EQ(err2.shape[0], 3);
  EXPECT_EQ(guard[3], -7.0f);
}

}  // namespace

#endif  // WEFT_WITH_CPU_JIT
