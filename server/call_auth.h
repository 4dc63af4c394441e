// Who is calling, and may they touch this session. A Unix-socket peer's principal is its uid
// as the kernel reports it (SO_PEERCRED, read by UnixListener): "unix-uid:<uid>"; a TCP peer
// must present the daemon token as metadata "authorization: Bearer <token>" and is
// "tcp-token". Any other peer is refused. Every service method resolves its session through
// SessionOf/SessionById, which refuse a session owned by another principal.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include <grpcpp/server_context.h>

#include "engine/core/status.h"
#include "engine/runtime/engine.h"
#include "server/unix_listener.h"

namespace weft::server {

class CallAuth {
 public:
  CallAuth(Engine& engine, std::string tcp_token, const UnixListener* unix_listener)
      : engine_(engine), tcp_token_(std::move(tcp_token)), unix_(unix_listener) {}

  // A connection accepted by the UnixListener.
  bool IsLocalPeer(const grpc::ServerContextBase& ctx) const;
  // The local peer's credentials (nullopt for TCP peers).
  std::optional<PeerCredentials> LocalPeer(const grpc::ServerContextBase& ctx) const;
  // "unix-uid:<peer uid>" for local peers, "tcp-token" for TCP peers.
  std::string Principal(const grpc::ServerContextBase& ctx) const;

  // UNAUTHENTICATED when a TCP caller has no or a wrong token.
  Status Authenticate(const grpc::ServerContextBase& ctx) const;
  // Authenticate + the session of metadata "weft-session" (FAILED_PRECONDITION when missing
  // or unknown).
  Expected<std::shared_ptr<Session>> SessionOf(const grpc::ServerContextBase& ctx) const;
  // Same, for an explicit id (Close/Attach carry it in the request).
  Expected<std::shared_ptr<Session>> SessionById(const grpc::ServerContextBase& ctx, const std::string& id) const;

  Engine& engine() const { return engine_; }
  // A session host (server/session_hosts.h) serves one principal: every other caller,
  // local or TCP, is refused.
  void RestrictTo(std::string principal) { only_principal_ = std::move(principal); }

 private:
  Engine& engine_;
  std::string tcp_token_;
  const UnixListener* unix_;
  std::string only_principal_;
};

// gRPC metadata value for `key`, or "".
std::string Metadata(const grpc::ServerContextBase& ctx, const std::string& key);

}  // namespace weft::server
