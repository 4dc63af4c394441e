// Runs one queued command of a session on its executor thread: copy and fill over checked
// views, CPU kernel launches (forward and explicit adjoint, recorded on the active tape), and
// tape operations (begin/end, backward replay in reverse, zero, reset) and gradient
// replacement (set_grad).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>

#include "engine/core/status.h"
#include "engine/runtime/commands.h"
#include "engine/runtime/module_store.h"
#include "engine/runtime/session.h"
#include "engine/runtime/thread_pool.h"

namespace weft {

// The allocations a batch names, captured at submit time so a later Free cannot pull memory out
// from under a queued command.
using HandleSnapshot = std::unordered_map<uint64_t, std::shared_ptr<Allocation>>;

struct CommandExecutorOptions {
  uint64_t print_capacity = 1 << 20;
};

class CommandExecutor {
 public:
  CommandExecutor(ThreadPool& pool, ModuleStore* store, CommandExecutorOptions options)
      : pool_(pool), store_(store), options_(options) {}

  Status Execute(Session& s, const Command& c, const HandleSnapshot& handles);

 private:
  Status Copy(const CopyCommand& c, const HandleSnapshot& h);
  Status Fill(const FillCommand& c, const HandleSnapshot& h);
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
