// CpuJit: hand-written translation units compiled in-process, loaded and called; compile errors
// as Status with the user's file:line; separate modules with the same symbol names; host
// symbols; concurrent compiles; the precompiled header.
#include "engine/jit/cpu/cpu_jit.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>

#include <unistd.h>
#include <vector>

#include "engine/native/launch_abi.h"

namespace weft::jit {
namespace {

namespace fs = std::filesystem;

using ForwardFn = void (*)(const wp::launch_context_t*, const void*, wp::int64, wp::int64);

// A stand-in for the native library: its own weft.h (so the PCH path is exercised) that pulls
// in the real launch ABI from engine/native, and a few helpers written with compiler builtins.
constexpr const char* kTestHeader = R"(#pragma once
#include "launch_abi.h"
namespace wp {
template <typename T> struct vec3_t { T x, y, z; };
inline float32 madd(float32 a, float32 x, float32 y) { return a * x + y; }
inline float32 sin(float32 x) { return __builtin_sinf(x); }
inline float64 sqrt(float64 x) { return __builtin_sqrt(x); }
template <typename T> inline T& index(const array_t<T>& a, int64 i) {
  return *(T*)((char*)a.data + i * a.strides[0]);
}
}  // namespace wp
)";

constexpr const char* kSaxpySource = R"(#include "weft.h"
struct saxpy_args { float a; float _pad; wp::array_t<float> x; wp::array_t<float> y; };
extern "C" void weft_saxpy_cpu_forward(const wp::launch_context_t* ctx, const void* args,
                                       wp::int64 begin, wp::int64 end) {
  const saxpy_args& p = *(const saxpy_args*)args;
  for (wp::int64 i = begin; i < end; ++i)
    wp::index(p.y, i) = wp::madd(p.a, wp::index(p.x, i), wp::index(p.y, i));
}
)";

struct SaxpyArgs {
  float a;
  float pad;
  wp::array_abi_t x;
  wp::array_abi_t y;
};

wp::array_abi_t Array1d(float* data, int64_t n) {
  wp::array_abi_t a{};
  a.data = data;
  a.shape[0] = n;
  a.strides[0] = sizeof(float);
  a.ndim = 1;
  return a;
}

class JitCpu : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("weft-jit-test-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    std::ofstream(dir_ / "weft.h") << kTestHeader;
  }
  void TearDown() override { fs::remove_all(dir_); }

  CpuJitOptions Options() const {
    CpuJitOptions options;
    options.include_dirs = {dir_.string(), WEFT_NATIVE_DIR};
    options.pch_dir = dir_.string();
    return options;
  }

  fs::path dir_;
};

TEST_F(JitCpu, CompilesLoadsAndRunsSaxpy) {
  auto start = std::chrono::steady_clock::now();
  auto jit = CpuJit::Create(Options());
  ASSERT_TRUE(jit.ok()) << jit.status().ToString();
  double create_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  EXPECT_TRUE((*jit)->has_pch());

  CpuCompileTimes cold, warm;
  auto object = (*jit)->Compile(kSaxpySource, "saxpy", &cold);
  ASSERT_TRUE(object.ok()) << object.status().ToString();
  auto again = (*jit)->Compile(kSaxpySource, "saxpy", &warm);
  ASSERT_TRUE(again.ok());
  std::printf("[ jit ] create %.1f ms (PCH %.1f ms), first compile %.1f ms, second %.1f ms\n",
              create_ms, (*jit)->pch_build_ms(), cold.frontend_and_codegen_ms,
              warm.frontend_and_codegen_ms);

  auto code = (*jit)->Load(*object, "saxpy");
  ASSERT_TRUE(code.ok()) << code.status().ToString();
  auto entry = (*code)->Lookup("weft_saxpy_cpu_forward");
  ASSERT_TRUE(entry.ok()) << entry.status().ToString();
  auto saxpy = reinterpret_cast<ForwardFn>(*entry);

  std::mt19937 rng(std::random_device{}());
  std::uniform_real_distribution<float> dist(-100.f, 100.f);
  const int64_t n = 1000 + rng() % 1000;
  std::vector<float> x(n), y(n);
  for (auto& v : x) v = dist(rng);
  for (auto& v : y) v = dist(rng);
  std::vector<float> y0 = y;
  SaxpyArgs args{dist(rng), 0, Array1d(x.data(), n), Array1d(y.data(), n)};
  wp::launch_context_t ctx{};
  // Two ranges, as the thread pool would split them.
  saxpy(&ctx, &args, 0, n / 3);
  saxpy(&ctx, &args, n / 3, n);
  for (int64_t i = 0; i < n; ++i) {
    double reference = double(args.a) * x[i] + y0[i];
    ASSERT_NEAR(y[i], reference, 1e-5 * (std::fabs(reference) + 1)) << "i=" << i;
  }
}

TEST_F(JitCpu, WorksWithoutPch) {
  auto options = Options();
  options.pch_header.clear();
  auto jit = CpuJit::Create(options);
  ASSERT_TRUE(jit.ok()) << jit.status().ToString();
  EXPECT_FALSE((*jit)->has_pch());
  CpuCompileTimes times;
  auto object = (*jit)->Compile(kSaxpySource, "saxpy", &times);
  ASSERT_TRUE(object.ok()) << object.status().ToString();
  std::printf("[ jit ] compile without PCH %.1f ms\n", times.frontend_and_codegen_ms);
}

TEST_F(JitCpu, CompileErrorNamesTheUserLine) {
  auto jit = CpuJit::Create(Options());
  ASSERT_TRUE(jit.ok()) << jit.status().ToString();
  const char* source = R"(#include "weft.h"
extern "C" void weft_k_cpu_forward(const wp::launch_context_t*, const void*, wp::int64, wp::int64) {
#line 42 "my_kernels.py"
  wp::float32 x = undefined_name + 1;
}
)";
  auto object = (*jit)->Compile(source, "k");
  ASSERT_FALSE(object.ok());
  EXPECT_EQ(object.status().code(), StatusCode::kInternal);
  EXPECT_NE(object.status().message().find("my_kernels.py:42"), std::string::npos)
      << object.status().message();
  EXPECT_NE(object.status().message().find("undefined_name"), std::string::npos);
  // The JIT is still usable after an error.
  EXPECT_TRUE((*jit)->Compile(kSaxpySource, "saxpy").ok());
}

// Two modules exporting the same entry name live side by side; dropping one leaves the other.
TEST_F(JitCpu, ModulesAreIsolatedAndUnloadable) {
  auto jit = CpuJit::Create(Options());
  ASSERT_TRUE(jit.ok()) << jit.status().ToString();
  auto source_returning = [](int value) {
    return "#include \"weft.h\"\nextern \"C\" int weft_value() { return " + std::to_string(value) +
           "; }\n";
  };
  auto a = (*jit)->Compile(source_returning(7), "a");
  auto b = (*jit)->Compile(source_returning(11), "b");
  ASSERT_TRUE(a.ok() && b.ok());
  auto code_a = (*jit)->Load(*a, "a");
  auto code_b = (*jit)->Load(*b, "b");
  ASSERT_TRUE(code_a.ok() && code_b.ok());
  auto fa = (*code_a)->Lookup("weft_value");
  auto fb = (*code_b)->Lookup("weft_value");
  ASSERT_TRUE(fa.ok() && fb.ok());
  EXPECT_EQ(reinterpret_cast<int (*)()>(*fa)(), 7);
  EXPECT_EQ(reinterpret_cast<int (*)()>(*fb)(), 11);
  code_a->reset();
  EXPECT_EQ(reinterpret_cast<int (*)()>(*fb)(), 11);
  auto missing = (*code_b)->Lookup("weft_no_such_symbol");
  EXPECT_FALSE(missing.ok());
  // Loading the same object again (as from the disk cache) works.
  auto code_a2 = (*jit)->Load(*a, "a");
  ASSERT_TRUE(code_a2.ok());
  auto fa2 = (*code_a2)->Lookup("weft_value");
  ASSERT_TRUE(fa2.ok());
  EXPECT_EQ(reinterpret_cast<int (*)()>(*fa2)(), 7);
}

extern "C" double weft_test_host_scale(double x) { return 3 * x; }

// Generated code reaches libm (through the process) and helpers handed in as host symbols.
TEST_F(JitCpu, CallsProcessAndHostSymbols) {
  auto options = Options();
  options.host_symbols["weft_test_host_scale"] = reinterpret_cast<void*>(&weft_test_host_scale);
  auto jit = CpuJit::Create(options);
  ASSERT_TRUE(jit.ok()) << jit.status().ToString();
  const char* source = R"(#include "weft.h"
extern "C" double weft_test_host_scale(double);
extern "C" double weft_f(float x, double y) {
  return wp::sin(x) + weft_test_host_scale(wp::sqrt(y));
}
)";
  auto object = (*jit)->Compile(source, "f");
  ASSERT_TRUE(object.ok()) << object.status().ToString();
  auto code = (*jit)->Load(*object, "f");
  ASSERT_TRUE(code.ok());
  auto f = (*code)->Lookup("weft_f");
  ASSERT_TRUE(f.ok()) << f.status().ToString();
  auto fn = reinterpret_cast<double (*)(float, double)>(*f);
  std::mt19937 rng(std::random_device{}());
  std::uniform_real_distribution<float> dist(-1000.f, 1000.f);
  for (int i = 0; i < 100; ++i) {
    float x = dist(rng);
    double y = std::fabs(dist(rng));
    EXPECT_NEAR(fn(x, y), std::sin(double(x)) + 3 * std::sqrt(y), 1e-5);
  }
}

TEST_F(JitCpu, UndefinedExternalIsAnErrorNotACrash) {
  auto jit = CpuJit::Create(Options());
  ASSERT_TRUE(jit.ok());
  const char* source = R"(extern "C" int weft_nowhere(int);
extern "C" int weft_g(int x) { return weft_nowhere(x); }
)";
  auto object = (*jit)->Compile(source, "g");
  ASSERT_TRUE(object.ok()) << object.status().ToString();
  auto code = (*jit)->Load(*object, "g");
  ASSERT_TRUE(code.ok());
  auto g = (*code)->Lookup("weft_g");
  EXPECT_FALSE(g.ok());
}

TEST_F(JitCpu, ConcurrentCompiles) {
  auto jit = CpuJit::Create(Options());
  ASSERT_TRUE(jit.ok());
  constexpr int kThreads = 4;
  std::vector<int> results(kThreads, -1);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      std::string source = "#include \"weft.h\"\nextern \"C\" int weft_value() { return " +
                           std::to_string(100 + t) + "; }\n";
      auto object = (*jit)->Compile(source, "m" + std::to_string(t));
      if (!object.ok()) return;
      auto code = (*jit)->Load(*object, "m" + std::to_string(t));
      if (!code.ok()) return;
      auto f = (*code)->Lookup("weft_value");
      if (f.ok()) results[t] = reinterpret_cast<int (*)()>(*f)();
    });
  }
  for (auto& t : threads) t.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(results[t], 100 + t);
}

TEST_F(JitCpu, TargetIdNamesTheCpu) {
  auto jit = CpuJit::Create(Options());
  ASSERT_TRUE(jit.ok());
  const std::string& id = (*jit)->target_id();
  EXPECT_NE(id.find("triple="), std::string::npos);
  EXPECT_NE(id.find("cpu="), std::string::npos);
  auto options = Options();
  options.native_cpu = false;
  auto generic = CpuJit::Create(options);
  ASSERT_TRUE(generic.ok());
  EXPECT_NE((*generic)->target_id(), id);
}

size_t ResidentBytes() {
  long pages = 0, resident = 0;
  if (FILE* f = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(f);
  }
  return size_t(resident) * size_t(::sysconf(_SC_PAGESIZE));
}

// DisableFree=false: compiling and dropping modules does not grow the process (clang's default
// leaks ~0.5-0.9 MB per compile on purpose, which a daemon cannot afford).
TEST_F(JitCpu, RepeatedCompilesDoNotLeak) {
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define WEFT_TEST_UNDER_ASAN 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(WEFT_TEST_UNDER_ASAN)
  GTEST_SKIP() << "ASan keeps freed memory in quarantine, so resident size says nothing here; "
                  "LeakSanitizer checks this build for leaks at exit";
#endif
  auto jit = CpuJit::Create(Options());
  ASSERT_TRUE(jit.ok());
  auto compile_and_drop = [&](int i) {
    std::string source = "#include \"weft.h\"\nextern \"C\" int weft_value() { return " +
                         std::to_string(i) + "; }\n" + kSaxpySource;
    auto object = (*jit)->Compile(source, "leak");
    ASSERT_TRUE(object.ok());
    auto code = (*jit)->Load(*object, "leak");
    ASSERT_TRUE(code.ok());
    ASSERT_TRUE((*code)->Lookup("weft_value").ok());
  };
  for (int i = 0; i < 10; ++i) compile_and_drop(i);  // warm up allocator arenas
  const size_t before = ResidentBytes();
  constexpr int kCompiles = 60;
  for (int i = 0; i < kCompiles; ++i) compile_and_drop(100 + i);
  const double growth_mb = (double(ResidentBytes()) - double(before)) / (1 << 20);
  std::printf("[ jit ] RSS growth over %d compile+load+drop cycles: %.2f MB\n", kCompiles,
              growth_mb);
  EXPECT_LT(growth_mb, 0.25 * kCompiles);  // a leak of 0.5 MB per compile would be 30 MB
}

// The real native library (engine/native/weft.h) under the JIT's flags, with and without its PCH;
// prints the times docs/backends.md quotes.
TEST(JitCpuNative, WeftHeaderCompilesWithAndWithoutPch) {
  if (!fs::exists(fs::path(WEFT_NATIVE_DIR) / "weft.h")) GTEST_SKIP() << "no engine/native/weft.h";
  const char* source = R"(#include "weft.h"
extern "C" void weft_scale_cpu_forward(const wp::launch_context_t* ctx, const void* args,
                                       wp::int64 begin, wp::int64 end) {
  const wp::array_t<wp::float32>& a = *(const wp::array_t<wp::float32>*)args;
  for (wp::int64 i = begin; i < end; ++i) wp::store(a, i, wp::load(a, i) * 2.0f);
}
)";
  for (bool pch : {true, false}) {
    CpuJitOptions options;
    options.include_dirs = {WEFT_NATIVE_DIR};
    if (!pch) options.pch_header.clear();
    auto jit = CpuJit::Create(options);
    ASSERT_TRUE(jit.ok()) << jit.status().ToString();
    EXPECT_EQ((*jit)->has_pch(), pch);
    CpuCompileTimes first, second, third;
    auto object = (*jit)->Compile(source, "scale", &first);
    ASSERT_TRUE(object.ok()) << object.status().ToString();
    ASSERT_TRUE((*jit)->Compile(source, "scale", &second).ok());
    ASSERT_TRUE((*jit)->Compile(source, "scale", &third).ok());
    std::printf("[ jit ] weft.h %s PCH: build %.1f ms, compiles %.1f / %.1f / %.1f ms\n",
                pch ? "with" : "without", (*jit)->pch_build_ms(), first.frontend_and_codegen_ms,
                second.frontend_and_codegen_ms, third.frontend_and_codegen_ms);
    auto code = (*jit)->Load(*object, "scale");
    ASSERT_TRUE(code.ok());
    auto entry = (*code)->Lookup("weft_scale_cpu_forward");
    ASSERT_TRUE(entry.ok()) << entry.status().ToString();
    std::vector<float> data = {1.f, -2.f, 3.5f};
    wp::array_abi_t a = Array1d(data.data(), 3);
    reinterpret_cast<ForwardFn>(*entry)(nullptr, &a, 0, 3);
    EXPECT_EQ(data, (std::vector<float>{2.f, -4.f, 7.f}));
  }
}

}  // namespace
}  // namespace weft::jit
