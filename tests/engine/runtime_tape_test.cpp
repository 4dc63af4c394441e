// Per-session tapes with hand-written forward/backward kernels: backward(loss) seeds 1 and
// replays adjoints in reverse (chain of two launches checked against the analytic gradient),
// backward(grads=...) seeds, zero/reset, explicit adjoint launches, lazy backward loading,
// freed arrays and empty tapes as clear errors, isolation between sessions, and gradients
// replaced by SetGradCommand.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "engine/runtime/command_executor.h"
#include "runtime_test_support.h"

namespace weft {
namespace {

using namespace weft::testing;

struct TwoArrays {
  wp::array_abi_t in;
  wp::array_abi_t out;
};

float& El(const wp::array_abi_t& a, int64_t i) {
  return *reinterpret_cast<float*>(static_cast<char*>(a.data) + i * a.strides[0]);
}

// out[i] = in[i] * in[i]
void SquareFwd(const wp::launch_context_t*, const void* args, wp::int64 b, wp::int64 e) {
  auto* p = static_cast<const TwoArrays*>(args);
  for (auto i = b; i < e; ++i) El(p->out, i) = El(p->in, i) * El(p->in, i);
}
void SquareBwd(const wp::launch_context_t*, const void* args, const void* adj, wp::int64 b, wp::int64 e) {
  auto* p = static_cast<const TwoArrays*>(args);
  auto* g = static_cast<const TwoArrays*>(adj);
  for (auto i = b; i < e; ++i)
    if (g->in.data && g->out.data) El(g->in, i) += 2.0f * El(p->in, i) * El(g->out, i);
}
// out[0] += sum(in)   (atomic)
void SumFwd(const wp::launch_context_t*, const void* args, wp::int64 b, wp::int64 e) {
  auto* p = static_cast<const TwoArrays*>(args);
  float s = 0;
  for (auto i = b; i < e; ++i) s += El(p->in, i);
  float* o = &El(p->out, 0);
  float cur;
  __atomic_load(o, &cur, __ATOMIC_RELAXED);
  float next = cur + s;
  while (!__atomic_compare_exchange(o, &cur, &next, false, __ATOMIC_RELAXED, __ATOMIC_RELAXED)) next = cur + s;
}
void SumBwd(const wp::launch_context_t*, const void*, const void* adj, wp::int64 b, wp::int64 e) {
  auto* g = static_cast<const TwoArrays*>(adj);
  for (auto i = b; i < e; ++i)
    if (g->in.data && g->out.data) El(g->in, i) += El(g->out, 0);
}

KernelLayout Layout(const std::string& name) {
  KernelLayout k;
  k.name = name;
  k.params = {ArrayParam("in", "float32", 1, 0), ArrayParam("out", "float32", 1, 88)};
  k.args_size = sizeof(TwoArrays);
  return k;
}

void Install(FakeModuleStore* store) {
  auto fwd = std::make_shared<LoadedModule>();
  fwd->id = "m";
  fwd->kernels = {LoadedKernel{Layout("square"), &SquareFwd, nullptr}, LoadedKernel{Layout("sum"), &SumFwd, nullptr}};
  auto bwd = std::make_shared<LoadedModule>(*fwd);
  bwd->kernels[0].cpu_backward = &SquareBwd;
  bwd->kernels[1].cpu_backward = &SumBwd;
  bwd->has_backward = true;
  store->forward["m"] = fwd;
  store->backward["m"] = bwd;
}

LaunchCommand L(const std::string& kernel, uint64_t in, uint64_t out, int64_t n) {
  LaunchCommand l;
  l.module_id = "m";
  l.kernel = kernel;
  l.dim = {n};
  l.args = {ArrayArg(in), ArrayArg(out)};
  return l;
}

TapeCommand T(TapeCommand::Op op, uint64_t id, uint64_t loss = 0) {
  TapeCommand t;
  t.op = op;
  t.tape_id = id;
  t.loss.handle = loss;
  return t;
}

struct TapeRig {
  FakeModuleStore* store = nullptr;
  std::unique_ptr<Engine> e = MakeEngine(&store);
  std::shared_ptr<Session> s = e->OpenSession(Local());
  TapeRig() { Install(store); }
  Status Run(std::vector<Command> cmds) {
    EXPECT_TRUE(e->Submit(*s, std::move(cmds)).ok());
    return e->Synchronize(*s).error;
  }
};

TEST(Tape, BackwardOfLossMatchesAnalyticGradient) {
  TapeRig t;
  std::mt19937 rng(std::random_device{}());
  const int64_t n = 5000;
  std::vector<float> x(n);
  for (auto& v : x) v = std::uniform_real_distribution<float>(-2, 2)(rng);
  auto xa = t.e->CreateArray(*t.s, FromFloats(x, true));
  auto sq = t.e->CreateArray(*t.s, FromFloats(std::vector<float>(n, 0), true));
  auto loss = t.e->CreateArray(*t.s, FromFloats({0}, true));
  EXPECT_EQ(t.store->backward_requests, 0);   // forward-only so far: no backward compiled
  Status st = t.Run({Cmd(T(TapeCommand::Op::kBegin, 1)), Cmd(L("square", xa->handle, sq->handle, n)),
                     Cmd(L("sum", sq->handle, loss->handle, n)), Cmd(T(TapeCommand::Op::kEnd, 1)),
                     Cmd(T(TapeCommand::Op::kBackward, 1, loss->handle))});
  ASSERT_TRUE(st.ok()) << st.ToString();
  EXPECT_GT(t.store->backward_requests, 0);
  auto g = ReadFloats(*t.e, *t.s, xa->grad_handle);
  for (int64_t i = 0; i < n; ++i) ASSERT_NEAR(g[i], 2.0 * x[i], 1e-5) << i;
  EXPECT_EQ(ReadFloats(*t.e, *t.s, loss->grad_handle), (std::vector<float>{1}));
  // A second backward without zero accumulates into every gradient, intermediates included
  // (Warp semantics): sq.grad becomes 2, so x.grad = 2x + 2*2x = 6x. Zero clears them all.
  ASSERT_TRUE(t.Run({Cmd(T(TapeCommand::Op::kBackward, 1, loss->handle))}).ok());
  g = ReadFloats(*t.e, *t.s, xa->grad_handle);
  EXPECT_NEAR(g[0], 6.0 * x[0], 1e-4);
  ASSERT_TRUE(t.Run({Cmd(T(TapeCommand::Op::kZero, 1))}).ok());
  for (uint64_t h : {xa->grad_handle, sq->grad_handle, loss->grad_handle})
    for (float v : ReadFloats(*t.e, *t.s, h)) ASSERT_EQ(v, 0.0f);
  // Reset forgets the records: backward is now an error.
  ASSERT_TRUE(t.Run({Cmd(T(TapeCommand::Op::kReset, 1))}).ok());
  Status empty = t.Run({Cmd(T(TapeCommand::Op::kBackward, 1, loss->handle))});
  EXPECT_EQ(empty.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(empty.message().find("recorded no launches"), std::string::npos) << empty.message();
}

TEST(Tape, BackwardWithSeedGradients) {
  TapeRig t;
  auto xa = t.e->CreateArray(*t.s, FromFloats({1, 2, 3}, true));
  auto ya = t.e->CreateArray(*t.s, FromFloats({0, 0, 0}, true));
  auto seed = t.e->CreateArray(*t.s, FromFloats({1, 10, 100}));
  TapeCommand bw = T(TapeCommand::Op::kBackward, 7);
  bw.seeds.emplace_back(ArrayRef{ya->handle, 0, {}, {}}, ArrayRef{seed->handle, 0, {}, {}});
  ASSERT_TRUE(t.Run({Cmd(T(TapeCommand::Op::kBegin, 7)), Cmd(L("square", xa->handle, ya->handle, 3)),
                     Cmd(T(TapeCommand::Op::kEnd, 7)), Cmd(bw)}).ok());
  EXPECT_EQ(ReadFloats(*t.e, *t.s, xa->grad_handle), (std::vector<float>{2, 40, 600}));
}

Command SetGradCmd(SetGradCommand g) {
  Command c;
  c.kind = std::move(g);
  return c;
}

Command SetGrad(uint64_t array, uint64_t grad) {
  SetGradCommand c;
  c.array.handle = array;
  c.grad.handle = grad;
  return SetGradCmd(c);
}

TEST(Tape, SetGradRedirectsBackwardAndKeepsReplacedGradientsHeld) {
  TapeRig t;
  auto xa = t.e->CreateArray(*t.s, FromFloats({1, 2, 3}, true));
  auto ya = t.e->CreateArray(*t.s, FromFloats({0, 0, 0}, true));
  auto g = t.e->CreateArray(*t.s, FromFloats({0, 0, 0}));
  auto seed = t.e->CreateArray(*t.s, FromFloats({1, 10, 100}));
  const uint64_t created = xa->grad_handle;
  TapeCommand bw = T(TapeCommand::Op::kBackward, 3);
  bw.seeds.emplace_back(ArrayRef{ya->handle, 0, {}, {}}, ArrayRef{seed->handle, 0, {}, {}});
  ASSERT_TRUE(t.Run({SetGrad(xa->handle, g->handle), Cmd(T(TapeCommand::Op::kBegin, 3)),
                     Cmd(L("square", xa->handle, ya->handle, 3)), Cmd(T(TapeCommand::Op::kEnd, 3)), Cmd(bw)})
                  .ok());
  EXPECT_EQ(ReadFloats(*t.e, *t.s, g->handle), (std::vector<float>{2, 40, 600}));
  EXPECT_EQ(ReadFloats(*t.e, *t.s, created), (std::vector<float>{0, 0, 0}));   // still held, untouched
  EXPECT_EQ(t.e->DescribeArray(*t.s, xa->handle)->grad_handle, g->handle);
  // No gradient: a later backward leaves x alone.
  ASSERT_TRUE(t.Run({SetGrad(xa->handle, 0), Cmd(bw)}).ok());
  EXPECT_EQ(t.e->DescribeArray(*t.s, xa->handle)->grad_handle, 0u);
  EXPECT_EQ(ReadFloats(*t.e, *t.s, g->handle), (std::vector<float>{2, 40, 600}));
  // Freeing the array releases the gradient the daemon made for it, not the assigned one.
  ASSERT_TRUE(t.e->FreeArray(*t.s, xa->handle).ok());
  EXPECT_FALSE(t.s->Holds(created));
  EXPECT_TRUE(t.s->Holds(g->handle));
}

TEST(Tape, SetGradRejectsViewsSelfCyclesAndMismatches) {
  TapeRig t;
  auto xa = t.e->CreateArray(*t.s, FromFloats({1, 2, 3, 4}, true));
  auto short_a = t.e->CreateArray(*t.s, FromFloats({0, 0}));
  auto with_grad = t.e->CreateArray(*t.s, FromFloats({0, 0, 0, 0}, true));
  SetGradCommand view;
  view.array.handle = xa->handle;
  view.array.byte_offset = 4;
  view.array.shape = {3};
  view.grad.handle = short_a->handle;
  // with_grad's gradient chain now reaches xa: making it xa's gradient would be a cycle.
  ASSERT_TRUE(t.Run({SetGrad(with_grad->handle, xa->handle)}).ok());
  const std::vector<Command> bad = {SetGradCmd(view), SetGrad(xa->handle, xa->handle),
                                    SetGrad(xa->handle, short_a->handle), SetGrad(xa->handle, with_grad->handle)};
  for (const Command& c : bad) {
    Status st = t.Run({c});
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << st.ToString();
    EXPECT_EQ(t.e->DescribeArray(*t.s, xa->handle)->grad_handle, xa->grad_handle);
  }
  Status cycle = t.Run({SetGrad(xa->handle, with_grad->handle)});
  EXPECT_NE(cycle.message().find("gradient cycle"), std::string::npos) << cycle.ToString();
  Status unknown = t.Run({SetGrad(xa->handle, 999999)});
  EXPECT_EQ(unknown.code(), StatusCode::kNotFound) << unknown.ToString();
  // A gradient with a gradient of its own is accepted (Warp's y.grad = wp.ones_like(y)).
  auto other = t.e->CreateArray(*t.s, FromFloats({0, 0, 0, 0}, true));
  ASSERT_TRUE(t.Run({SetGrad(xa->handle, other->handle)}).ok());
  EXPECT_EQ(t.e->DescribeArray(*t.s, xa->handle)->grad_handle, other->handle);
}

TEST(Tape, ExplicitAdjointLaunchWithoutTape) {
  TapeRig t;
  auto xa = t.e->CreateArray(*t.s, FromFloats({1, -2}));
  auto ya = t.e->CreateArray(*t.s, FromFloats({0, 0}));
  auto gx = t.e->CreateArray(*t.s, FromFloats({0.5f, 0.5f}));
  auto gy = t.e->CreateArray(*t.s, FromFloats({1, 3}));
  LaunchCommand l = L("square", xa->handle, ya->handle, 2);
  l.adjoint = true;
  l.adj_args = {ArrayArg(gx->handle), ArrayArg(gy->handle)};
  ASSERT_TRUE(t.Run({Cmd(l)}).ok());
  EXPECT_EQ(ReadFloats(*t.e, *t.s, gx->handle), (std::vector<float>{2.5f, -11.5f}));   // accumulates
  EXPECT_EQ(ReadFloats(*t.e, *t.s, ya->handle), (std::vector<float>{0, 0}));          // no forward write
}

TEST(Tape, FreedArraysAndMissingGradientsAreClearErrors) {
  TapeRig t;
  auto xa = t.e->CreateArray(*t.s, FromFloats({1, 2}, true));
  auto ya = t.e->CreateArray(*t.s, FromFloats({0, 0}, true));
  auto nograd = t.e->CreateArray(*t.s, FromFloats({0}));
  ASSERT_TRUE(t.Run({Cmd(T(TapeCommand::Op::kBegin, 1)), Cmd(L("square", xa->handle, ya->handle, 2)),
                     Cmd(T(TapeCommand::Op::kEnd, 1))}).ok());
  Status no = t.Run({Cmd(T(TapeCommand::Op::kBackward, 1, nograd->handle))});
  EXPECT_EQ(no.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(no.message().find("requires_grad"), std::string::npos) << no.message();
  ASSERT_TRUE(t.e->FreeArray(*t.s, xa->handle).ok());
  TapeCommand bw = T(TapeCommand::Op::kBackward, 1);
  Status freed = t.Run({Cmd(bw)});
  EXPECT_EQ(freed.code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(freed.message().find("'in'"), std::string::npos) << freed.message();
  EXPECT_NE(freed.message().find("freed"), std::string::npos) << freed.message();
  // Nothing was run: y's gradient is untouched.
  EXPECT_EQ(ReadFloats(*t.e, *t.s, ya->grad_handle), (std::vector<float>{0, 0}));
  // Backward while still recording is refused.
  Status rec = t.Run({Cmd(T(TapeCommand::Op::kBegin, 2)), Cmd(L("square", ya->handle, ya->handle, 2)),
                      Cmd(T(TapeCommand::Op::kBackward, 2))});
  EXPECT_EQ(rec.code(), StatusCode::kFailedPrecondition);
}

TEST(Tape, SessionsNeverSeeEachOthersTapes) {
  TapeRig t;
  auto other = t.e->OpenSession(Local("other"));
  auto xa = t.e->CreateArray(*t.s, FromFloats({1, 2}, true));
  auto ya = t.e->CreateArray(*t.s, FromFloats({0, 0}, true));
  ASSERT_TRUE(t.Run({Cmd(T(TapeCommand::Op::kBegin, 1)), Cmd(L("square", xa->handle, ya->handle, 2)),
                     Cmd(T(TapeCommand::Op::kEnd, 1))}).ok());
  ASSERT_TRUE(t.e->Submit(*other, {Cmd(T(TapeCommand::Op::kBackward, 1))}).ok());
  Status st = t.e->Synchronize(*other).error;
  EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition);
  // The recording session's tape is intact.
  TapeCommand bw = T(TapeCommand::Op::kBackward, 1);
  auto seed = t.e->CreateArray(*t.s, FromFloats({1, 1}));
  bw.seeds.emplace_back(ArrayRef{ya->handle, 0, {}, {}}, ArrayRef{seed->handle, 0, {}, {}});
  ASSERT_TRUE(t.Run({Cmd(bw)}).ok());
  EXPECT_EQ(ReadFloats(*t.e, *t.s, xa->grad_handle), (std::vector<float>{2, 4}));
}

// A record-only launch (a launch captured into a graph while a tape records) is checked like
// a forward launch and recorded, but does not run; backward replays its adjoint. Without a
// tape it runs nothing; with adjoint, or with arguments a forward launch would refuse, it fails.
TEST(Tape, RecordOnlyLaunchesAreRecordedNotRun) {
  TapeRig t;
  std::mt19937 rng(std::random_device{}());
  std::vector<float> x(64);
  for (auto& v : x) v = std::uniform_real_distribution<float>(-3, 3)(rng);
  auto xa = t.e->CreateArray(*t.s, FromFloats(x, true));
  auto sq = t.e->CreateArray(*t.s, FromFloats(std::vector<float>(64, 0), true));
  LaunchCommand rec = L("square", xa->handle, sq->handle, 64);
  rec.record_only = true;
  ASSERT_TRUE(t.Run({Cmd(rec)}).ok());   // no tape: validated, nothing recorded or run
  Status st = t.Run({Cmd(T(TapeCommand::Op::kBegin, 3)), Cmd(rec), Cmd(T(TapeCommand::Op::kEnd, 3))});
  ASSERT_TRUE(st.ok()) << st.ToString();
  EXPECT_EQ(ReadFloats(*t.e, *t.s, sq->handle), std::vector<float>(64, 0));   // not run
  TapeCommand back = T(TapeCommand::Op::kBackward, 3);
  auto ones = t.e->CreateArray(*t.s, FromFloats(std::vector<float>(64, 1), false));
  back.seeds.emplace_back(ArrayRef{sq->handle, 0, {}, {}}, ArrayRef{ones->handle, 0, {}, {}});
  st = t.Run({Cmd(back)});
  ASSERT_TRUE(st.ok()) << st.ToString();
  auto g = ReadFloats(*t.e, *t.s, xa->grad_handle);
  for (int i = 0; i < 64; ++i) ASSERT_NEAR(g[i], 2.0 * x[i], 1e-5) << i;

  LaunchCommand adjoint = rec;
  adjoint.adjoint = true;
  st = t.Run({Cmd(adjoint)});
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("record_only"), std::string::npos) << st.ToString();
  // Launches run from a graph, record-only ones included, are not recorded on tapes.
  Command in_graph;
  GraphCommand create;
  create.op = GraphCommand::Op::kCreate;
  create.graph_id = 1;
  create.device = "cpu";
  create.commands = {Cmd(rec), Cmd(L("square", xa->handle, sq->handle, 64))};
  in_graph.kind = create;
  Command launch_graph;
  GraphCommand run;
  run.op = GraphCommand::Op::kLaunch;
  run.graph_id = 1;
  launch_graph.kind = run;
  st = t.Run({in_graph, Cmd(T(TapeCommand::Op::kBegin, 6)), launch_graph, Cmd(T(TapeCommand::Op::kEnd, 6)),
              Cmd(T(TapeCommand::Op::kBackward, 6))});
  EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition) << st.ToString();   // tape 6 recorded nothing

  LaunchCommand stray = rec;
  stray.args[0] = ArrayArg(987654321);
  st = t.Run({Cmd(T(TapeCommand::Op::kBegin, 4)), Cmd(stray), Cmd(T(TapeCommand::Op::kEnd, 4))});
  ASSERT_FALSE(st.ok());
}

// MARK splits the backward pass where a client callback runs (wp.Tape.record_func): BACKWARD
// stops at the newest marker; BACKWARD from that marker runs the older records; an unknown
// marker is a clear error.
TEST(Tape, MarkersSplitTheBackwardPass) {
  TapeRig t;
  std::mt19937 rng(std::random_device{}());
  const int64_t n = 32;
  std::vector<float> x(n);
  for (auto& v : x) v = std::uniform_real_distribution<float>(-2, 2)(rng);
  auto xa = t.e->CreateArray(*t.s, FromFloats(x, true));
  auto sq = t.e->CreateArray(*t.s, FromFloats(std::vector<float>(n, 0), true));
  auto loss = t.e->CreateArray(*t.s, FromFloats({0}, true));
  TapeCommand mark = T(TapeCommand::Op::kMark, 5);
  mark.marker = 77;
  Status st = t.Run({Cmd(T(TapeCommand::Op::kBegin, 5)), Cmd(L("square", xa->handle, sq->handle, n)), Cmd(mark),
                     Cmd(L("sum", sq->handle, loss->handle, n)), Cmd(T(TapeCommand::Op::kEnd, 5)),
                     Cmd(T(TapeCommand::Op::kBackward, 5, loss->handle))});
  ASSERT_TRUE(st.ok()) << st.ToString();
  EXPECT_EQ(ReadFloats(*t.e, *t.s, sq->grad_handle), std::vector<float>(n, 1));   // sum's adjoint ran
  EXPECT_EQ(ReadFloats(*t.e, *t.s, xa->grad_handle), std::vector<float>(n, 0));   // square's did not
  TapeCommand rest = T(TapeCommand::Op::kBackward, 5);
  rest.marker = 77;
  ASSERT_TRUE(t.Run({Cmd(rest)}).ok());
  auto g = ReadFloats(*t.e, *t.s, xa->grad_handle);
  for (int64_t i = 0; i < n; ++i) ASSERT_NEAR(g[i], 2.0 * x[i], 1e-5) << i;
  rest.marker = 78;
  st = t.Run({Cmd(rest)});
  EXPECT_EQ(st.code(), StatusCode::kFailedPrecondition) << st.ToString();
  mark.marker = 0;
  st = t.Run({Cmd(mark)});
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << st.ToString();
}

// After a failed command the rest of the session's work is skipped until the client hears of
// the failure, but ending and freeing a tape still run: a tape left recording would refuse
// every later tape.
TEST(Tape, EndAndFreeRunAfterAFailure) {
  auto tape = [](TapeCommand::Op op) {
    TapeCommand t;
    t.op = op;
    t.tape_id = 7;
    Command c;
    c.kind = t;
    return c;
  };
  EXPECT_TRUE(RunsAfterFailure(tape(TapeCommand::Op::kEnd)));
  EXPECT_TRUE(RunsAfterFailure(tape(TapeCommand::Op::kFree)));
  for (TapeCommand::Op op : {TapeCommand::Op::kBegin, TapeCommand::Op::kBackward, TapeCommand::Op::kZero,
                             TapeCommand::Op::kReset, TapeCommand::Op::kMark})
    EXPECT_FALSE(RunsAfterFailure(tape(op)));
  GraphCommand g;
  g.op = GraphCommand::Op::kDestroy;
  Command destroy;
  destroy.kind = g;
  EXPECT_TRUE(RunsAfterFailure(destroy));
  g.op = GraphCommand::Op::kLaunch;
  Command launch;
  launch.kind = g;
  EXPECT_FALSE(RunsAfterFailure(launch));
}

}  // namespace
}  // namespace weft
