// NeedsGridStride (engine/device/device.h): when a GPU launch needs the grid-stride variant of its
// module because one grid of at most max_blocks blocks (and at most 2^31 - 1) cannot cover it,
// including thread counts a client makes overflow.
#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "engine/device/device.h"

namespace weft {
namespace {

KernelLaunch Launch(std::vector<int64_t> dim, uint32_t block_dim = 0, uint32_t max_blocks = 0) {
  KernelLaunch l;
  l.dim = std::move(dim);
  l.block_dim = block_dim;
  l.max_blocks = max_blocks;
  return l;
}

TEST(LaunchGeometry, AGridThatCoversTheLaunchNeedsNoLoop) {
  EXPECT_FALSE(NeedsGridStride(Launch({1})));
  EXPECT_FALSE(NeedsGridStride(Launch({100'000'000})));
  EXPECT_FALSE(NeedsGridStride(Launch({512, 512, 4}, 1024)));
  // max_blocks at or above the blocks needed changes nothing: 10,007 threads are 40 blocks of 256
  EXPECT_FALSE(NeedsGridStride(Launch({10'007}, 0, 40)));
  EXPECT_FALSE(NeedsGridStride(Launch({10'007}, 256, 1'000)));
  // the largest grid without a loop: 2^31 - 1 blocks of 256
  EXPECT_FALSE(NeedsGridStride(Launch({int64_t{0x7fffffff} * 256})));
}

TEST(LaunchGeometry, ACapOrAnOversizedGridNeedsTheLoop) {
  EXPECT_TRUE(NeedsGridStride(Launch({10'007}, 0, 39)));
  EXPECT_TRUE(NeedsGridStride(Launch({10'007}, 64, 3)));
  EXPECT_TRUE(NeedsGridStride(Launch({1'000}, 256, 1)));
  EXPECT_TRUE(NeedsGridStride(Launch({2, 50, 10}, 0, 1)));
  EXPECT_TRUE(NeedsGridStride(Launch({int64_t{0x7fffffff} * 256 + 1})));
  EXPECT_TRUE(NeedsGridStride(Launch({int64_t{1} << 40}, 32)));
}

TEST(LaunchGeometry, OverflowingThreadCountsNeedTheLoopAndEmptyLaunchesNone) {
  // a product past 2^64 must not wrap to a small grid
  EXPECT_TRUE(NeedsGridStride(Launch({int64_t{1} << 40, int64_t{1} << 40})));
  EXPECT_TRUE(NeedsGridStride(Launch({INT64_MAX, INT64_MAX, 2, 2})));
  // a zero (or, refused elsewhere, negative) extent: nothing runs
  EXPECT_FALSE(NeedsGridStride(Launch({0}, 0, 1)));
  EXPECT_FALSE(NeedsGridStride(Launch({1'000'000, 0}, 0, 1)));
  EXPECT_FALSE(NeedsGridStride(Launch({-5}, 0, 1)));
}

}  // namespace
}  // namespace weft
