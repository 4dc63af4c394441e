// The daemon's core, called by the server's services: sessions, devices, arrays in shared
// memory, ordered command batches (copy, fill, launch, tape) per session, module compiles and
// statistics. No gRPC here: plain types in, Status/Expected out.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/device/device_set.h"
#include "engine/geometry/geometry_ops.h"
#include "engine/runtime/command_executor.h"
#include "engine/runtime/command_limits.h"
#include "engine/runtime/launch_watchdog.h"
#include "engine/runtime/commands.h"
#include "engine/runtime/device_info.h"
#include "engine/runtime/memory_quota.h"
#include "engine/runtime/module_store.h"
#include "engine/runtime/session.h"
#include "engine/runtime/shm_slab_pool.h"
#include "engine/runtime/thread_pool.h"

namespace weft {

struct EngineOptions {
  ModuleStoreOptions modules;     // used when no store is passed to Create
  int cpu_threads = 0;            // launch pool size; 0 = all cores
  bool allow_unchecked = false;   // modules may ask for "bounds_checks": "false"
  ShmSlabPoolOptions slabs;
  // Array memory limits (reserved bytes). memory.daemon == 0: the size of /dev/shm, at most
  // physical memory + swap.
  MemoryLimits memory;
  uint64_t print_capacity = 1 << 20;   // per launch
  bool remove_stale_slabs = true;
  CommandLimits limits;                     // per command / per session, checked at submit
  double launch_time_limit_s = 300;         // a launch running longer is stopped; 0 = none
  uint32_t max_sessions_per_principal = 256;   // OpenClientSession refuses more
  bool use_gpus = true;                     // create a CUDA device for every GPU that computes
  // This process serves one unchecked session (a session host, server/session_hosts.h): a GPU
  // lost to a kernel fault ends that session instead of waiting for a daemon restart.
  bool session_host = false;
  // This process serves the sessions of one device (a device host, server/session_hosts.h):
  // only that GPU gets a CUDA device here (-1: every GPU; a CPU device host sets use_gpus =
  // false), and a GPU lost to a fault ends the process, which the daemon starts again.
  int only_gpu = -1;
  bool device_host = false;
};

// Everything a client needs to know about an allocation (engine twin of weft.v1.ArrayInfo).
struct ArrayDesc {
  uint64_t handle = 0;
  DType dtype;
  std::vector<int64_t> shape;
  std::vector<int64_t> strides;
  std::string device;
  uint64_t byte_size = 0;
  uint64_t grad_handle = 0;
  bool pinned = false;        // a CPU array created with pinned=true
  bool page_locked = false;   // its memory is page-locked for the daemon's GPUs
  std::string shm_name;   // local sessions only
  uint64_t shm_offset = 0;
  uint64_t shm_size = 0;
  // GPU arrays, local sessions only: the slab's CUDA IPC handle (64 bytes), the offset of the
  // array inside the slab, the slab's size and id (open each slab once).
  std::string cuda_ipc_handle;
  uint64_t cuda_ipc_offset = 0;
  uint64_t cuda_slab_size = 0;
  uint64_t cuda_slab_id = 0;
};

struct CreateArrayParams {
  enum class Init { kEmpty = 0, kZeros = 1, kFill = 2, kData = 3 };
  DType dtype;
  std::vector<int64_t> shape;
  std::string device = "cpu";
  bool requires_grad = false;
  Init init = Init::kEmpty;
  std::string value;   // kFill: one element; kData: all bytes, C order
  // CPU arrays: a slab of its own, page-locked for the daemon's GPUs (PageLock); ignored on GPUs.
  bool pinned = false;
};

// One view of client GPU memory to import by CUDA IPC (weft.v1.CudaMemoryRef).
struct CudaMemoryRef {
  std::string ipc_handle;      // 64 bytes
  uint64_t allocation_id = 0;  // the client's buffer id of the allocation
  uint64_t byte_offset = 0;    // the array's start inside the allocation
};

struct CudaImportParams {
  std::string device;          // "cuda:N"
  DType dtype;
  std::vector<int64_t> shape;  // C-contiguous
  CudaMemoryRef data;
  bool has_grad = false;
  CudaMemoryRef grad;          // same dtype and shape
};

struct EngineStats {
  uint32_t sessions = 0;
  uint64_t arrays = 0;
  uint64_t array_bytes = 0;
  uint32_t cpu_slabs = 0;
  uint64_t cpu_slab_bytes = 0;
  uint64_t module_cache_hits = 0;
  uint64_t module_cache_disk_hits = 0;
  uint64_t module_cache_misses = 0;
  uint64_t sessions_opened_total = 0;
  uint64_t sessions_reaped_total = 0;
  uint32_t gpu_slabs = 0;            // every GPU together
  uint64_t gpu_slab_bytes = 0;
  uint64_t gpu_resets = 0;           // device resets after kernel faults
  double last_gpu_reset_ms = 0;
  uint64_t gpu_coarsened_launches = 0;   // launches that ran a coarsened entry, every GPU
  uint64_t commands_run_total = 0;   // commands the executors ran, all sessions
  double command_run_seconds = 0;    // their time in the executor (GPU: queueing, not running)
};

class Engine {
 public:
  // `store` may be injected (tests); otherwise ModuleStore::Create(options.modules).
  static Expected<std::unique_ptr<Engine>> Create(const EngineOptions& options,
                                                  std::unique_ptr<ModuleStore> store = nullptr);
  ~Engine();   // closes every session; the slab pool unlinks every slab
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  // Sessions. Ids are 256 random bits (getrandom) and secret: logs name sessions by label.
  // OpenSession opens without limits (tests, embedding); OpenClientSession is what the server
  // calls: RESOURCE_EXHAUSTED when the principal already has max_sessions_per_principal
  // sessions, UNAVAILABLE once the engine is stopping.
  std::shared_ptr<Session> OpenSession(const SessionOptions& options);
  Expected<std::shared_ptr<Session>> OpenClientSession(const SessionOptions& options);
  std::shared_ptr<Session> FindSession(const std::string& id) const;
  // Cancels the session's queued and running work, waits for it to stop, then frees everything
  // it held. `reaped`: the client went away without closing.
  Status CloseSession(const std::string& id, bool reaped = false);
  void CloseAllSessions();
  // Closes (as reaped) every session that no Attach stream claimed within `timeout` of its
  // opening; returns how many.
  size_t ReapUnattachedSessions(std::chrono::steady_clock::duration timeout);
  // Daemon shutdown, first step: cancels every session's work (running launches stop at their
  // next poll) and refuses new sessions. Sessions stay open until CloseAllSessions.
  void CancelAllSessions();

  std::vector<DeviceInfo> ListDevices() const;

  // Arrays.
  Expected<ArrayDesc> CreateArray(Session& s, const CreateArrayParams& p);
  // Ordered after the session's queued commands (released when the executor reaches it).
  Status FreeArray(Session& s, uint64_t handle);
  Expected<ArrayDesc> DescribeArray(Session& s, uint64_t handle) const;
  // Streams [offset, offset+count) (count 0 = to the end) in chunks of at most `chunk` bytes
  // (0 = 1 MiB) to sink(offset, data, size); a false return from sink stops early.
  // Waits for the session's queued commands first.
  // A geometry operation of the session (create / build / refit / rebuild / free a HashGrid,
  // Bvh or Mesh) on the device of its arrays; engine_geometry.cpp.
  Expected<uint64_t> RunGeometry(Session& s, const geometry::GeometryRequest& r);
  // The same operation run on the calling thread, which must be the session's executor (a
  // geometry command of a batch or a replayed graph).
  Expected<uint64_t> RunGeometryHere(Session& s, const geometry::GeometryRequest& r);
  Status ReadArray(Session& s, uint64_t handle, uint64_t offset, uint64_t count, uint32_t chunk,
                   const std::function<bool(uint64_t, const char*, size_t)>& sink);
  // Writes bytes at offset of the allocation (range-checked; nothing written on error).
  Status WriteArray(Session& s, uint64_t handle, uint64_t offset, const void* data, size_t size);
  Expected<std::string> ExportArray(Session& s, uint64_t handle);
  Expected<ArrayDesc> ImportArray(Session& s, const std::string& token);
  // An array over GPU memory of the session's client process, opened by CUDA IPC (local
  // sessions only; the view is checked against the opened allocation, sizes overflow-checked).
  // Kernels use it in place; it is not counted in the memory quotas (the client owns it).
  Expected<ArrayDesc> ImportCudaArray(Session& s, const CudaImportParams& p);

  // Commands: queued in order on the session's executor; errors surface at Synchronize.
  // With `run_here_when_idle`, a batch the session's queue is idle for runs on the calling
  // thread before this returns (the fast lane: its connection thread, no thread switch);
  // otherwise, and when the queue is busy, it is queued behind the others.
  Expected<uint64_t> Submit(Session& s, std::vector<Command> commands, bool run_here_when_idle = false);
  Session::SyncResult Synchronize(Session& s);
  // The GPU time (ms) between two records of the session's timing events on `device`
  // (TimedEventCommand), once the commands queued before this call ran and the session's work
  // on the GPUs finished (a command's error stays for the next Synchronize).
  Expected<double> EventElapsed(Session& s, const std::string& device, uint64_t start_id, uint64_t end_id);
  // The properties of kernel `kernel` of module `module_id` (compiled for `device`, a GPU) as
  // loaded there (CudaDevice::PropertiesOf). NotFound for an unknown module or kernel,
  // InvalidArgument for the CPU or a module compiled for another target.
  Expected<CudaDevice::KernelProperties> KernelPropertiesOf(Session& s, const std::string& module_id,
                                                            const std::string& kernel, const std::string& device);
  // Submit + Synchronize in one step (the fused sync point): when the session's executor is
  // idle the batch runs on the calling thread, saving two thread hand-offs.
  Expected<Session::SyncResult> SubmitAndSynchronize(Session& s, std::vector<Command> commands);
  // Submit, then wait until the executor has run the batch (GPU work queued, not finished).
  // Returns the synchronized result when the session has failed (its error), else nullopt.
  Expected<std::optional<Session::SyncResult>> SubmitAndRun(Session& s, std::vector<Command> commands);

  // Modules.
  Expected<std::shared_ptr<const LoadedModule>> Compile(Session& s, ModuleSource source,
                                                        const std::string& device, CompileReport* report);
  // Compile only, with NVRTC for sm_<arch> (no GPU needed): the CUBIN and a report per entry
  // point (ModuleStore::CompileForArch).
  Expected<CudaArchCompile> CompileForArch(Session& s, ModuleSource source, int arch, CompileReport* report);

  EngineStats Stats() const;
  const EngineOptions& options() const { return options_; }
  // A GPU of this process was lost to a fault the driver keeps (CudaDevice::lost).
  bool AnyGpuLost() const;
  // Reserved array bytes of the session, its principal and the daemon, and the limits.
  MemoryUsage MemoryUsageOf(const Session& s) const;
  const MemoryLimits& memory_limits() const { return quota_->limits(); }
  ThreadPool& pool() { return *pool_; }
  DeviceSet& devices() { return *devices_; }
  // The GPU the alias "cuda" means for the session ("" before its first use).
  std::string CudaPlacement(const Session& s) const { return devices_->Placement(s.id()); }

 private:
  Engine(const EngineOptions& options, std::unique_ptr<ModuleStore> store);
  static std::vector<std::string> DropUncheckedOptions(const Session& s, ModuleSource* source);
  static void WarnIgnoredOptions(const std::vector<std::string>& ignored, CompileReport* report);
  // The executor task of one batch (holds the batch's arrays until it has run).
  std::function<void()> BatchTask(Session& s, std::vector<Command> commands);
  // Checks a batch against the limits and counts it as queued (BatchTask uncounts it).
  Status AdmitBatch(Session& s, const std::vector<Command>& commands);
  // A new allocation owned by `owner` on `device`: quota reserved, memory from the owner's slabs.
  // `dedicated`: a slab of its own (pinned host memory).
  Expected<std::shared_ptr<Allocation>> NewAllocation(Session& owner, Device& device, const DType& dtype,
                                                      const std::vector<int64_t>& shape, bool zero,
                                                      bool dedicated = false);
  // Page-locks a CPU allocation in a slab of its own for every GPU (the first GPU that accepts
  // it registers it portably; unregistered before the memory returns to its pool). Without a
  // usable GPU the memory stays pageable (page_locked false).
  void PageLock(Allocation& a);
  // One imported allocation of ImportCudaArray (the view checked against the mapping).
  Expected<std::shared_ptr<Allocation>> ImportedAllocation(Session& s, CudaDevice& gpu, const DType& dtype,
                                                           const std::vector<int64_t>& shape, uint64_t bytes,
                                                           const CudaMemoryRef& ref, const char* what);
  // Moves an allocation's bytes into a slab of its own (before its first export).
  Status MoveToOwnSlab(Allocation& a, Session& owner);
  // Waits for the session's work on every GPU; the first asynchronous error becomes its error.
  void SynchronizeDevices(Session& s);
  ArrayDesc Describe(const Session& s, const Allocation& a) const;
  Expected<std::shared_ptr<Allocation>> Held(const Session& s, uint64_t handle) const;

  EngineOptions options_;
  std::unique_ptr<DeviceSet> devices_;   // destroyed last (declared first); made in the constructor
  std::unique_ptr<MemoryQuota> quota_;   // outlives every allocation (declared early)
  std::unique_ptr<ModuleStore> store_;
  std::unique_ptr<ThreadPool> pool_;
  std::unique_ptr<LaunchWatchdog> watchdog_;
  std::unique_ptr<CommandExecutor> executor_;
  // RunGeometry (queued on the session's executor) and RunGeometryHere (already on it).
  Expected<uint64_t> RunGeometryWith(Session& s, const geometry::GeometryRequest& r, bool queued);
  mutable std::mutex mu_;        // sessions_
  std::map<std::string, std::shared_ptr<Session>> sessions_;
  mutable std::mutex alloc_mu_;  // allocations_; never drop an Allocation while holding it
  std::map<uint64_t, std::weak_ptr<Allocation>> allocations_;   // every live allocation
  std::atomic<uint64_t> live_bytes_{0};
  std::atomic<uint64_t> next_handle_{1};
  std::atomic<uint64_t> sessions_opened_{0};
  std::atomic<uint64_t> sessions_reaped_{0};
  std::atomic<uint64_t> commands_run_{0};
  std::atomic<uint64_t> command_run_ns_{0};
  std::atomic<bool> stopping_{false};
  uint64_t memory_limit_ = 0;
};

}  // namespace weft
