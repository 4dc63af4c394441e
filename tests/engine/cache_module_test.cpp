// ModuleStore end to end with the real native library, CpuJit and disk cache, and a stand-in
// code generator (so these tests do not depend on engine/codegen): the store's hit/miss counts,
// a disk hit after a new store instance, corrupted and truncated files rebuilt, concurrent
// compiles of one module coalescing into one miss, Find, the lazy backward variant, bounds-check
// option plumbing, compile errors with diagnostics, and verify_cuda through NVRTC.
#include "engine/runtime/module_store.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "engine/runtime/module_cache.h"
#include "saxpy_source.h"

namespace weft {
namespace {

namespace fs = std::filesystem;

// The stand-in generator: each kernel's FunctionSource::source is a C++ expression in a, x, y;
// the kernel computes y[i] = expr over float arrays; with backward, y's adjoint flows to x as
// a * adj_y (valid for expressions linear in x with slope a). "#error" in the source makes the
// generated C++ invalid (a native bug); "!" makes it a user error.
struct FakeCodegen {
  std::atomic<int> calls{0};
  std::mutex mutex;
  std::vector<CodegenOptions> seen;

  Expected<GeneratedModule> operator()(const ModuleSource& m, const CodegenOptions& options,
                                       std::vector<Diagnostic>* diags) {
    calls++;
    {
      std::lock_guard<std::mutex> lock(mutex);
      seen.push_back(options);
    }
    GeneratedModule g;
    g.source = "#include \"weft.h\"\n";
    for (const auto& f : m.functions) {
      if (f.source.find('!') != std::string::npos) {
        Diagnostic d;
        d.message = "unsupported construct '!'";
        d.location = {f.file, f.first_line + 1, 5};
        diags->push_back(d);
        return InvalidArgument(d.ToString());
      }
      const std::string k = f.name;
      g.source += "struct " + k + "_args { float a; float _pad; wp::array_t<float> x; wp::array_t<float> y; };\n";
      g.source += "#line " + std::to_string(f.first_line) + " \"" + f.file + "\"\n";
      if (options.target == Target::kCpu) {
        g.source += "extern \"C\" void weft_" + k +
                    "_cpu_forward(const wp::launch_context_t* ctx, const void* args_, wp::int64 begin, wp::int64 end) {\n"
                    "  const " + k + "_args& p = *(const " + k + "_args*)args_;\n"
                    "  for (wp::int64 i = begin; i < end; ++i) {\n"
                    "    float a = p.a, x = wp::load(p.x, i), y = wp::load(p.y, i);\n" +
                    "    wp::store(p.y, i, " + f.source + ");\n  }\n}\n";
        if (options.enable_backward) {
          g.source += "extern \"C\" void weft_" + k +
                      "_cpu_backward(const wp::launch_context_t* ctx, const void* args_, const void* adj_, wp::int64 begin, wp::int64 end) {\n"
                      "  const " + k + "_args& p = *(const " + k + "_args*)args_;\n"
                      "  const " + k + "_args& q = *(const " + k + "_args*)adj_;\n"
                      "  for (wp::int64 i = begin; i < end; ++i)\n"
                      "    wp::index(q.x, i) += p.a * wp::load(q.y, i);\n}\n";
        }
      } else {
        g.source += "extern \"C\" __global__ void weft_" + k + "_cuda_forward(wp::launch_context_t ctx, " + k +
                    "_args p) {\n"
                    "  wp::int64 i = wp::int64(blockIdx.x) * blockDim.x + threadIdx.x;\n"
                    "  if (i >= ctx.bounds.size) return;\n"
                    "  float a = p.a, x = wp::load(p.x, i), y = wp::load(p.y, i);\n" +
                    "  wp::store(p.y, i, " + f.source + ");\n}\n";
      }
      KernelLayout layout;
      layout.name = k;
      layout.forward_symbol = "weft_" + k + "_cpu_forward";
      if (options.enable_backward) layout.backward_symbol = "weft_" + k + "_cpu_backward";
      layout.params = {{"a", "float32", 0, 4, 4, false, "", 0, {}},
                       {"x", "array(float32,1)", 8, 88, 8, true, "float32", 1, {}},
                       {"y", "array(float32,1)", 96, 88, 8, true, "float32", 1, {}}};
      layout.args_size = 184;
      g.kernels.push_back(layout);
      g.function_names.push_back(f.file + ":" + k);
    }
    return g;
  }
};

ModuleSource Module(const std::string& expression, const std::string& name = "saxpy") {
  ModuleSource m;
  m.name = "tests.cache_module";
  FunctionSource f;
  f.name = name;
  f.key = name;
  f.file = "kernels.py";
  f.first_line = 20;
  f.is_kernel = true;
  f.source = expression;
  f.param_types = {"float32", "array(float32,1)", "array(float32,1)"};
  f.param_names = {"a", "x", "y"};
  m.functions.push_back(f);
  return m;
}

struct Args {
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

// Runs kernel `name` of `module` on fresh random data and checks y = a*x + y (+ extra * x).
void ExpectSaxpy(const LoadedModule& module, const std::string& name, float extra = 0) {
  const LoadedKernel* kernel = module.Find(name);
  ASSERT_NE(kernel, nullptr);
  ASSERT_NE(kernel->cpu_forward, nullptr);
  std::mt19937 rng(std::random_device{}());
  std::uniform_real_distribution<float> dist(-10.f, 10.f);
  const int64_t n = 257;
  std::vector<float> x(n), y(n);
  for (auto& v : x) v = dist(rng);
  for (auto& v : y) v = dist(rng);
  std::vector<float> y0 = y;
  Args args{dist(rng), 0, Array1d(x.data(), n), Array1d(y.data(), n)};
  wp::launch_context_t ctx{};
  kernel->cpu_forward(&ctx, &args, 0, n);
  for (int64_t i = 0; i < n; ++i) {
    double reference = double(args.a) * x[i] + y0[i] + double(extra) * x[i];
    ASSERT_NEAR(y[i], reference, 1e-4 * (std::fabs(reference) + 1)) << i;
  }
}

class CacheModule : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("weft-store-" + std::to_string(::getpid()) + "-" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::unique_ptr<ModuleStore> NewStore(bool verify_cuda = false) {
    ModuleStoreOptions options;
    options.cache_dir = dir_.string();
    options.verify_cuda = verify_cuda;
    options.build_id = "test-build";
    options.generate = [this](const ModuleSource& m, const CodegenOptions& o,
                              std::vector<Diagnostic>* d) { return codegen_(m, o, d); };
    auto store = ModuleStore::Create(options);
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    return store.ok() ? std::move(*store) : nullptr;
  }

  fs::path dir_;
  FakeCodegen codegen_;
};

TEST_F(CacheModule, MissThenMemoryHitThenDiskHitAfterRestart) {
  std::string id;
  {
    auto store = NewStore();
    ASSERT_NE(store, nullptr);
    CompileReport first;
    auto m = store->Compile(Module("a * x + y"), "cpu", &first);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    EXPECT_FALSE(first.cache_hit);
    EXPECT_FALSE(first.disk_hit);
    ExpectSaxpy(**m, "saxpy");
    id = (*m)->id;
    EXPECT_EQ(id.size(), 64u);
    CompileReport second;
    auto again = store->Compile(Module("a * x + y"), "cpu", &second);
    ASSERT_TRUE(again.ok());
    EXPECT_TRUE(second.cache_hit);
    EXPECT_EQ(again->get(), m->get());
    std::printf("[ store ] cold compile %.1f ms, memory hit %.3f ms\n", first.compile_ms,
                second.compile_ms);
    auto stats = store->stats();
    EXPECT_EQ(stats.misses, 1u);
    EXPECT_EQ(stats.memory_hits, 1u);
    EXPECT_EQ(stats.disk_hits, 0u);
    EXPECT_EQ(store->Find(id).get(), m->get());
  }
  auto restarted = NewStore();
  CompileReport report;
  auto m = restarted->Compile(Module("a * x + y"), "cpu", &report);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_TRUE(report.disk_hit);
  EXPECT_EQ((*m)->id, id);
  ExpectSaxpy(**m, "saxpy");
  std::printf("[ store ] disk hit %.1f ms\n", report.compile_ms);
  EXPECT_EQ(restarted->stats().disk_hits, 1u);
  EXPECT_EQ(restarted->stats().misses, 0u);
  EXPECT_EQ(codegen_.calls, 1);  // the disk hit generated nothing
}

TEST_F(CacheModule, DifferentSourceIsADifferentModule) {
  auto store = NewStore();
  auto a = store->Compile(Module("a * x + y"), "cpu", nullptr);
  auto b = store->Compile(Module("a * x + y + 2.0f * x"), "cpu", nullptr);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NE((*a)->id, (*b)->id);
  ExpectSaxpy(**a, "saxpy");
  ExpectSaxpy(**b, "saxpy", 2.0f);
  EXPECT_EQ(store->stats().misses, 2u);
}

TEST_F(CacheModule, CorruptedAndTruncatedFilesAreRebuilt) {
  std::string id;
  {
    auto store = NewStore();
    auto m = store->Compile(Module("a * x + y"), "cpu", nullptr);
    ASSERT_TRUE(m.ok());
    id = (*m)->id;
  }
  const std::string path = DiskModuleCache(dir_.string()).PathFor(id);
  ASSERT_TRUE(fs::exists(path));
  {  // corrupt one byte in the object code region
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(fs::file_size(path) / 2));
    f.put('\xAA');
  }
  {
    auto store = NewStore();
    CompileReport report;
    auto m = store->Compile(Module("a * x + y"), "cpu", &report);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    EXPECT_FALSE(report.disk_hit);
    EXPECT_EQ(store->stats().misses, 1u);
    ExpectSaxpy(**m, "saxpy");
  }
  fs::resize_file(path, fs::file_size(path) - 100);
  {
    auto store = NewStore();
    CompileReport report;
    auto m = store->Compile(Module("a * x + y"), "cpu", &report);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    EXPECT_FALSE(report.disk_hit);
    ExpectSaxpy(**m, "saxpy");
  }
  auto store = NewStore();  // the rebuilt file is good
  CompileReport report;
  ASSERT_TRUE(store->Compile(Module("a * x + y"), "cpu", &report).ok());
  EXPECT_TRUE(report.disk_hit);
  EXPECT_EQ(codegen_.calls, 3);
}

TEST_F(CacheModule, ConcurrentCompilesCoalesceIntoOneMiss) {
  auto store = NewStore();
  constexpr int kThreads = 6;
  std::vector<const LoadedModule*> got(kThreads, nullptr);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      auto m = store->Compile(Module("a * x + y"), "cpu", nullptr);
      if (m.ok()) got[t] = m->get();
    });
  }
  for (auto& t : threads) t.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(got[t], got[0]);
  ASSERT_NE(got[0], nullptr);
  EXPECT_EQ(store->stats().misses, 1u);
  EXPECT_EQ(store->stats().memory_hits, uint64_t(kThreads - 1));
  EXPECT_EQ(codegen_.calls, 1);
}

TEST_F(CacheModule, BackwardVariantIsCompiledOnceOnDemand) {
  auto store = NewStore();
  auto forward = store->Compile(Module("a * x + y"), "cpu", nullptr);
  ASSERT_TRUE(forward.ok());
  EXPECT_FALSE((*forward)->has_backward);
  EXPECT_EQ((*forward)->Find("saxpy")->cpu_backward, nullptr);
  EXPECT_EQ(codegen_.calls, 1);

  auto backward = store->WithBackward((*forward)->id);
  ASSERT_TRUE(backward.ok()) << backward.status().ToString();
  EXPECT_TRUE((*backward)->has_backward);
  EXPECT_EQ((*backward)->id, (*forward)->id);
  EXPECT_EQ(codegen_.calls, 2);
  EXPECT_TRUE(codegen_.seen.back().enable_backward);
  const LoadedKernel* kernel = (*backward)->Find("saxpy");
  ASSERT_NE(kernel, nullptr);
  ASSERT_NE(kernel->cpu_backward, nullptr);
  ExpectSaxpy(**backward, "saxpy");

  // adj_x += a * adj_y
  std::vector<float> x(4, 0.f), y(4, 0.f), adj_x(4, 1.f), adj_y = {1.f, 2.f, 3.f, 4.f};
  Args args{2.5f, 0, Array1d(x.data(), 4), Array1d(y.data(), 4)};
  Args adj{0.f, 0, Array1d(adj_x.data(), 4), Array1d(adj_y.data(), 4)};
  wp::launch_context_t ctx{};
  kernel->cpu_backward(&ctx, &args, &adj, 0, 4);
  for (int i = 0; i < 4; ++i) EXPECT_FLOAT_EQ(adj_x[i], 1.f + 2.5f * adj_y[i]);

  auto again = store->WithBackward((*forward)->id);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->get(), backward->get());
  EXPECT_EQ(codegen_.calls, 2);
  EXPECT_EQ(store->WithBackward("no-such-module").status().code(), StatusCode::kNotFound);
}

TEST_F(CacheModule, GridStrideVariantsAreForCudaModulesOnly) {
  // CUDA modules are generated lean and get a grid-stride variant on request; a CPU module has
  // none (its entries take ranges), nor has an unknown id.
  auto store = NewStore();
  auto forward = store->Compile(Module("a * x + y"), "cpu", nullptr);
  ASSERT_TRUE(forward.ok());
  EXPECT_FALSE(codegen_.seen.back().grid_stride);
  EXPECT_EQ(store->WithGridStride((*forward)->id, false).status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store->WithGridStride((*forward)->id, true).status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store->WithGridStride("no-such-module", false).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(codegen_.calls, 1);
}

TEST_F(CacheModule, BoundsCheckOptionReachesCodegenAndTheKey) {
  auto store = NewStore();
  ModuleSource checked = Module("a * x + y");
  ModuleSource unchecked = checked;
  unchecked.options["bounds_checks"] = "false";
  auto a = store->Compile(checked, "cpu", nullptr);
  auto b = store->Compile(unchecked, "cpu", nullptr);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_NE((*a)->id, (*b)->id);
  ASSERT_EQ(codegen_.seen.size(), 2u);
  EXPECT_TRUE(codegen_.seen[0].bounds_checks);
  EXPECT_FALSE(codegen_.seen[1].bounds_checks);
}

TEST_F(CacheModule, UserErrorsComeBackWithDiagnostics) {
  auto store = NewStore();
  CompileReport report;
  auto m = store->Compile(Module("a ! x"), "cpu", &report);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInvalidArgument);
  ASSERT_EQ(report.diagnostics.size(), 1u);
  EXPECT_EQ(report.diagnostics[0].location.file, "kernels.py");
  EXPECT_EQ(report.diagnostics[0].location.line, 21u);
  // The store still works.
  EXPECT_TRUE(store->Compile(Module("a * x + y"), "cpu", nullptr).ok());
}

TEST_F(CacheModule, NativeBugIsAnInternalErrorPointingAtTheUserLine) {
  auto store = NewStore();
  CompileReport report;
  auto m = store->Compile(Module("a * x + undefined_native_name"), "cpu", &report);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInternal);
  EXPECT_NE(m.status().message().find("weft bug"), std::string::npos);
  ASSERT_FALSE(report.diagnostics.empty());
  EXPECT_EQ(report.diagnostics[0].location.file, "kernels.py");
  EXPECT_NE(report.diagnostics[0].message.find("undefined_native_name"), std::string::npos);
}

// Generated code that (through a bug) includes a daemon-side file: the compiler's errors
// inside that file quote it, but the client gets neither the text nor the file's name, only a
// count (errors at the user's lines pass: NativeBugIsAnInternalErrorPointingAtTheUserLine).
TEST_F(CacheModule, DaemonFileContentsNeverReachTheClient) {
  fs::create_directories(dir_);
  const fs::path secret = dir_ / "daemon_secret.txt";
  std::ofstream(secret) << "TOPSECRET_TOKEN root:x:0:0:root:/root:/bin/bash\n";
  auto store = NewStore();
  CompileReport report;
  auto m = store->Compile(Module("a * x + y);\n#include \"" + secret.string() + "\"\n(0"), "cpu",
                          &report);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), StatusCode::kInternal);
  std::string everything = m.status().message();
  bool counted = false;
  for (const auto& d : report.diagnostics) {
    everything += d.ToString();
    counted |= d.message.find("in daemon-side files") != std::string::npos;
  }
  EXPECT_EQ(everything.find("TOPSECRET"), std::string::npos) << everything;
  EXPECT_EQ(everything.find("root:"), std::string::npos) << everything;
  EXPECT_EQ(everything.find(secret.string()), std::string::npos) << everything;
  EXPECT_TRUE(counted) << everything;
}

TEST_F(CacheModule, UnknownDeviceIsRejected) {
  auto store = NewStore();
  EXPECT_EQ(store->Compile(Module("a * x + y"), "tpu", nullptr).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(store->Find("0000"), nullptr);
}

#if WEFT_WITH_CUDA
TEST_F(CacheModule, VerifyCudaCompilesTheCudaFlavourWithNvrtc) {
  auto store = NewStore(/*verify_cuda=*/true);
  ASSERT_NE(store, nullptr);
  auto m = store->Compile(Module("a * x + y"), "cpu", nullptr);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  ASSERT_EQ(codegen_.seen.size(), 2u);
  EXPECT_EQ(codegen_.seen[1].target, Target::kCuda);
  // An x86 intrinsic compiles for the CPU but not under NVRTC.
  CompileReport report;
  auto bad = store->Compile(Module("a * x + y + __builtin_ia32_rdtsc()"), "cpu", &report);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInternal);
  EXPECT_NE(bad.status().message().find("CUDA"), std::string::npos) << bad.status().message();
}
#endif

}  // namespace
}  // namespace weft

namespace weft {
namespace {

// The real compiler (engine/codegen) behind the default store: Warp's saxpy from Python source,
// packed by the layout the compiler reports, verified under NVRTC too.
TEST_F(CacheModule, RealCompilerSaxpyThroughTheStore) {
  ModuleStoreOptions options;
  options.cache_dir = dir_.string();
#if WEFT_WITH_CUDA
  options.verify_cuda = true;
#endif
  auto store = ModuleStore::Create(options);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  ModuleSource m = testing::SaxpySource("tests.real_saxpy", "a * x[i] + y[i]", 5);

  CompileReport report;
  auto module = (*store)->Compile(m, "cpu", &report);
  std::string diags;
  for (const auto& d : report.diagnostics) diags += d.ToString() + "\n";
  ASSERT_TRUE(module.ok()) << module.status().ToString() << "\n" << diags;
  std::printf("[ store ] real saxpy: cold compile (codegen + NVRTC check + clang) %.1f ms\n",
              report.compile_ms);
  const LoadedKernel* kernel = (*module)->Find("saxpy");
  ASSERT_NE(kernel, nullptr);
  ASSERT_EQ(kernel->layout.params.size(), 3u);

  std::mt19937 rng(std::random_device{}());
  std::uniform_real_distribution<float> dist(-10.f, 10.f);
  const int64_t n = 1000;
  std::vector<float> x(n), y(n);
  for (auto& v : x) v = dist(rng);
  for (auto& v : y) v = dist(rng);
  std::vector<float> y0 = y;
  const float a = dist(rng);
  std::vector<char> block(kernel->layout.args_size + 16, 0);
  const auto& params = kernel->layout.params;
  std::memcpy(block.data() + params[0].offset, &a, sizeof a);
  wp::array_abi_t xa = Array1d(x.data(), n), ya = Array1d(y.data(), n);
  std::memcpy(block.data() + params[1].offset, &xa, sizeof xa);
  std::memcpy(block.data() + params[2].offset, &ya, sizeof ya);
  wp::launch_context_t ctx{};
  ctx.bounds.ndim = 1;
  ctx.bounds.shape[0] = n;
  ctx.bounds.size = n;
  wp::launch_error_t error{};
  ctx.error = &error;
  kernel->cpu_forward(&ctx, block.data(), 0, n);
  EXPECT_EQ(error.kind, 0);
  for (int64_t i = 0; i < n; ++i) {
    double reference = double(a) * x[i] + y0[i];
    ASSERT_NEAR(y[i], reference, 1e-5 * (std::fabs(reference) + 1)) << i;
  }
  CompileReport warm;
  ASSERT_TRUE((*store)->Compile(m, "cpu", &warm).ok());
  EXPECT_TRUE(warm.cache_hit);

  // A restarted daemon: the disk cache serves it (no codegen, no clang).
  store->reset();
  auto restarted = ModuleStore::Create(options);
  ASSERT_TRUE(restarted.ok());
  CompileReport disk;
  ASSERT_TRUE((*restarted)->Compile(m, "cpu", &disk).ok());
  EXPECT_TRUE(disk.disk_hit);
  // And without the NVRTC check, a cold CPU-only compile (different key: verified flag).
  options.verify_cuda = false;
  auto cpu_only = ModuleStore::Create(options);
  ASSERT_TRUE(cpu_only.ok());
  CompileReport cold_cpu;
  ASSERT_TRUE((*cpu_only)->Compile(m, "cpu", &cold_cpu).ok());
  EXPECT_FALSE(cold_cpu.disk_hit);
  std::printf("[ store ] real saxpy: memory hit %.3f ms, disk hit %.2f ms, cold CPU-only %.1f ms\n",
              warm.compile_ms, disk.compile_ms, cold_cpu.compile_ms);
}

}  // namespace
}  // namespace weft

namespace weft {
namespace {

#if WEFT_WITH_CUDA
// cuda:N modules: generated for Target::kCuda, compiled by NVRTC (for the device's sm, or
// verify_cuda_sm without a driver), cached on disk like CPU objects.
TEST_F(CacheModule, CudaModulesAreCubinsCachedOnDisk) {
  std::string id;
  {
    auto store = NewStore();
    CompileReport report;
    auto m = store->Compile(Module("a * x + y"), "cuda:0", &report);
    ASSERT_TRUE(m.ok()) << m.status().ToString();
    EXPECT_EQ((*m)->target, Target::kCuda);
    EXPECT_GE((*m)->cuda_sm, 50);
    ASSERT_GT((*m)->cuda_image.size(), 4u);
    EXPECT_EQ((*m)->cuda_image.substr(0, 4), std::string("\x7f" "ELF"));
    ASSERT_NE((*m)->Find("saxpy"), nullptr);
    EXPECT_EQ((*m)->Find("saxpy")->cpu_forward, nullptr);
    EXPECT_EQ(codegen_.seen.back().target, Target::kCuda);
    id = (*m)->id;
    auto cpu = store->Compile(Module("a * x + y"), "cpu", nullptr);
    ASSERT_TRUE(cpu.ok());
    EXPECT_NE((*cpu)->id, id);  // same source, different target: different module
    EXPECT_EQ(store->Find(id).get(), m->get());
  }
  auto store = NewStore();
  CompileReport report;
  auto m = store->Compile(Module("a * x + y"), "cuda:0", &report);
  ASSERT_TRUE(m.ok());
  EXPECT_TRUE(report.disk_hit);
  EXPECT_EQ((*m)->id, id);
  EXPECT_EQ(store->Compile(Module("a * x + y"), "cuda:x", nullptr).status().code(),
            StatusCode::kInvalidArgument);
}

// A CUDA module whose kernels index parameters by the thread gets its trusted-index variant
// built while it compiles (the real code generator, NVRTC in child processes as weftd runs it),
// so that the first launch proven in range finds it in memory; modules that could never use it
// (no such access, bounds checks off) build nothing more, and the option turns it off. Prints
// the time to the module and its variant both ways (not asserted).
TEST_F(CacheModule, CudaTrustedVariantIsBuiltBesideTheModule) {
  auto store_with = [&](bool beside) {
    ModuleStoreOptions options;
    options.cache_dir = (dir_ / (beside ? "beside" : "after")).string();
    options.build_id = "test-build";
    options.build_trusted_beside = beside;
    options.compile_time_limit_s = 30;   // weftd's default: compiles in child processes
    auto store = ModuleStore::Create(options);
    EXPECT_TRUE(store.ok()) << store.status().ToString();
    return store.ok() ? std::move(*store) : nullptr;
  };
  const ModuleSource saxpy = testing::SaxpySource("beside", "a * x[i] + y[i]", 3);
  // Compile, then the variant the first launch proven in range asks for.
  auto compile_and_variant = [&](ModuleStore& store, const char* how) {
    auto start = std::chrono::steady_clock::now();
    auto m = store.Compile(saxpy, "cuda:0", nullptr);
    auto v = m.ok() ? store.WithTrustedTidIndices((*m)->id, false) : m;
    std::printf("  module + trusted-index variant, %s: %.1f ms\n", how,
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    return std::make_pair(m, v);
  };

  auto store = store_with(true);
  ASSERT_NE(store, nullptr);
  auto [m, trusted] = compile_and_variant(*store, "built beside");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_FALSE((*m)->trusts_tid_indices);
  EXPECT_EQ(store->stats().misses, 2u);   // the module and its trusted-index variant
  ASSERT_TRUE(trusted.ok()) << trusted.status().ToString();
  EXPECT_TRUE((*trusted)->trusts_tid_indices);
  EXPECT_EQ((*trusted)->id, (*m)->id);
  ASSERT_NE((*trusted)->Find("saxpy"), nullptr);
  EXPECT_EQ(store->stats().misses, 2u);   // found in memory: nothing compiled at the launch
  EXPECT_EQ(store->stats().memory_hits, 1u);
  // Compiled again (another client): in memory, nothing built beside it.
  ASSERT_TRUE(store->Compile(saxpy, "cuda:0", nullptr).ok());
  EXPECT_EQ(store->stats().misses, 2u);

  // No access by the thread's index: the variant could never be taken, so it is not built.
  ModuleSource fixed = testing::SaxpySource("fixed_index", "a * x[0]", 3);
  fixed.functions[0].source = "def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):\n"
                              "    y[0] = a * x[0]\n";
  ASSERT_TRUE(store->Compile(fixed, "cuda:0", nullptr).ok());
  EXPECT_EQ(store->stats().misses, 3u);
  // Bounds checks off: there is no trusted-index variant of it.
  ModuleSource unchecked = testing::SaxpySource("unchecked", "a * x[i] + y[i]", 3);
  unchecked.options["bounds_checks"] = "false";
  ASSERT_TRUE(store->Compile(unchecked, "cuda:0", nullptr).ok());
  EXPECT_EQ(store->stats().misses, 4u);
  // A kernel the code generator rejects: the client's error, nothing built.
  ModuleSource bad = testing::SaxpySource("bad", "a * x[i] + undefined_name", 3);
  auto refused = store->Compile(bad, "cuda:0", nullptr);
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store->stats().misses, 5u);   // its own attempt only
  // CPU modules have no trusted-index variant.
  ASSERT_TRUE(store->Compile(testing::SaxpySource("on_cpu", "a * x[i] + y[i]", 3), "cpu", nullptr).ok());
  EXPECT_EQ(store->stats().misses, 6u);

  // Turned off: the variant is built when the first launch asks for it.
  auto after = store_with(false);
  ASSERT_NE(after, nullptr);
  auto [m2, trusted2] = compile_and_variant(*after, "built at the first launch");
  ASSERT_TRUE(m2.ok() && trusted2.ok());
  EXPECT_TRUE((*trusted2)->trusts_tid_indices);
  EXPECT_EQ(after->stats().misses, 2u);   // one at Compile, one at the variant's request
}
#endif

}  // namespace
}  // namespace weft
