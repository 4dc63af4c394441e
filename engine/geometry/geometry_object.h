// One geometry object of a session (wp.HashGrid, wp.Bvh, wp.Mesh or wp.Volume) on one device: the session
// arrays it reads (held, so freeing them client-side cannot free the memory under a kernel) and
// the daemon's own build products (BVH nodes, the checked copy of a mesh's indices, the hash
// grid's cells). Describe() writes the kernel-side descriptor (geometry_abi.h). Builds and refits
// run on the session's executor, ordered with its launches.
// On a GPU, hash grids and BVHs (grouped or not) are built on the device (a BVH as a linear BVH,
// bvh_build.h BvhBuildJob), and every BVH is refitted there. Where a device cannot build, the
// arrays are downloaded (after the session's queued work on the device), the tree is built as
// on the CPU, and the products are uploaded into device memory the object owns (counted in the
// session's quota); kernels read the user's arrays in place.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/geometry/bvh_build.h"
#include "engine/geometry/hash_grid_job.h"
#include "engine/geometry/volume_build.h"
#include "engine/native/geometry_abi.h"
#include "engine/runtime/allocation.h"

namespace weft::geometry {

// Hash grids: at most this many cells (dim_x * dim_y * dim_z, overflow-checked): 2^26 cells
// take 512 MiB of cell bounds.
constexpr int64_t kMaxHashGridCells = int64_t{1} << 26;
// Items of one Bvh or Mesh (faces, boxes, points): int32 indices in kernels.
constexpr int64_t kMaxGeometryItems = (int64_t{1} << 31) - 1;

// What an object on a GPU needs of the engine, bound to the calling session: host copies of
// device arrays and device memory for its build products. Null for CPU objects.
struct DeviceAccess {
  // Copies the first n bytes of `a` to dst, after the session's queued work on a's device.
  std::function<Status(const Allocation& a, void* dst, uint64_t n)> download;
  // A new allocation of `bytes` on `device`, owned by the session (quota), contents undefined.
  std::function<Expected<std::shared_ptr<Allocation>>(const std::string& device, uint64_t bytes)> allocate;
  // Copies n bytes from src to the start of `a`, ordered with the session's work on a's device.
  std::function<Status(const Allocation& a, const void* src, uint64_t n)> upload;
  // Refits a BVH on `device` (Device::RefitBvh; may be empty: the host refits).
  std::function<Status(const std::string& device, const BvhRefitJob& job)> refit_bvh;
  // Builds a hash grid on `device` (Device::BuildHashGrid; may be empty: the host builds; the
  // grids of a GPU are built there).
  std::function<Status(const std::string& device, const HashGridBuildJob& job)> build_hash_grid;
  // Builds a BVH on `device` (Device::BuildBvh; may be empty or Unimplemented: the host builds).
  std::function<Status(const std::string& device, const BvhBuildJob& job)> build_bvh;
  // Copies and checks a mesh's indices on `device` (Device::CheckMeshIndices; may be empty or
  // Unimplemented: they are downloaded and checked on the host).
  std::function<Status(const std::string& device, const MeshIndicesJob& job)> check_mesh_indices;
};

class GeometryObject {
 public:
  // A hash grid with no points yet (Build gives it some). dims each >= 1, product checked.
  static Expected<std::shared_ptr<GeometryObject>> NewHashGrid(const std::string& device, int32_t dim_x,
                                                               int32_t dim_y, int32_t dim_z);
  // A Bvh over lowers/uppers (contiguous vec3 float32 arrays of one length), built now.
  // `dev` is required for arrays on a GPU (each method below takes it the same way).
  // With `groups` (contiguous int32, one per item, on the arrays' device; may be null), each
  // group's items form one subtree (bvh_get_group_root); the ids are copied now and used by
  // every rebuild.
  static Expected<std::shared_ptr<GeometryObject>> NewBvh(std::shared_ptr<Allocation> lowers,
                                                          std::shared_ptr<Allocation> uppers,
                                                          const DeviceAccess* dev = nullptr,
                                                          std::shared_ptr<Allocation> groups = nullptr);
  // A Mesh over points (contiguous vec3 float32), indices (int32, length a multiple of 3, each
  // value < points: checked here and copied, so later writes to the array cannot reach a query)
  // and optional velocities (as points); its BVH built now.
  static Expected<std::shared_ptr<GeometryObject>> NewMesh(std::shared_ptr<Allocation> points,
                                                           std::shared_ptr<Allocation> indices,
                                                           std::shared_ptr<Allocation> velocities,
                                                           const DeviceAccess* dev = nullptr,
                                                           std::shared_ptr<Allocation> groups = nullptr);

  // A Volume (volume_build.h): leaves (int32 (n, 3) or vec3i (n), leaf origins), masks (uint64,
  // 8 per leaf) and, for value types, values (512 per leaf of the type's dtype, contiguous: kept
  // and used in place, so volume_store writes reach it). The leaves and masks are copied and
  // checked here; the kernel-side tables are built from the copies.
  static Expected<std::shared_ptr<GeometryObject>> NewVolume(std::shared_ptr<Allocation> leaves,
                                                             std::shared_ptr<Allocation> masks,
                                                             std::shared_ptr<Allocation> values, uint32_t type,
                                                             const std::string& background,
                                                             const std::vector<double>& transform,
                                                             const DeviceAccess* dev = nullptr);

  uint32_t kind() const { return kind_; }
  const std::string& device() const { return device_; }

  // HashGrid: sorts `points` (contiguous vec3 of float16/32/64) into cells of width `radius` (> 0).
  // With `groups` (contiguous int32, one per point, on the grid's device; may be null), each
  // cell's points are ordered by group id and the ids are kept for grouped queries (a copy taken
  // now: later writes to `groups` take effect at the next build).
  Status BuildHashGrid(std::shared_ptr<Allocation> points, float radius, const DeviceAccess* dev = nullptr,
                       std::shared_ptr<Allocation> groups = nullptr);
  // HashGrid: nothing to reserve ahead (cells are sized by the dims, sorted ids by the build).
  // Bvh / Mesh: recompute the node bounds from the arrays' current values.
  Status Refit(const DeviceAccess* dev = nullptr);
  // Bvh / Mesh: a new tree from the arrays' current values.
  Status Rebuild(const DeviceAccess* dev = nullptr);

  // The kernel-side descriptor; `keep` receives memory it points to beyond the object's own
  // (the points' gradient, which the array may replace while a launch still uses it).
  void Describe(wp::geometry_desc_t* d, std::vector<std::shared_ptr<const void>>* keep = nullptr) const;

 private:
  GeometryObject() = default;
  bool on_gpu() const { return device_ != "cpu"; }
  // Item bounds from host copies of the arrays (lowers/uppers of a Bvh, points of a Mesh).
  ItemBounds Bounds(const float* lowers, const float* uppers, const float* points) const;
  // Host copies of the tree's arrays (a GPU object's downloaded; a CPU object's in place).
  Status HostArrays(const DeviceAccess* dev, std::vector<float>* storage, const float** lowers,
                    const float** uppers, const float** points) const;
  // GPU: uploads the build products into the object's device memory (grown when too small).
  Status Mirror(const DeviceAccess* dev);
  struct DeviceCopy {
    std::shared_ptr<Allocation> memory;
    uint64_t bytes = 0;   // in use
  };
  Status MirrorOne(const DeviceAccess* dev, const void* src, uint64_t bytes, DeviceCopy* copy);
  // Device memory of at least `bytes` in `copy` (kept when large enough), contents undefined.
  Status EnsureDeviceMemory(const DeviceAccess* dev, uint64_t bytes, DeviceCopy* copy);
  // The device addresses of the items a BVH job reads: lowers/uppers (a Bvh) or points and the
  // checked indices (a Mesh); the others 0.
  void ItemAddresses(uintptr_t* lowers, uintptr_t* uppers, uintptr_t* points, uintptr_t* indices) const;
  // GPU: builds the tree on the device (Unimplemented when the device cannot).
  Status BuildBvhOnDevice(const DeviceAccess* dev);
  // GPU: copies the mesh's indices into gpu_indices_ and checks them there (Unimplemented when
  // the device cannot).
  Status CheckIndicesOnDevice(const std::shared_ptr<Allocation>& indices, uint64_t count, int64_t num_points,
                              const DeviceAccess* dev);
  // Checks `groups` (one int32 per item) and keeps them: copied into item_groups_ on the CPU; on
  // a GPU the device build copies them into gpu_item_groups_ (groups_ until then).
  Status TakeGroups(const std::shared_ptr<Allocation>& groups, const char* what);
  // GPU, grouped, where the device cannot build: item_groups_ from the device copy (or the
  // user's array before the first device build).
  Status DownloadGroups(const DeviceAccess* dev);

  uint32_t kind_ = wp::GEOMETRY_NONE;
  std::string device_;
  std::shared_ptr<Allocation> points_, velocities_, lowers_, uppers_;
  int64_t num_points_ = 0;
  int64_t num_prims_ = 0;
  std::vector<int32_t> indices_;   // mesh: checked copy (on a GPU, only where the host builds)
  std::vector<int32_t> item_groups_;   // grouped Bvh / Mesh: the group of each item (face)
  bool grouped_ = false;                  // built with groups
  std::shared_ptr<Allocation> groups_;    // GPU: the user's groups, until the device copied them
  std::shared_ptr<Allocation> user_indices_;   // mesh: the caller's array (mesh_get's indices)
  BvhData bvh_;
  // hash grid
  int32_t dim_[3] = {1, 1, 1};
  float cell_width_ = 0.0f;
  std::vector<int32_t> cell_starts_, cell_ends_, sorted_ids_;
  std::vector<int32_t> sorted_groups_;   // grouped build: the group of each sorted_ids_ entry
  int64_t num_sorted_ = 0;   // points of the last build (host or device)
  // volume
  VolumeData volume_;
  std::shared_ptr<Allocation> values_;
  // GPU: device copies of indices_, the nodes, the prim ids and the cells.
  DeviceCopy gpu_indices_, gpu_nodes_, gpu_prim_ids_, gpu_cell_starts_, gpu_cell_ends_, gpu_sorted_ids_;
  DeviceCopy gpu_sorted_groups_, gpu_levels_;
  DeviceCopy gpu_group_ids_, gpu_group_roots_;
  DeviceCopy gpu_item_groups_;    // a grouped BVH built on the device: the group of each item
  DeviceCopy gpu_vol_table_, gpu_vol_masks_, gpu_vol_prefix_;
  DeviceCopy gpu_sort_scratch_;   // a device build's sort buffers (a BVH's refit arrivals first)
  DeviceCopy gpu_parents_;        // a BVH built on the device: each node's parent
  bool device_built_ = false;     // the BVH was built on the device: bvh_ holds no nodes
};

// Checks that `a` is a whole contiguous array of vec3 float32 (any number of dimensions, or
// float32 of shape (n, 3)) through the one array validation; `any_float` also takes float16 and
// float64 (hash grid builds convert to float32). Returns the number of points.
Expected<int64_t> CheckVec3Array(const std::shared_ptr<Allocation>& a, const std::string& what, bool any_float = false);

}  // namespace weft::geometry
