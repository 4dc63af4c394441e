// ExecService: ordered command batches and synchronization.
#include <spdlog/spdlog.h>

#include "server/grpc_status.h"
#include "server/proto_convert.h"
#include "server/services.h"

namespace weft::server {

grpc::Status ExecServiceImpl::Submit(grpc::ServerContext* ctx, const v1::SubmitRequest* req, v1::SubmitResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  std::vector<Command> commands;
  commands.reserve(req->commands_size());
  for (int i = 0; i < req->commands_size(); ++i) {
    auto c = FromProto(req->commands(i), static_cast<size_t>(i));
    if (!c.ok()) return ToGrpc(c.status());   // nothing queued
    commands.push_back(std::move(c).value());
  }
  auto r = auth_.engine().Submit(**s, std::move(commands));
  if (!r.ok()) return ToGrpc(r.status());
  resp->set_queued(*r);
  return grpc::Status::OK;
}

grpc::Status ExecServiceImpl::Synchronize(grpc::ServerContext* ctx, const v1::SynchronizeRequest*,
                                          v1::SynchronizeResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  Session::SyncResult r = auth_.engine().Synchronize(**s);
  if (!r.error.ok()) {
    resp->set_error(r.error.message());
    resp->set_error_code(static_cast<int32_t>(r.error.code()));
    ToProto(r.origin, resp->mutable_error_origin());
  }
  resp->set_output(r.output);
  return grpc::Status::OK;
}

}  // namespace weft::server
