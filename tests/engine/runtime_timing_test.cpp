// CUDA activity timing (TimingCommand, Engine::Synchronize's collection): hostile commands (an
// unknown op, timing inside a graph) are clear errors and the session keeps serving; timing a
// CPU-only session's work ends with no activities; an error discards the records and still ends
// timing. On a GPU: fills and copies are timed with Warp's names and filters, a filter selects,
// a second BEGIN discards, and a flood of operations keeps at most kMaxTimedActivities records
// (the rest counted as dropped). Timing events (TimedEventCommand, Engine::EventElapsed): refused
// on the CPU, in a graph and with an unknown op; on a GPU the time between two records, unknown,
// released and another session's ids, the per-session limit, and nothing left after the session
// closes. The GPU
// cases skip without one.
#include <gtest/gtest.h>

#include "runtime_test_support.h"

namespace weft::testing {
namespace {

Command Timing(TimingCommand::Op op, uint32_t filter = 0xffffffffu) {
  Command c;
  c.kind = TimingCommand{op, filter};
  return c;
}

TEST(TimingTest, UnknownOpAndTimingInAGraphAreRefusedAndTheSessionServes) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = e->CreateArray(*s, FromFloats({0, 0, 0}));
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  std::vector<Command> bad;
  bad.push_back(Timing(static_cast<TimingCommand::Op>(7)));
  auto r = e->Submit(*s, std::move(bad));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("unknown timing op 7"), std::string::npos) << r.status().ToString();

  Command graph;
  GraphCommand g;
  g.op = GraphCommand::Op::kCreate;
  g.graph_id = 1;
  g.device = "cpu";
  g.commands.push_back(FillOnes(a->handle));
  g.commands.push_back(Timing(TimingCommand::Op::kBegin));
  graph.kind = std::move(g);
  std::vector<Command> batch;
  batch.push_back(std::move(graph));
  r = e->Submit(*s, std::move(batch));
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("a graph cannot hold timing commands"), std::string::npos)
      << r.status().ToString();

  std::vector<Command> fine;
  fine.push_back(FillOnes(a->handle));
  auto ok = e->SubmitAndSynchronize(*s, std::move(fine));
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_TRUE(ok->error.ok()) << ok->error.ToString();
  EXPECT_FALSE(ok->timing_ended);
  EXPECT_EQ(ReadFloats(*e, *s, a->handle), std::vector<float>({1, 1, 1}));
}

TEST(TimingTest, CpuWorkIsNotTimedAndEndIsReportedOnce) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = e->CreateArray(*s, FromFloats({4, 5}));
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  std::vector<Command> batch;
  batch.push_back(Timing(TimingCommand::Op::kBegin));
  batch.push_back(FillOnes(a->handle));
  batch.push_back(Timing(TimingCommand::Op::kEnd));
  auto r = e->SubmitAndSynchronize(*s, std::move(batch));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE(r->error.ok()) << r->error.ToString();
  EXPECT_TRUE(r->timing_ended);
  EXPECT_TRUE(r->timing.empty());
  EXPECT_EQ(r->timing_dropped, 0u);
  auto again = e->Synchronize(*s);   // collected once
  EXPECT_FALSE(again.timing_ended);
}

TEST(TimingTest, AnErrorBeforeEndDiscardsTheRecordsAndEndsTiming) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = e->CreateArray(*s, FromFloats({1, 2}));
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  std::vector<Command> batch;
  batch.push_back(Timing(TimingCommand::Op::kBegin));
  batch.push_back(FillOnes(a->handle + 999));   // unknown handle: the batch fails here
  batch.push_back(Timing(TimingCommand::Op::kEnd));   // still runs: timing stops
  auto r = e->SubmitAndSynchronize(*s, std::move(batch));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(r->error.ok());
  EXPECT_TRUE(r->timing_ended);
  EXPECT_TRUE(r->timing.empty());
}

Command TimedEvent(TimedEventCommand::Op op, uint64_t id, const std::string& device = "cuda:0") {
  Command c;
  c.kind = TimedEventCommand{op, id, device};
  return c;
}

TEST(TimingTest, TimingEventsAreForGpusAndNotForGraphs) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  std::vector<Command> bad_op;
  bad_op.push_back(TimedEvent(static_cast<TimedEventCommand::Op>(4), 1));
  auto q = e->Submit(*s, std::move(bad_op));
  ASSERT_FALSE(q.ok());
  EXPECT_NE(q.status().message().find("unknown timed_event op 4"), std::string::npos) << q.status().ToString();
  Command graph;
  GraphCommand g;
  g.graph_id = 2;
  g.device = "cpu";
  g.commands.push_back(TimedEvent(TimedEventCommand::Op::kRecord, 1));
  graph.kind = std::move(g);
  std::vector<Command> in_graph;
  in_graph.push_back(std::move(graph));
  q = e->Submit(*s, std::move(in_graph));
  ASSERT_FALSE(q.ok());
  EXPECT_NE(q.status().message().find("timing events"), std::string::npos) << q.status().ToString();
  std::vector<Command> on_cpu;
  on_cpu.push_back(TimedEvent(TimedEventCommand::Op::kRecord, 1, "cpu"));
  auto r = e->SubmitAndSynchronize(*s, std::move(on_cpu));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_NE(r->error.message().find("'cpu' is not a GPU"), std::string::npos) << r->error.ToString();
  auto ms = e->EventElapsed(*s, "cpu", 1, 2);
  ASSERT_FALSE(ms.ok());
  EXPECT_EQ(ms.status().code(), StatusCode::kInvalidArgument);
}

class TimingGpuTest : public ::testing::Test {
 protected:
  void SetUp() override {
    engine_ = MakeEngine();
    if (engine_->devices().gpus().empty()) GTEST_SKIP() << "no GPU the daemon can compute on";
    s_ = engine_->OpenSession(Local());
    CreateArrayParams p = FromFloats(std::vector<float>(1 << 16, 3.0f));
    p.device = "cuda:0";
    auto a = engine_->CreateArray(*s_, p);
    auto b = engine_->CreateArray(*s_, p);
    ASSERT_TRUE(a.ok() && b.ok());
    a_ = a->handle;
    b_ = b->handle;
  }
  Session::SyncResult Run(std::vector<Command> batch) {
    auto r = engine_->SubmitAndSynchronize(*s_, std::move(batch));
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_TRUE(r->error.ok()) << r->error.ToString();
    return std::move(r).value();
  }
  std::unique_ptr<Engine> engine_;
  std::shared_ptr<Session> s_;
  uint64_t a_ = 0, b_ = 0;
};

TEST_F(TimingGpuTest, FillsAndCopiesAreTimedWithWarpsNamesAndFilters) {
  std::vector<Command> batch;
  batch.push_back(Timing(TimingCommand::Op::kBegin));
  batch.push_back(FillOnes(a_));       // 1.0f: not a repeating byte pattern, but a 4-byte one: memset
  batch.push_back(CopyCmd(b_, a_));    // contiguous on one GPU: memcpy DtoD
  batch.push_back(Timing(TimingCommand::Op::kEnd));
  auto r = Run(std::move(batch));
  ASSERT_TRUE(r.timing_ended);
  ASSERT_EQ(r.timing.size(), 2u);
  EXPECT_EQ(r.timing[0].name, "memset");
  EXPECT_EQ(r.timing[0].filter, kTimingMemset);
  EXPECT_EQ(r.timing[1].name, "memcpy DtoD");
  EXPECT_EQ(r.timing[1].filter, kTimingMemcpy);
  for (const TimedActivity& t : r.timing) {
    EXPECT_EQ(t.device, "cuda:0");
    EXPECT_GE(t.elapsed_ms, 0.0);
    EXPECT_LT(t.elapsed_ms, 1000.0);
  }
  EXPECT_EQ(ReadFloats(*engine_, *s_, b_), std::vector<float>(1 << 16, 1.0f));

  // Only copies; a second BEGIN discards what the first recorded.
  std::vector<Command> selective;
  selective.push_back(Timing(TimingCommand::Op::kBegin, kTimingMemset));
  selective.push_back(FillOnes(a_));
  selective.push_back(Timing(TimingCommand::Op::kBegin, kTimingMemcpy));
  selective.push_back(FillOnes(a_));
  selective.push_back(CopyCmd(b_, a_));
  selective.push_back(Timing(TimingCommand::Op::kEnd));
  selective.push_back(CopyCmd(a_, b_));   // after END: not timed
  r = Run(std::move(selective));
  ASSERT_EQ(r.timing.size(), 1u);
  EXPECT_EQ(r.timing[0].name, "memcpy DtoD");
}

TEST_F(TimingGpuTest, TheFloodsCollectionHasTheLimitAndTheDroppedCount) {
  const uint64_t extra = 700;
  std::vector<Command> begin;
  begin.push_back(Timing(TimingCommand::Op::kBegin, kTimingMemset));
  ASSERT_TRUE(engine_->Submit(*s_, std::move(begin)).ok());
  uint64_t sent = 0;
  while (sent < kMaxTimedActivities + extra) {
    std::vector<Command> part;
    for (; part.size() < 8192 && sent < kMaxTimedActivities + extra; ++sent) part.push_back(FillOnes(a_));
    ASSERT_TRUE(engine_->Submit(*s_, std::move(part)).ok());
    engine_->Synchronize(*s_);   // no END yet: nothing collected, records stay
  }
  std::vector<Command> end;
  end.push_back(Timing(TimingCommand::Op::kEnd));
  auto r = Run(std::move(end));
  ASSERT_TRUE(r.timing_ended);
  EXPECT_EQ(r.timing.size(), kMaxTimedActivities);
  EXPECT_EQ(r.timing_dropped, extra);
  // The next BEGIN starts afresh: one fill, nothing dropped.
  std::vector<Command> one;
  one.push_back(Timing(TimingCommand::Op::kBegin));
  one.push_back(FillOnes(a_));
  one.push_back(Timing(TimingCommand::Op::kEnd));
  r = Run(std::move(one));
  ASSERT_TRUE(r.timing_ended);
  EXPECT_EQ(r.timing.size(), 1u);
  EXPECT_EQ(r.timing_dropped, 0u);
}

TEST_F(TimingGpuTest, TimingEventsMeasureTheWorkBetweenThemAndAreBounded) {
  std::vector<Command> batch;
  batch.push_back(TimedEvent(TimedEventCommand::Op::kRecord, 10));
  for (int i = 0; i < 50; ++i) batch.push_back(CopyCmd(b_, a_));
  batch.push_back(TimedEvent(TimedEventCommand::Op::kRecord, 11));
  batch.push_back(TimedEvent(TimedEventCommand::Op::kRecord, 12));   // nothing between 11 and 12
  ASSERT_TRUE(engine_->Submit(*s_, std::move(batch)).ok());
  auto work = engine_->EventElapsed(*s_, "cuda:0", 10, 11);
  auto none = engine_->EventElapsed(*s_, "cuda:0", 11, 12);
  ASSERT_TRUE(work.ok() && none.ok()) << work.status().ToString() << none.status().ToString();
  EXPECT_GT(*work, 0.0);
  EXPECT_LT(*none, *work);   // 50 copies of 256 KiB against none
  auto unknown = engine_->EventElapsed(*s_, "cuda:0", 10, 99);
  ASSERT_FALSE(unknown.ok());
  EXPECT_EQ(unknown.status().code(), StatusCode::kNotFound);
  // Another session names the same ids: they are not its events.
  auto other = engine_->OpenSession(Local("other"));
  auto foreign = engine_->EventElapsed(*other, "cuda:0", 10, 11);
  EXPECT_EQ(foreign.status().code(), StatusCode::kNotFound) << foreign.status().ToString();
  ASSERT_TRUE(engine_->CloseSession(other->id()).ok());
  EXPECT_TRUE(engine_->EventElapsed(*s_, "cuda:0", 10, 11).ok());   // the owner's stay
  std::vector<Command> release;
  release.push_back(TimedEvent(TimedEventCommand::Op::kDestroy, 10));
  ASSERT_TRUE(engine_->Submit(*s_, std::move(release)).ok());
  auto released = engine_->EventElapsed(*s_, "cuda:0", 10, 11);
  EXPECT_EQ(released.status().code(), StatusCode::kNotFound) << released.status().ToString();

  // The limit: a session holds at most kTimedEventsPerSession events.
  auto* gpu = engine_->devices().gpus()[0].get();
  std::vector<Command> many;
  for (uint64_t id = 1000; id < 1000 + CudaDevice::kTimedEventsPerSession; ++id)
    many.push_back(TimedEvent(TimedEventCommand::Op::kRecord, id));
  auto r = engine_->SubmitAndSynchronize(*s_, std::move(many));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(r->error.ok());   // 2 held before: the last ones are refused
  EXPECT_NE(r->error.message().find("timing events"), std::string::npos) << r->error.ToString();
  EXPECT_EQ(gpu->TimedEventCount(), CudaDevice::kTimedEventsPerSession);
  ASSERT_TRUE(engine_->CloseSession(s_->id()).ok());
  EXPECT_EQ(gpu->TimedEventCount(), 0u);
}

}  // namespace
}  // namespace weft::testing
