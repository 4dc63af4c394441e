// Who is calling: Unix-socket peers are local (same user, by socket permissions); TCP peers
// must present the daemon token as metadata "authorization: Bearer <token>". Resolves the
// session named by metadata "weft-session" and checks it belongs to the same kind of caller.
#pragma once

#include <memory>
#include <string>

#include <grpcpp/server_context.h>

#include "engine/core/status.h"
#include "engine/runtime/engine.h"

namespace weft::server {

class CallAuth {
 public:
  CallAuth(Engine& engine, std::string tcp_token) : engine_(engine), tcp_token_(std::move(tcp_token)) {}

  static bool IsLocalPeer(const grpc::ServerContext& ctx);
  // "unix-uid:<uid>" for local peers, "tcp-token" for authenticated TCP peers.
  static std::string Principal(const grpc::ServerContext& ctx);

  // UNAUTHENTICATED when a TCP caller has no or a wrong token.
  Status Authenticate(const grpc::ServerContext& ctx) const;
  // Authenticate + the session of metadata "weft-session" (FAILED_PRECONDITION when missing
  // or unknown).
  Expected<std::shared_ptr<Session>> SessionOf(const grpc::ServerContext& ctx) const;
  // Same, for an explicit id (Close/Attach carry it in the request).
  Expected<std::shared_ptr<Session>> SessionById(const grpc::ServerContext& ctx, const std::string& id) const;

  Engine& engine() const { return engine_; }

 private:
  Engine& engine_;
  std::string tcp_token_;
};

// gRPC metadata value for `key`, or "".
std::string Metadata(const grpc::ServerContext& ctx, const std::string& key);

}  // namespace weft::server
