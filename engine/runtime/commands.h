// Commands a session submits in a batch (engine twins of weft.v1.Command and its kinds):
// copy, fill, kernel launch, autodiff tape operations, gradient replacement, geometry builds,
// CUDA activity timing. Plain data; the server converts them.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "engine/core/module_source.h"
#include "engine/core/status.h"
#include "engine/geometry/geometry_ops.h"
#include "engine/runtime/array_view.h"

namespace weft {

// One kernel argument: raw little-endian bytes, an array view (handle 0 = None) or a struct.
struct ArgValue {
  enum class Kind { kRaw, kArray, kStruct };
  Kind kind = Kind::kRaw;
  std::string raw;
  ArrayRef array;
  std::vector<ArgValue> fields;   // kStruct, declaration order
};

struct CopyCommand {
  ArrayRef dst;
  ArrayRef src;
};

struct FillCommand {
  ArrayRef dst;
  std::string value;   // one element's bytes
};

struct LaunchCommand {
  std::string module_id;
  std::string kernel;
  std::vector<int64_t> dim;
  std::vector<ArgValue> args;
  bool adjoint = false;             // run the kernel's adjoint with adj_args
  std::vector<ArgValue> adj_args;   // array slots: the arrays receiving/providing adjoints
  std::string device;               // "cpu", "cuda:N", "cuda" (the session's GPU)
  uint32_t block_dim = 0;           // GPU threads per block (0 = 256), Warp's block_dim
  uint32_t max_blocks = 0;          // GPU grid bound (0 = none), Warp's max_blocks
  bool record_only = false;         // validate and record on the active tape, do not run
};

struct TapeCommand {
  enum class Op { kBegin = 0, kEnd = 1, kBackward = 2, kZero = 3, kReset = 4, kFree = 5, kMark = 6 };
  Op op = Op::kBegin;
  uint64_t tape_id = 0;
  // kMark: appends marker `marker` (non-zero) to the tape's records (a client callback's place,
  // wp.Tape.record_func). kBackward: runs the adjoints older than marker `marker` (0: from the
  // newest record), stopping at the next older marker.
  uint64_t marker = 0;
  ArrayRef loss;                                     // handle 0 = none
  std::vector<std::pair<ArrayRef, ArrayRef>> seeds;  // (array, gradient value)
};

// Replaces array's gradient allocation by grad's (handle 0: array has no gradient after it).
struct SetGradCommand {
  ArrayRef array;
  ArrayRef grad;
};

// Ordering with a CUDA stream of the client process (docs/interop.md, "Ordering"): an
// interprocess event of the client (its cuIpcGetEventHandle bytes, 64), opened by the daemon
// once per session. kWait: the session's stream on `device` waits for the event's latest
// record; kRecord: the event is recorded on that stream (after the work queued before it);
// kShare: the event is opened and shared with the other sessions of the session's principal
// (wp.Event(interprocess=True)); an event opened otherwise stays the session's own.
struct CudaEventCommand {
  enum class Op { kWait = 0, kRecord = 1, kShare = 2 };
  Op op = Op::kWait;
  std::string device;   // "cuda:N" or "cuda"
  std::string handle;   // the event's IPC handle bytes
};

// Ordering with a CUDA stream of the client process without a round trip (docs/interop.md,
// "Ordering by stream memory operations"): element `index` of `order`, one of the session's
// GPU arrays of 8-byte elements, is a counter. kWait: the session's stream waits on the GPU
// until it holds at least `value`; kWrite: the stream writes `value` after the work before it
// (run even after an earlier command failed: it releases a waiting client stream).
struct CudaValueCommand {
  enum class Op { kWait = 0, kWrite = 1 };
  Op op = Op::kWait;
  ArrayRef order;
  uint32_t index = 0;
  uint64_t value = 0;
};

// CUDA activity timing (wp.timing_begin / timing_end): kBegin times the session's later GPU
// operations whose kind is in `filter` (kTiming* bits); kEnd stops and asks the next synchronize
// to collect them (cuda_device.h, SetTiming / TakeTiming).
struct TimingCommand {
  enum class Op { kBegin = 0, kEnd = 1 };
  Op op = Op::kBegin;
  uint32_t filter = 0;
};

// A timing event of the session (wp.Event(enable_timing=True)): kRecord records the daemon's
// CUDA event `event_id` (private to the session, made at its first record) on the session's
// stream of `device`; kDestroy forgets it. Engine::EventElapsed reads the time between two.
struct TimedEventCommand {
  enum class Op { kRecord = 0, kDestroy = 1 };
  Op op = Op::kRecord;
  uint64_t event_id = 0;
  std::string device;   // "cuda:N" or "cuda"
};

struct Command;

// A graph of the session's commands (a captured wp.Graph, docs/graphs.md), by an id the client
// chooses (private to its session). kCreate: `commands` (launches, copies, fills; no graphs)
// become graph `graph_id` on `device`: on a GPU, a CUDA graph captured on the session's stream
// where every command can be captured, else the list, replayed command by command. kLaunch
// runs it; kDestroy forgets it.
struct GraphCommand {
  enum class Op { kCreate = 0, kLaunch = 1, kDestroy = 2 };
  Op op = Op::kLaunch;
  uint64_t graph_id = 0;
  std::string device;              // kCreate: "cpu", "cuda:N", "cuda"
  std::vector<Command> commands;   // kCreate
};

// INVALID_ARGUMENT for an op value outside TapeCommand::Op (a client may send any number).
Status CheckTapeOp(TapeCommand::Op op);

// A geometry build, refit or rebuild (geometry::GeometryRequest ops kBuildHashGrid, kRefit,
// kRebuild) run in order with the session's other commands (a captured graph's client replays
// one between its runs of launches).
struct GeometryCommand {
  geometry::GeometryRequest request;
};

struct Command {
  std::variant<CopyCommand, FillCommand, LaunchCommand, TapeCommand, SetGradCommand, CudaEventCommand,
               CudaValueCommand, GraphCommand, GeometryCommand, TimingCommand,
               TimedEventCommand>
      kind;
  SourceLocation origin;   // where the client issued it
};

}  // namespace weft
