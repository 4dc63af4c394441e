// CPU memory: shared-memory slabs (shm_open, mode 0600, names /weft-<pid>-<n>-<random>, never
// reused) sub-allocated first-fit with coalescing. Every slab has one owner (a session id): blocks
// of one owner are carved only from that owner's slabs, so a slab never holds two sessions'
// arrays and freed memory is reused only by the session that freed it. Big requests, and
// requests that ask for it, get a slab of their own (dedicated: it holds that block only); a
// slab that becomes empty is unmapped and unlinked. Thread-safe.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "engine/core/status.h"

namespace weft {

struct ShmSlabPoolOptions {
  std::string name_prefix;                 // "/weft-<pid>-" when empty
  uint64_t slab_size = 64ull << 20;        // regular slab size
  uint64_t alignment = 256;                // of every block (power of two)
  uint64_t dedicated_threshold = 16ull << 20;  // requests above this get their own slab
};

struct ShmSlabPoolStats {
  uint32_t slabs = 0;
  uint64_t slab_bytes = 0;
  uint64_t blocks = 0;
  uint64_t block_bytes = 0;   // allocated bytes (rounded to the alignment)
};

class ShmSlabPool {
 public:
  // One sub-allocation. `data` stays valid until Free.
  struct Block {
    uint64_t slab_id = 0;
    std::string slab_name;
    uint64_t slab_size = 0;
    uint64_t offset = 0;
    uint64_t size = 0;        // rounded size
    void* data = nullptr;
    bool zeroed = false;      // from a slab created for this request: already all zero
    bool dedicated = false;   // the slab holds this block and nothing else
    std::string owner;        // the owner of the slab
    // GPU blocks (engine/device/cuda_device): the slab's CUDA IPC handle (64 bytes) and the
    // device generation (bumped by a device reset: blocks of older generations are lost).
    std::string ipc_handle;
    uint64_t generation = 0;
  };

  explicit ShmSlabPool(ShmSlabPoolOptions options = {});
  ~ShmSlabPool();   // unmaps and unlinks every slab
  ShmSlabPool(const ShmSlabPool&) = delete;
  ShmSlabPool& operator=(const ShmSlabPool&) = delete;

  // Allocates `bytes` (0 allowed: gets one alignment unit) in a slab of `owner`; `dedicated`
  // forces a slab of its own. Contents are unspecified (but never another owner's data: a
  // slab's memory is only ever reused by its owner).
  Expected<Block> Allocate(uint64_t bytes, const std::string& owner = std::string(), bool dedicated = false);
  // The rounded size Allocate reserves for `bytes` (what quotas count).
  uint64_t ReservedSize(uint64_t bytes) const;
  void Free(const Block& block);
  ShmSlabPoolStats stats() const;

  // Unlinks /dev/shm/weft-<pid>-* left by daemons that are no longer running. Returns how many.
  static int RemoveStaleSlabs(const std::string& dir = "/dev/shm");

 private:
  struct Slab {
    uint64_t id = 0;
    std::string name;
    uint64_t size = 0;
    char* base = nullptr;
    bool dedicated = false;
    std::string owner;
    uint64_t used = 0;
    std::map<uint64_t, uint64_t> free_ranges;  // offset -> size, non-adjacent
  };
  Expected<Slab*> NewSlabLocked(uint64_t size, bool dedicated, const std::string& owner);
  void DestroySlabLocked(uint64_t id);

  ShmSlabPoolOptions options_;
  mutable std::mutex mu_;
  std::map<uint64_t, std::unique_ptr<Slab>> slabs_;  // by id, creation order
  uint64_t next_slab_id_ = 0;
  uint64_t blocks_ = 0;
  uint64_t block_bytes_ = 0;
};

}  // namespace weft
