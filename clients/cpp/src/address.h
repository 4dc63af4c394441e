// Where the client connects: explicit address, $WEFT_ADDRESS, or the default Unix socket.
#pragma once

#include <string>

#include "weft/client/client.h"

namespace weft::inline client_v1::detail {

struct ResolvedAddress {
  std::string target;    // gRPC target: "unix:/path" or "host:port"
  bool unix_socket = false;
};

// "unix:/p" and "/p" -> Unix socket; "tcp:h:p" and "h:p" -> TCP.
ResolvedAddress ParseAddress(const std::string& address);
// $XDG_RUNTIME_DIR/weft/weftd.sock when XDG_RUNTIME_DIR is set and the socket exists there;
// else /tmp/weft-$UID/weftd.sock when it exists; else the first of the two that applies.
std::string DefaultSocketPath();
ResolvedAddress Resolve(const ConnectOptions& options);

}  // namespace weft::client_v1::detail
