// Cancellation and command limits in the engine, with hand-written kernels served by a fake
// ModuleStore: a kernel spinning on the launch's cancel word (as generated loops poll it)
// stops when its session closes and when the launch time limit passes; a launch with many
// threads stops between chunks; launches, views and queues over their limits are refused at
// submit with the limit named; unknown tape ops are refused; sessions without work cost no
// thread; the watchdog on its own.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <string>
#include <thread>

#include "engine/runtime/launch_watchdog.h"
#include "engine/runtime/serial_queue.h"
#include "runtime_test_support.h"

namespace weft {
namespace {

using namespace weft::testing;
using Clock = std::chrono::steady_clock;

struct OneArray {
  wp::array_abi_t a;
};

// Spins until the launch is cancelled, as a generated `while True:` loop does (it polls the
// same word through wp::cg_loop_poll). Writes a[0] so the loop has an effect.
void SpinForward(const wp::launch_context_t* ctx, const void* args, wp::int64, wp::int64) {
  auto* p = static_cast<const OneArray*>(args);
  int32_t i = 0;
  while (!(ctx->cancel && __atomic_load_n(ctx->cancel, __ATOMIC_RELAXED) != 0)) {
    i = (i + 1) % 1000003;
    __atomic_store_n(static_cast<int32_t*>(p->a.data), i, __ATOMIC_RELAXED);
  }
}

// Counts the threads it runs (a[0] += end - begin), slowly: ~1 us per thread.
void CountForward(const wp::launch_context_t*, const void* args, wp::int64 begin, wp::int64 end) {
  auto* p = static_cast<const OneArray*>(args);
  auto until = Clock::now() + std::chrono::microseconds(end - begin);
  while (Clock::now() < until) {
  }
  __atomic_fetch_add(static_cast<int64_t*>(p->a.data), static_cast<int64_t>(end - begin), __ATOMIC_RELAXED);
}

void Install(FakeModuleStore* store) {
  auto m = std::make_shared<LoadedModule>();
  m->id = "mod";
  m->function_names = {"prog.py:spin"};
  KernelLayout spin;
  spin.name = "spin";
  spin.params = {ArrayParam("a", "int32", 1, 0)};
  spin.args_size = sizeof(OneArray);
  KernelLayout count = spin;
  count.name = "count";
  count.params = {ArrayParam("a", "int64", 1, 0)};
  m->kernels = {LoadedKernel{spin, &SpinForward, nullptr}, LoadedKernel{count, &CountForward, nullptr}};
  store->forward["mod"] = m;
}

std::unique_ptr<Engine> MakeLimitedEngine(FakeModuleStore** store, double time_limit_s, CommandLimits limits = {}) {
  auto fake = std::make_unique<FakeModuleStore>();
  *store = fake.get();
  EngineOptions o;
  o.cpu_threads = 2;
  o.remove_stale_slabs = false;
  o.launch_time_limit_s = time_limit_s;
  o.limits = limits;
  auto e = Engine::Create(o, std::move(fake));
  EXPECT_TRUE(e.ok()) << e.status().ToString();
  Install(*store);
  return std::move(e).value();
}

uint64_t IntArray(Engine& e, Session& s, ScalarType t, int64_t n = 4) {
  CreateArrayParams p;
  p.dtype.scalar = t;
  p.shape = {n};
  p.init = CreateArrayParams::Init::kZeros;
  auto a = e.CreateArray(s, p);
  EXPECT_TRUE(a.ok()) << a.status().ToString();
  return a->handle;
}

Command Launch(const std::string& kernel, uint64_t handle, std::vector<int64_t> dim) {
  LaunchCommand l;
  l.module_id = "mod";
  l.kernel = kernel;
  l.dim = std::move(dim);
  l.args = {ArrayArg(handle)};
  return Cmd(l);
}

double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

int ThreadCount() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("Threads:", 0) == 0) return std::stoi(line.substr(8));
  return -1;
}

TEST(RuntimeCancel, SpinningKernelStopsWhenItsSessionCloses) {
  FakeModuleStore* store;
  auto e = MakeLimitedEngine(&store, 0);
  auto s = e->OpenSession(Local("spinner"));
  auto other = e->OpenSession(Local("bystander"));
  uint64_t a = IntArray(*e, *s, ScalarType::kInt32);
  auto mine = e->CreateArray(*other, FromFloats({1, 2, 3}));
  ASSERT_TRUE(e->Submit(*s, {Launch("spin", a, {2}), Launch("spin", a, {2})}).ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  auto start = Clock::now();
  ASSERT_TRUE(e->CloseSession(s->id()).ok());
  EXPECT_LT(Seconds(start), 2.0);   // the running launch stopped, the queued one never ran
  EXPECT_TRUE(s->cancelled());
  EXPECT_EQ(ReadFloats(*e, *other, mine->handle), (std::vector<float>{1, 2, 3}));
}

TEST(RuntimeCancel, LaunchTimeLimitStopsAKernelAndTheSessionGoesOn) {
  FakeModuleStore* store;
  auto e = MakeLimitedEngine(&store, 0.2);
  auto s = e->OpenSession(Local());
  uint64_t a = IntArray(*e, *s, ScalarType::kInt32);
  uint64_t n = IntArray(*e, *s, ScalarType::kInt64, 1);
  auto start = Clock::now();
  auto r = e->SubmitAndSynchronize(*s, {Launch("spin", a, {1})});
  ASSERT_TRUE(r.ok());
  EXPECT_LT(Seconds(start), 3.0);
  EXPECT_EQ(r->error.code(), StatusCode::kDeadlineExceeded) << r->error.ToString();
  EXPECT_NE(r->error.message().find("launch time limit of 0.2 s"), std::string::npos) << r->error.message();
  EXPECT_NE(r->error.message().find("kernel 'spin'"), std::string::npos);
  auto again = e->SubmitAndSynchronize(*s, {Launch("count", n, {100})});
  ASSERT_TRUE(again.ok());
  EXPECT_TRUE(again->error.ok()) << again->error.ToString();
}

TEST(RuntimeCancel, ManyThreadLaunchStopsBetweenChunks) {
  FakeModuleStore* store;
  auto e = MakeLimitedEngine(&store, 0);
  auto s = e->OpenSession(Local());
  uint64_t n = IntArray(*e, *s, ScalarType::kInt64, 1);
  // 2^26 threads at ~1 us each: over a minute of work on 2 threads
  ASSERT_TRUE(e->Submit(*s, {Launch("count", n, {int64_t{1} << 26})}).ok());
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  auto start = Clock::now();
  ASSERT_TRUE(e->CloseSession(s->id()).ok());
  EXPECT_LT(Seconds(start), 2.0);
}

TEST(RuntimeCancel, LaunchesAndViewsOverTheLimitAreRefusedAtSubmit) {
  FakeModuleStore* store;
  CommandLimits limits;
  limits.max_launch_threads = 1 << 20;
  limits.max_queued_commands = 3;
  auto e = MakeLimitedEngine(&store, 0, limits);
  auto s = e->OpenSession(Local());
  uint64_t n = IntArray(*e, *s, ScalarType::kInt64, 1);
  for (std::vector<int64_t> dim : {std::vector<int64_t>{int64_t{1} << 40}, {1 << 11, 1 << 10}, {1 << 20, 1 << 20, 1 << 20, 1 << 20}}) {
    auto r = e->Submit(*s, {Launch("count", n, dim)});
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kResourceExhausted);
    EXPECT_NE(r.status().message().find("--max-launch-threads"), std::string::npos) << r.status().message();
  }
  Command fill;
  FillCommand f;
  f.dst = ArrayRef{n, 0, {int64_t{1} << 40}, {0}};
  f.value = std::string(8, '\0');
  fill.kind = f;
  auto r = e->Submit(*s, {fill});
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("fill dst view"), std::string::npos) << r.status().message();
  auto q = e->Submit(*s, {Launch("count", n, {1}), Launch("count", n, {1}), Launch("count", n, {1}),
                          Launch("count", n, {1})});
  ASSERT_FALSE(q.ok());
  EXPECT_NE(q.status().message().find("--max-queued-commands"), std::string::npos) << q.status().message();
  auto ok = e->SubmitAndSynchronize(*s, {Launch("count", n, {1000})});
  ASSERT_TRUE(ok.ok());
  EXPECT_TRUE(ok->error.ok()) << ok->error.ToString();
  EXPECT_EQ(s->queued_commands.load(), 0u);
}

TEST(RuntimeCancel, UnknownTapeOpIsRefused) {
  FakeModuleStore* store;
  auto e = MakeLimitedEngine(&store, 0);
  auto s = e->OpenSession(Local());
  TapeCommand t;
  t.op = static_cast<TapeCommand::Op>(42);
  t.tape_id = 7;
  auto r = e->Submit(*s, {Cmd(t)});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find("unknown tape op 42"), std::string::npos);
}

TEST(RuntimeCancel, SessionsWithoutWorkCostNoThread) {
  FakeModuleStore* store;
  auto e = MakeLimitedEngine(&store, 0);
  const int before = ThreadCount();
  std::vector<std::shared_ptr<Session>> idle;
  for (int i = 0; i < 200; ++i) idle.push_back(e->OpenSession(Local("idle")));
  EXPECT_LT(ThreadCount() - before, 5);
  for (auto& s : idle) ASSERT_TRUE(e->CloseSession(s->id()).ok());
}

TEST(RuntimeCancel, UnattachedSessionsAreReapedAfterTheTimeout) {
  FakeModuleStore* store;
  auto e = MakeLimitedEngine(&store, 0);
  auto idle = e->OpenSession(Local("idle"));
  auto attached = e->OpenSession(Local("attached"));
  ASSERT_TRUE(attached->ClaimAttach());
  EXPECT_FALSE(attached->ClaimAttach());   // attached once
  EXPECT_EQ(e->ReapUnattachedSessions(std::chrono::seconds(60)), 0u);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(e->ReapUnattachedSessions(std::chrono::milliseconds(10)), 1u);
  EXPECT_EQ(e->FindSession(idle->id()), nullptr);
  EXPECT_NE(e->FindSession(attached->id()), nullptr);
  EXPECT_EQ(e->Stats().sessions_reaped_total, 1u);
}

TEST(RuntimeCancel, SessionsPerPrincipalAreLimited) {
  auto fake = std::make_unique<FakeModuleStore>();
  EngineOptions o;
  o.cpu_threads = 1;
  o.remove_stale_slabs = false;
  o.max_sessions_per_principal = 2;
  auto e = std::move(Engine::Create(o, std::move(fake))).value();
  ASSERT_TRUE(e->OpenClientSession(Local()).ok());
  ASSERT_TRUE(e->OpenClientSession(Local()).ok());
  auto third = e->OpenClientSession(Local());
  ASSERT_FALSE(third.ok());
  EXPECT_EQ(third.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(third.status().message().find("--max-sessions-per-principal"), std::string::npos);
  SessionOptions other = Local();
  other.principal = "unix-uid:1000";
  EXPECT_TRUE(e->OpenClientSession(other).ok());   // another principal has its own count
}

TEST(RuntimeCancel, SessionIdsAre256RandomBits) {
  FakeModuleStore* store;
  auto e = MakeLimitedEngine(&store, 0);
  auto a = e->OpenSession(Local());
  auto b = e->OpenSession(Local());
  EXPECT_EQ(a->id().size(), 2u + 64u);
  EXPECT_NE(a->id(), b->id());
  EXPECT_EQ(a->id().find_first_not_of("0123456789abcdef", 2), std::string::npos);
  EXPECT_EQ(a->label().rfind("#", 0), 0u);   // logs name sessions by label, never by id
}

TEST(LaunchWatchdog, SetsTheWordOnSessionCancelAndOnTheDeadline) {
  LaunchWatchdog dog;
  std::atomic<bool> session{false};
  LaunchWatchdog::Watch by_session(dog, &session, 0);
  LaunchWatchdog::Watch by_time(dog, nullptr, 0.05);
  LaunchWatchdog::Watch never(dog, nullptr, 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(30));
  EXPECT_EQ(*by_session.word(), 0);
  session = true;
  auto start = Clock::now();
  while ((__atomic_load_n(by_session.word(), __ATOMIC_RELAXED) == 0 ||
          __atomic_load_n(by_time.word(), __ATOMIC_RELAXED) == 0) && Seconds(start) < 2.0)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(by_session.reason(), LaunchWatchdog::Reason::kSessionCancelled);
  EXPECT_EQ(by_time.reason(), LaunchWatchdog::Reason::kTimeLimit);
  EXPECT_EQ(never.reason(), LaunchWatchdog::Reason::kNone);
  EXPECT_EQ(*never.word(), 0);
}

}  // namespace
}  // namespace weft
