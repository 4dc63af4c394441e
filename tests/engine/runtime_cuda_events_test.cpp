// Cross-process ordering commands (CudaEventCommand) and Engine::SubmitAndRun, hostile requests:
// an event on the CPU, a forged or wrong-size handle, an unknown op fail the session's batch
// with a clear error that SubmitAndRun returns at once (the launch after a failed WAIT does not
// run) and the session keeps serving after it; SubmitAndRun has run the batch when it returns.
// What needs a GPU (the driver refusing forged handle bytes) skips without one. Ordering with a
// real framework stream needs a second process: tested from Python
// (clients/python/tests/interop/test_cuda_events.py).
#include <gtest/gtest.h>

#include <random>

#include "runtime_test_support.h"

namespace weft::testing {
namespace {

Command Event(CudaEventCommand::Op op, const std::string& device, std::string handle) {
  Command c;
  c.kind = CudaEventCommand{op, device, std::move(handle)};
  return c;
}

TEST(CudaEventsTest, SubmitAndRunHasRunTheBatchWhenItReturns) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = e->CreateArray(*s, FromFloats({0, 0, 0, 0}));
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  std::vector<Command> batch;
  batch.push_back(FillOnes(a->handle));
  auto r = e->SubmitAndRun(*s, std::move(batch));
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(r->has_value());                  // no error: no synchronized result
  EXPECT_EQ(s->queued_commands.load(), 0u);      // the executor ran it
  EXPECT_EQ(ReadFloats(*e, *s, a->handle), std::vector<float>({1, 1, 1, 1}));
}

TEST(CudaEventsTest, AnEventOnTheCpuFailsTheBatchAndRunReportsIt) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = e->CreateArray(*s, FromFloats({0, 0}));
  ASSERT_TRUE(a.ok()) << a.status().ToString();
  for (auto op : {CudaEventCommand::Op::kWait, CudaEventCommand::Op::kRecord,
                  static_cast<CudaEventCommand::Op>(9)}) {
    std::vector<Command> batch;
    batch.push_back(Event(op, "cpu", std::string(64, '\x05')));
    batch.push_back(FillOnes(a->handle));          // after the failed WAIT: does not run
    auto r = e->SubmitAndRun(*s, std::move(batch));
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    ASSERT_TRUE(r->has_value());
    EXPECT_EQ((*r)->error.code(), StatusCode::kInvalidArgument) << (*r)->error.ToString();
    const std::string want = op == static_cast<CudaEventCommand::Op>(9) ? "unknown op 9" : "'cpu' is not a GPU";
    EXPECT_NE((*r)->error.message().find(want), std::string::npos) << (*r)->error.ToString();
    EXPECT_EQ(ReadFloats(*e, *s, a->handle), std::vector<float>({0, 0}));
  }
  std::vector<Command> batch;                      // the session keeps serving
  batch.push_back(FillOnes(a->handle));
  auto ok = e->SubmitAndSynchronize(*s, std::move(batch));
  ASSERT_TRUE(ok.ok());
  EXPECT_TRUE(ok->error.ok()) << ok->error.ToString();
  EXPECT_EQ(ReadFloats(*e, *s, a->handle), std::vector<float>({1, 1}));
}

class CudaEventsGpuTest : public ::testing::Test {
 protected:
  void SetUp() override {
    engine_ = MakeEngine();
    if (engine_->devices().gpus().empty()) GTEST_SKIP() << "no GPU the daemon can compute on";
  }
  std::unique_ptr<Engine> engine_;
};

TEST_F(CudaEventsGpuTest, ForgedAndMisSizedHandlesAreClearErrors) {
  auto s = engine_->OpenSession(Local());
  std::mt19937 rng(17);
  std::string forged(64, '\0');
  for (char& c : forged) c = static_cast<char>(rng());
  const std::pair<std::string, const char*> cases[] = {
      {forged, "could not be opened on cuda:0"},
      {std::string(63, '\x01'), "has 64 bytes, got 63"},
  };
  for (const auto& [handle, want] : cases) {
    std::vector<Command> batch;
    batch.push_back(Event(CudaEventCommand::Op::kWait, "cuda:0", handle));
    auto r = engine_->SubmitAndRun(*s, std::move(batch));
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    ASSERT_TRUE(r->has_value());
    EXPECT_EQ((*r)->error.code(), StatusCode::kInvalidArgument) << (*r)->error.ToString();
    EXPECT_NE((*r)->error.message().find(want), std::string::npos) << (*r)->error.ToString();
  }
  EXPECT_EQ(engine_->devices().gpus()[0]->IpcEventCount(), 0u);
  EXPECT_TRUE(engine_->CloseSession(s->id()).ok());
}

}  // namespace
}  // namespace weft::testing
