// The one place engine Status values become grpc::Status (codes map one to one). The message
// travels in the grpc-message trailer, percent-encoded (up to 3 bytes per byte) inside the
// client's 8 KiB metadata limit: a longer message would reach the client as an opaque
// RESOURCE_EXHAUSTED, so messages are cut to kMaxStatusMessageBytes with a note saying so.
#pragma once

#include <cstddef>
#include <string>

#include <grpcpp/support/status.h>

#include "engine/core/status.h"

namespace weft::server {

constexpr size_t kMaxStatusMessageBytes = 2000;

// `message`, or its first kMaxStatusMessageBytes (at a UTF-8 boundary) + a truncation note.
std::string FitStatusMessage(const std::string& message);

grpc::Status ToGrpc(const Status& s);

}  // namespace weft::server
