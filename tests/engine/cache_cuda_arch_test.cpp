// ModuleStore::CompileForArch: a module compiled with NVRTC for sm_75 and sm_90 on a machine
// without a GPU, with a report per entry point (forward and adjoint) read from the CUBIN;
// cached like every module; architectures outside the known list refused with the list.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "engine/runtime/module_store.h"

#if WEFT_WITH_CUDA
#include "engine/jit/cuda/cubin_info.h"
#include "engine/jit/cuda/nvrtc_compiler.h"
#include "saxpy_source.h"
#endif

namespace weft {
namespace {

namespace fs = std::filesystem;

ModuleSource Saxpy() { return testing::SaxpySource("tests.arch_saxpy", "a * wp.sin(x[i]) + y[i]", 5); }

class CacheCudaArch : public ::testing::Test {
 protected:
  void SetUp() override {
#if !WEFT_WITH_CUDA
    GTEST_SKIP() << "built without NVRTC";
#else
    if (!jit::NvrtcVersion().ok()) GTEST_SKIP() << "NVRTC unavailable";
#endif
    dir_ = fs::temp_directory_path() / ("weft-arch-" + std::to_string(::getpid()) + "-" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    ModuleStoreOptions options;
    options.cache_dir = dir_.string();
    auto store = ModuleStore::Create(options);
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    store_ = std::move(*store);
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
  std::unique_ptr<ModuleStore> store_;
};

TEST_F(CacheCudaArch, ReportsForwardAndAdjointForSm75AndSm90) {
#if WEFT_WITH_CUDA
  for (int arch : {75, 90}) {
    if (!jit::NvrtcSupportsArch(arch)) continue;
    CompileReport report;
    auto c = store_->CompileForArch(Saxpy(), arch, &report);
    ASSERT_TRUE(c.ok()) << c.status().ToString();
    EXPECT_FALSE(report.cache_hit);
    EXPECT_EQ(c->arch, arch);
    auto cubin = jit::ParseCubin(c->image);
    ASSERT_TRUE(cubin.ok());
    EXPECT_EQ(cubin->sm, static_cast<uint32_t>(arch));
    ASSERT_EQ(c->kernels.size(), 2u);
    EXPECT_EQ(c->kernels[0].kernel, "saxpy");
    EXPECT_FALSE(c->kernels[0].adjoint);
    EXPECT_TRUE(c->kernels[1].adjoint);
    for (const auto& k : c->kernels) {
      EXPECT_GT(k.registers, 0u) << k.symbol;
      EXPECT_LE(k.registers, 255u) << k.symbol;
      EXPECT_GT(k.code_bytes, 0u) << k.symbol;
      EXPECT_GT(k.const_bytes, 0u) << k.symbol;
      std::printf("[ arch ] sm_%d %s: %u registers, %llu bytes of code (CUBIN %zu bytes, %.0f ms)\n", arch,
                  k.symbol.c_str(), k.registers, (unsigned long long)k.code_bytes, c->image.size(),
                  report.compile_ms);
    }
    CompileReport again;
    auto hit = store_->CompileForArch(Saxpy(), arch, &again);
    ASSERT_TRUE(hit.ok());
    EXPECT_TRUE(again.cache_hit);
    EXPECT_EQ(hit->image, c->image);
  }
#endif
}

TEST_F(CacheCudaArch, EnableBackwardFalseReportsTheForwardOnly) {
  ModuleSource m = Saxpy();
  m.options["enable_backward"] = "false";
  auto c = store_->CompileForArch(m, 90, nullptr);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  ASSERT_EQ(c->kernels.size(), 1u);
  EXPECT_FALSE(c->kernels[0].adjoint);
}

TEST_F(CacheCudaArch, UnknownArchitecturesAreRefusedWithTheList) {
  for (int arch : {0, -1, 52, 61, 70, 91, 999, 1 << 30}) {
    auto c = store_->CompileForArch(Saxpy(), arch, nullptr);
    ASSERT_FALSE(c.ok()) << arch;
    EXPECT_EQ(c.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(c.status().message().find("unknown CUDA architecture " + std::to_string(arch)), std::string::npos)
        << c.status().message();
    EXPECT_NE(c.status().message().find("75"), std::string::npos) << c.status().message();
  }
}

TEST_F(CacheCudaArch, UserErrorsComeBackAsDiagnostics) {
  ModuleSource m = Saxpy();
  m.functions[0].source =
      "def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):\n"
      "    i = wp.tid()\n"
      "    y[i] = a * no_such_name\n";
  CompileReport report;
  auto c = store_->CompileForArch(m, 90, &report);
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().code(), StatusCode::kInvalidArgument);
  ASSERT_FALSE(report.diagnostics.empty());
  EXPECT_EQ(report.diagnostics[0].location.file, "saxpy.py");
}

}  // namespace
}  // namespace weft
