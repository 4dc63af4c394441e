// GeometryService: geometry objects of the calling session (engine/geometry/geometry_ops.h).
#include <spdlog/spdlog.h>

#include "engine/geometry/geometry_ops.h"
#include "engine/runtime/engine.h"
#include "server/grpc_status.h"
#include "server/proto_convert.h"
#include "server/services.h"

namespace weft::server {

Status GeometryCall(Engine& engine, Session& s, const v1::GeometryRequest& req, v1::GeometryResponse* resp) {
  WEFT_ASSIGN_OR_RETURN(geometry::GeometryRequest r, FromProto(req));
  const int op = static_cast<int>(req.op());
  auto id = engine.RunGeometry(s, r);
  if (!id.ok()) {
    spdlog::info("geometry op {} of session {} failed: {}", op, s.label(), id.status().ToString());
    return id.status();
  }
  resp->set_id(*id);
  return Status::Ok();
}

grpc::Status GeometryServiceImpl::Call(grpc::ServerContext* ctx, const v1::GeometryRequest* req,
                                       v1::GeometryResponse* resp) {
  auto s = auth_.SessionOf(*ctx);
  if (!s.ok()) return ToGrpc(s.status());
  return ToGrpc(GeometryCall(auth_.engine(), **s, *req, resp));
}

}  // namespace weft::server
