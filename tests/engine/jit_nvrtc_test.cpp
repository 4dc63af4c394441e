// NVRTC: the native launch ABI plus a kernel compile for sm_90 to CUBIN and PTX without a GPU;
// errors carry NVRTC's log with the user's file:line. When engine/native/weft.h exists, a
// kernel using the whole native library compiles too.
#include "engine/jit/cuda/nvrtc_compiler.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <string>

namespace weft::jit {
namespace {

constexpr const char* kKernel = R"(#include "launch_abi.h"
WP_CALLABLE inline float madd(float a, float x, float y) { return a * x + y; }
struct saxpy_args { float a; float _pad; wp::array_t<float> x; wp::array_t<float> y; };
extern "C" __global__ void weft_saxpy_cuda_forward(wp::launch_context_t ctx, saxpy_args args) {
  wp::int64 i = wp::int64(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= ctx.bounds.size) return;
  args.y.data[i] = madd(args.a, args.x.data[i], args.y.data[i]);
}
)";

NvrtcOptions Options() {
  NvrtcOptions options;
  options.include_dirs = {WEFT_NATIVE_DIR};
  return options;
}

class JitNvrtc : public ::testing::Test {
 protected:
  void SetUp() override {
    auto version = NvrtcVersion();
    if (!version.ok()) GTEST_SKIP() << "NVRTC unavailable: " << version.status().ToString();
    if (!NvrtcSupportsArch(90)) GTEST_SKIP() << "NVRTC " << *version << " lacks sm_90";
  }
};

TEST_F(JitNvrtc, CompilesKernelToCubin) {
  auto output = NvrtcCompile(kKernel, "saxpy.cu", Options());
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  EXPECT_TRUE(output->is_cubin);
  ASSERT_GT(output->image.size(), 4u);
  EXPECT_EQ(output->image.substr(0, 4), std::string("\x7f" "ELF"));
  std::printf("[ nvrtc ] %s: saxpy to sm_90 CUBIN in %.1f ms (%zu bytes)\n",
              NvrtcVersion()->c_str(), output->compile_ms, output->image.size());
}

TEST_F(JitNvrtc, CompilesKernelToPtx) {
  auto options = Options();
  options.cubin = false;
  auto output = NvrtcCompile(kKernel, "saxpy.cu", options);
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  EXPECT_FALSE(output->is_cubin);
  EXPECT_NE(output->image.find(".entry weft_saxpy_cuda_forward"), std::string::npos);
  EXPECT_NE(output->image.find(".target sm_90"), std::string::npos);
}

TEST_F(JitNvrtc, ErrorCarriesLogAndUserLine) {
  const char* source = R"(#include "launch_abi.h"
extern "C" __global__ void weft_k_cuda_forward(wp::launch_context_t ctx) {
#line 17 "my_kernels.py"
  float x = no_such_name * 2.0f;
}
)";
  auto output = NvrtcCompile(source, "k.cu", Options());
  ASSERT_FALSE(output.ok());
  EXPECT_EQ(output.status().code(), StatusCode::kInternal);
  EXPECT_NE(output.status().message().find("my_kernels.py(17)"), std::string::npos)
      << output.status().message();
  EXPECT_NE(output.status().message().find("no_such_name"), std::string::npos);
}

TEST_F(JitNvrtc, MissingIncludePathIsAnError) {
  NvrtcOptions options;  // no include dirs: launch_abi.h is not found
  auto output = NvrtcCompile(kKernel, "saxpy.cu", options);
  EXPECT_FALSE(output.ok());
}

TEST_F(JitNvrtc, NativeLibraryCompiles) {
  if (!std::filesystem::exists(std::filesystem::path(WEFT_NATIVE_DIR) / "weft.h"))
    GTEST_SKIP() << "engine/native/weft.h not written yet";
  const char* source = R"(#include "weft.h"
extern "C" __global__ void weft_k_cuda_forward(wp::launch_context_t ctx, wp::array_t<float> a) {
  wp::int64 i = wp::int64(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < ctx.bounds.size) a.data[i] = a.data[i] * 2.0f;
}
)";
  auto output = NvrtcCompile(source, "native.cu", Options());
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  std::printf("[ nvrtc ] weft.h + kernel to sm_90 CUBIN in %.1f ms\n", output->compile_ms);
}

}  // namespace
}  // namespace weft::jit
