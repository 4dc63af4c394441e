// Status -> grpc::Status, with the message cut to fit gRPC's metadata.
#include "server/grpc_status.h"

namespace weft::server {

std::string FitStatusMessage(const std::string& message) {
  if (message.size() <= kMaxStatusMessageBytes) return message;
  // Cut at a UTF-8 character boundary (never inside a multi-byte sequence).
  size_t cut = kMaxStatusMessageBytes;
  while (cut > 0 && (static_cast<unsigned char>(message[cut]) & 0xC0) == 0x80) --cut;
  return message.substr(0, cut) + "\n[weftd: message truncated: " + std::to_string(message.size() - cut) +
         " more bytes]";
}

grpc::Status ToGrpc(const Status& s) {
  if (s.ok()) return grpc::Status::OK;
  return grpc::Status(static_cast<grpc::StatusCode>(static_cast<int>(s.code())), FitStatusMessage(s.message()));
}

}  // namespace weft::server
