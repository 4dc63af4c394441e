// IPC tokens: the opaque string that lets another session open an exported array.
// Format "weft-ipc-v1:<handle hex>:<secret, 32 hex digits = 128 random bits>".
#pragma once

#include <cstdint>
#include <string>

#include "engine/core/status.h"

namespace weft {

struct IpcToken {
  uint64_t handle = 0;
  std::string secret;   // 32 lowercase hex digits
};

std::string NewIpcSecret();   // 128 bits from getrandom()
std::string FormatIpcToken(const IpcToken& token);
Expected<IpcToken> ParseIpcToken(const std::string& text);
// Constant-time comparison of two secrets.
bool SecretsEqual(const std::string& a, const std::string& b);

}  // namespace weft
