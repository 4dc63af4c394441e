// The CUDA device through the engine (skipped with the reason when no GPU computes here):
// arrays on cuda:0 from data, strided fills and copies between cuda:0 and the CPU against a
// host reference on random data, the "cuda" alias placing a session, per-session GPU slabs in
// Stats and their release when the session closes, freed big slabs reused by their own session
// only (never another's, never an exported one's), and a CPU-compiled module refused on a GPU.
// With two GPUs or more: sessions opened with "cuda" spread over the GPUs, and copies between
// GPUs (contiguous and strided, both directions) are bit-exact on random bit patterns, and slab
// ids differ across GPUs.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <map>
#include <random>

#include "engine/device/cuda_device.h"
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

// Big arrays (over the 16 MiB dedicated threshold) get a slab of their own; a freed one stays
// with its session for the session's next big array of a similar size, never for another
// session's, never once its array was exported (another session may have mapped it), and goes
// back to the driver when the session closes. Contents of a reused slab: zeros when asked.
TEST_F(CudaDeviceTest, FreedBigSlabsAreReusedByTheirOwnSessionOnly) {
  auto a = engine_->OpenSession(Local());
  auto b = engine_->OpenSession(Local());
  CreateArrayParams big;
  big.dtype = F32();
  big.shape = {8 << 20};   // 32 MiB
  big.device = "cuda:0";
  big.init = CreateArrayParams::Init::kZeros;
  auto first = engine_->CreateArray(*a, big);
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  const uint64_t slab = first->cuda_slab_id;
  ASSERT_NE(slab, 0u);
  std::vector<float> ones(8 << 20, 1.f);
  ASSERT_TRUE(engine_->WriteArray(*a, first->handle, 0, ones.data(), ones.size() * 4).ok());
  const uint64_t slabs_before = engine_->Stats().gpu_slabs;
  ASSERT_TRUE(engine_->FreeArray(*a, first->handle).ok());
  ASSERT_TRUE(engine_->Synchronize(*a).error.ok());

  // another session's big array: a slab of its own, not a's
  auto other = engine_->CreateArray(*b, big);
  ASSERT_TRUE(other.ok());
  EXPECT_NE(other->cuda_slab_id, slab);
  // a's next big array of a similar size: a's freed slab, zeroed as asked
  CreateArrayParams again = big;
  again.shape = {7 << 20};   // 28 MiB: within the reuse bound
  auto second = engine_->CreateArray(*a, again);
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(second->cuda_slab_id, slab);
  std::vector<float> back = ReadFloats(*engine_, *a, second->handle);
  EXPECT_TRUE(std::all_of(back.begin(), back.end(), [](float x) { return x == 0.f; }));
  EXPECT_EQ(engine_->Stats().gpu_slabs, slabs_before + 1);   // b's slab only

  // an exported array's slab is never reused
  auto token = engine_->ExportArray(*a, second->handle);
  ASSERT_TRUE(token.ok()) << token.status().ToString();
  ASSERT_TRUE(engine_->FreeArray(*a, second->handle).ok());
  ASSERT_TRUE(engine_->Synchronize(*a).error.ok());
  auto third = engine_->CreateArray(*a, again);
  ASSERT_TRUE(third.ok());
  EXPECT_NE(third->cuda_slab_id, slab);

  ASSERT_TRUE(engine_->CloseSession(a->id()).ok());
  ASSERT_TRUE(engine_->CloseSession(b->id()).ok());
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

// Random 32-bit patterns as floats: NaNs with payloads, infinities, subnormals, signed zeros.
std::vector<float> RandomBits(size_t n, std::mt19937& rng) {
  std::vector<float> v(n);
  for (auto& x : v) {
    const uint32_t bits = static_cast<uint32_t>(rng());
    std::memcpy(&x, &bits, 4);
  }
  return v;
}

bool SameBits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * 4) == 0;
}

class CudaMultiGpuTest : public CudaDeviceTest {
 protected:
  void SetUp() override {
    CudaDeviceTest::SetUp();
    if (IsSkipped()) return;
    if (engine_->devices().gpus().size() < 2) GTEST_SKIP() << "fewer than two GPUs the daemon can compute on";
  }
};

TEST_F(CudaMultiGpuTest, CudaAliasSpreadsSessionsOverTheGpus) {
  const size_t gpus = engine_->devices().gpus().size();
  std::vector<std::shared_ptr<Session>> sessions;
  std::map<std::string, int> placed;
  for (size_t i = 0; i < 2 * gpus; ++i) {
    sessions.push_back(engine_->OpenSession(Local()));
    CreateArrayParams p = FromFloats(std::vector<float>(1 << 18, 1.f));
    p.device = "cuda";
    auto a = engine_->CreateArray(*sessions.back(), p);
    ASSERT_TRUE(a.ok()) << a.status().ToString();
    EXPECT_EQ(engine_->CudaPlacement(*sessions.back()), a->device);
    ++placed[a->device];
  }
  EXPECT_EQ(placed.size(), gpus);
  for (const auto& [device, count] : placed) EXPECT_EQ(count, 2) << device;
  for (auto& s : sessions) ASSERT_TRUE(engine_->CloseSession(s->id()).ok());
}

TEST_F(CudaMultiGpuTest, CopiesBetweenGpusAreBitExact) {
  std::mt19937 rng(std::random_device{}());
  auto s = engine_->OpenSession(Local());
  const size_t n = (1u << 20) + 3;
  const std::vector<float> host = RandomBits(n, rng);
  CreateArrayParams p = FromFloats(host);
  p.device = "cuda:0";
  auto a = engine_->CreateArray(*s, p);
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  const std::vector<float> other = RandomBits(n, rng);
  p = FromFloats(other);
  p.device = "cuda:1";
  auto b = engine_->CreateArray(*s, p);
  ASSERT_TRUE(b.ok()) << b.status().ToString();
  // slab ids are unique across the GPUs: a client keys its IPC mappings by them
  EXPECT_NE(a->cuda_slab_id, b->cuda_slab_id);

  auto run = [&](ArrayRef dst, ArrayRef src) {
    CopyCommand cp;
    cp.dst = std::move(dst);
    cp.src = std::move(src);
    Command c;
    c.kind = cp;
    auto submitted = engine_->Submit(*s, {c});
    ASSERT_TRUE(submitted.ok()) << submitted.status().ToString();
    auto r = engine_->Synchronize(*s);
    ASSERT_TRUE(r.error.ok()) << r.error.ToString();
  };
  const int64_t k = 1000;
  // every third element of cuda:0 [0, 3k) -> cuda:1 [k, 2k) reversed: both sides strided
  run(ArrayRef{b->handle, static_cast<uint64_t>((2 * k - 1) * 4), {k}, {-4}}, ArrayRef{a->handle, 0, {k}, {12}});
  std::vector<float> expect_b = other;
  for (int64_t i = 0; i < k; ++i) expect_b[2 * k - 1 - i] = host[3 * i];
  EXPECT_TRUE(SameBits(ReadFloats(*engine_, *s, b->handle), expect_b));

  // contiguous cuda:1 -> cuda:0, the whole array
  run(ArrayRef{a->handle, 0, {static_cast<int64_t>(n)}, {}}, ArrayRef{b->handle, 0, {static_cast<int64_t>(n)}, {}});
  EXPECT_TRUE(SameBits(ReadFloats(*engine_, *s, a->handle), expect_b));

  // a strided source only: every other element of cuda:0 -> the start of cuda:1
  run(ArrayRef{b->handle, 0, {k}, {}}, ArrayRef{a->handle, 4, {k}, {8}});
  std::vector<float> expect_b2 = expect_b;
  for (int64_t i = 0; i < k; ++i) expect_b2[i] = expect_b[1 + 2 * i];
  EXPECT_TRUE(SameBits(ReadFloats(*engine_, *s, b->handle), expect_b2));
  ASSERT_TRUE(engine_->CloseSession(s->id()).ok());
}

#if WEFT_WITH_CUDA
// The built-in kernels (copies, fills, BVH refit, hash grid build) compile for the oldest and
// the newest architecture weft targets, with or without a GPU here.
TEST(CudaBuiltinKernels, CompileForSm75AndSm90) {
  for (int sm : {75, 90}) {
    jit::NvrtcOptions o;
    o.sm = sm;
    o.include_dirs = {WEFT_NATIVE_DIR};
    auto r = jit::NvrtcCompile(CudaBuiltinSource(), "weft_builtin_copy_fill.cu", o);
    ASSERT_TRUE(r.ok()) << "sm_" << sm << ": " << r.status().ToString();
    EXPECT_FALSE(r->image.empty());
  }
}
#endif

}  // namespace
}  // namespace weft::testing
