// The device interface: what the engine, the command executor and the tapes ask of a place
// where arrays live and kernels run. One CPU implementation (shared-memory slabs, the thread
// pool) and one CUDA implementation per GPU (primary context, slabs of driver memory, one
// stream per session). Work a session submits runs in order on that session's stream of the
// device; asynchronous errors are collected at Synchronize. Memory blocks are slab
// sub-allocations (ShmSlabPool::Block; on a GPU `data` is the device address).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/core/module_source.h"
#include "engine/core/status.h"
#include "engine/geometry/bvh_build.h"
#include "engine/geometry/hash_grid_job.h"
#include "engine/runtime/array_view.h"
#include "engine/runtime/launch_args.h"
#include "engine/runtime/module_store.h"
#include "engine/runtime/shm_slab_pool.h"

namespace weft {

class Session;
using MemoryBlock = ShmSlabPool::Block;

// One kernel launch, forward (adj_args null) or adjoint.
struct KernelLaunch {
  std::shared_ptr<const LoadedModule> module;
  const LoadedKernel* kernel = nullptr;
  std::vector<int64_t> dim;
  const PackedArgs* args = nullptr;
  const PackedArgs* adj_args = nullptr;
  uint32_t block_dim = 0;     // threads per block (GPU); 0 = 256
  uint32_t max_blocks = 0;    // GPU grid bound (threads loop over the rest); 0 = as many as needed
  SourceLocation origin;      // where the client launched it (asynchronous errors name it)
};

// Whether a GPU launch needs an entry that strides over the grid: the blocks it needs (of
// block_dim threads, 256 when 0) are more than max_blocks (when set) or than one grid holds
// (2^31 - 1); a thread count that overflows 64 bits needs it too. A launch with a zero extent
// needs no grid at all.
inline bool NeedsGridStride(const KernelLaunch& l) {
  uint64_t size = 1;
  for (int64_t d : l.dim) {
    if (d <= 0) return false;
    if (__builtin_mul_overflow(size, static_cast<uint64_t>(d), &size)) return true;
  }
  const uint64_t block = l.block_dim ? l.block_dim : 256;
  const uint64_t blocks = size / block + (size % block != 0);
  return (l.max_blocks > 0 && blocks > l.max_blocks) || blocks > 0x7fffffffull;
}

// The first asynchronous error of a session on a device since its last Synchronize.
struct DeviceSyncResult {
  Status error;
  SourceLocation origin;
  std::string output;   // kernel print output of the launches since the last synchronize
};

class Device {
 public:
  virtual ~Device() = default;
  virtual const std::string& name() const = 0;   // "cpu", "cuda:0"
  virtual bool is_cpu() const = 0;

  // Memory. Allocate: `bytes` in a slab of `owner` (a session id), `dedicated` = a slab of its
  // own. ReservedSize: what Allocate reserves for `bytes` (the quotas count it).
  virtual uint64_t ReservedSize(uint64_t bytes) const = 0;
  virtual Expected<MemoryBlock> Allocate(uint64_t bytes, const std::string& owner, bool dedicated) = 0;
  virtual void Free(const MemoryBlock& block) = 0;
  // The block's memory may be seen by another session from now on (an export): a device that
  // keeps freed memory for its owner's next allocations must not keep this block's.
  virtual void MarkShared(const MemoryBlock&) {}
  // Bytes of slabs held / slab count (stats).
  virtual uint64_t SlabBytes() const = 0;
  virtual uint32_t SlabCount() const = 0;

  // Synchronous transfers between a block and host memory, ordered after the session's queued
  // work on this device (ReadArray, WriteArray, initial data, exports).
  virtual Status Upload(Session& s, const MemoryBlock& dst, uint64_t offset, const void* src, uint64_t n) = 0;
  virtual Status Download(Session& s, const MemoryBlock& src, uint64_t offset, void* dst, uint64_t n) = 0;
  virtual Status CopyBlock(Session& s, const MemoryBlock& dst, const MemoryBlock& src, uint64_t n) = 0;

  // Ordered work of a session (possibly asynchronous: errors may surface at Synchronize).
  virtual Status Fill(Session& s, const ArrayView& dst, const std::string& value) = 0;
  // dst or src (or both) live on this device; the other one may live on the CPU or another GPU.
  virtual Status Copy(Session& s, const ArrayView& dst, const ArrayView& src) = 0;
  virtual Status Launch(Session& s, const KernelLaunch& launch, std::string* output) = 0;
  // Waits for the session's work on this device; the first asynchronous error, if any.
  virtual DeviceSyncResult Synchronize(Session& s) = 0;
  // The session closed (its work already stopped and waited for): drop its stream.
  virtual void CloseSession(Session& s) = 0;

  // Recomputes a BVH's node bounds on this device (one launch per level of `job`, deepest first;
  // a tree built on the device: bottom-up along its parents), queued on the session's stream
  // after its earlier work (a GPU geometry refit).
  // Unimplemented where the device has no such path (the caller refits on the host).
  virtual Status RefitBvh(Session&, const geometry::BvhRefitJob&) { return Unimplemented(name() + " refits BVHs on the host"); }
  // Builds a hash grid on this device (cells, then the point ids sorted by cell), queued on the
  // session's stream after its earlier work. GPUs only (a CPU grid is built by the caller).
  virtual Status BuildHashGrid(Session&, const geometry::HashGridBuildJob&) {
    return Unimplemented(name() + " builds hash grids on the host");
  }
  // Builds a BVH on this device (bvh_build.h BvhBuildJob: a linear BVH), queued on the session's
  // stream after its earlier work. GPUs only (the caller builds on the host where unimplemented).
  virtual Status BuildBvh(Session&, const geometry::BvhBuildJob&) { return Unimplemented(name() + " builds BVHs on the host"); }
  // Copies and range-checks a mesh's indices on this device (bvh_build.h MeshIndicesJob), queued
  // on the session's stream; the caller reads the result back.
  virtual Status CheckMeshIndices(Session&, const geometry::MeshIndicesJob&) {
    return Unimplemented(name() + " checks mesh indices on the host");
  }
};

}  // namespace weft
