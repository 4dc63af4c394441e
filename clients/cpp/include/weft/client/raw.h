// Raw gRPC access to a Client's session, for calls the typed API does not wrap (e.g.
// ModuleService.Compile) and for tests that send requests the typed API would refuse. Contexts
// from NewContext carry the session's `weft-session` and `authorization` metadata. Including
// this header pulls in gRPC and the weft.v1 protobuf headers (installed with the package).
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>

#include "weft/client/client.h"
#include "weft/v1/array.grpc.pb.h"
#include "weft/v1/device.grpc.pb.h"
#include "weft/v1/exec.grpc.pb.h"
#include "weft/v1/module.grpc.pb.h"
#include "weft/v1/session.grpc.pb.h"

namespace weft {
inline namespace client_v1 {

// The channel of `client` (null when not connected).
std::shared_ptr<grpc::Channel> RawChannel(const Client& client);
// A fresh context with the session metadata; use it for exactly one call.
std::unique_ptr<grpc::ClientContext> RawContext(const Client& client);

}  // namespace client_v1
}  // namespace weft
