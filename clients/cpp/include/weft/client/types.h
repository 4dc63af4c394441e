// Plain descriptions the client hands out: devices, arrays, daemon statistics, the session.
// Copies of the daemon's answers (proto/weft/v1), free of protobuf types.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "weft/client/dtype.h"

namespace weft {
inline namespace client_v1 {

struct DeviceInfo {
  std::string name;          // "cpu", "cuda:0"
  std::string kind;          // "cpu" or "cuda"
  std::string description;   // CPU model or GPU product name
  std::uint64_t total_memory = 0;
  std::uint64_t free_memory = 0;
  int compute_capability_major = 0;   // GPUs only
  int compute_capability_minor = 0;
  int cores = 0;             // CPU threads in the pool / GPU SMs
};

// Everything the daemon says about one allocation.
struct ArrayInfo {
  std::uint64_t handle = 0;
  DType dtype;
  std::vector<std::int64_t> shape;
  std::vector<std::int64_t> strides;   // bytes
  std::string device;
  std::uint64_t byte_size = 0;
  std::uint64_t grad_handle = 0;       // 0: no gradient
  // Local clients only: the shared-memory slab holding the bytes ("" when not mappable).
  std::string shm_name;
  std::uint64_t shm_offset = 0;
  std::uint64_t shm_size = 0;

  // Elements (product of the shape; 1 for a 0-d array).
  std::int64_t size() const;
  int ndim() const { return static_cast<int>(shape.size()); }
};

// SessionService.Stats: daemon-wide counters.
struct DaemonStats {
  std::uint32_t sessions = 0;
  std::uint64_t arrays = 0;
  std::uint64_t array_bytes = 0;
  std::uint32_t cpu_slabs = 0;
  std::uint64_t cpu_slab_bytes = 0;
  std::uint64_t module_cache_hits = 0;
  std::uint64_t module_cache_disk_hits = 0;
  std::uint64_t module_cache_misses = 0;
  std::uint64_t sessions_opened_total = 0;
  std::uint64_t sessions_reaped_total = 0;
};

// What SessionService.Open answered.
struct SessionInfo {
  std::string session_id;
  std::string daemon_version;
  bool local = false;         // the daemon fills shared-memory fields; arrays can be mapped
  std::int64_t daemon_pid = 0;
  std::string address;        // the gRPC target the client connected to
};

}  // namespace client_v1
}  // namespace weft
