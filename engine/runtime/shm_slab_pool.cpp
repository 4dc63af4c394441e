// ShmSlabPool: shm_open slabs, first-fit sub-allocation with coalescing, stale-slab cleanup.
#include "engine/runtime/shm_slab_pool.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <spdlog/spdlog.h>

namespace weft {

namespace {
uint64_t RoundUp(uint64_t v, uint64_t a) { return (v + a - 1) / a * a; }

// 16 random hex digits: slab names cannot be guessed from the daemon pid and a counter.
std::string RandomSuffix() {
  unsigned char b[8] = {};
  size_t got = 0;
  while (got < sizeof(b)) {
    ssize_t r = getrandom(b + got, sizeof(b) - got, 0);
    if (r > 0) got += static_cast<size_t>(r);
  }
  static const char* hex = "0123456789abcdef";
  std::string s;
  for (unsigned char c : b) {
    s += hex[c >> 4];
    s += hex[c & 15];
  }
  return s;
}
}  // namespace

ShmSlabPool::ShmSlabPool(ShmSlabPoolOptions options) : options_(std::move(options)) {
  if (options_.name_prefix.empty())
    options_.name_prefix = "/weft-" + std::to_string(getpid()) + "-";
  if (options_.alignment == 0 || (options_.alignment & (options_.alignment - 1)))
    options_.alignment = 256;
  if (options_.slab_size < options_.alignment) options_.slab_size = options_.alignment;
  options_.slab_size = RoundUp(options_.slab_size, static_cast<uint64_t>(getpagesize()));
}

ShmSlabPool::~ShmSlabPool() {
  std::lock_guard<std::mutex> lock(mu_);
  while (!slabs_.empty()) DestroySlabLocked(slabs_.begin()->first);
}

Expected<ShmSlabPool::Slab*> ShmSlabPool::NewSlabLocked(uint64_t size, bool dedicated, const std::string& owner) {
  struct statvfs vfs {};
  if (statvfs("/dev/shm", &vfs) == 0) {
    uint64_t avail = static_cast<uint64_t>(vfs.f_bavail) * vfs.f_frsize;
    if (size > avail)
      return ResourceExhausted("shared memory exhausted: need a slab of " + std::to_string(size) +
                               " bytes, /dev/shm has " + std::to_string(avail) + " bytes free");
  }
  auto slab = std::make_unique<Slab>();
  slab->id = next_slab_id_++;
  slab->name = options_.name_prefix + std::to_string(slab->id) + "-" + RandomSuffix();
  slab->size = size;
  slab->dedicated = dedicated;
  slab->owner = owner;
  int fd = shm_open(slab->name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600);
  if (fd < 0) return Internal("shm_open(" + slab->name + "): " + std::strerror(errno));
  fchmod(fd, 0600);  // umask may have narrowed it; never widen beyond 0600
  if (ftruncate(fd, static_cast<off_t>(size)) != 0) {
    int e = errno;
    close(fd);
    shm_unlink(slab->name.c_str());
    return ResourceExhausted("cannot size shared memory slab " + slab->name + " to " +
                             std::to_string(size) + " bytes: " + std::strerror(e));
  }
  void* p = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  int e = errno;
  close(fd);
  if (p == MAP_FAILED) {
    shm_unlink(slab->name.c_str());
    return ResourceExhausted("cannot map shared memory slab of " + std::to_string(size) +
                             " bytes: " + std::strerror(e));
  }
  slab->base = static_cast<char*>(p);
  slab->free_ranges[0] = size;
  Slab* raw = slab.get();
  slabs_[raw->id] = std::move(slab);
  spdlog::debug("slab {} created ({} bytes{})", raw->name, size, dedicated ? ", dedicated" : "");
  return raw;
}

void ShmSlabPool::DestroySlabLocked(uint64_t id) {
  auto it = slabs_.find(id);
  if (it == slabs_.end()) return;
  Slab& s = *it->second;
  munmap(s.base, s.size);
  shm_unlink(s.name.c_str());
  spdlog::debug("slab {} removed", s.name);
  slabs_.erase(it);
}

uint64_t ShmSlabPool::ReservedSize(uint64_t bytes) const {
  const uint64_t a = options_.alignment;
  if (bytes > (1ull << 62)) return bytes;
  return RoundUp(bytes == 0 ? a : bytes, a);
}

Expected<ShmSlabPool::Block> ShmSlabPool::Allocate(uint64_t bytes, const std::string& owner, bool dedicated) {
  const uint64_t a = options_.alignment;
  if (bytes > (1ull << 62)) return ResourceExhausted("allocation of " + std::to_string(bytes) + " bytes is too large");
  uint64_t size = RoundUp(bytes == 0 ? a : bytes, a);
  std::lock_guard<std::mutex> lock(mu_);
  Slab* slab = nullptr;
  uint64_t offset = 0;
  bool fresh = false;
  if (dedicated || size > options_.dedicated_threshold || size > options_.slab_size) {
    uint64_t slab_size = RoundUp(size, static_cast<uint64_t>(getpagesize()));
    WEFT_ASSIGN_OR_RETURN(slab, NewSlabLocked(slab_size, true, owner));
    fresh = true;
  } else {
    for (auto& [id, s] : slabs_) {
      if (s->dedicated || s->owner != owner) continue;
      for (auto& [off, len] : s->free_ranges) {
        if (len >= size) {
          slab = s.get();
          offset = off;
          break;
        }
      }
      if (slab) break;
    }
    if (!slab) {
      WEFT_ASSIGN_OR_RETURN(slab, NewSlabLocked(options_.slab_size, false, owner));
      offset = 0;
      fresh = true;
    }
  }
  // Carve [offset, offset+size) out of the free range that starts at offset.
  auto fr = slab->free_ranges.find(offset);
  uint64_t len = fr->second;
  slab->free_ranges.erase(fr);
  if (len > size) slab->free_ranges[offset + size] = len - size;
  slab->used += size;
  ++blocks_;
  block_bytes_ += size;
  Block b;
  b.slab_id = slab->id;
  b.slab_name = slab->name;
  b.slab_size = slab->size;
  b.offset = offset;
  b.size = size;
  b.data = slab->base + offset;
  b.zeroed = fresh;
  b.dedicated = slab->dedicated;
  b.owner = slab->owner;
  return b;
}

void ShmSlabPool::Free(const Block& block) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = slabs_.find(block.slab_id);
  if (it == slabs_.end()) return;
  Slab& s = *it->second;
  --blocks_;
  block_bytes_ -= block.size;
  s.used -= block.size;
  if (s.used == 0) {
    DestroySlabLocked(block.slab_id);
    return;
  }
  uint64_t off = block.offset, len = block.size;
  auto next = s.free_ranges.lower_bound(off);
  if (next != s.free_ranges.begin()) {
    auto prev = std::prev(next);
    if (prev->first + prev->second == off) {
      off = prev->first;
      len += prev->second;
      s.free_ranges.erase(prev);
    }
  }
  if (next != s.free_ranges.end() && off + len == next->first) {
    len += next->second;
    s.free_ranges.erase(next);
  }
  s.free_ranges[off] = len;
}

ShmSlabPoolStats ShmSlabPool::stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  ShmSlabPoolStats st;
  st.slabs = static_cast<uint32_t>(slabs_.size());
  for (auto& [id, s] : slabs_) st.slab_bytes += s->size;
  st.blocks = blocks_;
  st.block_bytes = block_bytes_;
  return st;
}

int ShmSlabPool::RemoveStaleSlabs(const std::string& dir) {
  DIR* d = opendir(dir.c_str());
  if (!d) return 0;
  int removed = 0;
  while (dirent* e = readdir(d)) {
    const char* n = e->d_name;
    if (std::strncmp(n, "weft-", 5) != 0) continue;
    char* end = nullptr;
    long pid = std::strtol(n + 5, &end, 10);
    if (end == n + 5 || *end != '-' || pid <= 0) continue;
    if (pid == getpid()) continue;
    if (kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive (or not ours to judge)
    std::string name = std::string("/") + n;
    if (shm_unlink(name.c_str()) == 0) {
      ++removed;
      spdlog::info("removed stale shared memory {} (daemon pid {} is gone)", name, pid);
    }
  }
  closedir(d);
  return removed;
}

}  // namespace weft
