// Shared-memory slabs of the daemon mapped into this process, once per slab.
#include "mapped_slab.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace weft::inline client_v1::detail {

MappedSlab::~MappedSlab() {
  if (data_ != nullptr) ::munmap(data_, size_);
}

namespace {

// A bare shm name ("/weft-1") goes through shm_open; anything with a second '/' is a path.
int OpenSlab(const std::string& name) {
  const bool is_path = name.find('/', 1) != std::string::npos;
  return is_path ? ::open(name.c_str(), O_RDWR | O_CLOEXEC)
                 : ::shm_open(name.c_str(), O_RDWR, 0);
}

}  // namespace

Expected<std::shared_ptr<MappedSlab>> SlabCache::Map(const std::string& name,
                                                     std::uint64_t size) {
  if (name.empty()) return FailedPrecondition("array has no shared-memory slab");
  if (size == 0) return FailedPrecondition("slab " + name + " has size 0");
  std::lock_guard lock(mu_);
  auto it = slabs_.find(name);
  if (it != slabs_.end()) {
    if (auto live = it->second.lock(); live && live->size() == size) return live;
  }
  const int fd = OpenSlab(name);
  if (fd < 0)
    return Unavailable("cannot open shared-memory slab " + name + ": " + std::strerror(errno));
  struct stat st{};
  if (::fstat(fd, &st) != 0 || static_cast<std::uint64_t>(st.st_size) < size) {
    ::close(fd);
    return DataLoss("shared-memory slab " + name + " is smaller than the daemon said (" +
                    std::to_string(st.st_size) + " < " + std::to_string(size) + " bytes)");
  }
  void* p = ::mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  const int mmap_errno = errno;
  ::close(fd);
  if (p == MAP_FAILED)
    return Unavailable("cannot map shared-memory slab " + name + ": " +
                       std::strerror(mmap_errno));
  auto slab = std::make_shared<MappedSlab>(name, static_cast<std::byte*>(p), size);
  slabs_[name] = slab;
  // Forget expired entries so a long-lived client does not accumulate names.
  for (auto i = slabs_.begin(); i != slabs_.end();) {
    if (i->second.expired()) i = slabs_.erase(i);
    else ++i;
  }
  return slab;
}

std::size_t SlabCache::live() const {
  std::lock_guard lock(mu_);
  std::size_t n = 0;
  for (const auto& [name, w] : slabs_) n += w.expired() ? 0 : 1;
  return n;
}

}  // namespace weft::client_v1::detail
