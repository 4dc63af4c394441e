// CoarsenMinThreads and CoarsenMaxLoadedBytes (engine/device/cuda_device.h): which GPU launches
// take a kernel's coarsened entry (docs/cuda.md, "Coarsened launches"), and the environment
// overrides a GPU reads when weftd initialises it. Runs without a GPU.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>

#include "engine/codegen/generate_module.h"
#include "engine/device/cuda_device.h"

namespace weft {
namespace {

class CoarsenRule : public ::testing::Test {
 protected:
  void SetUp() override { Clear(); }
  void TearDown() override { Clear(); }
  static void Clear() {
    unsetenv("WEFT_COARSEN");
    unsetenv("WEFT_COARSEN_MIN_THREADS");
    unsetenv("WEFT_COARSEN_MAX_LOADED_BYTES");
  }
};

TEST_F(CoarsenRule, TheCoarsenedGridStillFillsTheGpuTwice) {
  // An H200: 132 SMs of 2048 resident threads; 4 logical threads per GPU thread.
  EXPECT_EQ(CoarsenMinThreads(132, 2048), 2ull * kCoarseFactor * 132 * 2048);
  EXPECT_EQ(CoarsenMinThreads(132, 2048), 2'162'688u);
  EXPECT_EQ(CoarsenMinThreads(80, 1024), 2ull * kCoarseFactor * 80 * 1024);
  // A GPU whose attributes could not be read never coarsens.
  EXPECT_EQ(CoarsenMinThreads(0, 2048), 0u);
  EXPECT_EQ(CoarsenMinThreads(132, -1), 0u);
}

TEST_F(CoarsenRule, EnvironmentTurnsItOffOrMovesTheLimits) {
  setenv("WEFT_COARSEN", "0", 1);
  EXPECT_EQ(CoarsenMinThreads(132, 2048), 0u);
  setenv("WEFT_COARSEN", "1", 1);
  EXPECT_EQ(CoarsenMinThreads(132, 2048), 2'162'688u);
  setenv("WEFT_COARSEN_MIN_THREADS", "1000", 1);
  EXPECT_EQ(CoarsenMinThreads(132, 2048), 1000u);
  for (const char* bad : {"", "0", "-5", "12abc", "abc"}) {
    setenv("WEFT_COARSEN_MIN_THREADS", bad, 1);
    EXPECT_EQ(CoarsenMinThreads(132, 2048), 2'162'688u) << "'" << bad << "'";
  }
  EXPECT_EQ(CoarsenMaxLoadedBytes(), 12u);
  setenv("WEFT_COARSEN_MAX_LOADED_BYTES", "24", 1);
  EXPECT_EQ(CoarsenMaxLoadedBytes(), 24u);
  setenv("WEFT_COARSEN_MAX_LOADED_BYTES", "0", 1);
  EXPECT_EQ(CoarsenMaxLoadedBytes(), 0u);
  for (const char* bad : {"", "x", "16 ", "99999999999999999999"}) {
    setenv("WEFT_COARSEN_MAX_LOADED_BYTES", bad, 1);
    EXPECT_EQ(CoarsenMaxLoadedBytes(), 12u) << "'" << bad << "'";
  }
}

}  // namespace
}  // namespace weft
