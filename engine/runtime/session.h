// One client session: who it is (its principal), the arrays it holds, its ordered executor,
// the first error since the last synchronize, kernel print output, its autodiff tapes, whether
// its Attach stream has claimed it, and its cancellation flag (set when it closes: queued and
// running work stops).
// The id is a secret (whoever knows it may use the session); `label` ("#<n>") names the
// session in logs and is never accepted in place of the id.
// Threading: `mu` guards arrays/error/output; tapes are touched only on the executor thread.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "engine/core/module_source.h"
#include "engine/core/status.h"
#include "engine/device/activity_timing.h"
#include "engine/geometry/geometry_registry.h"
#include "engine/runtime/allocation.h"
#include "engine/runtime/commands.h"
#include "engine/runtime/serial_queue.h"
#include "engine/runtime/tape.h"

namespace weft {

// A session's command graph (GraphCommand, docs/graphs.md): its commands, the arrays they name
// (held for the graph's life, so a replay never meets a freed handle), and the device graph
// captured from them where the device has one (CudaDevice::Graph), else none: the commands are
// replayed one by one.
struct CommandGraph {
  std::string device;
  std::vector<Command> commands;
  std::unordered_map<uint64_t, std::shared_ptr<Allocation>> arrays;
  std::shared_ptr<void> device_graph;
};

struct SessionOptions {
  std::string client_name;
  int64_t client_pid = 0;
  bool local = false;          // unix-socket peer: gets shared-memory names
  std::string principal;       // who owns it: "unix-uid:<peer uid>" or "tcp-token"
};

class Session {
 public:
  Session(std::string id, std::string label, SessionOptions options)
      : id_(std::move(id)), label_(std::move(label)), options_(std::move(options)),
        opened_at_(std::chrono::steady_clock::now()) {}

  const std::string& id() const { return id_; }
  const std::string& label() const { return label_; }
  const SessionOptions& options() const { return options_; }
  std::chrono::steady_clock::time_point opened_at() const { return opened_at_; }

  // The first Attach stream claims the session; later ones are refused (false).
  bool ClaimAttach() { return !attached_.exchange(true); }
  bool attached() const { return attached_.load(); }

  // Cancellation: set once when the session closes (or the daemon stops). Queued batches are
  // skipped and running launches, fills and copies stop at their next check.
  void Cancel() { cancelled_.store(true); }
  bool cancelled() const { return cancelled_.load(std::memory_order_relaxed); }
  const std::atomic<bool>* cancel_flag() const { return &cancelled_; }

  // Commands submitted and not yet run (the per-session queue limit counts these).
  std::atomic<uint64_t> queued_commands{0};

  // Held arrays (array handles and gradient handles).
  std::shared_ptr<Allocation> Find(uint64_t handle) const;
  void Hold(const std::shared_ptr<Allocation>& a);   // also holds a->grad
  // Drops the hold on `handle` (and the gradients created for it). False when not held.
  bool Release(uint64_t handle);
  // a->grad = g (null: none). A gradient the daemon created for `a` stays held until `a` is
  // released (clients may still hold views of it); `g` is an array of this session.
  void ReplaceGrad(const std::shared_ptr<Allocation>& a, std::shared_ptr<Allocation> g);
  bool Holds(uint64_t handle) const;
  size_t array_count() const;
  // Drops every hold (session close).
  void ReleaseAll();

  // Errors: the first failure since the last TakeResult wins; later commands are skipped.
  bool failed() const;
  void Fail(const Status& s, const SourceLocation& origin);
  void CountSkipped();
  void AppendOutput(const std::string& text);
  struct SyncResult {
    Status error;
    SourceLocation origin;
    std::string output;
    // After a TimingCommand END: the timed GPU operations (none when a command failed).
    bool timing_ended = false;
    std::vector<TimedActivity> timing;
    uint64_t timing_dropped = 0;
  };
  SyncResult TakeResult();
  // The timed operations a synchronize collected after a TimingCommand END (TakeResult returns them).
  void SetTimingResult(std::vector<TimedActivity> timing, uint64_t dropped);

  SerialQueue& queue() { return queue_; }

  // Geometry objects (wp.HashGrid, wp.Bvh, wp.Mesh); dropped with the arrays at close.
  geometry::GeometryRegistry& geometry() { return geometry_; }

  // Executor-thread state.
  std::map<uint64_t, Tape> tapes;
  uint64_t active_tape = 0;   // 0 = none
  // Command graphs by the client's id (GraphCommand); launches while one is created or
  // replayed are not recorded on tapes (as Warp's graph launches).
  std::map<uint64_t, CommandGraph> graphs;
  bool in_graph = false;
  bool unchecked_allowed = false;
  // Set by a TimingCommand END (executor thread), taken by the next synchronize, which then
  // collects the session's timed GPU operations (Engine::SynchronizeDevices).
  std::atomic<bool> timing_collect{false};

 private:
  std::string id_;
  std::string label_;
  SessionOptions options_;
  std::chrono::steady_clock::time_point opened_at_;
  std::atomic<bool> attached_{false};
  std::atomic<bool> cancelled_{false};
  mutable std::mutex mu_;
  std::unordered_map<uint64_t, std::shared_ptr<Allocation>> arrays_;
  std::unordered_map<uint64_t, uint64_t> grad_owner_;   // grad handle -> array handle
  std::unordered_multimap<uint64_t, uint64_t> owned_grads_;   // array handle -> its grad handles
  Status error_;
  SourceLocation error_origin_;
  uint64_t skipped_ = 0;
  std::string output_;
  bool timing_ended_ = false;
  std::vector<TimedActivity> timing_;
  uint64_t timing_dropped_ = 0;
  SerialQueue queue_;
  geometry::GeometryRegistry geometry_;
};

}  // namespace weft
