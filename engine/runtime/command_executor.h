// Runs one queued command of a session on its executor thread: copy and fill over checked
// views, kernel launches (forward and explicit adjoint, recorded on the active tape), and
// tape operations (begin/end, backward replay in reverse, zero, reset) and gradient
// replacement (set_grad), CUDA activity timing, and geometry builds and refits (through the Engine). Every operation goes to the Device the arrays or the launch name
// (engine/device): the CPU runs it here, a GPU queues it on the session's stream. Cancellation
// and the per-launch time limit are the devices' (see cpu_device.h, cuda_device.h).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>

#include "engine/core/status.h"
#include "engine/runtime/commands.h"
#include "engine/device/device_set.h"
#include "engine/runtime/module_store.h"
#include "engine/runtime/session.h"

namespace weft {

// The allocations a batch names, captured at submit time so a later Free cannot pull memory out
// from under a queued command.
using HandleSnapshot = std::unordered_map<uint64_t, std::shared_ptr<Allocation>>;

class CommandExecutor {
 public:
  static constexpr size_t kMaxGraphsPerSession = 4096;   // GraphCommand CREATE
  // Runs a geometry operation on the calling thread (the session's executor), with the
  // session's device access (Engine::RunGeometryHere).
  using GeometryRunner = std::function<Status(Session&, const geometry::GeometryRequest&)>;
  CommandExecutor(DeviceSet& devices, ModuleStore* store, GeometryRunner geometry = nullptr)
      : devices_(devices), store_(store), geometry_(std::move(geometry)) {}

  Status Execute(Session& s, const Command& c, const HandleSnapshot& handles);

 private:
  Status Copy(Session& s, const CopyCommand& c, const HandleSnapshot& h);
  Status Fill(Session& s, const FillCommand& c, const HandleSnapshot& h);
  // The device of an allocation / of a copy (the GPU side when one side is a GPU).
  Expected<Device*> DeviceOf(const Allocation& a) const;
  Status ZeroGradients(Session& s, Tape& tape);
  Status Launch(Session& s, const LaunchCommand& c, const HandleSnapshot& h, const SourceLocation& origin);
  // A GPU launch of a kernel whose entries run one index per thread, when its grid cannot cover
  // it (max_blocks, more blocks than a grid holds): *module and *kernel become those of the
  // module's grid-stride variant (ModuleStore::WithGridStride). Otherwise, or where the module
  // was built lean on purpose (the device then refuses the launch), unchanged.
  // A launch the grid covers whose kernel accesses p[wp.tid()] of 1-D array parameters, each
  // holding at least as many elements as the launch has threads (TidIndicesInRange): the
  // module's trusted-index variant, whose entries skip those checks
  // (ModuleStore::WithTrustedTidIndices).
  Status UseGridStrideWhereNeeded(const Device& device, const std::string& module_id, const std::string& kernel_name,
                                  bool adjoint, const KernelLaunch& launch, std::shared_ptr<const LoadedModule>* module,
                                  const LoadedKernel** kernel);
  Status UseTrustedIndicesWhereProven(const std::string& module_id, const std::string& kernel_name, bool adjoint,
                                      const KernelLaunch& launch, std::shared_ptr<const LoadedModule>* module,
                                      const LoadedKernel** kernel);
  // Appends a forward launch (its packed arguments) to the session's active tape, unless it
  // runs from a graph.
  void RecordOnTape(Session& s, const LaunchCommand& c, const std::string& device, const SourceLocation& origin,
                    PackedArgs packed);
  Status TapeOp(Session& s, const TapeCommand& c, const HandleSnapshot& h);
  // GraphCommand: create (captured as a CUDA graph where the device and commands allow,
  // else kept as a list), launch, destroy.
  Status Graph(Session& s, const GraphCommand& c, const HandleSnapshot& h);
  Status Backward(Session& s, Tape& tape, const TapeCommand& c, const HandleSnapshot& h);
  Status SetGrad(Session& s, const SetGradCommand& c, const HandleSnapshot& h);
  Status CudaEvent(Session& s, const CudaEventCommand& c);
  Status CudaValue(Session& s, const CudaValueCommand& c, const HandleSnapshot& h);
  // TimingCommand: the filter of every GPU's stream of the session (0 at END); END asks the
  // next synchronize to collect the timed operations.
  Status Timing(Session& s, const TimingCommand& c);
  // TimedEventCommand: records or forgets a timing event of the session on a GPU.
  Status TimedEvent(Session& s, const TimedEventCommand& c);

  DeviceSet& devices_;
  ModuleStore* store_;
  GeometryRunner geometry_;
};

// Every array handle a command names (for the snapshot).
void CollectHandles(const Command& c, std::vector<uint64_t>* out);

// Whether the command still runs after an earlier command of the session failed: those that
// release something the client will not ask for again (a cuda_value WRITE releases a client
// stream waiting for it; a tape END stops the recording, as leaving `with tape:` does after an
// error in Warp; a tape FREE, a graph DESTROY and a geometry FREE drop what the client dropped).
bool RunsAfterFailure(const Command& c);

}  // namespace weft
