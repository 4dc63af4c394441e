// Geometry objects: construction with checked arrays, builds and refits; see geometry_object.h.
#include "engine/geometry/geometry_object.h"

#include <cstring>
#include <new>

#include "engine/runtime/array_validation.h"

namespace weft::geometry {

namespace {

const float* Floats(const std::shared_ptr<Allocation>& a) {
  return a ? reinterpret_cast<const float*>(a->data()) : nullptr;
}

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

// Coordinate k of point i of a vec3 array of float16/32/64, as float32.
float Coord(const Allocation& a, int64_t i, int k) {
  const char* p = a.data();
  switch (a.dtype.scalar) {
    case ScalarType::kFloat64: { double d; std::memcpy(&d, p + 8 * (3 * i + k), 8); return static_cast<float>(d); }
    case ScalarType::kFloat16: { uint16_t h; std::memcpy(&h, p + 2 * (3 * i + k), 2); return HalfToFloat(h); }
    default: { float f; std::memcpy(&f, p + 4 * (3 * i + k), 4); return f; }
  }
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
                                                                 std::shared_ptr<Allocation> uppers) {
  WEFT_ASSIGN_OR_RETURN(int64_t nl, CheckVec3Array(lowers, "Bvh lowers"));
  WEFT_ASSIGN_OR_RETURN(int64_t nu, CheckVec3Array(uppers, "Bvh uppers"));
  if (nl != nu)
    return InvalidArgument("Bvh: lowers has " + std::to_string(nl) + " items and uppers " + std::to_string(nu));
  if (lowers->device != uppers->device) return InvalidArgument("Bvh: lowers and uppers live on different devices");
  std::shared_ptr<GeometryObject> g(new GeometryObject());
  g->kind_ = wp::GEOMETRY_BVH;
  g->device_ = lowers->device;
  g->lowers_ = std::move(lowers);
  g->uppers_ = std::move(uppers);
  g->num_prims_ = nl;
  WEFT_RETURN_IF_ERROR(g->Rebuild());
  return g;
}

Expected<std::shared_ptr<GeometryObject>> GeometryObject::NewMesh(std::shared_ptr<Allocation> points,
                                                                  std::shared_ptr<Allocation> indices,
                                                                  std::shared_ptr<Allocation> velocities) {
  WEFT_ASSIGN_OR_RETURN(int64_t np, CheckVec3Array(points, "Mesh points"));
  if (velocities) {
    WEFT_ASSIGN_OR_RETURN(int64_t nv, CheckVec3Array(velocities, "Mesh velocities"));
    if (nv != np)
      return InvalidArgument("Mesh: velocities has " + std::to_string(nv) + " entries and points " + std::to_string(np));
    if (velocities->device != points->device) return InvalidArgument("Mesh: velocities and points live on different devices");
  }
  if (!indices) return InvalidArgument("Mesh indices: an array is required");
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
  try {
    g->indices_.resize(count);
  } catch (const std::bad_alloc&) {
    return ResourceExhausted("Mesh: out of memory for the indices");
  }
  if (count) std::memcpy(g->indices_.data(), iv.data(), count * sizeof(int32_t));
  for (uint64_t i = 0; i < count; ++i) {
    int32_t v = g->indices_[i];
    if (v < 0 || v >= np)
      return InvalidArgument("Mesh indices: indices[" + std::to_string(i) + "] = " + std::to_string(v) +
                             " is out of range for " + std::to_string(np) + " points");
  }
  g->kind_ = wp::GEOMETRY_MESH;
  g->device_ = points->device;
  g->points_ = std::move(points);
  g->velocities_ = std::move(velocities);
  g->num_points_ = np;
  g->num_prims_ = static_cast<int64_t>(count / 3);
  WEFT_RETURN_IF_ERROR(g->Rebuild());
  return g;
}

ItemBounds GeometryObject::Bounds() const {
  if (kind_ == wp::GEOMETRY_BVH) {
    const float* lo = Floats(lowers_);
    const float* hi = Floats(uppers_);
    return [lo, hi](int64_t i, float* l, float* h) {
      for (int k = 0; k < 3; ++k) {
        l[k] = lo[3 * i + k];
        h[k] = hi[3 * i + k];
      }
    };
  }
  const float* p = Floats(points_);
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

Status GeometryObject::Rebuild() {
  if (kind_ == wp::GEOMETRY_HASH_GRID) return Status::Ok();
  try {
    BuildBvh(num_prims_, Bounds(), &bvh_);
  } catch (const std::bad_alloc&) {
    return ResourceExhausted("out of memory building the BVH");
  }
  return Status::Ok();
}

Status GeometryObject::Refit() {
  if (kind_ == wp::GEOMETRY_HASH_GRID) return Status::Ok();
  RefitBvh(Bounds(), &bvh_);
  return Status::Ok();
}

Status GeometryObject::BuildHashGrid(std::shared_ptr<Allocation> points, float radius) {
  if (kind_ != wp::GEOMETRY_HASH_GRID) return InvalidArgument("build(points, radius) is a HashGrid operation");
  if (!(radius > 0.0f) || radius > 3.0e38f)
    return InvalidArgument("HashGrid.build: radius must be a positive finite number, got " + std::to_string(radius));
  WEFT_ASSIGN_OR_RETURN(int64_t n, CheckVec3Array(points, "HashGrid.build points", true));
  if (points->device != device_)
    return InvalidArgument("HashGrid.build: the points live on " + points->device + ", the grid on " + device_);
  const int64_t cells = static_cast<int64_t>(dim_[0]) * dim_[1] * dim_[2];
  const Allocation& pa = *points;
  try {
    std::vector<int32_t> cell_of(static_cast<size_t>(n));
    cell_starts_.assign(static_cast<size_t>(cells), 0);
    cell_ends_.assign(static_cast<size_t>(cells), 0);
    sorted_ids_.resize(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) {
      int64_t c = wp::hash_grid_cell(dim_, wp::hash_grid_coord(Coord(pa, i, 0), radius),
                                     wp::hash_grid_coord(Coord(pa, i, 1), radius), wp::hash_grid_coord(Coord(pa, i, 2), radius));
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
  } catch (const std::bad_alloc&) {
    sorted_ids_.clear();
    return ResourceExhausted("HashGrid.build: out of memory for the cells");
  }
  points_ = std::move(points);
  num_points_ = n;
  cell_width_ = radius;
  return Status::Ok();
}

void GeometryObject::Describe(wp::geometry_desc_t* d) const {
  std::memset(d, 0, sizeof(*d));
  d->kind = kind_;
  d->points = Floats(points_);
  d->velocities = Floats(velocities_);
  d->indices = indices_.empty() ? nullptr : indices_.data();
  d->lowers = Floats(lowers_);
  d->uppers = Floats(uppers_);
  d->num_points = num_points_;
  d->num_prims = num_prims_;
  d->nodes = bvh_.nodes.empty() ? nullptr : bvh_.nodes.data();
  d->prim_ids = bvh_.prim_ids.empty() ? nullptr : bvh_.prim_ids.data();
  d->num_nodes = static_cast<int64_t>(bvh_.nodes.size());
  if (kind_ == wp::GEOMETRY_HASH_GRID) {
    d->cell_starts = cell_starts_.empty() ? nullptr : cell_starts_.data();
    d->cell_ends = cell_ends_.empty() ? nullptr : cell_ends_.data();
    d->sorted_ids = sorted_ids_.empty() ? nullptr : sorted_ids_.data();
    d->num_sorted = cell_width_ > 0.0f ? static_cast<int64_t>(sorted_ids_.size()) : 0;
    for (int k = 0; k < 3; ++k) d->dim[k] = dim_[k];
    d->cell_width = cell_width_;
  }
}

}  // namespace weft::geometry
