// Runs one queued command of a session on its executor thread: copy and fill over checked
// views, CPU kernel launches (forward and explicit adjoint, recorded on the active tape), and
// tape operations (begin/end, backward replay in reverse, zero, reset) and gradient
// replacement (set_grad). Launches, fills and copies stop when the session is cancelled;
// launches also at the per-launch time limit.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>

#include "engine/core/status.h"
#include "engine/runtime/commands.h"
#include "engine/runtime/cpu_launch.h"
#include "engine/runtime/launch_watchdog.h"
#include "engine/runtime/module_store.h"
#include "engine/runtime/session.h"
#include "engine/runtime/thread_pool.h"

namespace weft {

// The allocations a batch names, captured at submit time so a later Free cannot pull memory out
// from under a queued command.
using HandleSnapshot = std::unordered_map<uint64_t, std::shared_ptr<Allocation>>;

struct CommandExecutorOptions {
  uint64_t print_capacity = 1 << 20;
  LaunchWatchdog* watchdog = nullptr;   // cancels launches of closed sessions / past the time limit
  double launch_time_limit_s = 0;       // 0 = none
};

class CommandExecutor {
 public:
  CommandExecutor(ThreadPool& pool, ModuleStore* store, CommandExecutorOptions options)
      : pool_(pool), store_(store), options_(options) {}

  Status Execute(Session& s, const Command& c, const HandleSnapshot& handles);

 private:
  Status Copy(Session& s, const CopyCommand& c, const HandleSnapshot& h);
  Status Fill(Session& s, const FillCommand& c, const HandleSnapshot& h);
  // Runs a launch under the watchdog (session cancel + time limit).
  Status RunWatched(Session& s, CpuLaunch& launch, std::string* output);
  Status Launch(Session& s, const LaunchCommand& c, const HandleSnapshot& h, const SourceLocation& origin);
  Status TapeOp(Session& s, const TapeCommand& c, const HandleSnapshot& h);
  Status Backward(Session& s, Tape& tape, const TapeCommand& c, const HandleSnapshot& h);
  Status SetGrad(Session& s, const SetGradCommand& c, const HandleSnapshot& h);

  ThreadPool& pool_;
  ModuleStore* store_;
  CommandExecutorOptions options_;
};

// Every array handle a command names (for the snapshot).
void CollectHandles(const Command& c, std::vector<uint64_t>* out);

}  // namespace weft
