// Cooperative CPU blocks (engine/runtime/cpu_lanes.h): the lanes of a block run in rounds, each
// lane to its next sync; the lanes that take part in a round and its leader are fixed at the
// round's start; lanes that return early or sync a different number of times never hang the
// block; scratch memory grows and earlier buffers stay valid until the block ends. Through
// RunCpuLaunch: a kernel compiled with lanes runs its blocks (the last one short) as fibers
// and refuses a launch whose block_dim is not its lane count.
#include <gtest/gtest.h>

#include <sys/mman.h>
#include <unistd.h>

#include <cstring>
#include <vector>

#include "engine/runtime/cpu_launch.h"
#include "engine/runtime/cpu_lanes.h"
#include "engine/runtime/thread_pool.h"

namespace weft {
namespace {

TEST(CpuLanes, EveryLaneReachesASyncBeforeAnyPassesIt) {
  LaneBlockRunner runner(5);
  wp::lane_block_t* b = runner.block();
  std::vector<std::pair<int, int>> log;   // (lane, phase)
  std::vector<int> leaders;
  ASSERT_TRUE(runner.Run(5, [&](int lane) {
    for (int phase = 0; phase < 3; ++phase) {
      log.emplace_back(lane, phase);
      if (lane == 0) leaders.push_back(b->leader);
      b->sync(b);
    }
  }).ok());
  ASSERT_EQ(log.size(), 15u);
  for (size_t k = 0; k < log.size(); ++k) {
    EXPECT_EQ(log[k].second, static_cast<int>(k / 5)) << k;
    EXPECT_EQ(log[k].first, static_cast<int>(k % 5)) << k;
  }
  EXPECT_EQ(leaders, (std::vector<int>{0, 0, 0}));
  EXPECT_EQ(b->dim, 5);
  EXPECT_EQ(b->count, 5);
}

TEST(CpuLanes, LanesThatReturnLeaveTheNextRoundAndTheLeaderMoves) {
  LaneBlockRunner runner(4);
  wp::lane_block_t* b = runner.block();
  std::vector<int> seen_leader(4, -1), seen_running(4, -1);
  ASSERT_TRUE(runner.Run(4, [&](int lane) {
    if (lane < 2) return;                 // lanes 0 and 1 leave in the first round
    b->sync(b);
    seen_leader[lane] = b->leader;
    seen_running[lane] = b->running[0] + b->running[1] + b->running[2] + b->running[3];
  }).ok());
  EXPECT_EQ(seen_leader[2], 2);
  EXPECT_EQ(seen_leader[3], 2);
  EXPECT_EQ(seen_running[2], 2);
  EXPECT_EQ(seen_running[3], 2);
}

TEST(CpuLanes, DivergentSyncCountsFinish) {
  LaneBlockRunner runner(8);
  wp::lane_block_t* b = runner.block();
  int finished = 0;
  ASSERT_TRUE(runner.Run(8, [&](int lane) {
    for (int k = 0; k < lane * 3; ++k) b->sync(b);
    ++finished;
  }).ok());
  EXPECT_EQ(finished, 8);
  // the runner is reused for the next block, a short one
  finished = 0;
  ASSERT_TRUE(runner.Run(3, [&](int lane) {
    b->sync(b);
    finished += lane + 1;
  }).ok());
  EXPECT_EQ(finished, 6);
  EXPECT_EQ(b->count, 3);
}

TEST(CpuLanes, ScratchIsSharedGrowsAndKeepsEarlierBuffersForTheBlock) {
  LaneBlockRunner runner(4);
  wp::lane_block_t* b = runner.block();
  std::vector<int> sums(4, 0);
  char* first = nullptr;
  ASSERT_TRUE(runner.Run(4, [&](int lane) {
    int* s = reinterpret_cast<int*>(b->scratch(b, 4 * sizeof(int)));
    if (lane == 0) first = reinterpret_cast<char*>(s);
    s[lane] = 10 * (lane + 1);
    b->sync(b);
    sums[lane] = s[0] + s[1] + s[2] + s[3];
    b->sync(b);
    char* big = b->scratch(b, 1 << 20);   // grows: `first` stays writable until the block ends
    ASSERT_NE(big, nullptr);
    first[lane] = 1;
    big[(1 << 20) - 1 - lane] = 2;
  }).ok());
  EXPECT_EQ(sums, (std::vector<int>{100, 100, 100, 100}));
  EXPECT_EQ(b->scratch(b, LaneBlockRunner::kMaxScratchBytes + 1), nullptr);
}

TEST(CpuLanes, ThreadRunnerIsKeptAndTrimGivesBackDeepStackPages) {
  LaneBlockRunner& runner = LaneBlockRunner::ForThisThread(2);
  EXPECT_EQ(&runner, &LaneBlockRunner::ForThisThread(2));
  const size_t page = static_cast<size_t>(sysconf(_SC_PAGESIZE));
  char* deep = nullptr;
  ASSERT_TRUE(runner.Run(2, [&](int lane) {
    char big[2 << 20];   // far below the kept top of the lane's stack
    std::memset(big, lane + 1, sizeof big);
    if (lane == 0) deep = big;
    asm volatile("" : : "r"(big) : "memory");
  }).ok());
  ASSERT_NE(deep, nullptr);
  char* page_of = reinterpret_cast<char*>(reinterpret_cast<uintptr_t>(deep) & ~(uintptr_t(page) - 1));
  unsigned char resident = 0;
  ASSERT_EQ(mincore(page_of, page, &resident), 0);
  EXPECT_EQ(resident & 1, 1);
  runner.Trim();
  ASSERT_EQ(mincore(page_of, page, &resident), 0);
  EXPECT_EQ(resident & 1, 0);
  // the stacks still work after the trim
  int ran = 0;
  ASSERT_TRUE(runner.Run(2, [&](int) { ++ran; }).ok());
  EXPECT_EQ(ran, 2);
}

// A lanes kernel by hand: each lane shares its flat index, and every lane writes the sum of
// its block's indices to out[i].
struct LaneArgs {
  int64_t* out;
};
void LaneSumForward(const wp::launch_context_t* ctx, const void* args, wp::int64 begin, wp::int64 end) {
  const auto* a = static_cast<const LaneArgs*>(args);
  wp::lane_block_t* b = ctx->lanes;
  for (wp::int64 i = begin; i < end; ++i) {
    if (!b) {
      a->out[i] = -1;
      continue;
    }
    auto* s = reinterpret_cast<int64_t*>(b->scratch(b, sizeof(int64_t) * static_cast<uint64_t>(b->dim)));
    s[b->lane] = i;
    b->sync(b);
    int64_t sum = 0;
    for (int l = 0; l < b->count; ++l)
      if (b->running[l]) sum += s[l];
    b->sync(b);
    a->out[i] = sum;
  }
}

TEST(CpuLanes, LaunchRunsBlocksOfLanesAndChecksBlockDim) {
  ThreadPool pool(2);
  auto module = std::make_shared<LoadedModule>();
  module->id = "lanes";
  module->function_names = {"prog.py:lane_sum"};
  LoadedKernel kernel;
  kernel.layout.name = "lane_sum";
  kernel.layout.lanes = 4;
  kernel.layout.args_size = sizeof(LaneArgs);
  kernel.cpu_forward = &LaneSumForward;
  std::vector<int64_t> out(10, 0);
  PackedArgs args;
  args.block = ArgBlock(sizeof(LaneArgs));
  LaneArgs la{out.data()};
  std::memcpy(args.block.data(), &la, sizeof la);

  CpuLaunch launch;
  launch.module = module.get();
  launch.kernel = &kernel;
  launch.dim = {10};
  launch.args = &args;
  launch.block_dim = 4;
  ASSERT_TRUE(RunCpuLaunch(pool, launch, nullptr).ok());
  // blocks [0..3], [4..7], [8, 9]
  EXPECT_EQ(out, (std::vector<int64_t>{6, 6, 6, 6, 22, 22, 22, 22, 17, 17}));

  launch.block_dim = 8;
  Status st = RunCpuLaunch(pool, launch, nullptr);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("compiled for CPU blocks of 4 threads"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("block_dim 8"), std::string::npos) << st.message();
}

}  // namespace
}  // namespace weft
