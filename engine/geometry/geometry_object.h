// One geometry object of a session (wp.HashGrid, wp.Bvh or wp.Mesh) on one device: the session
// arrays it reads (held, so freeing them client-side cannot free the memory under a kernel) and
// the daemon's own build products (BVH nodes, the checked copy of a mesh's indices, the hash
// grid's cells). Describe() writes the kernel-side descriptor (geometry_abi.h). Builds and refits
// run on the session's executor, ordered with its launches.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/geometry/bvh_build.h"
#include "engine/native/geometry_abi.h"
#include "engine/runtime/allocation.h"

namespace weft::geometry {

// Hash grids: at most this many cells (dim_x * dim_y * dim_z, overflow-checked): 2^26 cells
// take 512 MiB of cell bounds.
constexpr int64_t kMaxHashGridCells = int64_t{1} << 26;
// Items of one Bvh or Mesh (faces, boxes, points): int32 indices in kernels.
constexpr int64_t kMaxGeometryItems = (int64_t{1} << 31) - 1;

class GeometryObject {
 public:
  // A hash grid with no points yet (Build gives it some). dims each >= 1, product checked.
  static Expected<std::shared_ptr<GeometryObject>> NewHashGrid(const std::string& device, int32_t dim_x,
                                                               int32_t dim_y, int32_t dim_z);
  // A Bvh over lowers/uppers (contiguous vec3 float32 arrays of one length), built now.
  static Expected<std::shared_ptr<GeometryObject>> NewBvh(std::shared_ptr<Allocation> lowers,
                                                          std::shared_ptr<Allocation> uppers);
  // A Mesh over points (contiguous vec3 float32), indices (int32, length a multiple of 3, each
  // value < points: checked here and copied, so later writes to the array cannot reach a query)
  // and optional velocities (as points); its BVH built now.
  static Expected<std::shared_ptr<GeometryObject>> NewMesh(std::shared_ptr<Allocation> points,
                                                           std::shared_ptr<Allocation> indices,
                                                           std::shared_ptr<Allocation> velocities);

  uint32_t kind() const { return kind_; }
  const std::string& device() const { return device_; }

  // HashGrid: sorts `points` (contiguous vec3 of float16/32/64) into cells of width `radius` (> 0).
  Status BuildHashGrid(std::shared_ptr<Allocation> points, float radius);
  // HashGrid: nothing to reserve ahead (cells are sized by the dims, sorted ids by the build).
  // Bvh / Mesh: recompute the node bounds from the arrays' current values.
  Status Refit();
  // Bvh / Mesh: a new tree from the arrays' current values.
  Status Rebuild();

  void Describe(wp::geometry_desc_t* d) const;

 private:
  GeometryObject() = default;
  ItemBounds Bounds() const;

  uint32_t kind_ = wp::GEOMETRY_NONE;
  std::string device_;
  std::shared_ptr<Allocation> points_, velocities_, lowers_, uppers_;
  int64_t num_points_ = 0;
  int64_t num_prims_ = 0;
  std::vector<int32_t> indices_;   // mesh: checked copy
  BvhData bvh_;
  // hash grid
  int32_t dim_[3] = {1, 1, 1};
  float cell_width_ = 0.0f;
  std::vector<int32_t> cell_starts_, cell_ends_, sorted_ids_;
};

// Checks that `a` is a whole contiguous array of vec3 float32 (any number of dimensions, or
// float32 of shape (n, 3)) through the one array validation; `any_float` also takes float16 and
// float64 (hash grid builds convert to float32). Returns the number of points.
Expected<int64_t> CheckVec3Array(const std::shared_ptr<Allocation>& a, const std::string& what, bool any_float = false);

}  // namespace weft::geometry
