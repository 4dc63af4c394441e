// SpinWindow: how long a fast-lane thread polls for its client's next frame before it blocks,
// learnt from the client's gaps between frames (server/fast_lane.cpp; docs/protocol.md "Fast
// lane"). Header-only and clock-free (the caller passes the times) so that tests drive it.
#pragma once

#include <algorithm>
#include <chrono>

namespace weft::server {

// A frame that came while the lane polled (or before) gives the client's gap exactly: the
// window grows to twice it at once, or shrinks towards that by an eighth (frames often come in
// pairs, a long gap and then one of microseconds, and the window must still cover the long
// one). A frame that woke a sleeping lane gives the gap plus the thread's wake-up (tens to
// hundreds of microseconds on virtual machines), so the gap is not known: when that sum is at
// most kHotGap the window doubles, otherwise (the client paused) it falls back to kShortest.
// Always between kShortest and kLongest. Not adaptive: always kShortest.
class SpinWindow {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr Clock::duration kShortest = std::chrono::microseconds(60);
  static constexpr Clock::duration kLongest = std::chrono::microseconds(400);
  static constexpr Clock::duration kHotGap = std::chrono::milliseconds(1);

  explicit SpinWindow(bool adaptive = true) : adaptive_(adaptive) {}

  // A frame arrived at `now`; `woke_the_lane`: the lane thread had blocked for it.
  void FrameArrived(Clock::time_point now, bool woke_the_lane) {
    if (done_ == Clock::time_point{} || !adaptive_) return;
    const Clock::duration gap = now - done_;
    if (!woke_the_lane) {
      const Clock::duration target = std::clamp(2 * gap, kShortest, kLongest);
      window_ = target >= window_ ? target : window_ - (window_ - target) / 8;
    } else if (gap <= kHotGap) {
      window_ = std::min(2 * window_, kLongest);
    } else {
      window_ = kShortest;
    }
  }
  // The frame was served (and answered) at `now`: the client's next gap starts.
  void FrameDone(Clock::time_point now) { done_ = now; }
  Clock::duration window() const { return window_; }

 private:
  bool adaptive_;
  Clock::time_point done_{};
  Clock::duration window_ = kShortest;
};

}  // namespace weft::server
