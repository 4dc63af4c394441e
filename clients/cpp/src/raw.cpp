// Raw gRPC access to a Client's session (weft/client/raw.h).
#include "weft/client/raw.h"

#include "client_core.h"

namespace weft {
inline namespace client_v1 {

std::shared_ptr<grpc::Channel> RawChannel(const Client& client) {
  return client.core() ? client.core()->channel() : nullptr;
}

std::unique_ptr<grpc::ClientContext> RawContext(const Client& client) {
  return client.core() ? client.core()->NewContext() : std::make_unique<grpc::ClientContext>();
}

}  // namespace client_v1
}  // namespace weft
