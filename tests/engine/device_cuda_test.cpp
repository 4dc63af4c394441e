// The CUDA device through the engine (skipped with the reason when no GPU computes here):
// arrays on cuda:0 from data, strided fills and copies between cuda:0 and the CPU against a
// host reference on random data, the "cuda" alias placing a session, per-session GPU slabs in
// Stats and their release when the session closes, and a CPU-compiled module refused on a GPU.
#include <gtest/gtest.h>

#include <random>

#include "runtime_test_support.h"
#if WEFT_WITH_CUDA
#include "engine/jit/cuda/nvrtc_compiler.h"
#endif

namespace weft::testing {
namespace {

// The fake store, plus NVRTC for the device's built-in copy/fill kernels.
class NvrtcFakeStore : public FakeModuleStore {
 public:
  Expected<std::string> CompileCudaSource(const std::string& source, const std::string& name, int sm) override {
#if WEFT_WITH_CUDA
    jit::NvrtcOptions o;
    o.sm = sm;
    o.include_dirs = {WEFT_NATIVE_DIR};
    auto r = jit::NvrtcCompile(source, name, o);
    if (!r.ok()) return r.status();
    return r->image;
#else
    (void)source, (void)name, (void)sm;
    return Unimplemented("no NVRTC");
#endif
  }
};

class CudaDeviceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto store = std::make_unique<NvrtcFakeStore>();
    store_ = store.get();
    EngineOptions o;
    o.cpu_threads = 2;
    o.remove_stale_slabs = false;
    auto e = Engine::Create(o, std::move(store));
    ASSERT_TRUE(e.ok()) << e.status().ToString();
    engine_ = std::move(e).value();
    if (engine_->devices().gpus().empty()) GTEST_SKIP() << "no GPU the daemon can compute on";
  }
  NvrtcFakeStore* store_ = nullptr;
  std::unique_ptr<Engine> engine_;
};

std::vector<float> RandomFloats(size_t n, std::mt19937& rng) {
  std::uniform_real_distribution<float> d(-100.f, 100.f);
  std::vector<float> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}

TEST_F(CudaDeviceTest, ArraysFillsAndCopiesBetweenCpuAndGpu) {
  std::mt19937 rng(std::random_device{}());
  auto s = engine_->OpenSession(Local());
  const std::vector<float> host = RandomFloats(1000, rng);
  CreateArrayParams p = FromFloats(host);
  p.device = "cuda:0";
  auto g = engine_->CreateArray(*s, p);
  ASSERT_TRUE(g.ok()) << g.status().ToString();
  EXPECT_EQ(g->device, "cuda:0");
  EXPECT_TRUE(g->shm_name.empty());
  EXPECT_EQ(g->cuda_ipc_handle.size(), 64u);
  EXPECT_EQ(ReadFloats(*engine_, *s, g->handle), host);

  // every third element of the GPU array = 5 (a strided fill: the built-in kernel)
  FillCommand f;
  f.dst = ArrayRef{g->handle, 0, {334}, {12}};
  float five = 5.f;
  f.value.assign(reinterpret_cast<const char*>(&five), 4);
  Command fc;
  fc.kind = f;
  // GPU elements [10, 20) -> CPU array elements [0, 10) reversed (a strided destination)
  auto c = engine_->CreateArray(*s, FromFloats(std::vector<float>(10, 0.f)));
  ASSERT_TRUE(c.ok());
  CopyCommand cp;
  cp.dst = ArrayRef{c->handle, 36, {10}, {-4}};
  cp.src = ArrayRef{g->handle, 40, {10}, {}};
  Command cc;
  cc.kind = cp;
  ASSERT_TRUE(engine_->Submit(*s, {fc, cc}).ok());
  auto r = engine_->Synchronize(*s);
  ASSERT_TRUE(r.error.ok()) << r.error.ToString();
  std::vector<float> expect = host;
  for (size_t i = 0; i < expect.size(); i += 3) expect[i] = 5.f;
  EXPECT_EQ(ReadFloats(*engine_, *s, g->handle), expect);
  std::vector<float> back = ReadFloats(*engine_, *s, c->handle);
  for (int i = 0; i < 10; ++i) EXPECT_EQ(back[9 - i], expect[10 + i]) << i;

  EXPECT_GT(engine_->Stats().gpu_slabs, 0u);
  ASSERT_TRUE(engine_->CloseSession(s->id()).ok());
  EXPECT_EQ(engine_->Stats().gpu_slabs, 0u);
}

TEST_F(CudaDeviceTest, CudaAliasPlacesTheSessionAndCpuModulesAreRefused) {
  auto s = engine_->OpenSession(Local());
  EXPECT_EQ(engine_->CudaPlacement(*s), "");
  CreateArrayParams p = FromFloats({1, 2, 3});
  p.device = "cuda";
  auto a = engine_->CreateArray(*s, p);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  EXPECT_EQ(a->device.rfind("cuda:", 0), 0u);
  EXPECT_EQ(engine_->CudaPlacement(*s), a->device);

  p.device = "cuda:99";
  EXPECT_EQ(engine_->CreateArray(*s, p).status().code(), StatusCode::kInvalidArgument);

  // a module the store built for the CPU cannot launch on a GPU
  auto m = std::make_shared<LoadedModule>();
  m->id = "cpu-module";
  m->target = Target::kCpu;
  LoadedKernel k;
  k.layout.name = "k";
  m->kernels.push_back(k);
  store_->forward["cpu-module"] = m;
  LaunchCommand l;
  l.module_id = "cpu-module";
  l.kernel = "k";
  l.dim = {3};
  l.device = a->device;
  ASSERT_TRUE(engine_->Submit(*s, {Cmd(l)}).ok());
  auto r = engine_->Synchronize(*s);
  EXPECT_EQ(r.error.code(), StatusCode::kInvalidArgument) << r.error.ToString();
  EXPECT_NE(r.error.message().find("compiled for the CPU"), std::string::npos) << r.error.message();
}

}  // namespace
}  // namespace weft::testing
