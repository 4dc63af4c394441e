// Shared-memory slabs of the daemon mapped into this process: each slab is mapped once and
// shared by every Array that lives in it; the mapping goes away with the last such Array.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>

#include "weft/client/status.h"

namespace weft::inline client_v1::detail {

class MappedSlab {
 public:
  MappedSlab(std::string name, std::byte* data, std::size_t size)
      : name_(std::move(name)), data_(data), size_(size) {}
  ~MappedSlab();
  MappedSlab(const MappedSlab&) = delete;
  MappedSlab& operator=(const MappedSlab&) = delete;

  const std::string& name() const { return name_; }
  std::byte* data() const { return data_; }
  std::size_t size() const { return size_; }

 private:
  std::string name_;
  std::byte* data_;
  std::size_t size_;
};

class SlabCache {
 public:
  // The mapping of slab `name` (a POSIX shm name such as "/weft-1234-7", or a file path such
  // as "/dev/shm/x" or "/proc/PID/fd/N") of `size` bytes, mapping it if no live Array has.
  Expected<std::shared_ptr<MappedSlab>> Map(const std::string& name, std::uint64_t size);
  // Slabs currently mapped (for tests and stats).
  std::size_t live() const;

 private:
  mutable std::mutex mu_;
  std::unordered_map<std::string, std::weak_ptr<MappedSlab>> slabs_;
};

}  // namespace weft::client_v1::detail
