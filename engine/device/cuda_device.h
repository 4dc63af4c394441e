// One GPU as a Device: the device's primary context (retained for the daemon's life, rebuilt
// after a fault), memory in slabs of driver allocations (cuMemAlloc) sub-allocated first-fit
// per owner like the CPU slabs and each exported once for CUDA IPC (cuIpcGetMemHandle), one
// non-blocking stream per session, modules loaded lazily per module id from the CUBIN the
// module store built, built-in strided copy/fill kernels (NVRTC, compiled on first use), and
// asynchronous launch errors: each launch gets its own error slot in device memory, read back
// at Synchronize and reported like the CPU's (kernel, array, index, shape, file:line).
// Cancellation: every stream has a cancel word in device memory that kernels poll at loop
// back-edges; Synchronize waits in bounded steps and sets it when the session is closing or the
// launch time limit has passed. A sticky fault (illegal address, __trap) resets the device:
// streams, modules and memory of the old context are dropped, the primary context is reset and
// retained again; blocks and streams of the old generation report "device was reset". When the
// driver keeps the sticky error through the reset (driver 580 does: the process must end), the
// device is marked lost: its sessions get a clear error, the CPU and other GPUs keep serving.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "engine/device/activity_timing.h"
#include "engine/device/cuda_driver.h"
#include "engine/device/device.h"
#include "engine/device/imported_memory.h"

namespace weft {

// The first 8 bytes of a client's CUDA IPC handle (memory or event) in hex, for error messages.
std::string IpcHandlePrefix(const std::string& handle);

struct wp_launch_error;   // wp::launch_error_t (engine/native/launch_abi.h), kept opaque here
struct StreamSignal;      // wakes a synchronize blocked on a stream (cuda_device.cpp)

struct CudaDeviceOptions {
  int ordinal = 0;
  uint64_t slab_size = 64ull << 20;
  uint64_t dedicated_threshold = 16ull << 20;
  // Empty dedicated slabs a live session keeps for its next big arrays (bytes per session); a
  // slab whose IPC handle may have gone to another session (an exported array) is never kept.
  uint64_t dedicated_cache_bytes = 1ull << 30;
  double launch_time_limit_s = 0;     // 0 = none
  // This process serves one session and ends with it (a session host): a device lost to a
  // fault is not worth a daemon restart, and the messages say so.
  bool process_ends_with_session = false;
  // This process serves every session of this device (a device host): a device lost to a fault
  // ends the process, and the messages say so.
  bool process_of_device = false;
  // Compiles CUDA C++ for sm_XX to a loadable image (NVRTC through the module store).
  std::function<Expected<std::string>(const std::string& source, const std::string& name, int sm)> compile;
};

// The CUDA source of the device's built-in kernels (strided copy and fill, radix sort, BVH build
// and refit, hash grid build), compiled by NVRTC on first use.
std::string CudaBuiltinSource();

// Blocks of `block` threads for n items (at least 1, at most max_blocks when > 0: the built-in
// kernels loop over the rest with a grid stride).
inline unsigned GridFor(uint64_t n, unsigned block, uint64_t max_blocks) {
  uint64_t g = (n + block - 1) / block;
  if (max_blocks > 0 && g > max_blocks) g = max_blocks;
  if (g > 0x7fffffffull) g = 0x7fffffffull;
  return static_cast<unsigned>(g ? g : 1);
}

struct CudaDeviceStats {
  uint64_t resets = 0;
  double last_reset_ms = 0;
  uint64_t coarsened_launches = 0;   // launches that ran a kernel's coarsened entry
};

// The fewest threads of a 1-D launch that take a kernel's coarsened entry (KernelLayout::
// coarse_symbol) on a GPU of `sms` multiprocessors of `threads_per_sm` resident threads each:
// enough that the coarsened grid still fills the GPU twice over, so a compute-bound kernel keeps
// its parallelism. WEFT_COARSEN_MIN_THREADS=N overrides it; WEFT_COARSEN=0 turns the entry off.
uint64_t CoarsenMinThreads(int sms, int threads_per_sm);
// The most bytes a kernel may load per thread at wp.tid() (KernelLayout::coarse_loaded_bytes)
// and still take its coarsened entry: 12 (WEFT_COARSEN_MAX_LOADED_BYTES=N overrides it).
// Measured on an H200 (bench/prof_coarsen.py, docs/cuda.md "Coarsened launches"): kernels
// loading 4, 8 and 12 bytes per thread ran 1.37, 1.22 and 1.10x faster at 1e8 threads, those
// loading 16 (a float64 axpy, a vec4) and 24 (a vec3 integration) 0.93-0.98x.
uint32_t CoarsenMaxLoadedBytes();

class CudaDevice final : public Device {
 public:
  static Expected<std::unique_ptr<CudaDevice>> Create(const CudaDeviceOptions& options);
  ~CudaDevice() override;

  const std::string& name() const override { return name_; }
  bool is_cpu() const override { return false; }
  int sm() const { return sm_; }
  int ordinal() const { return options_.ordinal; }
  jit::CuContext context() const { return ctx_; }
  // Other GPUs (peer copies).
  void SetPeers(std::vector<CudaDevice*> peers) { peers_ = std::move(peers); }

  uint64_t ReservedSize(uint64_t bytes) const override;
  Expected<MemoryBlock> Allocate(uint64_t bytes, const std::string& owner, bool dedicated) override;
  void MarkShared(const MemoryBlock& block) override;
  void Free(const MemoryBlock& block) override;
  uint64_t SlabBytes() const override;
  uint32_t SlabCount() const override;

  Status Upload(Session& s, const MemoryBlock& dst, uint64_t offset, const void* src, uint64_t n) override;
  Status Download(Session& s, const MemoryBlock& src, uint64_t offset, void* dst, uint64_t n) override;
  Status CopyBlock(Session& s, const MemoryBlock& dst, const MemoryBlock& src, uint64_t n) override;
  Status Fill(Session& s, const ArrayView& dst, const std::string& value) override;
  Status Copy(Session& s, const ArrayView& dst, const ArrayView& src) override;
  Status Launch(Session& s, const KernelLaunch& launch, std::string* output) override;
  DeviceSyncResult Synchronize(Session& s) override;
  Status RefitBvh(Session& s, const geometry::BvhRefitJob& job) override;
  Status BuildHashGrid(Session& s, const geometry::HashGridBuildJob& job) override;   // cuda_device_hash_grid.cpp
  Status BuildBvh(Session& s, const geometry::BvhBuildJob& job) override;             // cuda_device_bvh.cpp
  Status CheckMeshIndices(Session& s, const geometry::MeshIndicesJob& job) override;  // cuda_device_bvh.cpp
  void CloseSession(Session& s) override;

  // CUDA IPC import of a client process's allocation (cuda_device_import.cpp): the open
  // mapping of `handle` (64 bytes) for `session_id`, from the session's cache when the same
  // handle and allocation identity were imported before. Errors: a handle of the wrong size, one
  // naming this daemon's own memory, one another session imported, one the driver cannot open
  // (forged, freed, not cudaMalloc memory), memory the driver reports on another GPU (with
  // the peer-access flag the driver requires, another GPU's memory is usually mapped here and
  // reported as this GPU's: the client checks the device, docs/interop.md).
  Expected<std::shared_ptr<ImportedMemory>> OpenImport(const std::string& session_id, const std::string& handle,
                                                       uint64_t identity);
  // Open imported allocations (stats, tests).
  size_t ImportCount() const;
  uint64_t ImportOpens() const { return import_opens_.load(); }

  // Cross-process ordering (cuda_device_events.cpp): `handle` (64 bytes) is an interprocess
  // event of a client process, opened once per session (the session's 16 most recently used
  // events stay open; all close with the session). kWait: the session's stream waits for the
  // event's latest record (cuStreamWaitEvent); kRecord: the event is recorded on the session's
  // stream; kShare: only opened, and shared. The first session to open a handle owns it; another
  // session may use it only when the owner shared it (kShare: wp.Event(interprocess=True)) and
  // both sessions have the same principal. Errors: a handle of the wrong size, one another
  // session owns and did not share with this one, one the driver cannot open (forged, of a
  // process that is gone, not interprocess), an event the driver refuses to wait on or record
  // here (another GPU's event).
  enum class EventUse { kWait, kRecord, kShare };
  Status IpcEvent(Session& s, const std::string& handle, EventUse use);
  size_t IpcEventCount() const;      // open events of every session (tests)

  // Pinned host arrays (Engine::PageLock): page-locks [p, p + bytes) for every context
  // (cuMemHostRegister, portable), so copies between it and the GPUs are DMA; false where the
  // device is unusable or the driver refuses (the memory stays pageable). UnregisterHost undoes
  // it before the memory is reused (errors ignored: a reset took the registration with it).
  bool RegisterHost(void* p, uint64_t bytes);
  void UnregisterHost(void* p);

  // Cross-process ordering without a round trip (cuda_device_values.cpp): the 8-byte counter at
  // `byte_offset` in `order` (a block of the session's on this device). write=false: the
  // session's stream waits until it holds at least `value` (cuStreamWaitValue64 GEQ; remembered,
  // with `keep`, until the stream is idle, so the daemon can release it); write=true: the stream
  // writes `value` after the work queued before. FAILED_PRECONDITION where the device or driver
  // has no 64-bit stream memory operations.
  Status StreamValue(Session& s, const MemoryBlock& order, uint64_t byte_offset, uint64_t value, bool write,
                     std::shared_ptr<const void> keep);
  bool StreamMemOpsSupported() const;

  // CUDA graphs of a session's commands (cuda_device_graphs.cpp, docs/graphs.md). A Graph owns
  // the instantiated graph, its own error slots (one per launch, copied into the stream's after
  // each replay so errors read back as a plain launch's), and the launches' names and origins.
  class Graph;
  // Whether the driver has what capture needs.
  bool GraphsSupported() const;
  // Starts recording the session's stream: until EndCapture the operations queued on it (launches,
  // fills, copies on this GPU) are captured, not run. A launch then uses the capture's error slots.
  Status BeginCapture(Session& s);
  // Ends the capture. `keep` false (a command failed) discards it. Errors (the capture is dropped):
  // more launches than error slots, a launch that would read the session's geometry table, an
  // operation the driver could not capture or instantiate.
  Expected<std::shared_ptr<Graph>> EndCapture(Session& s, bool keep);
  // Queues one replay of `g` (captured for this session on this device) on the session's stream.
  Status LaunchGraph(Session& s, Graph& g);

  // CUDA activity timing (cuda_device_timing.cpp, docs/cuda.md "Activity timing"): from now on
  // the session's operations on this GPU whose kind is in `filter` (kTiming* bits; 0 stops) are
  // timed by a pair of events on its stream; a non-zero filter first discards what was recorded
  // and not collected. Operations queued while the stream captures a graph are not timed (the
  // graph's launch is).
  Status SetTiming(Session& s, uint32_t filter);
  // Once the session's stream here is idle (after a synchronize): the timed operations in the
  // order the stream ran them appended to `out` (`keep`; else discarded), `dropped` += those not
  // timed past kMaxTimedActivities; the records are cleared and their events kept for reuse.
  void TakeTiming(Session& s, std::vector<TimedActivity>* out, uint64_t* dropped, bool keep);

  // Timing events of a session (wp.Event(enable_timing=True), cuda_device_timing.cpp): event
  // `id` (the session's own; made at its first record, at most kTimedEventsPerSession) recorded
  // on the session's stream; forgotten; the milliseconds between two records once both
  // completed (the caller waited for the stream). Errors: more events than the limit, an id
  // never recorded or destroyed, a device reset since a record, a record not yet complete.
  Status RecordTimedEvent(Session& s, uint64_t id);
  void DestroyTimedEvent(Session& s, uint64_t id);
  Expected<double> TimedEventElapsed(Session& s, uint64_t start_id, uint64_t end_id);
  size_t TimedEventCount() const;   // every session's (tests)
  static constexpr size_t kTimedEventsPerSession = 4096;

  // The properties of a kernel's forward entry as loaded on this GPU (wp.get_cuda_kernel_properties,
  // wp.get_suggested_block_size): registers and local memory per thread, static shared memory,
  // the most threads a block may have, and the occupancy API's block size with the fewest blocks
  // that fill the GPU at it (0, 0 where the driver lacks that API).
  struct KernelProperties {
    int register_count = 0;
    int local_memory_size = 0;
    int shared_memory_size = 0;
    int max_threads_per_block = 0;
    int suggested_block_size = 0;
    int min_grid_size = 0;
  };
  Expected<KernelProperties> PropertiesOf(const LoadedModule& module, const LoadedKernel& kernel);

  CudaDeviceStats stats() const;
  // True once a fault left the device unusable for the rest of this process (the driver kept
  // the sticky error through the context reset); every operation then fails with the reason.
  bool lost() const { return lost_.load(); }

 private:
  // Launch, with `trace` (WEFT_LANE_TRACE): the driver call timed into frame_trace.
  Status LaunchTraced(Session& s, const KernelLaunch& launch, std::string* output, bool trace);
  struct Slab {
    uint64_t id = 0;
    jit::CuDevicePtr base = 0;
    uint64_t size = 0;
    bool dedicated = false;
    std::string owner;
    uint64_t used = 0;
    std::map<uint64_t, uint64_t> free_ranges;   // offset -> size
    std::string ipc;
    bool shared = false;   // its IPC handle may have gone to another session: never reused
    bool cached = false;   // an empty dedicated slab kept for its owner's next big array
  };
  struct Pending {
    std::shared_ptr<const LoadedModule> module;
    const LoadedKernel* kernel = nullptr;
    bool adjoint = false;
    SourceLocation origin;
  };
  struct Stream {
    uint64_t generation = 0;
    jit::CuStream stream = nullptr;
    // One device allocation: the print buffer's header (wp::print_buffer_t, kPrintHeader
    // bytes) then kErrorSlots launch_error_t; read back together into `readback` (pinned) at a
    // synchronize when a kernel set `report_host` (below).
    jit::CuDevicePtr errors_base = 0;
    jit::CuDevicePtr errors = 0;      // errors_base + kPrintHeader
    char* readback = nullptr;         // pinned: header, then the slots
    wp_launch_error* errors_host = nullptr;   // readback + kPrintHeader, read after the stream finished
    jit::CuDevicePtr print_data = 0;  // kPrintCapacity bytes of print records
    std::vector<Pending> pending;     // launches since the last drain, slot = index
    // The cancel word kernels poll (cg_loop_poll) is device memory, in the print header's
    // block (errors_base + kCancelOffset): a poll is an L2 read. The daemon sets it while a
    // kernel runs with a copy from `cancel_host` (pinned, holds 1) on `cancel_stream`, which
    // the copy engine runs beside the kernel; it is cleared on the stream once the wait ends.
    int32_t* cancel_host = nullptr;
    jit::CuStream cancel_stream = nullptr;
    // A word of mapped pinned memory the stream's kernels set (launch_context_t::report_flag)
    // when they report an error or print: the slots and the print header are read back at a
    // synchronize only then. Cleared by the daemon after a read-back, while the stream is idle.
    // Null where mapped host memory could not be had: then every synchronize reads back.
    volatile int32_t* report_host = nullptr;
    jit::CuDevicePtr report_device = 0;
    bool cancel_set = false;
    std::string first_error_text;
    // The session's geometry table in device memory (cuda_device_geometry.cpp): reused while
    // its objects do not change; a replaced one is retired and freed once the stream is idle.
    struct GeometryUpload {
      jit::CuDevicePtr memory = 0;
      std::string image;                   // header + descriptors, alive until freed
      std::shared_ptr<const void> keep;    // the objects the descriptors point into
    };
    GeometryUpload geometry;
    std::vector<GeometryUpload> geometry_retired;
    // cuStreamWaitValue64 waits queued since the stream was last idle: address -> the value
    // waited for (the largest) and the allocation it lies in, kept alive until released.
    struct ValueWait {
      uint64_t value = 0;
      std::shared_ptr<const void> keep;
    };
    std::mutex value_waits_mu;
    std::map<jit::CuDevicePtr, ValueWait> value_waits;
    // While a graph is being captured on this stream (BeginCapture .. EndCapture).
    struct Capture {
      jit::CuDevicePtr slots = 0;      // kErrorSlots launch_error_t, zeroed
      std::vector<Pending> launches;   // slot = index
      std::string refused;             // why the capture cannot become a graph
    };
    std::unique_ptr<Capture> capture;
    // Activity timing (cuda_device_timing.cpp): the session's filter on this GPU (kTiming* bits),
    // the operations timed since the last collection (two events each, at most
    // kMaxTimedActivities), events kept for reuse, and the operations past the limit.
    std::atomic<uint32_t> timing_filter{0};
    struct Timed {
      std::string name;
      uint32_t filter = 0;
      jit::CuEvent start = nullptr;
      jit::CuEvent end = nullptr;
    };
    std::mutex timing_mu;   // timed, spare_events, timing_dropped
    std::vector<Timed> timed;
    std::vector<jit::CuEvent> spare_events;
    uint64_t timing_dropped = 0;
    // Set by a host function queued on the stream when a synchronize stops spinning
    // (WaitStream); the host functions in flight hold it too, so it outlives the stream.
    std::shared_ptr<StreamSignal> signal;
  };
  // One operation timed on a stream (RAII, cuda_device_timing.cpp): its start event recorded
  // at construction when the stream times `filter` and is not capturing, its end event and its
  // record at destruction. The name ("memcpy HtoD", "forward kernel " + the kernel's name) is
  // built only when it is timed.
  class TimedSpan {
   public:
    TimedSpan(CudaDevice& device, Stream& st, uint32_t filter, const char* name, const std::string& suffix = {});
    ~TimedSpan();
    TimedSpan(const TimedSpan&) = delete;
    TimedSpan& operator=(const TimedSpan&) = delete;

   private:
    CudaDevice& device_;
    Stream& st_;
    Stream::Timed record_;
  };
  // A timing event of `st` (a spare one, else a new one); nullptr when the driver refuses.
  jit::CuEvent TimingEventLocked(Stream& st);
  // The stream's timed records' events back to its spares (at most kSpareTimingEvents kept).
  void RecycleTimingLocked(Stream& st);
  static constexpr size_t kSpareTimingEvents = 1024;
  struct TimedEvent {
    jit::CuEvent event = nullptr;
    uint64_t generation = 0;   // the context it lives in
  };
  mutable std::mutex timed_events_mu_;
  std::unordered_map<std::string, std::unordered_map<uint64_t, TimedEvent>> timed_events_;   // by session id
  // Destroys the session's timing events (session close).
  void ForgetTimedEvents(const std::string& session_id);
  std::unordered_map<std::string, uint32_t> timing_filters_;   // by session id (mu_): for streams made later
  struct CuModuleEntry {
    jit::CuModule module = nullptr;
    std::unordered_map<std::string, jit::CuFunction> functions;
  };
  static constexpr uint32_t kErrorSlots = 1024;
  static constexpr uint64_t kPrintHeader = 64;
  static constexpr uint64_t kCancelOffset = 48;   // in the print header's block, past print_buffer_t
  static constexpr uint64_t kPrintCapacity = 1 << 20;   // print records between two synchronizes

  explicit CudaDevice(CudaDeviceOptions options);
  Status Init();
  Status MakeCurrent() const;
  Expected<Stream*> StreamOf(const std::string& session_id);   // created on first use (mu_ not held)
  Stream* FindStream(const std::string& session_id);
  void DestroyStream(Stream& st);
  Expected<Slab*> NewSlabLocked(uint64_t size, bool dedicated, const std::string& owner);
  // A cached dedicated slab of `owner` for `need` bytes (at most half of it unused), or nullptr.
  Slab* TakeCachedLocked(uint64_t need, const std::string& owner);
  void DropCachedLocked();   // every cached slab back to the driver (before an allocation fails)
  Status CheckBlock(const MemoryBlock& b, const std::string& what) const;
  Status CheckUsable() const;
  Expected<jit::CuFunction> Function(const LoadedModule& module, const std::string& symbol);
  Expected<jit::CuFunction> Builtin(const char* name);
  // Waits for the stream: polls it (yielding the core) for WEFT_STREAM_SPIN_US (default 20000),
  // then blocks until a host function queued on the stream signals, waking every millisecond to
  // check the session and the time limit (WEFT_STREAM_WAIT=poll: polls with 100 us sleeps
  // instead, as where the driver lacks cuLaunchHostFunc). Sets the cancel word when `s` is
  // cancelled or the time limit passes. Returns the CUDA result and why the cancel word was set
  // (0 none, 1 session, 2 limit).
  jit::CuResult WaitStream(Session& s, Stream& st, int* cancel_reason);
  // Writes every pending wait's value (from the cancel stream), so a wait the client never
  // satisfies cannot hold the stream; then forgets them.
  void ReleaseValueWaits(Stream& st);
  // The stream went idle: its waits were satisfied.
  void ForgetValueWaits(Stream& st);
  // After a wait that set the cancel word: clears it (ordered before the stream's next work).
  Status ClearCancel(Stream& st);
  // Waits for the stream and drains its error slots when fewer than `n` are free.
  Status MakeRoom(Session& s, Stream& st, size_t n);
  // Queues the read-back of the pending launches' error slots (before waiting for the stream).
  Status QueueErrorReadback(Stream& st);
  // After the stream went idle: reads the slots and the print header back when a kernel set
  // the stream's report flag (else they are known to be clear), then drains them.
  DeviceSyncResult ReadBackAndDrain(Stream& st);
  // After the wait: the first error of the pending launches (or Ok); their slots are cleared.
  DeviceSyncResult Drain(Stream& st);
  // After a sticky fault: a fresh context. Called without locks held. `cause` names the fault
  // in the lost-device message when the context cannot be brought back. When it cannot, every
  // other GPU of the daemon is probed (ProbeAfterFaultOn): the driver may keep the error for
  // all of the process's contexts.
  void Reset(uint64_t faulted_generation, const std::string& cause = "a kernel faulted");
  // A tiny allocation + memset + synchronize on this GPU after `faulted` could not be brought
  // back; a sticky error here resets (and, failing that, marks lost) this GPU too.
  void ProbeAfterFaultOn(const std::string& faulted);
  Status StridedCopyOnDevice(Stream& st, const ArrayView& dst, const ArrayView& src);
  // A stable radix sort of n (key, id) pairs by the keys' low `bits` bits (cuda_device_sort.cpp):
  // the pairs start in keys[*cur] / ids[*cur] and end in the buffers *cur names then; hist holds
  // geometry::SortHistogramBytes(n).
  struct SortBuffers {
    jit::CuDevicePtr keys[2];
    jit::CuDevicePtr ids[2];
    jit::CuDevicePtr hist;
  };
  Status SortPairs(Stream& st, const SortBuffers& b, int64_t n, int bits, int* cur);
  // A grouped device BVH build's group step (cuda_device_bvh.cpp): the items (ids[0], in code
  // order) sorted stably by group, keys[1] = their codes in that order, ids[1] = the dense rank
  // of each one's group, and job.group_ids filled (ascending, the rest INT32_MAX).
  Status GroupRanks(Stream& st, const geometry::BvhBuildJob& job, const SortBuffers& b, jit::CuDevicePtr codes_by_item);
  // Node bounds bottom-up from the leaves of a device-built BVH (cuda_device_bvh.cpp).
  Status BvhBoundsUp(Stream& st, const geometry::BvhRefitJob& job);
  // The device address of the session's geometry table for a launch on `st` (0: the session
  // holds no geometry objects); uploaded on the stream when the objects changed.
  Expected<uint64_t> GeometryTable(Session& s, Stream& st);
  // Frees the retired geometry tables (the stream is idle), or every table (`all`: the stream
  // is being destroyed).
  void ReleaseGeometry(Stream& st, bool all);

  CudaDeviceOptions options_;
  // What brings a lost device back: "restart weftd", or the end of a session host's session.
  std::string WhatBringsItBack() const {
    if (options_.process_of_device)
      return "a new session (the process of this device's sessions ends now, and weftd starts a fresh one)";
    return options_.process_ends_with_session ? "a new session (this one's process ends with it)"
                                              : "a restart of weftd";
  }
  std::string name_;
  const jit::CudaDriver* driver_ = nullptr;
  jit::CuDevice device_ = 0;
  jit::CuContext ctx_ = nullptr;
  int sm_ = 0;
  bool stream_mem_ops_ = false;   // CU_DEVICE_ATTRIBUTE_CAN_USE_64_BIT_STREAM_MEM_OPS
  uint64_t coarsen_min_threads_ = 0;   // CoarsenMinThreads of this GPU (0: never coarsen)
  uint32_t coarsen_max_loaded_bytes_ = CoarsenMaxLoadedBytes();
  std::atomic<uint64_t> coarsened_launches_{0};
  std::vector<CudaDevice*> peers_;

  // Held shared by every operation, exclusively by Reset.
  mutable std::shared_mutex reset_mu_;
  std::atomic<uint64_t> generation_{1};
  std::atomic<bool> lost_{false};
  std::string lost_reason_;   // set once, before lost_
  mutable std::mutex mu_;   // slabs_, streams_, modules_, builtins_
  std::map<uint64_t, std::unique_ptr<Slab>> slabs_;
  std::unordered_map<std::string, std::unique_ptr<Stream>> streams_;
  std::unordered_map<std::string, CuModuleEntry> modules_;   // by module id + "/f" or "/b"
  jit::CuModule builtins_ = nullptr;
  std::unordered_map<std::string, jit::CuFunction> builtin_functions_;
  // CUDA IPC imports: every open mapping by handle bytes (weak: the holders own it), and per
  // session the most recently imported ones (kept open for the next import of the same block).
  static constexpr size_t kRecentImports = 16;
  mutable std::mutex imports_mu_;   // never drops an ImportedMemory while held
  std::unordered_map<std::string, std::weak_ptr<ImportedMemory>> imports_;
  std::unordered_map<std::string, std::vector<std::shared_ptr<ImportedMemory>>> recent_imports_;
  std::atomic<uint64_t> import_opens_{0};
  // Drops the session's recent imports (session close).
  void ForgetImports(const std::string& session_id);
  // Interprocess events opened for sessions: per session, least recently used first.
  struct OpenedEvent {
    std::string handle;
    jit::CuEvent event = nullptr;
    uint64_t generation = 0;
  };
  static constexpr size_t kEventsPerSession = 16;
  mutable std::mutex events_mu_;
  std::unordered_map<std::string, std::vector<OpenedEvent>> ipc_events_;   // by session id
  struct EventOwner {
    std::string session_id;   // the first session that opened the handle
    std::string principal;    // its principal
    bool shared = false;      // it shared the event (kShare) with its principal's sessions
  };
  std::unordered_map<std::string, EventOwner> event_owner_;                // by handle
  Expected<jit::CuEvent> OpenEventLocked(const Session& s, const std::string& handle, bool share);
  // Forgets who owns `handle` when `session_id` does (a sharer closing leaves the owner's claim).
  void ForgetOwnerLocked(const std::string& session_id, const std::string& handle);
  // Destroys the session's events (session close).
  void ForgetEvents(const std::string& session_id);
  std::map<std::string, uint64_t> reset_sessions_;   // session id -> generation it lost arrays in
  uint64_t resets_ = 0;
  double last_reset_ms_ = 0;
};

}  // namespace weft
