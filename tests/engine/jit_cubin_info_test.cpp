// ParseCubin: per-kernel registers, code, shared, local and constant sizes read from CUBINs
// that NVRTC builds here (no GPU) for sm_75 and sm_90, and malformed images (truncated at every
// length, corrupted headers and tables) rejected as errors without reading outside the bytes.
#include "engine/jit/cuda/cubin_info.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <string>

#include "engine/jit/cuda/nvrtc_compiler.h"

namespace weft::jit {
namespace {

// Two entry points: one with a static shared array and a local array indexed at run time
// (a stack frame), one empty.
constexpr const char* kKernels = R"(#include "launch_abi.h"
extern "C" __global__ void weft_big_cuda_forward(const float* x, float* y, int n) {
  __shared__ float tile[64];
  float local[40];
  int i = blockIdx.x * blockDim.x + threadIdx.x;
  for (int j = 0; j < 40; ++j) local[j] = x[(i + j) % n];
  tile[threadIdx.x % 64] = x[i % n];
  __syncthreads();
  if (i < n) y[i] = tile[(threadIdx.x + 1) % 64] + local[i % 40];
}
extern "C" __global__ void weft_empty_cuda_forward() {}
)";

class JitCubinInfo : public ::testing::TestWithParam<int> {
 protected:
  void SetUp() override {
    auto version = NvrtcVersion();
    if (!version.ok()) GTEST_SKIP() << "NVRTC unavailable: " << version.status().ToString();
    if (!NvrtcSupportsArch(GetParam())) GTEST_SKIP() << "NVRTC " << *version << " lacks sm_" << GetParam();
  }
  std::string Cubin() {
    NvrtcOptions options;
    options.sm = GetParam();
    options.include_dirs = {WEFT_NATIVE_DIR};
    auto out = NvrtcCompile(kKernels, "kernels.cu", options);
    EXPECT_TRUE(out.ok()) << out.status().ToString();
    return out.ok() ? out->image : std::string();
  }
};

TEST_P(JitCubinInfo, ReportsEveryEntryPoint) {
  std::string image = Cubin();
  auto info = ParseCubin(image);
  ASSERT_TRUE(info.ok()) << info.status().ToString();
  EXPECT_EQ(info->sm, static_cast<uint32_t>(GetParam()));
  const CubinKernelInfo* big = info->Find("weft_big_cuda_forward");
  const CubinKernelInfo* empty = info->Find("weft_empty_cuda_forward");
  ASSERT_NE(big, nullptr);
  ASSERT_NE(empty, nullptr);
  EXPECT_GT(big->registers, empty->registers);
  EXPECT_GT(empty->registers, 0u);
  EXPECT_LE(big->registers, 255u);
  EXPECT_GT(big->code_bytes, empty->code_bytes);
  EXPECT_GE(big->shared_bytes, 64u * 4);
  EXPECT_EQ(empty->shared_bytes, 0u);
  EXPECT_EQ(empty->local_bytes, 0u);
  EXPECT_GT(big->const_bytes, empty->const_bytes);   // bank 0 holds the parameters
  std::printf("[ cubin ] sm_%d: %zu bytes; big: %u regs, %llu code, %llu shared, %llu local, %llu const\n",
              GetParam(), image.size(), big->registers, (unsigned long long)big->code_bytes,
              (unsigned long long)big->shared_bytes, (unsigned long long)big->local_bytes,
              (unsigned long long)big->const_bytes);
}

TEST_P(JitCubinInfo, MalformedImagesAreErrors) {
  std::string image = Cubin();
  ASSERT_GT(image.size(), 64u);
  EXPECT_FALSE(ParseCubin("").ok());
  EXPECT_FALSE(ParseCubin("not an elf file at all, but long enough to hold a header of 64 bytes....").ok());
  // Every truncation either fails cleanly or (beyond the last table) parses.
  for (size_t n = 0; n < image.size(); n += 7) {
    auto info = ParseCubin(std::string_view(image).substr(0, n));
    if (info.ok()) EXPECT_GT(n, 64u);
    else EXPECT_EQ(info.status().code(), StatusCode::kInvalidArgument);
  }
  // Random byte corruption never reads outside the image (ASan builds check it).
  std::mt19937 rng(1234);
  for (int round = 0; round < 2000; ++round) {
    std::string bad = image;
    for (int k = 0; k < 4; ++k) bad[rng() % bad.size()] = static_cast<char>(rng());
    (void)ParseCubin(bad);
  }
  // A section header table pointing past the end.
  std::string far = image;
  uint64_t huge = ~uint64_t{0} - 8;
  std::memcpy(far.data() + 0x28, &huge, sizeof huge);
  EXPECT_EQ(ParseCubin(far).status().code(), StatusCode::kInvalidArgument);
}

INSTANTIATE_TEST_SUITE_P(Archs, JitCubinInfo, ::testing::Values(75, 90),
                         [](const auto& info) { return "sm_" + std::to_string(info.param); });

}  // namespace
}  // namespace weft::jit
