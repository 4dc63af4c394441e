// Fibers for cooperative CPU blocks: see cpu_lanes.h.
#include "engine/runtime/cpu_lanes.h"

#include <sys/mman.h>
#include <unistd.h>

#include <cstring>

namespace weft {

namespace {
// The runner whose fibers run on this thread (fibers never leave the thread that made them).
thread_local LaneBlockRunner* current_runner = nullptr;

size_t PageSize() {
  static const size_t page = static_cast<size_t>(sysconf(_SC_PAGESIZE));
  return page;
}
}  // namespace

LaneBlockRunner::LaneBlockRunner(int dim) : dim_(dim) {
  fibers_.resize(static_cast<size_t>(dim));
  running_.assign(static_cast<size_t>(dim), 0);
  done_.assign(static_cast<size_t>(dim), 0);
  block_.dim = dim;
  block_.running = running_.data();
  block_.sync = &LaneBlockRunner::Sync;
  block_.scratch = &LaneBlockRunner::Scratch;
  block_.runtime = this;
}

LaneBlockRunner& LaneBlockRunner::ForThisThread(int dim) {
  thread_local std::unique_ptr<LaneBlockRunner> runner;
  if (!runner || runner->dim() != dim) runner = std::make_unique<LaneBlockRunner>(dim);
  return *runner;
}

void LaneBlockRunner::Trim() {
  // A stack that went below its kept top has the page just below it resident (mincore: one
  // cheap call); only those are given back (madvise over 8 MiB costs even when nothing is there).
  const size_t page = PageSize();
  for (void* s : stacks_) {
    char* low = static_cast<char*>(s) + page;                    // above the guard page
    char* below_keep = low + kStackBytes - kKeepBytes - page;
    unsigned char resident = 0;
    if (mincore(below_keep, page, &resident) == 0 && (resident & 1) == 0) continue;
    madvise(low, kStackBytes - kKeepBytes, MADV_DONTNEED);
  }
}

LaneBlockRunner::~LaneBlockRunner() {
  for (void* s : stacks_) munmap(s, kStackBytes + PageSize());
}

void LaneBlockRunner::Sync(wp::lane_block_t* block) {
  auto* self = static_cast<LaneBlockRunner*>(block->runtime);
  FiberSwitch(&self->fibers_[static_cast<size_t>(block->lane)], &self->scheduler_);
}

char* LaneBlockRunner::Scratch(wp::lane_block_t* block, wp::uint64 bytes) {
  auto* self = static_cast<LaneBlockRunner*>(block->runtime);
  if (bytes > kMaxScratchBytes) return nullptr;
  if (bytes > self->scratch_bytes_ || self->scratch_.empty()) {
    uint64_t n = self->scratch_bytes_ ? self->scratch_bytes_ : 256;
    while (n < bytes) n *= 2;
    self->scratch_.emplace_back(new (std::nothrow) char[n]());
    if (!self->scratch_.back()) {
      self->scratch_.pop_back();
      return nullptr;
    }
    self->scratch_bytes_ = n;
  }
  return self->scratch_.back().get();
}

void LaneBlockRunner::Entry() {
  LaneBlockRunner* self = current_runner;
  const int lane = self->block_.lane;
  (*self->body_)(lane);
  self->done_[static_cast<size_t>(lane)] = 1;   // leaves the block at the next round
  FiberSwitch(&self->fibers_[static_cast<size_t>(lane)], &self->scheduler_);   // for good
  __builtin_trap();
}

Status LaneBlockRunner::Run(int count, const std::function<void(int)>& body) {
  if (count <= 0) return Status::Ok();
  if (count > dim_) count = dim_;
  const size_t guard = PageSize();
  while (stacks_.size() < static_cast<size_t>(count)) {
    void* p = mmap(nullptr, kStackBytes + guard, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE,
                   -1, 0);
    if (p == MAP_FAILED) return ResourceExhausted("cannot reserve stacks for the lanes of a CPU block");
    mprotect(p, guard, PROT_NONE);   // below the stack: an overflow faults instead of writing on
    stacks_.push_back(p);
  }
  body_ = &body;
  block_.count = count;
  LaneBlockRunner* outer = current_runner;
  current_runner = this;
  for (int l = 0; l < count; ++l) {
    FiberPrepare(&fibers_[static_cast<size_t>(l)], static_cast<char*>(stacks_[static_cast<size_t>(l)]) + guard,
                 kStackBytes, &LaneBlockRunner::Entry);
    done_[static_cast<size_t>(l)] = 0;
  }
  // Rounds: each running lane runs to its next sync (or its end); a sync returns in the next
  // round. The lanes that take part in a round (block_.running) are fixed at its start.
  for (;;) {
    int leader = -1;
    for (int l = 0; l < count; ++l) {
      running_[static_cast<size_t>(l)] = done_[static_cast<size_t>(l)] ? 0 : 1;
      if (leader < 0 && running_[static_cast<size_t>(l)]) leader = l;
    }
    if (leader < 0) break;
    block_.leader = leader;
    for (int l = 0; l < count; ++l) {
      if (!running_[static_cast<size_t>(l)]) continue;
      block_.lane = l;
      FiberSwitch(&scheduler_, &fibers_[static_cast<size_t>(l)]);
    }
  }
  current_runner = outer;
  body_ = nullptr;
  if (scratch_.size() > 1) scratch_.erase(scratch_.begin(), scratch_.end() - 1);
  return Status::Ok();
}

}  // namespace weft
