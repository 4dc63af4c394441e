// The one place engine Status values become grpc::Status (codes map one to one).
#pragma once

#include <grpcpp/support/status.h>

#include "engine/core/status.h"

namespace weft::server {

grpc::Status ToGrpc(const Status& s);

}  // namespace weft::server
