// Command graphs (GraphCommand): CREATE records without running, LAUNCH replays, DESTROY
// forgets; a graph holds the arrays it names (a freed handle still replays on live memory);
// hostile requests (an unknown handle, an unknown or destroyed graph id, another session's
// graph id, more graphs than the per-session limit) are clear errors and the session goes on.
// On a GPU the same graph is captured as a CUDA graph (CommandGraph::device_graph) and replays
// with the same results.
#include <gtest/gtest.h>

#include "runtime_test_support.h"

namespace weft::testing {
namespace {

constexpr size_t kGraphLimit = CommandExecutor::kMaxGraphsPerSession;

Command GraphCmd(GraphCommand::Op op, uint64_t id, const std::string& device = "", std::vector<Command> inner = {}) {
  Command c;
  GraphCommand g;
  g.op = op;
  g.graph_id = id;
  g.device = device;
  g.commands = std::move(inner);
  c.kind = std::move(g);
  return c;
}

Status RunGraph(Engine& e, Session& s, std::vector<Command> cmds) {
  auto r = e.SubmitAndSynchronize(s, std::move(cmds));
  if (!r.ok()) return r.status();
  return r->error;
}

void CreateLaunchDestroy(Engine& e, const std::string& device, bool expect_device_graph) {
  auto s = e.OpenSession(Local());
  CreateArrayParams p = FromFloats({0, 0, 0, 0});
  p.device = device;
  const uint64_t ones = e.CreateArray(*s, p)->handle;
  const uint64_t copy = e.CreateArray(*s, p)->handle;
  std::vector<Command> inner;
  inner.push_back(FillOnes(ones));
  inner.push_back(CopyCmd(copy, ones));
  Status st = RunGraph(e, *s, {GraphCmd(GraphCommand::Op::kCreate, 7, device, std::move(inner))});
  ASSERT_TRUE(st.ok()) << st.ToString();
  ASSERT_EQ(s->graphs.count(7), 1u);
  EXPECT_EQ(s->graphs[7].device_graph != nullptr, expect_device_graph);
  EXPECT_EQ(ReadFloats(e, *s, copy), std::vector<float>(4, 0));   // created, not run
  // The graph holds its arrays: freeing the handles does not free the memory it replays on.
  ASSERT_TRUE(e.FreeArray(*s, ones).ok());
  st = RunGraph(e, *s, {GraphCmd(GraphCommand::Op::kLaunch, 7)});
  ASSERT_TRUE(st.ok()) << st.ToString();
  EXPECT_EQ(ReadFloats(e, *s, copy), std::vector<float>(4, 1));
  st = RunGraph(e, *s, {GraphCmd(GraphCommand::Op::kDestroy, 7), GraphCmd(GraphCommand::Op::kLaunch, 7)});
  EXPECT_EQ(st.code(), StatusCode::kNotFound) << st.ToString();
  EXPECT_TRUE(e.CloseSession(s->id()).ok());
}

TEST(CommandGraph, CreateRecordsLaunchReplaysDestroyForgetsOnCpu) {
  auto e = MakeEngine();
  CreateLaunchDestroy(*e, "cpu", false);
}

TEST(CommandGraph, HostileGraphRequestsAreClearErrors) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto other = e->OpenSession(Local("other"));
  const uint64_t mine = e->CreateArray(*s, FromFloats({0, 0}))->handle;
  const uint64_t theirs = e->CreateArray(*other, FromFloats({0, 0}))->handle;
  // Another session's array: not held by this one.
  std::vector<Command> inner;
  inner.push_back(FillOnes(theirs));
  Status st = RunGraph(*e, *s, {GraphCmd(GraphCommand::Op::kCreate, 1, "cpu", std::move(inner))});
  EXPECT_EQ(st.code(), StatusCode::kNotFound) << st.ToString();
  EXPECT_EQ(s->graphs.count(1), 0u);
  // Another session's graph id names nothing here.
  std::vector<Command> theirs_inner;
  theirs_inner.push_back(FillOnes(theirs));
  ASSERT_TRUE(RunGraph(*e, *other, {GraphCmd(GraphCommand::Op::kCreate, 2, "cpu", std::move(theirs_inner))}).ok());
  st = RunGraph(*e, *s, {GraphCmd(GraphCommand::Op::kLaunch, 2)});
  EXPECT_EQ(st.code(), StatusCode::kNotFound) << st.ToString();
  EXPECT_EQ(ReadFloats(*e, *other, theirs), std::vector<float>(2, 0));
  // A graph inside a graph is refused by the batch limits.
  std::vector<Command> nested;
  nested.push_back(GraphCmd(GraphCommand::Op::kLaunch, 2));
  auto refused = e->Submit(*s, {GraphCmd(GraphCommand::Op::kCreate, 3, "cpu", std::move(nested))});
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument) << refused.status().ToString();
  // At most kMaxGraphsPerSession graphs.
  std::vector<Command> many;
  for (size_t i = 0; i <= kGraphLimit; ++i) {
    std::vector<Command> one;
    one.push_back(FillOnes(mine));
    many.push_back(GraphCmd(GraphCommand::Op::kCreate, 100 + i, "cpu", std::move(one)));
  }
  st = RunGraph(*e, *s, std::move(many));
  EXPECT_EQ(st.code(), StatusCode::kResourceExhausted) << st.ToString();
  EXPECT_EQ(s->graphs.size(), kGraphLimit);
  // The session goes on.
  ASSERT_TRUE(RunGraph(*e, *s, {FillOnes(mine)}).ok());
  EXPECT_EQ(ReadFloats(*e, *s, mine), std::vector<float>(2, 1));
  EXPECT_TRUE(e->CloseSession(s->id()).ok());
  EXPECT_TRUE(e->CloseSession(other->id()).ok());
}

TEST(CommandGraph, CapturedAsACudaGraphOnAGpu) {
  auto e = MakeEngine();
  if (e->devices().gpus().empty()) GTEST_SKIP() << "no GPU the daemon can compute on";
  CreateLaunchDestroy(*e, "cuda:0", e->devices().gpus()[0]->GraphsSupported());
}

}  // namespace
}  // namespace weft::testing
