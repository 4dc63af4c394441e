// The geometry operations a client asks for (weft.v1.GeometryService): create a HashGrid, Bvh,
// Mesh or Volume from the session's arrays, build a hash grid, refit / rebuild a tree, free an object.
// Each runs on the session's executor after the commands queued before it (so a build sees what
// earlier launches wrote), resolves array handles among the session's own arrays, and checks
// them through the one array validation. Objects on a GPU need `dev` (Engine::RunGeometry
// binds it to the session): without it a GPU array or device is refused.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/geometry/geometry_object.h"

namespace weft {
class Session;
}

namespace weft::geometry {

struct GeometryRequest {
  enum class Op { kCreateHashGrid = 1, kCreateBvh = 2, kCreateMesh = 3, kBuildHashGrid = 4, kRefit = 5,
                  kRebuild = 6, kFree = 7, kCreateVolume = 8 };
  Op op = Op::kCreateHashGrid;
  uint64_t id = 0;                 // build / refit / rebuild / free
  std::string device = "cpu";      // create hash grid
  int32_t dim[3] = {0, 0, 0};      // create hash grid
  uint64_t points = 0;             // mesh / hash grid build
  uint64_t groups = 0;             // hash grid build, bvh, mesh (optional)
  uint64_t indices = 0;            // mesh
  uint64_t velocities = 0;         // mesh, 0 = none
  uint64_t lowers = 0, uppers = 0; // bvh
  float radius = 0.0f;             // hash grid build
  uint64_t leaves = 0, masks = 0;  // volume
  uint64_t values = 0;             // volume, 0 = index grid
  uint32_t value_type = 0;         // volume (wp::volume_type)
  std::string background;          // volume: one value's bytes
  std::vector<double> transform;   // volume: 3x3 index-to-world matrix (row-major), translation
};

// Runs `r` for session `s`; returns the new object's id for a create, 0 otherwise. `r.device`
// of a hash grid must name a device of the daemon (the caller checks it).
Expected<uint64_t> RunGeometryOp(Session& s, const GeometryRequest& r, const DeviceAccess* dev = nullptr);
// The same on the calling thread, which must be the session's executor (a geometry command).
Expected<uint64_t> RunGeometryOpHere(Session& s, const GeometryRequest& r, const DeviceAccess* dev = nullptr);

}  // namespace weft::geometry
