// CPU launches through the Engine with hand-written kernels served by a fake ModuleStore:
// argument checks (count, kind, dtype, ndim, value size), packing of strided views, parallel
// execution over the pool against a float64 reference, print output, and out-of-bounds reports
// that name kernel, array, index, shape and file:line.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <random>

#include "engine/runtime/thread_pool.h"
#include "runtime_test_support.h"

namespace weft {
namespace {

using namespace weft::testing;

struct SaxpyArgs {
  wp::array_abi_t x;
  wp::array_abi_t y;
  float a;
};

float& At(const wp::array_abi_t& arr, int64_t i) {
  return *reinterpret_cast<float*>(static_cast<char*>(arr.data) + i * arr.strides[0]);
}

// y[i] = a * x[i] + y[i], bounds-checked like generated code.
void SaxpyForward(const wp::launch_context_t* ctx, const void* args, wp::int64 begin, wp::int64 end) {
  auto* p = static_cast<const SaxpyArgs*>(args);
  for (wp::int64 i = begin; i < end; ++i) {
    if (i >= p->x.shape[0] || i >= p->y.shape[0]) {
      int expected = 0;
      if (__atomic_compare_exchange_n(&ctx->error->kind, &expected, wp::LAUNCH_OUT_OF_BOUNDS, false,
                                      __ATOMIC_SEQ_CST, __ATOMIC_SEQ_CST)) {
        ctx->error->line = 7;
        ctx->error->array_param = i >= p->x.shape[0] ? 0 : 1;
        ctx->error->ndim = 1;
        ctx->error->index[0] = i;
        ctx->error->shape[0] = i >= p->x.shape[0] ? p->x.shape[0] : p->y.shape[0];
        ctx->error->function_id = 0;
      }
      return;
    }
    At(p->y, i) = p->a * At(p->x, i) + At(p->y, i);
  }
}

// Prints "hi <i>" for each index.
void PrintForward(const wp::launch_context_t* ctx, const void*, wp::int64 begin, wp::int64 end) {
  for (wp::int64 i = begin; i < end; ++i) {
    char line[32];
    int n = std::snprintf(line, sizeof(line), "hi %lld\n", static_cast<long long>(i));
    wp::uint64 at = __atomic_fetch_add(&ctx->print->used, static_cast<wp::uint64>(n), __ATOMIC_RELAXED);
    if (at + n <= ctx->print->capacity) std::memcpy(ctx->print->data + at, line, n);
  }
}

KernelLayout SaxpyLayout() {
  KernelLayout k;
  k.name = "saxpy";
  k.params = {ArrayParam("x", "float32", 1, 0), ArrayParam("y", "float32", 1, 88), ValueParam("a", "float32", 176, 4)};
  k.args_size = sizeof(SaxpyArgs);
  return k;
}

void Install(FakeModuleStore* store) {
  auto m = std::make_shared<LoadedModule>();
  m->id = "mod1";
  m->function_names = {"prog.py:saxpy"};
  LoadedKernel saxpy{SaxpyLayout(), &SaxpyForward, nullptr};
  KernelLayout pk;
  pk.name = "printer";
  pk.args_size = 8;
  LoadedKernel printer{pk, &PrintForward, nullptr};
  m->kernels = {saxpy, printer};
  store->forward["mod1"] = m;
}

LaunchCommand Saxpy(uint64_t x, uint64_t y, float a, int64_t n) {
  LaunchCommand l;
  l.module_id = "mod1";
  l.kernel = "saxpy";
  l.dim = {n};
  l.args = {ArrayArg(x), ArrayArg(y), RawArg(a)};
  return l;
}

TEST(CpuLaunch, SaxpyMatchesFloat64ReferenceOnFreshData) {
  FakeModuleStore* store;
  auto e = MakeEngine(&store);
  Install(store);
  auto s = e->OpenSession(Local());
  std::mt19937 rng(std::random_device{}());
  for (int64_t n : {1, 7, 1000, 100003}) {
    std::vector<float> x(n), y(n);
    std::uniform_real_distribution<float> d(-100, 100);
    for (auto& v : x) v = d(rng);
    for (auto& v : y) v = d(rng);
    auto xa = e->CreateArray(*s, FromFloats(x));
    auto ya = e->CreateArray(*s, FromFloats(y));
    float a = d(rng);
    ASSERT_TRUE(e->Submit(*s, {Cmd(Saxpy(xa->handle, ya->handle, a, n))}).ok());
    auto r = e->Synchronize(*s);
    ASSERT_TRUE(r.error.ok()) << r.error.ToString();
    auto out = ReadFloats(*e, *s, ya->handle);
    for (int64_t i = 0; i < n; ++i) {
      double ref = static_cast<double>(a) * x[i] + y[i];
      ASSERT_NEAR(out[i], ref, 1e-5 * (1 + std::fabs(ref))) << "n=" << n << " i=" << i;
    }
  }
}

TEST(CpuLaunch, StridedViewsArePackedWithByteStrides) {
  FakeModuleStore* store;
  auto e = MakeEngine(&store);
  Install(store);
  auto s = e->OpenSession(Local());
  auto xa = e->CreateArray(*s, FromFloats({1, 2, 3, 4, 5, 6}));
  auto ya = e->CreateArray(*s, FromFloats({0, 0, 0}));
  LaunchCommand l = Saxpy(xa->handle, ya->handle, 2.0f, 3);
  l.args[0].array = ArrayRef{xa->handle, 4, {3}, {8}};   // x[1::2] = 2, 4, 6
  ASSERT_TRUE(e->Submit(*s, {Cmd(l)}).ok());
  ASSERT_TRUE(e->Synchronize(*s).error.ok());
  EXPECT_EQ(ReadFloats(*e, *s, ya->handle), (std::vector<float>{4, 8, 12}));
}

TEST(CpuLaunch, BadArgumentsGetClearErrorsAndChangeNothing) {
  FakeModuleStore* store;
  auto e = MakeEngine(&store);
  Install(store);
  auto s = e->OpenSession(Local());
  auto xa = e->CreateArray(*s, FromFloats({1, 2}));
  auto ya = e->CreateArray(*s, FromFloats({3, 4}));
  CreateArrayParams ip;
  ip.dtype.scalar = ScalarType::kInt32;
  ip.shape = {2};
  ip.init = CreateArrayParams::Init::kZeros;
  auto ia = e->CreateArray(*s, ip);
  CreateArrayParams mp = FromFloats({1, 2, 3, 4});
  mp.shape = {2, 2};
  auto ma = e->CreateArray(*s, mp);

  struct Case { LaunchCommand l; StatusCode code; std::string text; };
  std::vector<Case> cases;
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.module_id = "nope"; cases.push_back({l, StatusCode::kNotFound, "unknown module"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.kernel = "nope"; cases.push_back({l, StatusCode::kNotFound, "no kernel 'nope'"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.args.pop_back(); cases.push_back({l, StatusCode::kInvalidArgument, "takes 3 arguments, got 2"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.args[2] = ArrayArg(xa->handle); cases.push_back({l, StatusCode::kInvalidArgument, "parameter 'a' (float32): expected a value"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.args[0] = RawArg(1.0f); cases.push_back({l, StatusCode::kInvalidArgument, "parameter 'x' (array(float32,1)): expected an array"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.args[2] = RawArg(1.0); cases.push_back({l, StatusCode::kInvalidArgument, "value has 8 bytes, expected 4"}); }
  { auto l = Saxpy(ia->handle, ya->handle, 1, 2); cases.push_back({l, StatusCode::kInvalidArgument, "has dtype int32, expected float32"}); }
  { auto l = Saxpy(ma->handle, ya->handle, 1, 2); cases.push_back({l, StatusCode::kInvalidArgument, "expected 1"}); }
  { auto l = Saxpy(777, ya->handle, 1, 2); cases.push_back({l, StatusCode::kNotFound, "unknown array handle 777"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.args[0].array = ArrayRef{xa->handle, 0, {3}, {}}; cases.push_back({l, StatusCode::kOutOfRange, "reaches outside"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.dim = {}; cases.push_back({l, StatusCode::kInvalidArgument, "1 to 4 dimensions"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.dim = {-3}; cases.push_back({l, StatusCode::kInvalidArgument, "negative"}); }
  { auto l = Saxpy(xa->handle, ya->handle, 1, 2); l.device = "cuda:0"; cases.push_back({l, StatusCode::kInvalidArgument, "cuda:0"}); }
  for (auto& c : cases) {
    ASSERT_TRUE(e->Submit(*s, {Cmd(c.l)}).ok());
    auto r = e->Synchronize(*s);
    EXPECT_EQ(r.error.code(), c.code) << r.error.ToString();
    EXPECT_NE(r.error.message().find(c.text), std::string::npos) << r.error.message();
  }
  EXPECT_EQ(ReadFloats(*e, *s, ya->handle), (std::vector<float>{3, 4}));
}

TEST(CpuLaunch, OutOfBoundsNamesKernelArrayIndexShapeAndLine) {
  FakeModuleStore* store;
  auto e = MakeEngine(&store);
  Install(store);
  auto s = e->OpenSession(Local());
  auto other = e->OpenSession(Local("bystander"));
  auto xa = e->CreateArray(*s, FromFloats({1, 2, 3}));
  auto ya = e->CreateArray(*s, FromFloats({0, 0, 0, 0, 0}));
  Command c = Cmd(Saxpy(xa->handle, ya->handle, 1, 5));
  c.origin = {"prog.py", 30, 0};
  ASSERT_TRUE(e->Submit(*s, {c}).ok());
  auto r = e->Synchronize(*s);
  EXPECT_EQ(r.error.code(), StatusCode::kOutOfRange);
  EXPECT_NE(r.error.message().find("prog.py:7"), std::string::npos) << r.error.message();
  EXPECT_NE(r.error.message().find("kernel 'saxpy'"), std::string::npos) << r.error.message();
  EXPECT_NE(r.error.message().find("index [3]"), std::string::npos) << r.error.message();
  EXPECT_NE(r.error.message().find("array 'x' of shape (3,)"), std::string::npos) << r.error.message();
  EXPECT_EQ(r.origin.line, 30u);
  // The other session is unaffected and the engine keeps working.
  auto oa = e->CreateArray(*other, FromFloats({1}));
  EXPECT_TRUE(oa.ok());
  EXPECT_TRUE(e->Synchronize(*other).error.ok());
}

TEST(CpuLaunch, PrintOutputComesBackAtSync) {
  FakeModuleStore* store;
  auto e = MakeEngine(&store);
  Install(store);
  auto s = e->OpenSession(Local());
  LaunchCommand l;
  l.module_id = "mod1";
  l.kernel = "printer";
  l.dim = {3};
  ASSERT_TRUE(e->Submit(*s, {Cmd(l)}).ok());
  auto r = e->Synchronize(*s);
  ASSERT_TRUE(r.error.ok());
  for (const char* line : {"hi 0\n", "hi 1\n", "hi 2\n"}) EXPECT_NE(r.output.find(line), std::string::npos);
  EXPECT_TRUE(e->Synchronize(*s).output.empty());
}

TEST(ThreadPool, CoversEveryIndexOnceFromConcurrentCallers) {
  ThreadPool pool(3);
  std::vector<std::thread> callers;
  std::atomic<bool> ok{true};
  for (int t = 0; t < 4; ++t) {
    callers.emplace_back([&, t] {
      for (int64_t n : {0, 1, 1000, 1025, 100000 + t}) {
        std::vector<std::atomic<int>> hits(n);
        pool.ParallelFor(n, [&](int64_t b, int64_t e) {
          for (int64_t i = b; i < e; ++i) hits[i].fetch_add(1);
        });
        for (auto& h : hits)
          if (h.load() != 1) ok = false;
      }
    });
  }
  for (auto& c : callers) c.join();
  EXPECT_TRUE(ok.load());
}

}  // namespace
}  // namespace weft
