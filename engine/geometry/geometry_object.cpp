// Geometry objects: construction with checked arrays, builds and refits; see geometry_object.h.
#include "engine/geometry/geometry_object.h"

#include <algorithm>
#include <cstring>
#include <new>

#include "engine/runtime/array_validation.h"

namespace weft::geometry {

namespace {

const float* Floats(const std::shared_ptr<Allocation>& a) {
  return a ? reinterpret_cast<const float*>(a->data()) : nullptr;
}

// The device (or host) address of an array or object memory, 0 for none.
uintptr_t AddressOf(const std::shared_ptr<Allocation>& a) { return a ? reinterpret_cast<uintptr_t>(a->data()) : uintptr_t{0}; }

}  // namespace

Expected<int64_t> CheckVec3Array(const std::shared_ptr<Allocation>& a, const std::string& what, bool any_float) {
  if (!a) return InvalidArgument(what + ": an array is required");
  ArrayRequirement req;
  req.what = what;
  req.device = a->device;
  WEFT_ASSIGN_OR_RETURN(ArrayView v, ValidateArray(a, ArrayRef{a->handle, 0, {}, {}}, req));
  const DType& d = a->dtype;
  bool scalar_ok = d.scalar == ScalarType::kFloat32 ||
                   (any_float && (d.scalar == ScalarType::kFloat64 || d.scalar == ScalarType::kFloat16));
  bool vec3 = scalar_ok && !d.is_struct() && d.elem_shape == std::vector<uint32_t>{3};
  bool rows3 = scalar_ok && !d.is_struct() && d.elem_shape.empty() && v.shape.size() == 2 && v.shape[1] == 3;
  if (!vec3 && !rows3)
    return InvalidArgument(what + ": expected an array of vec3 (" +
                           std::string(any_float ? "float16, float32 or float64" : "float32") + "), got " + d.Name() +
                           " " + ShapeString(v.shape));
  if (!v.contiguous()) return InvalidArgument(what + ": the array must be contiguous");
  uint64_t count = vec3 ? v.element_count() : static_cast<uint64_t>(v.shape[0]);
  if (count > static_cast<uint64_t>(kMaxGeometryItems)) return InvalidArgument(what + ": too many points (at most 2^31 - 1)");
  return static_cast<int64_t>(count);
}

namespace {

float HalfToFloat(uint16_t h) {
  uint32_t sign = static_cast<uint32_t>(h & 0x8000u) << 16, exp = (h >> 10) & 0x1fu, mant = h & 0x3ffu, bits;
  if (exp == 0) {
    if (mant == 0) {
      bits = sign;
    } else {   // subnormal
      exp = 127 - 15 + 1;
      while (!(mant & 0x400u)) {
        mant <<= 1;
        --exp;
      }
      bits = sign | (exp << 23) | ((mant & 0x3ffu) << 13);
    }
  } else if (exp == 31) {
    bits = sign | 0x7f800000u | (mant << 13);
  } else {
    bits = sign | ((exp + 127 - 15) << 23) | (mant << 13);
  }
  float f;
  std::memcpy(&f, &bits, 4);
  return f;
}

// Coordinate k of point i of a vec3 array of float16/32/64 (bytes p), as float32.
float Coord(const char* p, ScalarType scalar, int64_t i, int k) {
  switch (scalar) {
    case ScalarType::kFloat64: { double d; std::memcpy(&d, p + 8 * (3 * i + k), 8); return static_cast<float>(d); }
    case ScalarType::kFloat16: { uint16_t h; std::memcpy(&h, p + 2 * (3 * i + k), 2); return HalfToFloat(h); }
    default: { float f; std::memcpy(&f, p + 4 * (3 * i + k), 4); return f; }
  }
}

Status MeshIndexOutOfRange(uint64_t i, int64_t v, int64_t points) {
  return InvalidArgument("Mesh indices: indices[" + std::to_string(i) + "] = " + std::to_string(v) +
                         " is out of range for " + std::to_string(points) + " points");
}

Status NeedAccess(const std::string& device, const DeviceAccess* dev, const char* what) {
  if (device != "cpu" && !dev) return FailedPrecondition(std::string(what) + " on " + device + ": no device access");
  return Status::Ok();
}

}  // namespace

Expected<std::shared_ptr<GeometryObject>> GeometryObject::NewHashGrid(const std::string& device, int32_t dim_x,
                                                                      int32_t dim_y, int32_t dim_z) {
  if (dim_x < 1 || dim_y < 1 || dim_z < 1)
    return InvalidArgument("HashGrid: dims must be >= 1, got (" + std::to_string(dim_x) + ", " + std::to_string(dim_y) +
                           ", " + std::to_string(dim_z) + ")");
  __int128 cells = static_cast<__int128>(dim_x) * dim_y * dim_z;
  if (cells > kMaxHashGridCells)
    return InvalidArgument("HashGrid: cell count exceeds supported limit: dims (" + std::to_string(dim_x) + ", " +
                           std::to_string(dim_y) + ", " + std::to_string(dim_z) + ") give more than 2^26 cells");
  std::shared_ptr<GeometryObject> g(new GeometryObject());
  g->kind_ = wp::GEOMETRY_HASH_GRID;
  g->device_ = device;
  g->dim_[0] = dim_x;
  g->dim_[1] = dim_y;
  g->dim_[2] = dim_z;
  return g;
}

Expected<std::shared_ptr<GeometryObject>> GeometryObject::NewBvh(std::shared_ptr<Allocation> lowers,
                                                                 std::shared_ptr<Allocation> uppers,
                                                                 const DeviceAccess* dev,
                                                                 std::shared_ptr<Allocation> groups) {
  WEFT_ASSIGN_OR_RETURN(int64_t nl, CheckVec3Array(lowers, "Bvh lowers"));
  WEFT_ASSIGN_OR_RETURN(int64_t nu, CheckVec3Array(uppers, "Bvh uppers"));
  if (nl != nu)
    return InvalidArgument("Bvh: lowers has " + std::to_string(nl) + " items and uppers " + std::to_string(nu));
  if (lowers->device != uppers->device) return InvalidArgument("Bvh: lowers and uppers live on different devices");
  WEFT_RETURN_IF_ERROR(NeedAccess(lowers->device, dev, "Bvh"));
  std::shared_ptr<GeometryObject> g(new GeometryObject());
  g->kind_ = wp::GEOMETRY_BVH;
  g->device_ = lowers->device;
  g->lowers_ = std::move(lowers);
  g->uppers_ = std::move(uppers);
  g->num_prims_ = nl;
  WEFT_RETURN_IF_ERROR(g->TakeGroups(groups, "Bvh groups"));
  WEFT_RETURN_IF_ERROR(g->Rebuild(dev));
  return g;
}

Expected<std::shared_ptr<GeometryObject>> GeometryObject::NewMesh(std::shared_ptr<Allocation> points,
                                                                  std::shared_ptr<Allocation> indices,
                                                                  std::shared_ptr<Allocation> velocities,
                                                                  const DeviceAccess* dev,
                                                                  std::shared_ptr<Allocation> groups) {
  WEFT_ASSIGN_OR_RETURN(int64_t np, CheckVec3Array(points, "Mesh points"));
  if (velocities) {
    WEFT_ASSIGN_OR_RETURN(int64_t nv, CheckVec3Array(velocities, "Mesh velocities"));
    if (nv != np)
      return InvalidArgument("Mesh: velocities has " + std::to_string(nv) + " entries and points " + std::to_string(np));
    if (velocities->device != points->device) return InvalidArgument("Mesh: velocities and points live on different devices");
  }
  if (!indices) return InvalidArgument("Mesh indices: an array is required");
  WEFT_RETURN_IF_ERROR(NeedAccess(points->device, dev, "Mesh"));
  ArrayRequirement req;
  req.what = "Mesh indices";
  req.device = points->device;
  req.dtype = "int32";
  WEFT_ASSIGN_OR_RETURN(ArrayView iv, ValidateArray(indices, ArrayRef{indices->handle, 0, {}, {}}, req));
  if (indices->dtype.scalar != ScalarType::kInt32 || !indices->dtype.elem_shape.empty() || indices->dtype.is_struct())
    return InvalidArgument("Mesh indices: expected an int32 array, got " + indices->dtype.Name());
  if (!iv.contiguous()) return InvalidArgument("Mesh indices: the array must be contiguous");
  uint64_t count = iv.element_count();
  if (count % 3 != 0)
    return InvalidArgument("Mesh indices: " + std::to_string(count) + " values is not a multiple of 3 (one triple per face)");
  if (count / 3 > static_cast<uint64_t>(kMaxGeometryItems)) return InvalidArgument("Mesh indices: too many faces");
  std::shared_ptr<GeometryObject> g(new GeometryObject());
  g->kind_ = wp::GEOMETRY_MESH;
  g->device_ = points->device;
  // A GPU mesh is built on the device and checks its indices there: no download.
  Status checked = Unimplemented("host check");
  if (count && g->on_gpu()) checked = g->CheckIndicesOnDevice(indices, count, np, dev);
  if (checked.code() != StatusCode::kUnimplemented) WEFT_RETURN_IF_ERROR(checked);
  if (checked.code() == StatusCode::kUnimplemented) {
    try {
      g->indices_.resize(count);
    } catch (const std::bad_alloc&) {
      return ResourceExhausted("Mesh: out of memory for the indices");
    }
    if (count && points->device != "cpu") {
      WEFT_RETURN_IF_ERROR(dev->download(*indices, g->indices_.data(), count * sizeof(int32_t)));
    } else if (count) {
      std::memcpy(g->indices_.data(), iv.data(), count * sizeof(int32_t));
    }
    for (uint64_t i = 0; i < count; ++i) {
      int32_t v = g->indices_[i];
      if (v < 0 || v >= np) return MeshIndexOutOfRange(i, v, np);
    }
  }
  g->points_ = std::move(points);
  g->velocities_ = std::move(velocities);
  g->user_indices_ = std::move(indices);
  g->num_points_ = np;
  g->num_prims_ = static_cast<int64_t>(count / 3);
  WEFT_RETURN_IF_ERROR(g->TakeGroups(groups, "Mesh groups"));
  WEFT_RETURN_IF_ERROR(g->Rebuild(dev));
  return g;
}

namespace {

// The whole array `a` checked through the one array validation: contiguous, of scalar `scalar`
// (int64 also for uint64), not a struct; returns its scalar count.
Expected<uint64_t> CheckScalars(const std::shared_ptr<Allocation>& a, const std::string& what, ScalarType scalar) {
  ArrayRequirement req;
  req.what = what;
  req.device = a->device;
  WEFT_ASSIGN_OR_RETURN(ArrayView v, ValidateArray(a, ArrayRef{a->handle, 0, {}, {}}, req));
  const DType& d = a->dtype;
  bool ok = !d.is_struct() && (d.scalar == scalar || (scalar == ScalarType::kUInt64 && d.scalar == ScalarType::kInt64));
  if (!ok) return InvalidArgument(what + ": expected " + std::string(ScalarName(scalar)) + " values, got " + d.Name());
  if (!v.contiguous()) return InvalidArgument(what + ": the array must be contiguous");
  uint64_t per = 1;
  for (uint32_t e : d.elem_shape) per *= e;
  return v.element_count() * per;
}

}  // namespace

Expected<std::shared_ptr<GeometryObject>> GeometryObject::NewVolume(std::shared_ptr<Allocation> leaves,
                                                                    std::shared_ptr<Allocation> masks,
                                                                    std::shared_ptr<Allocation> values, uint32_t type,
                                                                    const std::string& background,
                                                                    const std::vector<double>& transform,
                                                                    const DeviceAccess* dev) {
  if (!leaves || !masks) return InvalidArgument("Volume: the leaves and masks arrays are required");
  WEFT_ASSIGN_OR_RETURN(uint32_t value_size, VolumeValueSize(type));
  const std::string device = leaves->device;
  WEFT_RETURN_IF_ERROR(NeedAccess(device, dev, "Volume"));
  WEFT_ASSIGN_OR_RETURN(uint64_t coords, CheckScalars(leaves, "Volume leaves", ScalarType::kInt32));
  if (coords % 3 != 0)
    return InvalidArgument("Volume leaves: expected n leaf origins of 3 int32 each, got " + std::to_string(coords) +
                           " values");
  const uint64_t n = coords / 3;
  if (n > static_cast<uint64_t>(kMaxVolumeLeaves))
    return InvalidArgument("Volume: " + std::to_string(n) + " leaves exceed the limit of 2^22 (2^31 voxels)");
  if (masks->device != device) return InvalidArgument("Volume masks live on " + masks->device + ", the leaves on " + device);
  WEFT_ASSIGN_OR_RETURN(uint64_t words, CheckScalars(masks, "Volume masks", ScalarType::kUInt64));
  if (words != 8 * n)
    return InvalidArgument("Volume masks: expected 8 words per leaf (" + std::to_string(8 * n) + "), got " +
                           std::to_string(words));
  if (value_size == 0 && values) return InvalidArgument("Volume: an index grid (" + VolumeTypeName(type) + ") has no values array");
  if (value_size != 0) {
    if (!values) return InvalidArgument("Volume: a " + VolumeTypeName(type) + " grid needs its values array");
    if (values->device != device)
      return InvalidArgument("Volume values live on " + values->device + ", the leaves on " + device);
    static const struct { uint32_t type; ScalarType scalar; } kScalars[] = {
        {wp::VOLUME_FLOAT, ScalarType::kFloat32}, {wp::VOLUME_DOUBLE, ScalarType::kFloat64},
        {wp::VOLUME_INT32, ScalarType::kInt32},   {wp::VOLUME_INT64, ScalarType::kInt64},
        {wp::VOLUME_UINT32, ScalarType::kUInt32}, {wp::VOLUME_VEC3F, ScalarType::kFloat32},
        {wp::VOLUME_VEC3D, ScalarType::kFloat64}, {wp::VOLUME_VEC4F, ScalarType::kFloat32},
        {wp::VOLUME_VEC4D, ScalarType::kFloat64}};
    ScalarType scalar = ScalarType::kFloat32;
    for (const auto& e : kScalars)
      if (e.type == type) scalar = e.scalar;
    WEFT_ASSIGN_OR_RETURN(uint64_t scalars, CheckScalars(values, "Volume values", scalar));
    const uint64_t want = n * wp::VOLUME_LEAF_VOXELS * (value_size / ScalarSize(scalar));
    if (scalars != want)
      return InvalidArgument("Volume values: a " + VolumeTypeName(type) + " grid of " + std::to_string(n) +
                             " leaves needs " + std::to_string(n * wp::VOLUME_LEAF_VOXELS) + " values (" +
                             std::to_string(want) + " " + ScalarName(scalar) + "), got " + std::to_string(scalars));
  }
  std::vector<int32_t> origins;
  std::vector<uint64_t> mask_words;
  try {
    origins.resize(3 * n);
    mask_words.resize(8 * n);
  } catch (const std::bad_alloc&) {
    return ResourceExhausted("Volume: out of host memory for " + std::to_string(n) + " leaves");
  }
  if (device != "cpu") {
    WEFT_RETURN_IF_ERROR(dev->download(*leaves, origins.data(), origins.size() * sizeof(int32_t)));
    WEFT_RETURN_IF_ERROR(dev->download(*masks, mask_words.data(), mask_words.size() * sizeof(uint64_t)));
  } else {
    std::memcpy(origins.data(), leaves->data(), origins.size() * sizeof(int32_t));
    std::memcpy(mask_words.data(), masks->data(), mask_words.size() * sizeof(uint64_t));
  }
  auto g = std::shared_ptr<GeometryObject>(new GeometryObject());
  WEFT_RETURN_IF_ERROR(BuildVolume(type, origins.data(), mask_words.data(), static_cast<int64_t>(n), background,
                                   transform, &g->volume_));
  g->kind_ = wp::GEOMETRY_VOLUME;
  g->device_ = device;
  g->values_ = std::move(values);
  g->num_prims_ = static_cast<int64_t>(n);
  if (g->on_gpu()) {
    const VolumeData& v = g->volume_;
    WEFT_RETURN_IF_ERROR(g->MirrorOne(dev, v.table.data(), v.table.size() * sizeof(int32_t), &g->gpu_vol_table_));
    WEFT_RETURN_IF_ERROR(g->MirrorOne(dev, v.masks.data(), v.masks.size() * sizeof(uint64_t), &g->gpu_vol_masks_));
    WEFT_RETURN_IF_ERROR(g->MirrorOne(dev, v.prefix.data(), v.prefix.size() * sizeof(int64_t), &g->gpu_vol_prefix_));
  }
  return g;
}

Status GeometryObject::CheckIndicesOnDevice(const std::shared_ptr<Allocation>& indices, uint64_t count,
                                            int64_t num_points, const DeviceAccess* dev) {
  if (!dev || !dev->check_mesh_indices || !dev->build_bvh) return Unimplemented("no device index check");
  WEFT_RETURN_IF_ERROR(EnsureDeviceMemory(dev, count * sizeof(int32_t), &gpu_indices_));
  DeviceCopy result;
  WEFT_RETURN_IF_ERROR(EnsureDeviceMemory(dev, 2 * sizeof(uint64_t), &result));
  MeshIndicesJob job;
  job.src = reinterpret_cast<uintptr_t>(indices->data());
  job.dst = reinterpret_cast<uintptr_t>(gpu_indices_.memory->data());
  job.result = reinterpret_cast<uintptr_t>(result.memory->data());
  job.count = static_cast<int64_t>(count);
  job.limit = static_cast<int32_t>(num_points);   // points < 2^31 (CheckVec3Array)
  Status queued = dev->check_mesh_indices(device_, job);
  if (!queued.ok()) {
    gpu_indices_ = DeviceCopy{};
    return queued;
  }
  uint64_t found[2] = {0, 0};
  WEFT_RETURN_IF_ERROR(dev->download(*result.memory, found, sizeof(found)));   // after the check
  if (found[0] != ~uint64_t{0}) return MeshIndexOutOfRange(found[0], static_cast<int32_t>(found[1]), num_points);
  return Status::Ok();
}

Status GeometryObject::TakeGroups(const std::shared_ptr<Allocation>& groups, const char* what) {
  item_groups_.clear();
  grouped_ = groups != nullptr;
  if (!groups) return Status::Ok();
  if (groups->device != device_)
    return InvalidArgument(std::string(what) + ": the groups live on " + groups->device + ", the object on " + device_);
  WEFT_ASSIGN_OR_RETURN(uint64_t count, CheckScalars(groups, what, ScalarType::kInt32));
  if (count != static_cast<uint64_t>(num_prims_))
    return InvalidArgument(std::string(what) + ": " + std::to_string(count) + " group ids for " +
                           std::to_string(num_prims_) + " items (one per item)");
  if (count == 0) return Status::Ok();
  if (on_gpu()) {   // read by the device build (or downloaded where the host builds)
    groups_ = groups;
    return Status::Ok();
  }
  try {
    item_groups_.resize(count);
  } catch (const std::bad_alloc&) {
    return ResourceExhausted(std::string(what) + ": out of host memory");
  }
  std::memcpy(item_groups_.data(), groups->data(), count * sizeof(int32_t));
  return Status::Ok();
}

Status GeometryObject::DownloadGroups(const DeviceAccess* dev) {
  if (!grouped_ || !item_groups_.empty() || num_prims_ == 0) return Status::Ok();
  const uint64_t bytes = static_cast<uint64_t>(num_prims_) * sizeof(int32_t);
  try {
    item_groups_.resize(static_cast<size_t>(num_prims_));
  } catch (const std::bad_alloc&) {
    return ResourceExhausted("out of host memory for the groups");
  }
  if (gpu_item_groups_.memory && gpu_item_groups_.bytes >= bytes) return dev->download(*gpu_item_groups_.memory, item_groups_.data(), bytes);
  if (groups_) return dev->download(*groups_, item_groups_.data(), bytes);
  return Internal("the groups of this object are gone");
}

ItemBounds GeometryObject::Bounds(const float* lo, const float* hi, const float* p) const {
  if (kind_ == wp::GEOMETRY_BVH) {
    return [lo, hi](int64_t i, float* l, float* h) {
      for (int k = 0; k < 3; ++k) {
        l[k] = lo[3 * i + k];
        h[k] = hi[3 * i + k];
      }
    };
  }
  const int32_t* idx = indices_.data();
  return [p, idx](int64_t f, float* l, float* h) {
    for (int k = 0; k < 3; ++k) {
      l[k] = 3.0e38f;
      h[k] = -3.0e38f;
    }
    for (int c = 0; c < 3; ++c) {
      const float* v = p + 3 * static_cast<int64_t>(idx[3 * f + c]);
      for (int k = 0; k < 3; ++k) {
        if (v[k] < l[k]) l[k] = v[k];
        if (v[k] > h[k]) h[k] = v[k];
      }
    }
  };
}

Status GeometryObject::HostArrays(const DeviceAccess* dev, std::vector<float>* storage, const float** lo,
                                  const float** hi, const float** p) const {
  *lo = *hi = *p = nullptr;
  if (!on_gpu()) {
    *lo = Floats(lowers_);
    *hi = Floats(uppers_);
    *p = Floats(points_);
    return Status::Ok();
  }
  WEFT_RETURN_IF_ERROR(NeedAccess(device_, dev, "geometry object"));
  const int64_t items = kind_ == wp::GEOMETRY_BVH ? num_prims_ : num_points_;
  const uint64_t bytes = static_cast<uint64_t>(items) * 3 * sizeof(float);
  try {
    storage->resize(static_cast<size_t>(items) * (kind_ == wp::GEOMETRY_BVH ? 6 : 3));
  } catch (const std::bad_alloc&) {
    return ResourceExhausted("out of host memory for a copy of the geometry's arrays");
  }
  if (kind_ == wp::GEOMETRY_BVH) {
    WEFT_RETURN_IF_ERROR(dev->download(*lowers_, storage->data(), bytes));
    WEFT_RETURN_IF_ERROR(dev->download(*uppers_, storage->data() + 3 * items, bytes));
    *lo = storage->data();
    *hi = storage->data() + 3 * items;
  } else {
    WEFT_RETURN_IF_ERROR(dev->download(*points_, storage->data(), bytes));
    *p = storage->data();
  }
  return Status::Ok();
}

Status GeometryObject::EnsureDeviceMemory(const DeviceAccess* dev, uint64_t bytes, DeviceCopy* copy) {
  copy->bytes = bytes;
  if (bytes == 0) return Status::Ok();
  if (!copy->memory || copy->memory->byte_size < bytes) {
    copy->memory.reset();
    WEFT_ASSIGN_OR_RETURN(copy->memory, dev->allocate(device_, bytes));
  }
  return Status::Ok();
}

Status GeometryObject::MirrorOne(const DeviceAccess* dev, const void* src, uint64_t bytes, DeviceCopy* copy) {
  WEFT_RETURN_IF_ERROR(EnsureDeviceMemory(dev, bytes, copy));
  if (bytes == 0) return Status::Ok();
  return dev->upload(*copy->memory, src, bytes);
}

Status GeometryObject::Mirror(const DeviceAccess* dev) {
  if (!on_gpu()) return Status::Ok();
  WEFT_RETURN_IF_ERROR(NeedAccess(device_, dev, "geometry object"));
  if (!indices_.empty() && gpu_indices_.bytes != indices_.size() * sizeof(int32_t))   // fixed at creation
    WEFT_RETURN_IF_ERROR(MirrorOne(dev, indices_.data(), indices_.size() * sizeof(int32_t), &gpu_indices_));
  WEFT_RETURN_IF_ERROR(MirrorOne(dev, bvh_.nodes.data(), bvh_.nodes.size() * sizeof(wp::bvh_node_t), &gpu_nodes_));
  WEFT_RETURN_IF_ERROR(MirrorOne(dev, bvh_.prim_ids.data(), bvh_.prim_ids.size() * sizeof(int32_t), &gpu_prim_ids_));
  WEFT_RETURN_IF_ERROR(MirrorOne(dev, bvh_.levels.data(), bvh_.levels.size() * sizeof(int32_t), &gpu_levels_));
  WEFT_RETURN_IF_ERROR(MirrorOne(dev, bvh_.group_ids.data(), bvh_.group_ids.size() * sizeof(int32_t), &gpu_group_ids_));
  WEFT_RETURN_IF_ERROR(
      MirrorOne(dev, bvh_.group_roots.data(), bvh_.group_roots.size() * sizeof(int32_t), &gpu_group_roots_));
  WEFT_RETURN_IF_ERROR(
      MirrorOne(dev, cell_starts_.data(), cell_starts_.size() * sizeof(int32_t), &gpu_cell_starts_));
  WEFT_RETURN_IF_ERROR(MirrorOne(dev, cell_ends_.data(), cell_ends_.size() * sizeof(int32_t), &gpu_cell_ends_));
  WEFT_RETURN_IF_ERROR(MirrorOne(dev, sorted_ids_.data(), sorted_ids_.size() * sizeof(int32_t), &gpu_sorted_ids_));
  return MirrorOne(dev, sorted_groups_.data(), sorted_groups_.size() * sizeof(int32_t), &gpu_sorted_groups_);
}

Status GeometryObject::Rebuild(const DeviceAccess* dev) {
  if (kind_ == wp::GEOMETRY_HASH_GRID) return Status::Ok();
  if (kind_ == wp::GEOMETRY_VOLUME) return InvalidArgument("rebuild() is a Bvh or Mesh operation, not a Volume's");
  if (on_gpu() && num_prims_ > 0) {
    Status built = BuildBvhOnDevice(dev);
    if (built.code() != StatusCode::kUnimplemented) return built;
    WEFT_RETURN_IF_ERROR(DownloadGroups(dev));
  }
  device_built_ = false;
  gpu_parents_.bytes = 0;
  if (kind_ == wp::GEOMETRY_MESH && num_prims_ > 0 && indices_.empty())
    return Internal("Mesh: the indices were checked on " + device_ + ", which cannot build the tree");
  std::vector<float> host;
  const float *lo, *hi, *p;
  WEFT_RETURN_IF_ERROR(HostArrays(dev, &host, &lo, &hi, &p));
  try {
    BuildBvh(num_prims_, Bounds(lo, hi, p), &bvh_, item_groups_.empty() ? nullptr : item_groups_.data());
  } catch (const std::bad_alloc&) {
    return ResourceExhausted("out of memory building the BVH");
  }
  return Mirror(dev);
}

void GeometryObject::ItemAddresses(uintptr_t* lowers, uintptr_t* uppers, uintptr_t* points, uintptr_t* indices) const {
  *lowers = *uppers = *points = *indices = 0;
  if (kind_ == wp::GEOMETRY_BVH) {
    *lowers = AddressOf(lowers_);
    *uppers = AddressOf(uppers_);
  } else {
    *points = AddressOf(points_);
    *indices = AddressOf(gpu_indices_.memory);
  }
}

Status GeometryObject::BuildBvhOnDevice(const DeviceAccess* dev) {
  if (!dev || !dev->build_bvh) return Unimplemented("no device BVH build");
  // From here on there is no host tree: a failure leaves an empty tree (queries find nothing).
  bvh_ = BvhData{};
  device_built_ = false;
  gpu_levels_.bytes = gpu_group_ids_.bytes = gpu_group_roots_.bytes = 0;
  const uint64_t n = static_cast<uint64_t>(num_prims_);
  Status memory = EnsureDeviceMemory(dev, (2 * n - 1) * sizeof(wp::bvh_node_t), &gpu_nodes_);
  if (memory.ok()) memory = EnsureDeviceMemory(dev, n * sizeof(int32_t), &gpu_prim_ids_);
  if (memory.ok()) memory = EnsureDeviceMemory(dev, (2 * n - 1) * sizeof(int32_t), &gpu_parents_);
  if (memory.ok()) memory = EnsureDeviceMemory(dev, BvhBuildScratchBytes(num_prims_), &gpu_sort_scratch_);
  const bool copied = gpu_item_groups_.memory && gpu_item_groups_.bytes == n * sizeof(int32_t);
  if (grouped_) {
    if (memory.ok() && !copied) memory = EnsureDeviceMemory(dev, n * sizeof(int32_t), &gpu_item_groups_);
    if (memory.ok()) memory = EnsureDeviceMemory(dev, n * sizeof(int32_t), &gpu_group_ids_);
    if (memory.ok()) memory = EnsureDeviceMemory(dev, n * sizeof(int32_t), &gpu_group_roots_);
  }
  if (memory.ok() && kind_ == wp::GEOMETRY_MESH && !indices_.empty() &&
      gpu_indices_.bytes != indices_.size() * sizeof(int32_t))   // checked on the host
    memory = MirrorOne(dev, indices_.data(), indices_.size() * sizeof(int32_t), &gpu_indices_);
  if (!memory.ok()) {
    gpu_nodes_.bytes = gpu_prim_ids_.bytes = gpu_parents_.bytes = 0;
    gpu_group_ids_.bytes = gpu_group_roots_.bytes = 0;
    if (!copied) gpu_item_groups_.bytes = 0;
    return memory;
  }
  BvhBuildJob job;
  job.n = num_prims_;
  ItemAddresses(&job.lowers, &job.uppers, &job.points, &job.indices);
  job.nodes = AddressOf(gpu_nodes_.memory);
  job.prim_ids = AddressOf(gpu_prim_ids_.memory);
  job.parents = AddressOf(gpu_parents_.memory);
  job.scratch = AddressOf(gpu_sort_scratch_.memory);
  if (grouped_) {
    job.item_groups = AddressOf(gpu_item_groups_.memory);
    job.groups_src = copied ? job.item_groups : AddressOf(groups_);   // the user's array, once
    job.group_ids = AddressOf(gpu_group_ids_.memory);
    job.group_roots = AddressOf(gpu_group_roots_.memory);
  }
  Status built = dev->build_bvh(device_, job);
  device_built_ = built.ok();
  if (!built.ok()) {
    gpu_nodes_.bytes = gpu_prim_ids_.bytes = gpu_parents_.bytes = 0;
    gpu_group_ids_.bytes = gpu_group_roots_.bytes = 0;
    if (!copied) gpu_item_groups_.bytes = 0;
  } else if (grouped_) {
    groups_.reset();   // copied: a rebuild reads the object's copy
  }
  return built;
}

Status GeometryObject::Refit(const DeviceAccess* dev) {
  if (kind_ == wp::GEOMETRY_HASH_GRID) return Status::Ok();
  if (kind_ == wp::GEOMETRY_VOLUME) return InvalidArgument("refit() is a Bvh or Mesh operation, not a Volume's");
  if (on_gpu() && dev && dev->refit_bvh && gpu_nodes_.bytes > 0) {
    // On the device, queued after the session's work: no download, no upload.
    BvhRefitJob job;
    job.nodes = AddressOf(gpu_nodes_.memory);
    job.prim_ids = AddressOf(gpu_prim_ids_.memory);
    job.levels = AddressOf(gpu_levels_.memory);
    job.level_starts = bvh_.level_starts;
    if (device_built_) {
      job.parents = AddressOf(gpu_parents_.memory);
      job.arrivals = AddressOf(gpu_sort_scratch_.memory);
      job.num_items = num_prims_;
    }
    ItemAddresses(&job.lowers, &job.uppers, &job.points, &job.indices);
    Status refit = dev->refit_bvh(device_, job);
    if (refit.code() != StatusCode::kUnimplemented || device_built_) return refit;
  }
  if (device_built_) return Status::Ok();   // the tree failed to build: nothing to refit
  std::vector<float> host;
  const float *lo, *hi, *p;
  WEFT_RETURN_IF_ERROR(HostArrays(dev, &host, &lo, &hi, &p));
  RefitBvh(Bounds(lo, hi, p), &bvh_);
  if (!on_gpu()) return Status::Ok();
  return MirrorOne(dev, bvh_.nodes.data(), bvh_.nodes.size() * sizeof(wp::bvh_node_t), &gpu_nodes_);
}

Status GeometryObject::BuildHashGrid(std::shared_ptr<Allocation> points, float radius, const DeviceAccess* dev,
                                     std::shared_ptr<Allocation> groups) {
  if (kind_ != wp::GEOMETRY_HASH_GRID) return InvalidArgument("build(points, radius) is a HashGrid operation");
  if (!(radius > 0.0f) || radius > 3.0e38f)
    return InvalidArgument("HashGrid.build: radius must be a positive finite number, got " + std::to_string(radius));
  WEFT_ASSIGN_OR_RETURN(int64_t n, CheckVec3Array(points, "HashGrid.build points", true));
  if (points->device != device_)
    return InvalidArgument("HashGrid.build: the points live on " + points->device + ", the grid on " + device_);
  // A GPU grid is built on its device (the groups read there too); others on the host.
  const bool on_device = on_gpu() && dev && dev->build_hash_grid;
  std::vector<int32_t> group_of;   // the groups' copy (grouped build on the host)
  if (groups) {
    ArrayRequirement req;
    req.what = "HashGrid.build groups";
    req.device = device_;
    req.dtype = "int32";
    WEFT_ASSIGN_OR_RETURN(ArrayView gv, ValidateArray(groups, ArrayRef{groups->handle, 0, {}, {}}, req));
    if (groups->dtype.scalar != ScalarType::kInt32 || !groups->dtype.elem_shape.empty() || groups->dtype.is_struct())
      return InvalidArgument("HashGrid.build groups: expected an int32 array, got " + groups->dtype.Name());
    if (!gv.contiguous()) return InvalidArgument("HashGrid.build groups: the array must be contiguous");
    if (gv.element_count() != static_cast<uint64_t>(n))
      return InvalidArgument("HashGrid.build groups: " + std::to_string(gv.element_count()) + " group ids for " +
                             std::to_string(n) + " points (one per point)");
    try {
      if (!on_device) group_of.resize(static_cast<size_t>(n));
    } catch (const std::bad_alloc&) {
      return ResourceExhausted("HashGrid.build: out of memory for a copy of the groups");
    }
    if (n > 0 && !on_device) {
      if (on_gpu()) {
        WEFT_RETURN_IF_ERROR(NeedAccess(device_, dev, "HashGrid.build"));
        WEFT_RETURN_IF_ERROR(dev->download(*groups, group_of.data(), static_cast<uint64_t>(n) * sizeof(int32_t)));
      } else {
        std::memcpy(group_of.data(), groups->data(), static_cast<size_t>(n) * sizeof(int32_t));
      }
    }
  }
  const int64_t cells = static_cast<int64_t>(dim_[0]) * dim_[1] * dim_[2];
  const ScalarType scalar = points->dtype.scalar;
  if (n > INT32_MAX) return InvalidArgument("HashGrid.build: more than 2^31 - 1 points");
  if (on_device) {
    // On the device, queued after the session's work: no download, no upload.
    HashGridBuildJob job;
    job.points = reinterpret_cast<uintptr_t>(points->data());
    job.scalar_size = static_cast<int32_t>(ScalarSize(scalar));
    job.n = n;
    job.cell_width = radius;
    for (int k = 0; k < 3; ++k) job.dim[k] = dim_[k];
    job.cells = cells;
    Status built = EnsureDeviceMemory(dev, static_cast<uint64_t>(cells) * 4, &gpu_cell_starts_);
    if (built.ok()) built = EnsureDeviceMemory(dev, static_cast<uint64_t>(cells) * 4, &gpu_cell_ends_);
    if (built.ok()) built = EnsureDeviceMemory(dev, static_cast<uint64_t>(n) * 4, &gpu_sorted_ids_);
    if (built.ok()) built = EnsureDeviceMemory(dev, HashGridScratchBytes(n), &gpu_sort_scratch_);
    if (built.ok()) built = EnsureDeviceMemory(dev, groups ? static_cast<uint64_t>(n) * 4 : 0, &gpu_sorted_groups_);
    if (built.ok()) {
      job.cell_starts = AddressOf(gpu_cell_starts_.memory);
      job.cell_ends = AddressOf(gpu_cell_ends_.memory);
      job.sorted_ids = AddressOf(gpu_sorted_ids_.memory);
      job.scratch = AddressOf(gpu_sort_scratch_.memory);
      job.groups = groups ? reinterpret_cast<uintptr_t>(groups->data()) : 0;
      job.sorted_groups = AddressOf(gpu_sorted_groups_.memory);
      built = dev->build_hash_grid(device_, job);
    }
    cell_starts_.clear();
    cell_ends_.clear();
    sorted_ids_.clear();
    sorted_groups_.clear();
    if (!built.ok()) {   // the device memory may hold a partial build: the grid is empty
      num_sorted_ = 0;
      gpu_sorted_groups_.bytes = 0;
      return built;
    }
    points_ = std::move(points);
    num_points_ = n;
    num_sorted_ = n;
    cell_width_ = radius;
    return Status::Ok();
  }
  const char* bytes = points->data();
  std::vector<char> host;
  if (on_gpu()) {
    WEFT_RETURN_IF_ERROR(NeedAccess(device_, dev, "HashGrid.build"));
    const uint64_t n_bytes = static_cast<uint64_t>(n) * 3 * ScalarSize(scalar);
    try {
      host.resize(n_bytes);
    } catch (const std::bad_alloc&) {
      return ResourceExhausted("HashGrid.build: out of host memory for a copy of the points");
    }
    WEFT_RETURN_IF_ERROR(dev->download(*points, host.data(), n_bytes));
    bytes = host.data();
  }
  try {
    std::vector<int32_t> cell_of(static_cast<size_t>(n));
    cell_starts_.assign(static_cast<size_t>(cells), 0);
    cell_ends_.assign(static_cast<size_t>(cells), 0);
    sorted_ids_.resize(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) {
      int64_t c = wp::hash_grid_cell(dim_, wp::hash_grid_coord(Coord(bytes, scalar, i, 0), radius),
                                     wp::hash_grid_coord(Coord(bytes, scalar, i, 1), radius),
                                     wp::hash_grid_coord(Coord(bytes, scalar, i, 2), radius));
      cell_of[i] = static_cast<int32_t>(c);
      ++cell_ends_[c];   // counts first
    }
    int32_t run = 0;
    for (int64_t c = 0; c < cells; ++c) {
      cell_starts_[c] = run;
      run += cell_ends_[c];
      cell_ends_[c] = cell_starts_[c];   // fill cursor
    }
    for (int64_t i = 0; i < n; ++i) sorted_ids_[cell_ends_[cell_of[i]]++] = static_cast<int32_t>(i);
    sorted_groups_.clear();
    if (groups) {   // each cell's run ordered by group id (point order within a group kept)
      for (int64_t c = 0; c < cells; ++c) {
        if (cell_ends_[c] - cell_starts_[c] > 1)
          std::stable_sort(sorted_ids_.begin() + cell_starts_[c], sorted_ids_.begin() + cell_ends_[c],
                           [&](int32_t a, int32_t b) { return group_of[a] < group_of[b]; });
      }
      sorted_groups_.resize(static_cast<size_t>(n));
      for (int64_t k = 0; k < n; ++k) sorted_groups_[k] = group_of[sorted_ids_[k]];
    }
  } catch (const std::bad_alloc&) {
    sorted_ids_.clear();
    sorted_groups_.clear();
    return ResourceExhausted("HashGrid.build: out of memory for the cells");
  }
  points_ = std::move(points);
  num_points_ = n;
  num_sorted_ = n;
  cell_width_ = radius;
  return Mirror(dev);
}

namespace {

template <typename T>
const T* DevicePtr(const std::shared_ptr<Allocation>& memory, uint64_t bytes) {
  return memory && bytes ? reinterpret_cast<const T*>(memory->data()) : nullptr;
}

}  // namespace

void GeometryObject::Describe(wp::geometry_desc_t* d, std::vector<std::shared_ptr<const void>>* keep) const {
  std::memset(d, 0, sizeof(*d));
  d->kind = kind_;
  d->points = Floats(points_);
  d->velocities = Floats(velocities_);
  d->indices = indices_.empty() ? nullptr : indices_.data();
  d->user_indices = user_indices_ && num_prims_ > 0 ? reinterpret_cast<const int32_t*>(user_indices_->data()) : nullptr;
  if (kind_ == wp::GEOMETRY_MESH && points_) {
    std::shared_ptr<Allocation> grad = points_->grad;
    if (grad && grad->byte_size >= points_->byte_size && grad->device == points_->device) {
      d->points_grad = reinterpret_cast<float*>(grad->data());
      if (keep) keep->push_back(std::move(grad));
    }
  }
  d->lowers = Floats(lowers_);
  d->uppers = Floats(uppers_);
  d->num_points = num_points_;
  d->num_prims = num_prims_;
  d->nodes = bvh_.nodes.empty() ? nullptr : bvh_.nodes.data();
  d->prim_ids = bvh_.prim_ids.empty() ? nullptr : bvh_.prim_ids.data();
  d->num_nodes = device_built_ ? 2 * num_prims_ - 1 : static_cast<int64_t>(bvh_.nodes.size());
  d->group_ids = bvh_.group_ids.empty() ? nullptr : bvh_.group_ids.data();
  d->group_roots = bvh_.group_roots.empty() ? nullptr : bvh_.group_roots.data();
  // A grouped tree built on the device lists its groups in n entries (the rest INT32_MAX, -1).
  d->num_groups = device_built_ && grouped_ ? num_prims_ : static_cast<int64_t>(bvh_.group_ids.size());
  if (kind_ == wp::GEOMETRY_HASH_GRID) {
    d->cell_starts = cell_starts_.empty() ? nullptr : cell_starts_.data();
    d->cell_ends = cell_ends_.empty() ? nullptr : cell_ends_.data();
    d->sorted_ids = sorted_ids_.empty() ? nullptr : sorted_ids_.data();
    d->sorted_groups = sorted_groups_.empty() ? nullptr : sorted_groups_.data();
    d->num_sorted = cell_width_ > 0.0f ? num_sorted_ : 0;
    for (int k = 0; k < 3; ++k) d->dim[k] = dim_[k];
    d->cell_width = cell_width_;
  }
  if (kind_ == wp::GEOMETRY_VOLUME) {
    const VolumeData& v = volume_;
    d->vol_table = v.table.data();
    d->vol_masks = reinterpret_cast<const wp::uint64*>(v.masks.data());
    d->vol_prefix = reinterpret_cast<const wp::int64*>(v.prefix.data());
    d->vol_values = values_ ? values_->data() : nullptr;
    d->vol_table_mask = static_cast<int64_t>(v.table.size() / 4) - 1;
    d->vol_active = v.active;
    d->vol_max_probe = v.max_probe;
    d->vol_type = v.type;
    d->vol_value_size = v.value_size;
    std::memcpy(d->vol_background, v.background, sizeof(d->vol_background));
    std::memcpy(d->vol_xform, v.xform, sizeof(d->vol_xform));
    std::memcpy(d->vol_inverse, v.inverse, sizeof(d->vol_inverse));
    std::memcpy(d->vol_translation, v.translation, sizeof(d->vol_translation));
    if (on_gpu()) {
      d->vol_table = DevicePtr<int32_t>(gpu_vol_table_.memory, gpu_vol_table_.bytes);
      d->vol_masks = DevicePtr<wp::uint64>(gpu_vol_masks_.memory, gpu_vol_masks_.bytes);
      d->vol_prefix = DevicePtr<wp::int64>(gpu_vol_prefix_.memory, gpu_vol_prefix_.bytes);
    }
    return;
  }
  if (on_gpu()) {   // the same layout, with the device copies of the build products
    d->indices = DevicePtr<int32_t>(gpu_indices_.memory, gpu_indices_.bytes);
    d->nodes = DevicePtr<wp::bvh_node_t>(gpu_nodes_.memory, gpu_nodes_.bytes);
    d->prim_ids = DevicePtr<int32_t>(gpu_prim_ids_.memory, gpu_prim_ids_.bytes);
    d->group_ids = DevicePtr<int32_t>(gpu_group_ids_.memory, gpu_group_ids_.bytes);
    d->group_roots = DevicePtr<int32_t>(gpu_group_roots_.memory, gpu_group_roots_.bytes);
    d->cell_starts = DevicePtr<int32_t>(gpu_cell_starts_.memory, gpu_cell_starts_.bytes);
    d->cell_ends = DevicePtr<int32_t>(gpu_cell_ends_.memory, gpu_cell_ends_.bytes);
    d->sorted_ids = DevicePtr<int32_t>(gpu_sorted_ids_.memory, gpu_sorted_ids_.bytes);
    d->sorted_groups = DevicePtr<int32_t>(gpu_sorted_groups_.memory, gpu_sorted_groups_.bytes);
    // Memory a failed build or upload left missing: the object reads as empty, never as a count
    // over a null pointer.
    if (!d->nodes || !d->prim_ids) d->num_nodes = 0;
    if (!d->group_ids || !d->group_roots) d->num_groups = 0;
    if (kind_ == wp::GEOMETRY_MESH && !d->indices) d->num_prims = 0;
    if (!d->cell_starts || !d->cell_ends || !d->sorted_ids) d->num_sorted = 0;
  }
}

}  // namespace weft::geometry
