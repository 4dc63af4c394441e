// CpuJit with a compile time limit: compiles run in the weft-cc child process and give the same
// object code as in process; clang's errors come back as in process; a compile that does not
// end is killed at the limit (ResourceExhausted naming the flag), leaves no process behind, and
// the CpuJit keeps compiling.
#include "engine/jit/cpu/cpu_jit.h"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace weft::jit {
namespace {

namespace fs = std::filesystem;

constexpr const char* kSource = R"(#include "weft.h"
extern "C" float weft_twice(float x) { return 2.0f * x; }
)";

double MsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

// Child processes of this process still alive (/proc/self/task/*/children).
std::string Children() {
  std::string all;
  for (const auto& task : fs::directory_iterator("/proc/self/task")) {
    std::ifstream in(task.path() / "children");
    std::string line;
    std::getline(in, line);
    all += line;
  }
  return all;
}

class JitCpuChild : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("weft-jit-child-test-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  CpuJitOptions Options(double limit_s) const {
    CpuJitOptions options;
    options.include_dirs = {WEFT_NATIVE_DIR};
    options.pch_dir = dir_.string();
    options.compile_time_limit_s = limit_s;
    return options;
  }

  fs::path dir_;
};

TEST_F(JitCpuChild, CompilesTheSameObjectAsInProcessAndLoadsIt) {
  auto in_process = CpuJit::Create(Options(0));
  ASSERT_TRUE(in_process.ok()) << in_process.status().ToString();
  auto child = CpuJit::Create(Options(30));
  ASSERT_TRUE(child.ok()) << child.status().ToString();
  EXPECT_EQ((*child)->target_id(), (*in_process)->target_id());
  // Warm both once, then time one compile each (the cost of the child process).
  ASSERT_TRUE((*in_process)->Compile(kSource, "twice").ok());
  ASSERT_TRUE((*child)->Compile(kSource, "twice").ok());
  CpuCompileTimes here, there;
  auto a = (*in_process)->Compile(kSource, "twice", &here);
  auto b = (*child)->Compile(kSource, "twice", &there);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  std::printf("[ jit ] small module: in process %.1f ms, in the child process %.1f ms\n",
              here.frontend_and_codegen_ms, there.frontend_and_codegen_ms);
  EXPECT_EQ(*a, *b) << "the child's object code differs from the in-process compile";
  auto code = (*child)->Load(*b, "twice");
  ASSERT_TRUE(code.ok()) << code.status().ToString();
  auto entry = (*code)->Lookup("weft_twice");
  ASSERT_TRUE(entry.ok()) << entry.status().ToString();
  EXPECT_EQ(reinterpret_cast<float (*)(float)>(*entry)(1.25f), 2.5f);
  EXPECT_EQ(Children(), "");
}

TEST_F(JitCpuChild, CompileErrorsComeBackAsInProcess) {
  auto jit = CpuJit::Create(Options(30));
  ASSERT_TRUE(jit.ok()) << jit.status().ToString();
  const char* source = R"(#include "weft.h"
extern "C" void weft_k(float* out) {
#line 42 "my_kernels.py"
  *out = undefined_name + 1;
}
)";
  auto object = (*jit)->Compile(source, "k");
  ASSERT_FALSE(object.ok());
  EXPECT_EQ(object.status().code(), StatusCode::kInternal);
  EXPECT_NE(object.status().message().find("clang rejected k.cpp"), std::string::npos) << object.status().message();
  EXPECT_NE(object.status().message().find("my_kernels.py:42"), std::string::npos) << object.status().message();
  EXPECT_NE(object.status().message().find("undefined_name"), std::string::npos);
}

// A compile that never ends: the source includes a FIFO nobody writes, so clang blocks in
// open(). It is killed at the limit (4 s); the CpuJit compiles the next module normally.
TEST_F(JitCpuChild, ACompileOverTheLimitIsKilledAndTheJitGoesOn) {
  const fs::path fifo = dir_ / "never.h";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  auto jit = CpuJit::Create(Options(4.0));   // room for the next, small compile on a loaded machine
  ASSERT_TRUE(jit.ok()) << jit.status().ToString();
  const std::string source = "#include \"" + fifo.string() + "\"\nint x;\n";
  auto start = std::chrono::steady_clock::now();
  auto object = (*jit)->Compile(source, "endless");
  double ms = MsSince(start);
  ASSERT_FALSE(object.ok());
  EXPECT_EQ(object.status().code(), StatusCode::kResourceExhausted) << object.status().ToString();
  EXPECT_NE(object.status().message().find("--compile-time-limit"), std::string::npos) << object.status().message();
  EXPECT_NE(object.status().message().find("endless.cpp"), std::string::npos) << object.status().message();
  EXPECT_GE(ms, 4000.0);
  EXPECT_LT(ms, 12000.0) << "the compile was not stopped at its limit";
  EXPECT_EQ(Children(), "") << "the killed compiler process was not reaped";
  auto next = (*jit)->Compile(kSource, "twice");
  EXPECT_TRUE(next.ok()) << next.status().ToString();
}

TEST_F(JitCpuChild, AMissingChildExecutableIsACreateError) {
  auto options = Options(5);
  options.compiler_child = (dir_ / "no-such-weft-cc").string();
  auto jit = CpuJit::Create(options);
  ASSERT_FALSE(jit.ok());
  EXPECT_NE(jit.status().message().find("no-such-weft-cc"), std::string::npos) << jit.status().message();
}

}  // namespace
}  // namespace weft::jit
