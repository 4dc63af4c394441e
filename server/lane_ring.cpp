// LaneRing: the sealed memfd, the checked reading of request records, the writing of reply
// records, and the sleep flags with their barriers.
#include "server/lane_ring.h"

#include <fcntl.h>
#include <linux/membarrier.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>

namespace weft::server {

namespace {

constexpr size_t kRecordAlign = 8;
size_t RecordBytes(size_t n) { return (4 + n + kRecordAlign - 1) & ~(kRecordAlign - 1); }

int Membarrier(int cmd) { return static_cast<int>(syscall(SYS_membarrier, cmd, 0, 0)); }

// A full barrier on this thread and on every CPU running a thread of a process registered for
// MEMBARRIER_CMD_GLOBAL_EXPEDITED (the clients of rings): a store before it and a client's
// store before the client's next load cannot both be missed.
void BarrierWithClients() {
  if (Membarrier(MEMBARRIER_CMD_GLOBAL_EXPEDITED) != 0) std::atomic_thread_fence(std::memory_order_seq_cst);
}

}  // namespace

bool LaneRing::Supported() {
  const int mask = Membarrier(MEMBARRIER_CMD_QUERY);
  return mask > 0 && (mask & MEMBARRIER_CMD_GLOBAL_EXPEDITED) != 0;
}

Expected<std::unique_ptr<LaneRing>> LaneRing::Create(size_t max_request) {
  if (RecordBytes(max_request) > kRequestCapacity / 2)
    return InvalidArgument("lane ring: a request of " + std::to_string(max_request) + " bytes does not fit");
  const size_t size = kControlBytes + kRequestCapacity + kReplyCapacity;
  int fd = memfd_create("weft-lane-ring", MFD_CLOEXEC | MFD_ALLOW_SEALING);
  if (fd < 0) return Unavailable(std::string("lane ring: memfd_create: ") + std::strerror(errno));
  if (ftruncate(fd, static_cast<off_t>(size)) != 0 ||
      fcntl(fd, F_ADD_SEALS, F_SEAL_SHRINK | F_SEAL_GROW | F_SEAL_SEAL) != 0) {
    std::string err = std::strerror(errno);
    close(fd);
    return Unavailable("lane ring: cannot size and seal the region: " + err);
  }
  void* p = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (p == MAP_FAILED) {
    std::string err = std::strerror(errno);
    close(fd);
    return Unavailable("lane ring: mmap: " + err);
  }
  auto ring = std::unique_ptr<LaneRing>(new LaneRing(fd, static_cast<char*>(p), size, max_request));
  const uint32_t header[6] = {kMagic, kVersion, static_cast<uint32_t>(kRequestCapacity),
                              static_cast<uint32_t>(kReplyCapacity), static_cast<uint32_t>(kControlBytes),
                              static_cast<uint32_t>(kControlBytes + kRequestCapacity)};
  std::memcpy(ring->base_, header, sizeof(header));
  return ring;
}

LaneRing::~LaneRing() {
  if (base_) munmap(base_, size_);
  CloseFd();
}

void LaneRing::CloseFd() {
  if (fd_ >= 0) close(fd_);
  fd_ = -1;
}

uint64_t LaneRing::Load64(size_t off) const {
  return __atomic_load_n(reinterpret_cast<const uint64_t*>(base_ + off), __ATOMIC_ACQUIRE);
}
void LaneRing::Store64(size_t off, uint64_t v) {
  __atomic_store_n(reinterpret_cast<uint64_t*>(base_ + off), v, __ATOMIC_RELEASE);
}

bool LaneRing::RequestPublished() const { return Load64(kRequestHead) != request_tail_; }

LaneRing::Take LaneRing::TakeRequest(char* out, size_t cap, size_t* len, std::string* why) {
  const char* area = base_ + kControlBytes;
  for (int wraps = 0; wraps < 2; ++wraps) {
    const uint64_t head = Load64(kRequestHead);   // read once: the client may change it any time
    const uint64_t avail = head - request_tail_;
    if (avail == 0) return Take::kEmpty;
    if (avail > kRequestCapacity || avail % kRecordAlign != 0) {
      *why = "lane ring: the request head is not within the ring";
      return Take::kCorrupt;
    }
    const size_t pos = static_cast<size_t>(request_tail_ % kRequestCapacity);
    const uint32_t n = __atomic_load_n(reinterpret_cast<const uint32_t*>(area + pos), __ATOMIC_RELAXED);
    if (n == kWrap) {
      const size_t skip = kRequestCapacity - pos;
      if (skip > avail) {
        *why = "lane ring: a wrap record past the published bytes";
        return Take::kCorrupt;
      }
      request_tail_ += skip;
      Store64(kRequestTail, request_tail_);
      continue;
    }
    const size_t rec = RecordBytes(n);
    if (n > max_request_ || n > cap || rec > avail || rec > kRequestCapacity - pos) {
      *why = "lane ring: a request record of " + std::to_string(n) + " bytes does not fit the ring or the lane's limit";
      return Take::kCorrupt;
    }
    std::memcpy(out, area + pos + 4, n);   // the only read of the record's bytes
    request_tail_ += rec;
    Store64(kRequestTail, request_tail_);
    *len = n;
    return Take::kFrame;
  }
  *why = "lane ring: two wrap records in a row";
  return Take::kCorrupt;
}

bool LaneRing::SleepUnlessPublished() {
  __atomic_store_n(reinterpret_cast<uint32_t*>(base_ + kDaemonAsleep), 1u, __ATOMIC_SEQ_CST);
  BarrierWithClients();
  if (!RequestPublished()) return true;
  Wake();
  return false;
}

void LaneRing::Wake() { __atomic_store_n(reinterpret_cast<uint32_t*>(base_ + kDaemonAsleep), 0u, __ATOMIC_SEQ_CST); }

bool LaneRing::TryPutReply(const char* data, size_t n, bool* asleep, bool* corrupt, std::string* why) {
  *corrupt = false;
  *asleep = false;
  char* area = base_ + kControlBytes + kRequestCapacity;
  const uint64_t tail = Load64(kReplyTail);   // the client's: checked
  const uint64_t used = reply_head_ - tail;
  if (used > kReplyCapacity || used % kRecordAlign != 0) {
    *corrupt = true;
    *why = "lane ring: the reply tail is not within the ring";
    return false;
  }
  const size_t rec = RecordBytes(n);
  if (rec > kReplyCapacity / 2) {
    *corrupt = true;
    *why = "lane ring: a reply frame larger than half the reply area";
    return false;
  }
  const size_t pos = static_cast<size_t>(reply_head_ % kReplyCapacity);
  const size_t contiguous = kReplyCapacity - pos;
  const size_t need = rec <= contiguous ? rec : contiguous + rec;
  if (kReplyCapacity - used < need) return false;
  if (rec > contiguous) {
    const uint32_t wrap = kWrap;
    std::memcpy(area + pos, &wrap, 4);
    reply_head_ += contiguous;
  }
  const size_t at = static_cast<size_t>(reply_head_ % kReplyCapacity);
  const uint32_t n32 = static_cast<uint32_t>(n);
  std::memcpy(area + at, &n32, 4);
  std::memcpy(area + at + 4, data, n);
  reply_head_ += rec;
  Store64(kReplyHead, reply_head_);
  std::atomic_thread_fence(std::memory_order_seq_cst);   // the head before the client's flag
  *asleep = __atomic_load_n(reinterpret_cast<const uint32_t*>(base_ + kClientAsleep), __ATOMIC_ACQUIRE) != 0;
  return true;
}

}  // namespace weft::server
