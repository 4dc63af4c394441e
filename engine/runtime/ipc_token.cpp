// IPC token generation, formatting and parsing.
#include "engine/runtime/ipc_token.h"

#include <sys/random.h>

#include <cstdio>
#include <cstring>

namespace weft {

namespace {
constexpr const char* kPrefix = "weft-ipc-v1:";
bool IsHex(const std::string& s) {
  for (char c : s)
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  return !s.empty();
}
}  // namespace

std::string NewIpcSecret() {
  unsigned char buf[16];
  size_t got = 0;
  while (got < sizeof(buf)) {
    ssize_t r = getrandom(buf + got, sizeof(buf) - got, 0);
    if (r > 0) got += static_cast<size_t>(r);
  }
  char hex[33];
  for (int i = 0; i < 16; ++i) std::snprintf(hex + 2 * i, 3, "%02x", buf[i]);
  return std::string(hex, 32);
}

std::string FormatIpcToken(const IpcToken& token) {
  char h[17];
  std::snprintf(h, sizeof(h), "%llx", static_cast<unsigned long long>(token.handle));
  return std::string(kPrefix) + h + ":" + token.secret;
}

Expected<IpcToken> ParseIpcToken(const std::string& text) {
  const size_t plen = std::strlen(kPrefix);
  if (text.compare(0, plen, kPrefix) != 0)
    return InvalidArgument("not a weft IPC token (expected it to start with \"weft-ipc-v1:\")");
  std::string rest = text.substr(plen);
  size_t colon = rest.find(':');
  if (colon == std::string::npos) return InvalidArgument("malformed weft IPC token");
  std::string h = rest.substr(0, colon), secret = rest.substr(colon + 1);
  if (!IsHex(h) || h.size() > 16 || secret.size() != 32 || !IsHex(secret))
    return InvalidArgument("malformed weft IPC token");
  IpcToken t;
  t.handle = std::stoull(h, nullptr, 16);
  t.secret = secret;
  return t;
}

bool SecretsEqual(const std::string& a, const std::string& b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ b[i]);
  return diff == 0;
}

}  // namespace weft
