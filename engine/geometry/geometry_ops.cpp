// Geometry operations on the session's executor; see geometry_ops.h.
#include "engine/geometry/geometry_ops.h"

#include "engine/geometry/geometry_registry.h"
#include "engine/runtime/session.h"

namespace weft::geometry {

namespace {

Expected<std::shared_ptr<Allocation>> Array(Session& s, uint64_t handle, const std::string& what, bool optional = false) {
  if (handle == 0) {
    if (optional) return std::shared_ptr<Allocation>();
    return InvalidArgument(what + ": an array is required (handle 0)");
  }
  std::shared_ptr<Allocation> a = s.Find(handle);
  if (!a)
    return NotFound(what + ": unknown array handle " + std::to_string(handle) +
                    " (never created, already freed, or not held by this session)");
  return a;
}

Expected<uint64_t> Run(Session& s, const GeometryRequest& r, const DeviceAccess* dev) {
  GeometryRegistry& reg = s.geometry();
  switch (r.op) {
    case GeometryRequest::Op::kCreateHashGrid: {
      if (r.device != "cpu" && !dev)
        return FailedPrecondition("HashGrid on " + r.device + ": this daemon has no such device");
      WEFT_ASSIGN_OR_RETURN(auto g, GeometryObject::NewHashGrid(r.device, r.dim[0], r.dim[1], r.dim[2]));
      return reg.Add(std::move(g));
    }
    case GeometryRequest::Op::kCreateBvh: {
      WEFT_ASSIGN_OR_RETURN(auto lo, Array(s, r.lowers, "Bvh lowers"));
      WEFT_ASSIGN_OR_RETURN(auto hi, Array(s, r.uppers, "Bvh uppers"));
      WEFT_ASSIGN_OR_RETURN(auto groups, Array(s, r.groups, "Bvh groups", true));
      WEFT_ASSIGN_OR_RETURN(auto g, GeometryObject::NewBvh(std::move(lo), std::move(hi), dev, std::move(groups)));
      return reg.Add(std::move(g));
    }
    case GeometryRequest::Op::kCreateMesh: {
      WEFT_ASSIGN_OR_RETURN(auto p, Array(s, r.points, "Mesh points"));
      WEFT_ASSIGN_OR_RETURN(auto i, Array(s, r.indices, "Mesh indices"));
      WEFT_ASSIGN_OR_RETURN(auto v, Array(s, r.velocities, "Mesh velocities", true));
      WEFT_ASSIGN_OR_RETURN(auto groups, Array(s, r.groups, "Mesh groups", true));
      WEFT_ASSIGN_OR_RETURN(auto g, GeometryObject::NewMesh(std::move(p), std::move(i), std::move(v), dev, std::move(groups)));
      return reg.Add(std::move(g));
    }
    case GeometryRequest::Op::kCreateVolume: {
      WEFT_ASSIGN_OR_RETURN(auto leaves, Array(s, r.leaves, "Volume leaves"));
      WEFT_ASSIGN_OR_RETURN(auto masks, Array(s, r.masks, "Volume masks"));
      WEFT_ASSIGN_OR_RETURN(auto values, Array(s, r.values, "Volume values", true));
      WEFT_ASSIGN_OR_RETURN(auto g, GeometryObject::NewVolume(std::move(leaves), std::move(masks), std::move(values),
                                                              r.value_type, r.background, r.transform, dev));
      return reg.Add(std::move(g));
    }
    case GeometryRequest::Op::kBuildHashGrid: {
      WEFT_ASSIGN_OR_RETURN(auto g, reg.Find(r.id));
      WEFT_ASSIGN_OR_RETURN(auto p, Array(s, r.points, "HashGrid.build points"));
      WEFT_ASSIGN_OR_RETURN(auto groups, Array(s, r.groups, "HashGrid.build groups", true));
      WEFT_RETURN_IF_ERROR(g->BuildHashGrid(std::move(p), r.radius, dev, std::move(groups)));
      return uint64_t{0};
    }
    case GeometryRequest::Op::kRefit: {
      WEFT_ASSIGN_OR_RETURN(auto g, reg.Find(r.id));
      WEFT_RETURN_IF_ERROR(g->Refit(dev));
      return uint64_t{0};
    }
    case GeometryRequest::Op::kRebuild: {
      WEFT_ASSIGN_OR_RETURN(auto g, reg.Find(r.id));
      WEFT_RETURN_IF_ERROR(g->Rebuild(dev));
      return uint64_t{0};
    }
    case GeometryRequest::Op::kFree:
      WEFT_RETURN_IF_ERROR(reg.Remove(r.id));
      return uint64_t{0};
  }
  return InvalidArgument("unknown geometry operation " + std::to_string(static_cast<int>(r.op)));
}

}  // namespace

Expected<uint64_t> RunGeometryOpHere(Session& s, const GeometryRequest& r, const DeviceAccess* dev) {
  return Run(s, r, dev);
}

Expected<uint64_t> RunGeometryOp(Session& s, const GeometryRequest& r, const DeviceAccess* dev) {
  Expected<uint64_t> result = Internal("geometry operation did not run");
  s.queue().RunAndWait([&] { result = Run(s, r, dev); });
  return result;
}

}  // namespace weft::geometry
