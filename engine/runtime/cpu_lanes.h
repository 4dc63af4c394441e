// Cooperative CPU blocks (Warp's wp.config.enable_cpu_blocks): runs the block_dim threads of
// one block as fibers on the calling thread, each until its next lane_sync in turn, so that tile
// ops can combine the values of a block's lanes (engine/native/lanes.h). One LaneBlockRunner
// per worker thread (ForThisThread), kept across launches: its fiber stacks are reused block
// after block, and after a launch each stack gives back what lies below its top kKeepBytes.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "engine/core/status.h"
#include "engine/native/launch_abi.h"
#include "engine/runtime/fiber_switch.h"

namespace weft {

class LaneBlockRunner {
 public:
  // Stack of each lane's fiber, reserved (not committed) per lane.
  static constexpr size_t kStackBytes = size_t{8} << 20;
  // Most scratch memory one block may ask for.
  static constexpr uint64_t kMaxScratchBytes = uint64_t{256} << 20;

  explicit LaneBlockRunner(int dim);
  ~LaneBlockRunner();
  LaneBlockRunner(const LaneBlockRunner&) = delete;
  LaneBlockRunner& operator=(const LaneBlockRunner&) = delete;

  // Stack bytes (from the top) each lane keeps between launches; Trim releases the rest.
  static constexpr size_t kKeepBytes = size_t{32} << 10;

  // This thread's runner for blocks of `dim` lanes (made on first use, or when dim changes).
  static LaneBlockRunner& ForThisThread(int dim);

  // The block the lanes see (launch_context_t::lanes).
  wp::lane_block_t* block() { return &block_; }
  int dim() const { return dim_; }

  // Gives back the stack pages below each lane's top kKeepBytes (after a launch that went deep).
  void Trim();

  // Runs body(lane) for lanes [0, count) of one block (count <= dim), each on its own fiber,
  // and returns when every lane has returned. A lane that calls block()->sync waits until every
  // running lane called it as often. Fails only when stack memory cannot be reserved.
  Status Run(int count, const std::function<void(int)>& body);

 private:
  static void Sync(wp::lane_block_t* block);
  static char* Scratch(wp::lane_block_t* block, wp::uint64 bytes);
  static void Entry();

  int dim_;
  wp::lane_block_t block_{};
  FiberContext scheduler_;
  std::vector<FiberContext> fibers_;
  std::vector<void*> stacks_;              // mmap'd, a guard page below each
  std::vector<unsigned char> running_;     // lanes running at the start of this round
  std::vector<unsigned char> done_;        // lanes that returned
  std::vector<std::unique_ptr<char[]>> scratch_;   // the last is current; earlier ones live on
  uint64_t scratch_bytes_ = 0;                      //   until the block ends (lanes may hold them)
  const std::function<void(int)>* body_ = nullptr;
};

}  // namespace weft
