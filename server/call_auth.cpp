// CallAuth: peer kind, token check, session lookup.
#include "server/call_auth.h"

#include <unistd.h>

#include "engine/runtime/ipc_token.h"

namespace weft::server {

std::string Metadata(const grpc::ServerContextBase& ctx, const std::string& key) {
  const auto& md = ctx.client_metadata();
  auto it = md.find(key);
  if (it == md.end()) return "";
  return std::string(it->second.data(), it->second.size());
}

std::optional<PeerCredentials> CallAuth::LocalPeer(const grpc::ServerContextBase& ctx) const {
  if (!unix_) return std::nullopt;
  return unix_->PeerOf(ctx.peer());
}

bool CallAuth::IsLocalPeer(const grpc::ServerContextBase& ctx) const { return LocalPeer(ctx).has_value(); }

std::string CallAuth::Principal(const grpc::ServerContextBase& ctx) const {
  if (auto peer = LocalPeer(ctx)) return "unix-uid:" + std::to_string(peer->uid);
  return "tcp-token";
}

Status CallAuth::Authenticate(const grpc::ServerContextBase& ctx) const {
  if (!only_principal_.empty()) {   // a session host: its one principal, locally, and nobody else
    if (!IsLocalPeer(ctx) || Principal(ctx) != only_principal_)
      return Status(StatusCode::kPermissionDenied, "this weftd is the session host of another principal");
    return Status::Ok();
  }
  if (IsLocalPeer(ctx)) return Status::Ok();
  const std::string peer = ctx.peer();
  if (peer.rfind("ipv4:", 0) != 0 && peer.rfind("ipv6:", 0) != 0)
    return Status(StatusCode::kUnauthenticated, "connection of unknown kind refused");
  if (tcp_token_.empty())
    return Status(StatusCode::kUnauthenticated, "this daemon accepts no TCP clients without a token");
  std::string auth = Metadata(ctx, "authorization");
  const std::string prefix = "Bearer ";
  if (auth.empty())
    return Status(StatusCode::kUnauthenticated, "missing token: send metadata \"authorization: Bearer <token>\"");
  if (auth.rfind(prefix, 0) != 0 || !SecretsEqual(auth.substr(prefix.size()), tcp_token_))
    return Status(StatusCode::kUnauthenticated, "wrong token");
  return Status::Ok();
}

// The id is never echoed (messages may be logged); a wrong id and another principal's id get
// different codes, but ids are 256 random bits, so the difference reveals nothing usable.
Expected<std::shared_ptr<Session>> CallAuth::SessionById(const grpc::ServerContextBase& ctx, const std::string& id) const {
  WEFT_RETURN_IF_ERROR(Authenticate(ctx));
  if (id.empty()) return FailedPrecondition("no session: call SessionService.Open first");
  auto s = engine_.FindSession(id);
  if (!s) return FailedPrecondition("no session: call SessionService.Open first (unknown or closed session id)");
  if (s->options().principal != Principal(ctx))
    return PermissionDenied("session " + s->label() + " belongs to another client (" + s->options().principal +
                            "); a session may only be used by the principal that opened it");
  return s;
}

Expected<std::shared_ptr<Session>> CallAuth::SessionOf(const grpc::ServerContextBase& ctx) const {
  return SessionById(ctx, Metadata(ctx, "weft-session"));
}

}  // namespace weft::server
