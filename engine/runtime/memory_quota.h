// Memory quotas: the bytes of arrays each session, each principal and the whole daemon have
// reserved (what was allocated, not what was touched), checked against their limits before an
// allocation is made. Thread-safe.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <string>

#include "engine/core/status.h"

namespace weft {

// 0 = no limit of its own (the wider limits still apply).
struct MemoryLimits {
  uint64_t daemon = 0;          // every array of every session
  uint64_t per_principal = 0;   // every array created by sessions of one principal
  uint64_t per_session = 0;     // every array one session created
};

struct MemoryUsage {
  uint64_t daemon = 0;
  uint64_t principal = 0;
  uint64_t session = 0;
};

class MemoryQuota {
 public:
  explicit MemoryQuota(MemoryLimits limits) : limits_(limits) {}

  // Reserves `bytes` for an array `session` (of `principal`) creates. Over a limit: nothing is
  // reserved and the error (RESOURCE_EXHAUSTED) names the limit, its value and what is in use.
  Status Reserve(const std::string& session, const std::string& principal, uint64_t bytes);
  // Returns bytes reserved earlier (the array was freed by its last holder).
  void Release(const std::string& session, const std::string& principal, uint64_t bytes);

  MemoryUsage Usage(const std::string& session, const std::string& principal) const;
  const MemoryLimits& limits() const { return limits_; }

 private:
  MemoryLimits limits_;
  mutable std::mutex mu_;
  uint64_t daemon_ = 0;
  std::map<std::string, uint64_t> principals_;
  std::map<std::string, uint64_t> sessions_;
};

// "1073741824 bytes (1.0 GiB)" for messages.
std::string ByteCountString(uint64_t bytes);

}  // namespace weft
