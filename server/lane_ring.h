// The shared-memory ring of a fast-lane connection: the daemon's side of a memory region that a
// local client and weftd both map, which carries the lane's frames without a system call per
// frame while the reader of each direction polls (docs/protocol.md "Ring").
// Owns: the region (a sealed memfd: the client can neither shrink nor grow it), its layout, the
// reading of request records (every byte the client wrote is checked before use and copied out
// once; a record that breaks the layout is a corrupt ring, never a read outside it), the
// writing of reply records, and the two sleep flags with the barriers that make a wake-up
// impossible to miss (membarrier GLOBAL_EXPEDITED; a client registers for it before it asks
// for a ring).
//
// Layout (little endian; offsets in bytes):
//   0    u32 magic "WFRG", u32 version, u32 request capacity, u32 reply capacity,
//        u32 request area offset, u32 reply area offset (written once by weftd)
//   64   u64 request head   (client: bytes of records published)
//   128  u64 request tail   (weftd: bytes of records consumed)
//   192  u32 weftd asleep   (weftd: 1 while it blocks on the socket for a wake frame)
//   256  u64 reply head     (weftd)
//   320  u64 reply tail     (client)
//   384  u32 client asleep  (client: 1 while it blocks on the socket for a wake frame)
//   4096 request area, then reply area
// A record is u32 length + that many bytes (one lane frame), padded to 8 bytes; it never wraps:
// a length of 0xffffffff skips the rest of the area. A writer that finds the reader asleep after
// publishing sends one wake frame on the socket (client: u32 method 12; weftd: a reply header
// with flag 8).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "engine/core/status.h"

namespace weft::server {

class LaneRing {
 public:
  static constexpr uint32_t kMagic = 0x47524657;   // "WFRG"
  static constexpr uint32_t kVersion = 1;
  static constexpr size_t kControlBytes = 4096;
  static constexpr size_t kRequestCapacity = 384u << 10;   // two records of the largest request fit
  static constexpr size_t kReplyCapacity = 256u << 10;
  static constexpr uint32_t kWrap = 0xffffffffu;
  static constexpr size_t kRequestHead = 64, kRequestTail = 128, kDaemonAsleep = 192;
  static constexpr size_t kReplyHead = 256, kReplyTail = 320, kClientAsleep = 384;

  // Whether this kernel offers the barrier the sleep flags need (membarrier GLOBAL_EXPEDITED).
  static bool Supported();
  // A new region: memfd sized, sealed and mapped, header written. `max_request`: the largest
  // request frame the lane accepts (a record of it must fit the request area).
  static Expected<std::unique_ptr<LaneRing>> Create(size_t max_request);
  ~LaneRing();
  LaneRing(const LaneRing&) = delete;
  LaneRing& operator=(const LaneRing&) = delete;

  int fd() const { return fd_; }            // the memfd, for the client (SCM_RIGHTS)
  void CloseFd();                           // once sent: the mapping stays
  size_t size() const { return size_; }

  enum class Take { kFrame, kEmpty, kCorrupt };
  // The next request frame, copied into `out` (capacity `cap` >= max_request) with its length
  // in `*len`. kCorrupt (with `*why`) when the client's head or record breaks the layout.
  Take TakeRequest(char* out, size_t cap, size_t* len, std::string* why);
  // Whether the client published bytes not yet taken (a cheap look for polling).
  bool RequestPublished() const;

  // weftd goes to sleep: sets its flag, makes that store and the client's latest stores
  // visible to each other (membarrier), and says whether a request was published meanwhile
  // (then the flag is cleared again and weftd must not block).
  bool SleepUnlessPublished();
  void Wake();   // clears weftd's flag

  // Writes one reply frame (at most half the reply area) when the area has room for it; false
  // when it has none yet (the caller waits and retries). `*asleep`: the client's flag after publishing (full
  // barrier between the two), so the caller knows to send a wake frame. Corrupt: the client's
  // tail breaks the layout.
  bool TryPutReply(const char* data, size_t n, bool* asleep, bool* corrupt, std::string* why);

 private:
  LaneRing(int fd, char* base, size_t size, size_t max_request)
      : fd_(fd), base_(base), size_(size), max_request_(max_request) {}
  uint64_t Load64(size_t off) const;
  void Store64(size_t off, uint64_t v);

  int fd_ = -1;
  char* base_ = nullptr;
  size_t size_ = 0;
  size_t max_request_ = 0;
  // weftd's own positions: never read back from the shared region.
  uint64_t request_tail_ = 0;
  uint64_t reply_head_ = 0;
};

}  // namespace weft::server
