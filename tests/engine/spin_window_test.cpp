// SpinWindow (server/spin_window.h): the fast lane's polling window follows the client's gaps
// between frames, within its bounds, and falls back when the client pauses.
#include "server/spin_window.h"

#include <gtest/gtest.h>

#include <random>

namespace weft::server {
namespace {

using std::chrono::microseconds;
using Clock = SpinWindow::Clock;

// Feeds `w` one frame: it arrives `gap` after the previous one was done, having woken the lane
// when the window was shorter than the gap (what the lane's receive does), and is served at once.
// Returns whether it woke the lane.
bool Frame(SpinWindow& w, Clock::time_point& now, Clock::duration gap) {
  const bool woke = gap > w.window();
  now += gap;
  w.FrameArrived(now, woke);
  w.FrameDone(now);
  return woke;
}

TEST(SpinWindow, StartsAtTheShortestAndStaysThereWhenNotAdaptive) {
  SpinWindow fixed(false);
  Clock::time_point now{};
  EXPECT_EQ(fixed.window(), SpinWindow::kShortest);
  for (int i = 0; i < 50; ++i) Frame(fixed, now, microseconds(150));
  EXPECT_EQ(fixed.window(), SpinWindow::kShortest);
}

TEST(SpinWindow, CoversAClientWhoseFramesComeInPairs) {
  // A training step: a long gap of the client's Python, then a second frame microseconds later.
  SpinWindow w;
  Clock::time_point now{};
  int woke_late = 0;
  for (int step = 0; step < 200; ++step) {
    const bool woke = Frame(w, now, microseconds(160));
    Frame(w, now, microseconds(3));
    if (step >= 10 && woke) ++woke_late;
  }
  EXPECT_EQ(woke_late, 0) << "after a few steps every long gap is inside the window";
  EXPECT_GE(w.window(), microseconds(160));
  EXPECT_LE(w.window(), SpinWindow::kLongest);
}

TEST(SpinWindow, FallsBackWhenTheClientPauses) {
  SpinWindow w;
  Clock::time_point now{};
  for (int i = 0; i < 20; ++i) Frame(w, now, microseconds(180));
  EXPECT_GT(w.window(), SpinWindow::kShortest);
  Frame(w, now, std::chrono::milliseconds(3));   // woke the lane after a pause
  EXPECT_EQ(w.window(), SpinWindow::kShortest);
}

TEST(SpinWindow, ShrinksTowardsShortGapsAndNeverLeavesItsBounds) {
  SpinWindow w;
  Clock::time_point now{};
  for (int i = 0; i < 20; ++i) Frame(w, now, microseconds(300));
  EXPECT_EQ(w.window(), SpinWindow::kLongest);
  for (int i = 0; i < 200; ++i) Frame(w, now, microseconds(5));
  EXPECT_LT(w.window(), microseconds(62));
  std::mt19937_64 rng(std::random_device{}());
  std::uniform_int_distribution<int> us(0, 5000);
  for (int i = 0; i < 100000; ++i) {
    Frame(w, now, microseconds(us(rng)));
    ASSERT_GE(w.window(), SpinWindow::kShortest);
    ASSERT_LE(w.window(), SpinWindow::kLongest);
  }
}

TEST(SpinWindow, TheFirstFrameLeavesTheWindowAlone) {
  SpinWindow w;
  w.FrameArrived(Clock::time_point{} + std::chrono::seconds(5), true);
  EXPECT_EQ(w.window(), SpinWindow::kShortest);
}

}  // namespace
}  // namespace weft::server
