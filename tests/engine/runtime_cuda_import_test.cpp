// CUDA IPC import of client GPU memory (Engine::ImportCudaArray), hostile requests: what the
// daemon checks before any driver call (remote sessions, CPU devices, dtypes, shapes whose size
// overflows, handles of the wrong size, zero allocation ids, absurd offsets, unknown GPUs) runs
// everywhere; what needs a GPU (forged handles, weft's own memory) skips
// without one. Imports of real framework memory need a second process: they are tested from
// Python (clients/python/tests/interop/test_cuda_import.py).
#include <gtest/gtest.h>

#include <random>

#include "runtime_test_support.h"

namespace weft::testing {
namespace {

CudaImportParams Valid(const std::string& device = "cuda:0") {
  CudaImportParams p;
  p.device = device;
  p.dtype = F32();
  p.shape = {16};
  p.data.ipc_handle = std::string(64, '\x01');
  p.data.allocation_id = 7;
  return p;
}

TEST(CudaImportTest, RemoteSessionsAreRefused) {
  auto e = MakeEngine();
  SessionOptions o = Local();
  o.local = false;
  o.principal = "tcp-token";
  auto s = e->OpenSession(o);
  auto r = e->ImportCudaArray(*s, Valid());
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kPermissionDenied);
  EXPECT_NE(r.status().message().find("local (Unix-socket) session"), std::string::npos) << r.status().ToString();
}

TEST(CudaImportTest, MalformedRequestsAreRefusedBeforeAnyDriverCall) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  struct Case {
    const char* name;
    std::function<void(CudaImportParams&)> edit;
    StatusCode code;
    const char* message;
  };
  const std::vector<Case> cases = {
      {"cpu device", [](CudaImportParams& p) { p.device = "cpu"; }, StatusCode::kInvalidArgument, "is not a GPU"},
      {"no dtype", [](CudaImportParams& p) { p.dtype = DType{}; }, StatusCode::kInvalidArgument, ""},
      {"no dims", [](CudaImportParams& p) { p.shape = {}; }, StatusCode::kInvalidArgument, "1 to 4 dimensions"},
      {"5 dims", [](CudaImportParams& p) { p.shape = {1, 1, 1, 1, 1}; }, StatusCode::kInvalidArgument,
       "1 to 4 dimensions"},
      {"negative", [](CudaImportParams& p) { p.shape = {4, -1}; }, StatusCode::kInvalidArgument, "negative"},
      {"overflow", [](CudaImportParams& p) { p.shape = {int64_t(1) << 40, int64_t(1) << 40}; },
       StatusCode::kOutOfRange, "overflows"},
      {"short handle", [](CudaImportParams& p) { p.data.ipc_handle = "abc"; }, StatusCode::kInvalidArgument,
       "64 bytes, got 3"},
      {"long grad handle",
       [](CudaImportParams& p) {
         p.has_grad = true;
         p.grad = p.data;
         p.grad.ipc_handle += "x";
       },
       StatusCode::kInvalidArgument, "64 bytes, got 65"},
      {"zero id", [](CudaImportParams& p) { p.data.allocation_id = 0; }, StatusCode::kInvalidArgument,
       "allocation id is 0"},
      {"absurd offset", [](CudaImportParams& p) { p.data.byte_offset = ~uint64_t(0) - 3; }, StatusCode::kOutOfRange,
       "absurdly large"},
      {"unknown gpu", [](CudaImportParams& p) { p.device = "cuda:99"; }, StatusCode::kInvalidArgument, ""},
  };
  for (const Case& c : cases) {
    CudaImportParams p = Valid();
    c.edit(p);
    auto r = e->ImportCudaArray(*s, p);
    ASSERT_FALSE(r.ok()) << c.name;
    if (std::string(c.name) != "unknown gpu") {
      EXPECT_EQ(r.status().code(), c.code) << c.name << ": " << r.status().ToString();
    }
    EXPECT_NE(r.status().message().find(c.message), std::string::npos) << c.name << ": " << r.status().ToString();
  }
  EXPECT_EQ(s->array_count(), 0u);   // nothing was held
}

class CudaImportGpuTest : public ::testing::Test {
 protected:
  void SetUp() override {
    engine_ = MakeEngine();
    if (engine_->devices().gpus().empty()) GTEST_SKIP() << "no GPU the daemon can compute on";
  }
  std::unique_ptr<Engine> engine_;
};

TEST_F(CudaImportGpuTest, AForgedHandleIsRefusedByTheDriver) {
  auto s = engine_->OpenSession(Local());
  std::mt19937 rng(11);
  CudaImportParams p = Valid();
  for (char& c : p.data.ipc_handle) c = static_cast<char>(rng());
  auto r = engine_->ImportCudaArray(*s, p);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << r.status().ToString();
  EXPECT_NE(r.status().message().find("could not be opened on cuda:0"), std::string::npos) << r.status().ToString();
  EXPECT_EQ(engine_->devices().gpus()[0]->ImportCount(), 0u);
}

TEST_F(CudaImportGpuTest, WeftsOwnMemoryIsRefused) {
  auto owner = engine_->OpenSession(Local("owner"));
  CreateArrayParams c;
  c.dtype = F32();
  c.shape = {64};
  c.device = "cuda:0";
  auto made = engine_->CreateArray(*owner, c);
  ASSERT_TRUE(made.ok()) << made.status().ToString();
  ASSERT_EQ(made->cuda_ipc_handle.size(), 64u);
  auto other = engine_->OpenSession(Local("other"));
  CudaImportParams p = Valid();
  p.data.ipc_handle = made->cuda_ipc_handle;
  auto r = engine_->ImportCudaArray(*other, p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("weft's own memory"), std::string::npos) << r.status().ToString();
}

}  // namespace
}  // namespace weft::testing
