// Ordering by stream memory operations (CudaValueCommand), hostile requests: an order array on
// the CPU, of the wrong element type or shape, an index past its end, an unknown handle or op
// fail the batch with a clear error and the session keeps serving. On a GPU: a WRITE runs even
// after an earlier command of the session failed (it releases a waiting client stream), a WAIT
// for a value written before passes, and a WAIT the client never satisfies cannot hold the
// session: closing it, or the launch time limit, releases it. Ordering with a real framework
// stream of another process is tested from Python (clients/python/tests/interop/test_cuda_events.py).
#include <gtest/gtest.h>

#include <chrono>
#include <future>

#include "runtime_test_support.h"

namespace weft::testing {
namespace {

DType U64() {
  DType d;
  d.scalar = ScalarType::kUInt64;
  return d;
}

Command Value(CudaValueCommand::Op op, uint64_t handle, uint32_t index, uint64_t value) {
  Command c;
  CudaValueCommand v;
  v.op = op;
  v.order.handle = handle;
  v.index = index;
  v.value = value;
  c.kind = v;
  return c;
}

uint64_t Zeros(Engine& e, Session& s, DType dtype, std::vector<int64_t> shape, const std::string& device) {
  CreateArrayParams p;
  p.dtype = dtype;
  p.shape = std::move(shape);
  p.device = device;
  p.init = CreateArrayParams::Init::kZeros;
  auto a = e.CreateArray(s, p);
  EXPECT_TRUE(a.ok()) << a.status().ToString();
  return a.ok() ? a->handle : 0;
}

std::vector<uint64_t> ReadU64(Engine& e, Session& s, uint64_t handle) { return ReadValues<uint64_t>(e, s, handle); }

TEST(CudaValuesTest, OnlyWritesRunAfterAFailure) {
  EXPECT_TRUE(RunsAfterFailure(Value(CudaValueCommand::Op::kWrite, 1, 0, 1)));
  EXPECT_FALSE(RunsAfterFailure(Value(CudaValueCommand::Op::kWait, 1, 0, 1)));
  EXPECT_FALSE(RunsAfterFailure(FillOnes(1)));
}

TEST(CudaValuesTest, BadOrderArraysAreClearErrorsAndTheSessionKeepsServing) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  const uint64_t floats = Zeros(*e, *s, F32(), {4}, "cpu");
  const uint64_t matrix = Zeros(*e, *s, U64(), {2, 2}, "cpu");
  const uint64_t cpu_order = Zeros(*e, *s, U64(), {4}, "cpu");
  const uint64_t target = Zeros(*e, *s, F32(), {2}, "cpu");
  struct Case {
    Command command;
    StatusCode code;
    const char* want;
  };
  const Case cases[] = {
      {Value(CudaValueCommand::Op::kWait, 987654, 0, 1), StatusCode::kNotFound, "unknown array handle 987654"},
      {Value(CudaValueCommand::Op::kWait, floats, 0, 1), StatusCode::kInvalidArgument, "8-byte elements"},
      {Value(CudaValueCommand::Op::kWrite, matrix, 0, 1), StatusCode::kInvalidArgument, "must be 1-D"},
      {Value(CudaValueCommand::Op::kWait, cpu_order, 4, 1), StatusCode::kOutOfRange, "index 4 is out of range"},
      {Value(CudaValueCommand::Op::kWrite, cpu_order, 0xffffffffu, 1), StatusCode::kOutOfRange, "out of range"},
      {Value(CudaValueCommand::Op::kWait, cpu_order, 1, 1), StatusCode::kInvalidArgument, "not a GPU"},
      {Value(static_cast<CudaValueCommand::Op>(7), cpu_order, 1, 1), StatusCode::kInvalidArgument, "unknown op 7"},
  };
  for (const Case& c : cases) {
    std::vector<Command> batch;
    batch.push_back(c.command);
    batch.push_back(FillOnes(target));   // after the failed command: does not run
    auto r = e->SubmitAndRun(*s, std::move(batch));
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    ASSERT_TRUE(r->has_value()) << c.want;
    EXPECT_EQ((*r)->error.code(), c.code) << (*r)->error.ToString();
    EXPECT_NE((*r)->error.message().find(c.want), std::string::npos) << (*r)->error.ToString();
    EXPECT_EQ(ReadFloats(*e, *s, target), std::vector<float>({0, 0}));
  }
  // A view of the order array (not the whole array) is refused too.
  Command view = Value(CudaValueCommand::Op::kWait, cpu_order, 0, 1);
  std::get<CudaValueCommand>(view.kind).order.byte_offset = 8;
  std::vector<Command> batch{view};
  auto r = e->SubmitAndRun(*s, std::move(batch));
  ASSERT_TRUE(r.ok() && r->has_value());
  EXPECT_NE((*r)->error.message().find("must name the whole array"), std::string::npos) << (*r)->error.ToString();

  std::vector<Command> fill{FillOnes(target)};
  auto ok = e->SubmitAndSynchronize(*s, std::move(fill));
  ASSERT_TRUE(ok.ok());
  EXPECT_TRUE(ok->error.ok()) << ok->error.ToString();
  EXPECT_EQ(ReadFloats(*e, *s, target), std::vector<float>({1, 1}));
}

class CudaValuesGpuTest : public ::testing::Test {
 protected:
  void SetUp() override {
    engine_ = MakeEngine();
    if (engine_->devices().gpus().empty()) GTEST_SKIP() << "no GPU the daemon can compute on";
    if (!engine_->devices().gpus()[0]->StreamMemOpsSupported())
      GTEST_SKIP() << "cuda:0 has no 64-bit stream memory operations";
  }
  std::unique_ptr<Engine> engine_;
};

TEST_F(CudaValuesGpuTest, WritesRunAfterAFailureAndSatisfiedWaitsPass) {
  auto s = engine_->OpenSession(Local());
  const uint64_t order = Zeros(*engine_, *s, U64(), {4}, "cuda:0");
  const uint64_t target = Zeros(*engine_, *s, F32(), {3}, "cuda:0");
  std::vector<Command> batch;
  batch.push_back(FillOnes(987654));                                     // fails
  batch.push_back(FillOnes(target));                                     // skipped
  batch.push_back(Value(CudaValueCommand::Op::kWrite, order, 1, 41));   // runs anyway
  auto r = engine_->SubmitAndSynchronize(*s, std::move(batch));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->error.code(), StatusCode::kNotFound) << r->error.ToString();
  EXPECT_EQ(ReadU64(*engine_, *s, order), std::vector<uint64_t>({0, 41, 0, 0}));
  EXPECT_EQ(ReadFloats(*engine_, *s, target), std::vector<float>({0, 0, 0}));

  std::vector<Command> ordered;
  ordered.push_back(Value(CudaValueCommand::Op::kWait, order, 1, 41));  // already satisfied
  ordered.push_back(FillOnes(target));
  ordered.push_back(Value(CudaValueCommand::Op::kWrite, order, 2, 42));
  auto ok = engine_->SubmitAndSynchronize(*s, std::move(ordered));
  ASSERT_TRUE(ok.ok());
  EXPECT_TRUE(ok->error.ok()) << ok->error.ToString();
  EXPECT_EQ(ReadFloats(*engine_, *s, target), std::vector<float>({1, 1, 1}));
  EXPECT_EQ(ReadU64(*engine_, *s, order), std::vector<uint64_t>({0, 41, 42, 0}));
  EXPECT_TRUE(engine_->CloseSession(s->id()).ok());
}

TEST_F(CudaValuesGpuTest, AWaitNeverSatisfiedIsReleasedWhenTheSessionCloses) {
  auto s = engine_->OpenSession(Local());
  auto other = engine_->OpenSession(Local("other"));
  const uint64_t order = Zeros(*engine_, *s, U64(), {2}, "cuda:0");
  const uint64_t target = Zeros(*engine_, *s, F32(), {2}, "cuda:0");
  std::vector<Command> batch;
  batch.push_back(Value(CudaValueCommand::Op::kWait, order, 0, 1000));   // nobody writes 1000
  batch.push_back(FillOnes(target));
  auto queued = engine_->SubmitAndRun(*s, std::move(batch));
  ASSERT_TRUE(queued.ok()) << queued.status().ToString();
  EXPECT_FALSE(queued->has_value());
  // Another session on the same GPU is not held by it.
  const uint64_t theirs = Zeros(*engine_, *other, F32(), {2}, "cuda:0");
  std::vector<Command> fill{FillOnes(theirs)};
  auto done = engine_->SubmitAndSynchronize(*other, std::move(fill));
  ASSERT_TRUE(done.ok());
  EXPECT_TRUE(done->error.ok()) << done->error.ToString();
  EXPECT_EQ(ReadFloats(*engine_, *other, theirs), std::vector<float>({1, 1}));
  // Closing the waiting session returns (its wait is released), bounded here by 60 s.
  auto closing = std::async(std::launch::async, [&] { return engine_->CloseSession(s->id()); });
  ASSERT_EQ(closing.wait_for(std::chrono::seconds(60)), std::future_status::ready) << "CloseSession hung on the wait";
  EXPECT_TRUE(closing.get().ok());
  EXPECT_TRUE(engine_->CloseSession(other->id()).ok());
}

TEST(CudaValuesLimitTest, TheLaunchTimeLimitReleasesAWaitAndTheSessionGoesOn) {
  auto store = std::make_unique<FakeModuleStore>();
  EngineOptions o;
  o.cpu_threads = 2;
  o.remove_stale_slabs = false;
  o.launch_time_limit_s = 1;
  auto created = Engine::Create(o, std::move(store));
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  auto e = std::move(created).value();
  if (e->devices().gpus().empty()) GTEST_SKIP() << "no GPU the daemon can compute on";
  if (!e->devices().gpus()[0]->StreamMemOpsSupported()) GTEST_SKIP() << "no 64-bit stream memory operations";
  auto s = e->OpenSession(Local());
  const uint64_t order = Zeros(*e, *s, U64(), {2}, "cuda:0");
  const uint64_t target = Zeros(*e, *s, F32(), {2}, "cuda:0");
  std::vector<Command> batch;
  batch.push_back(Value(CudaValueCommand::Op::kWait, order, 1, 77));
  batch.push_back(FillOnes(target));
  auto sync = std::async(std::launch::async, [&] { return e->SubmitAndSynchronize(*s, std::move(batch)); });
  ASSERT_EQ(sync.wait_for(std::chrono::seconds(60)), std::future_status::ready) << "Synchronize hung on the wait";
  auto r = sync.get();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(r->error.ok());   // stopped by the time limit, reported
  EXPECT_EQ(ReadU64(*e, *s, order)[1], 77u);   // the daemon released the wait
  std::vector<Command> fill{FillOnes(target)};
  auto ok = e->SubmitAndSynchronize(*s, std::move(fill));
  ASSERT_TRUE(ok.ok());
  EXPECT_TRUE(ok->error.ok()) << ok->error.ToString();
  EXPECT_EQ(ReadFloats(*e, *s, target), std::vector<float>({1, 1}));
}

}  // namespace
}  // namespace weft::testing
