// NVRTC in the compiler child (weft-cc --nvrtc, under --compile-time-limit): the child's CUBIN
// equals the in-process one; NVRTC's errors come back as in process; a compile that never ends
// (an #include of a FIFO nobody writes) is killed at the limit with an error naming the
// architecture and the flag, no process is left, and the next compile works. No GPU needed.
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>

#include "engine/jit/cpu/compile_process.h"
#include "engine/jit/cpu/cpu_jit.h"
#include "engine/jit/cuda/nvrtc_child.h"
#include "engine/jit/cuda/nvrtc_compiler.h"

namespace weft::jit {
namespace {

constexpr const char* kKernel = R"(#include "launch_abi.h"
struct saxpy_args { float a; float _pad; wp::array_t<float> x; wp::array_t<float> y; };
extern "C" __global__ void weft_saxpy_cuda_forward(wp::launch_context_t ctx, saxpy_args args) {
  wp::int64 i = wp::int64(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= ctx.bounds.size) return;
  args.y.data[i] = args.a * args.x.data[i] + args.y.data[i];
}
)";

// Child processes of this process still alive (/proc/self/task/*/children).
std::string Children() {
  std::string all;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream in(task.path() / "children");
    std::string line;
    std::getline(in, line);
    all += line;
  }
  return all;
}

class JitNvrtcChild : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!NvrtcVersion().ok()) GTEST_SKIP() << "NVRTC unavailable";
    if (!NvrtcSupportsArch(90)) GTEST_SKIP() << "NVRTC lacks sm_90";
    child_ = DefaultCompilerChild();
    if (::access(child_.c_str(), X_OK) != 0) GTEST_SKIP() << "no weft-cc at " << child_;
  }
  NvrtcOptions Options() const {
    NvrtcOptions o;
    o.sm = 90;
    o.include_dirs = {WEFT_NATIVE_DIR};
    return o;
  }
  Expected<std::string> InChild(const std::string& source, double limit) {
    return CompileInChild(child_, NvrtcChildArgs(Options(), "k.cu", limit), source, "k.cu", limit, "CUDA sm_90 (NVRTC)");
  }
  std::string child_;
};

TEST_F(JitNvrtcChild, CompilesTheSameCubinAsInProcess) {
  auto in_process = NvrtcCompile(kKernel, "k.cu", Options());
  ASSERT_TRUE(in_process.ok()) << in_process.status().ToString();
  auto start = std::chrono::steady_clock::now();
  auto child = InChild(kKernel, 60);
  double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(child.ok()) << child.status().ToString();
  EXPECT_EQ(*child, in_process->image);
  std::printf("[ nvrtc child ] saxpy sm_90: %.0f ms in process, %.0f ms in weft-cc\n", in_process->compile_ms, ms);
}

TEST_F(JitNvrtcChild, ErrorsComeBackAsInProcess) {
  const char* source = R"(#include "launch_abi.h"
extern "C" __global__ void weft_k_cuda_forward(wp::launch_context_t ctx) {
#line 17 "my_kernels.py"
  float x = no_such_name * 2.0f;
}
)";
  auto child = InChild(source, 60);
  ASSERT_FALSE(child.ok());
  EXPECT_EQ(child.status().code(), StatusCode::kInternal);
  EXPECT_NE(child.status().message().find("my_kernels.py(17)"), std::string::npos) << child.status().message();
  EXPECT_NE(child.status().message().find("no_such_name"), std::string::npos);
}

TEST_F(JitNvrtcChild, ACompileOverTheLimitIsKilledAndTheNextWorks) {
  std::string fifo = ::testing::TempDir() + "/weft_nvrtc_fifo_" + std::to_string(::getpid());
  ::unlink(fifo.c_str());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string source = std::string(kKernel) + "#include \"" + fifo + "\"\n";
  auto start = std::chrono::steady_clock::now();
  auto stuck = InChild(source, 3.0);
  double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ::unlink(fifo.c_str());
  ASSERT_FALSE(stuck.ok());
  EXPECT_EQ(stuck.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(stuck.status().message().find("CUDA sm_90 (NVRTC)"), std::string::npos) << stuck.status().message();
  EXPECT_NE(stuck.status().message().find("--compile-time-limit"), std::string::npos);
  EXPECT_GE(s, 2.9);
  EXPECT_LT(s, 10.0);
  EXPECT_EQ(Children(), "");
  auto next = InChild(kKernel, 60);
  EXPECT_TRUE(next.ok()) << next.status().ToString();
}

}  // namespace
}  // namespace weft::jit
