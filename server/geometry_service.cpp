// GeometryService: geometry objects of the calling session (engine/geometry/geometry_ops.h).
#include <spdlog/spdlog.h>

#include "engine/geometry/geometry_ops.h"
#include "engine/runtime/engine.h"
#include "server/grpc_status.h"
#include "server/services.h"

namespace weft::server {

Status GeometryCall(Engine& engine, Session& s, const v1::GeometryRequest& req, v1::GeometryResponse* resp) {
  geometry::GeometryRequest r;
  int op = static_cast<int>(req.op());
  if (op < 1 || op > 8) return InvalidArgument("geometry: unknown operation " + std::to_string(op));
  r.op = static_cast<geometry::GeometryRequest::Op>(op);
  r.id = req.id();
  r.device = req.device().empty() ? "cpu" : req.device();
  if (r.op == geometry::GeometryRequest::Op::kCreateHashGrid) {
    if (req.dim_size() != 3) return InvalidArgument("HashGrid: dim must have 3 values");
    for (int k = 0; k < 3; ++k) r.dim[k] = req.dim(k);
  }
  r.points = req.points();
  r.indices = req.indices();
  r.velocities = req.velocities();
  r.lowers = req.lowers();
  r.uppers = req.uppers();
  r.radius = req.radius();
  r.groups = req.groups();
  r.leaves = req.leaves();
  r.masks = req.masks();
  r.values = req.values();
  r.value_type = static_cast<uint32_t>(req.value_type());
  if (req.background().size() > 64) return InvalidArgument("Volume: the background value is too long");
  r.background = req.background();
  if (req.transform_size() > 12) return InvalidArgument("Volume: the transform has more than 12 values");
  r.transform.assign(req.transform().begin(), req.transform().end());
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
