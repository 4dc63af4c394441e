// Engine::RunGeometry: a geometry operation of a session (engine/geometry/geometry_ops.h) with
// access to the session's devices: host copies of GPU arrays for the builds, device memory (in
// the session's quota) for the build products of objects on a GPU.
#include "engine/geometry/geometry_ops.h"
#include "engine/runtime/engine.h"

namespace weft {

Expected<uint64_t> Engine::RunGeometry(Session& s, const geometry::GeometryRequest& request) {
  return RunGeometryWith(s, request, true);
}

Expected<uint64_t> Engine::RunGeometryHere(Session& s, const geometry::GeometryRequest& request) {
  return RunGeometryWith(s, request, false);
}

Expected<uint64_t> Engine::RunGeometryWith(Session& s, const geometry::GeometryRequest& request, bool queued) {
  geometry::GeometryRequest r = request;
  if (r.op == geometry::GeometryRequest::Op::kCreateHashGrid) {
    // The client names the device ("cpu", "cuda:N" or the session's "cuda").
    WEFT_ASSIGN_OR_RETURN(Device * device, devices_->Resolve(s.id(), r.device));
    r.device = device->name();
  }
  geometry::DeviceAccess access;
  access.download = [this, &s](const Allocation& a, void* dst, uint64_t n) -> Status {
    Device* d = devices_->Find(a.device);
    if (!d) return Internal("array " + std::to_string(a.handle) + " lives on unknown device '" + a.device + "'");
    if (n > a.byte_size) return Internal("geometry download past the end of array " + std::to_string(a.handle));
    return d->Download(s, a.block, 0, dst, n);
  };
  access.upload = [this, &s](const Allocation& a, const void* src, uint64_t n) -> Status {
    Device* d = devices_->Find(a.device);
    if (!d) return Internal("geometry memory on unknown device '" + a.device + "'");
    if (n > a.byte_size) return Internal("geometry upload past the end of its memory");
    return d->Upload(s, a.block, 0, src, n);
  };
  access.allocate = [this, &s](const std::string& device, uint64_t bytes) -> Expected<std::shared_ptr<Allocation>> {
    Device* d = devices_->Find(device);
    if (!d) return Internal("geometry memory on unknown device '" + device + "'");
    DType bytes_type;
    bytes_type.scalar = ScalarType::kUInt8;
    return NewAllocation(s, *d, bytes_type, {static_cast<int64_t>(bytes)}, false);
  };
  // The device an object's job runs on (its name comes from the object, never the client).
  auto device_of = [this](const std::string& device) -> Expected<Device*> {
    Device* d = devices_->Find(device);
    if (!d) return Internal("geometry object on unknown device '" + device + "'");
    return d;
  };
  access.refit_bvh = [device_of, &s](const std::string& device, const geometry::BvhRefitJob& job) -> Status {
    WEFT_ASSIGN_OR_RETURN(Device * d, device_of(device));
    return d->RefitBvh(s, job);
  };
  access.build_hash_grid = [device_of, &s](const std::string& device, const geometry::HashGridBuildJob& job) -> Status {
    WEFT_ASSIGN_OR_RETURN(Device * d, device_of(device));
    return d->BuildHashGrid(s, job);
  };
  access.build_bvh = [device_of, &s](const std::string& device, const geometry::BvhBuildJob& job) -> Status {
    WEFT_ASSIGN_OR_RETURN(Device * d, device_of(device));
    return d->BuildBvh(s, job);
  };
  access.check_mesh_indices = [device_of, &s](const std::string& device, const geometry::MeshIndicesJob& job) -> Status {
    WEFT_ASSIGN_OR_RETURN(Device * d, device_of(device));
    return d->CheckMeshIndices(s, job);
  };
  if (!queued) return geometry::RunGeometryOpHere(s, r, &access);
  return geometry::RunGeometryOp(s, r, &access);
}

}  // namespace weft
