// grpc::Status -> weft::Status at the client's edge (codes share gRPC's numbering).
#pragma once

#include <grpcpp/support/status.h>

#include <string_view>

#include "weft/client/status.h"

namespace weft::inline client_v1::detail {

// The daemon's message, prefixed with the call it answered: "ArrayService.Free: no array 42".
inline Status FromRpc(const grpc::Status& s, std::string_view call) {
  if (s.ok()) return Status::Ok();
  return Status(static_cast<StatusCode>(s.error_code()),
                std::string(call) + ": " + s.error_message());
}

}  // namespace weft::client_v1::detail
