// MemoryQuota: reservation counters per session, per principal and daemon-wide.
#include "engine/runtime/memory_quota.h"

#include <cstdio>

namespace weft {

std::string ByteCountString(uint64_t bytes) {
  static const char* units[] = {"KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  std::string s = std::to_string(bytes) + " bytes";
  if (bytes < 1024) return s;
  double v = static_cast<double>(bytes);
  int u = -1;
  while (v >= 1024.0 && u < 5) {
    v /= 1024.0;
    ++u;
  }
  char buf[32];
  std::snprintf(buf, sizeof(buf), " (%.1f %s)", v, units[u]);
  return s + buf;
}

namespace {

// True when used + bytes stays within limit (0 = unlimited), without overflowing.
bool Fits(uint64_t used, uint64_t bytes, uint64_t limit) {
  if (limit == 0) return true;
  return used <= limit && bytes <= limit - used;
}

Status OverLimit(const char* which, const char* flag, uint64_t limit, uint64_t used, uint64_t bytes) {
  return ResourceExhausted("array of " + ByteCountString(bytes) + " would exceed the " + which + " memory limit (" +
                           flag + " = " + ByteCountString(limit) + "; " + ByteCountString(used) +
                           " already reserved); free arrays or raise the limit");
}

}  // namespace

Status MemoryQuota::Reserve(const std::string& session, const std::string& principal, uint64_t bytes) {
  if (bytes > (1ull << 62)) return ResourceExhausted("array of " + ByteCountString(bytes) + " is absurdly large");
  std::lock_guard<std::mutex> lock(mu_);
  const uint64_t s = sessions_.count(session) ? sessions_[session] : 0;
  const uint64_t p = principals_.count(principal) ? principals_[principal] : 0;
  if (!Fits(s, bytes, limits_.per_session))
    return OverLimit("per-session", "--max-session-memory", limits_.per_session, s, bytes);
  if (!Fits(p, bytes, limits_.per_principal))
    return OverLimit("per-principal", "--max-principal-memory", limits_.per_principal, p, bytes);
  if (!Fits(daemon_, bytes, limits_.daemon))
    return OverLimit("daemon-wide", "--max-memory", limits_.daemon, daemon_, bytes);
  sessions_[session] = s + bytes;
  principals_[principal] = p + bytes;
  daemon_ += bytes;
  return Status::Ok();
}

void MemoryQuota::Release(const std::string& session, const std::string& principal, uint64_t bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  auto drop = [bytes](std::map<std::string, uint64_t>& m, const std::string& key) {
    auto it = m.find(key);
    if (it == m.end()) return;
    it->second = it->second > bytes ? it->second - bytes : 0;
    if (it->second == 0) m.erase(it);
  };
  drop(sessions_, session);
  drop(principals_, principal);
  daemon_ = daemon_ > bytes ? daemon_ - bytes : 0;
}

MemoryUsage MemoryQuota::Usage(const std::string& session, const std::string& principal) const {
  std::lock_guard<std::mutex> lock(mu_);
  MemoryUsage u;
  u.daemon = daemon_;
  if (auto it = sessions_.find(session); it != sessions_.end()) u.session = it->second;
  if (auto it = principals_.find(principal); it != principals_.end()) u.principal = it->second;
  return u;
}

}  // namespace weft
