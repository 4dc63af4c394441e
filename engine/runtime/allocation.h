// One array allocation in daemon memory: its element type, shape, C-contiguous strides, where
// its bytes live (a slab block), its gradient allocation and its export secret. Shared by every
// session that holds it (std::shared_ptr); the bytes return to the pool when the last holder
// (session, queued command) lets go.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "engine/runtime/dtype.h"
#include "engine/runtime/shm_slab_pool.h"

namespace weft {

struct Allocation {
  uint64_t handle = 0;
  DType dtype;
  std::vector<int64_t> shape;
  std::vector<int64_t> strides;    // bytes, C-contiguous
  std::string device = "cpu";
  uint64_t byte_size = 0;          // element size * element count
  ShmSlabPool::Block block;        // CPU memory (changes only when an export moves it: block_mu)
  std::function<void(const ShmSlabPool::Block&)> release;  // returns the block to its pool
  // Where the bytes lived before an export moved them into a slab of their own; kept (never
  // reused) until the allocation dies, so a stale pointer still names memory of this array.
  ShmSlabPool::Block retired_block;
  std::function<void(const ShmSlabPool::Block&)> release_retired;
  mutable std::mutex block_mu;     // guards block/retired_block against concurrent Describe
  std::shared_ptr<Allocation> grad;  // requires_grad arrays
  bool is_grad = false;              // this allocation is some array's gradient
  bool pinned = false;               // a CPU array created with pinned=true (a slab of its own)
  bool page_locked = false;          // ... and page-locked for the daemon's GPUs (Engine::PageLock)
  // Client GPU memory imported by CUDA IPC (Engine::ImportCudaArray): `block` points into the
  // mapping, which `release` keeps open; never exported, never moved.
  bool imported = false;

  // Export secret (set on first export) and the credential of the exporting session.
  std::mutex export_mu;
  std::string export_secret;
  std::string export_principal;

  char* data() const { return static_cast<char*>(block.data); }
  uint64_t element_count() const;

  Allocation() = default;
  Allocation(const Allocation&) = delete;
  Allocation& operator=(const Allocation&) = delete;
  ~Allocation() {
    if (release) release(block);
    if (release_retired && retired_block.data) release_retired(retired_block);
  }
};

// C-contiguous byte strides for `shape` with elements of `elem_size` bytes.
std::vector<int64_t> ContiguousStrides(const std::vector<int64_t>& shape, uint64_t elem_size);
// strides == ContiguousStrides(shape, elem_size), without building them (every launch checks
// every array argument); false where the strides would overflow.
bool HasContiguousStrides(const std::vector<int64_t>& shape, const std::vector<int64_t>& strides,
                          uint64_t elem_size);
std::string ShapeString(const std::vector<int64_t>& shape);   // "(2, 3)"

}  // namespace weft
