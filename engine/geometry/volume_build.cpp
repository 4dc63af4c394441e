// The daemon-side build of a wp.Volume; see volume_build.h.
#include "engine/geometry/volume_build.h"

#include <bit>
#include <cmath>
#include <cstring>
#include <new>

#include "engine/native/geometry_abi.h"

namespace weft::geometry {

Expected<uint32_t> VolumeValueSize(uint32_t type) {
  switch (type) {
    case wp::VOLUME_FLOAT: case wp::VOLUME_INT32: case wp::VOLUME_UINT32: return 4u;
    case wp::VOLUME_DOUBLE: case wp::VOLUME_INT64: return 8u;
    case wp::VOLUME_VEC3F: return 12u;
    case wp::VOLUME_VEC3D: return 24u;
    case wp::VOLUME_VEC4F: return 16u;
    case wp::VOLUME_VEC4D: return 32u;
    case wp::VOLUME_INDEX: case wp::VOLUME_ONINDEX: return 0u;
    default: break;
  }
  return InvalidArgument("Volume: value type " + std::to_string(type) +
                         " is not supported (float, double, int32, int64, uint32, Vec3f, Vec3d, Vec4f, Vec4d, "
                         "Index, OnIndex)");
}

std::string VolumeTypeName(uint32_t type) {
  switch (type) {
    case wp::VOLUME_FLOAT: return "float";
    case wp::VOLUME_DOUBLE: return "double";
    case wp::VOLUME_INT32: return "int32";
    case wp::VOLUME_INT64: return "int64";
    case wp::VOLUME_UINT32: return "uint32";
    case wp::VOLUME_VEC3F: return "Vec3f";
    case wp::VOLUME_VEC3D: return "Vec3d";
    case wp::VOLUME_VEC4F: return "Vec4f";
    case wp::VOLUME_VEC4D: return "Vec4d";
    case wp::VOLUME_INDEX: return "Index";
    case wp::VOLUME_ONINDEX: return "OnIndex";
    default: return "unknown";
  }
}

namespace {

// Inverse of a row-major 3x3 matrix; false when it is singular (or not finite).
bool Invert3(const double* m, double* inv) {
  double c00 = m[4] * m[8] - m[5] * m[7], c01 = m[5] * m[6] - m[3] * m[8], c02 = m[3] * m[7] - m[4] * m[6];
  double det = m[0] * c00 + m[1] * c01 + m[2] * c02;
  double scale = 0;
  for (int k = 0; k < 9; ++k) scale = std::fmax(scale, std::fabs(m[k]));
  if (!std::isfinite(det) || scale == 0 || std::fabs(det) <= 1e-300 || std::fabs(det) < 1e-12 * scale * scale * scale)
    return false;
  inv[0] = c00 / det;
  inv[1] = (m[2] * m[7] - m[1] * m[8]) / det;
  inv[2] = (m[1] * m[5] - m[2] * m[4]) / det;
  inv[3] = c01 / det;
  inv[4] = (m[0] * m[8] - m[2] * m[6]) / det;
  inv[5] = (m[2] * m[3] - m[0] * m[5]) / det;
  inv[6] = c02 / det;
  inv[7] = (m[1] * m[6] - m[0] * m[7]) / det;
  inv[8] = (m[0] * m[4] - m[1] * m[3]) / det;
  for (int k = 0; k < 9; ++k)
    if (!std::isfinite(inv[k])) return false;
  return true;
}

}  // namespace

Status BuildVolume(uint32_t type, const int32_t* origins, const uint64_t* masks, int64_t n,
                   const std::string& background, const std::vector<double>& transform, VolumeData* out) {
  WEFT_ASSIGN_OR_RETURN(uint32_t value_size, VolumeValueSize(type));
  if (n < 0) return InvalidArgument("Volume: a negative leaf count");
  if (n > kMaxVolumeLeaves)
    return InvalidArgument("Volume: " + std::to_string(n) + " leaves exceed the limit of 2^22 (2^31 voxels)");
  if (background.size() != value_size)
    return InvalidArgument("Volume: the background value has " + std::to_string(background.size()) +
                           " bytes, a " + VolumeTypeName(type) + " has " + std::to_string(value_size));
  if (transform.size() != 12)
    return InvalidArgument("Volume: the transform needs 12 values (3x3 matrix, translation), got " +
                           std::to_string(transform.size()));
  for (double v : transform)
    if (!std::isfinite(v)) return InvalidArgument("Volume: the transform has a value that is not finite");
  VolumeData d;
  d.type = type;
  d.value_size = value_size;
  std::memcpy(d.xform, transform.data(), 9 * sizeof(double));
  std::memcpy(d.translation, transform.data() + 9, 3 * sizeof(double));
  if (!Invert3(d.xform, d.inverse)) return InvalidArgument("Volume: the index-to-world matrix is singular");
  std::memcpy(d.background, background.data(), value_size);
  constexpr int32_t kLimit = 1 << 30;
  try {
    d.masks.assign(masks, masks + 8 * n);
    d.prefix.resize(static_cast<size_t>(n));
    // At least twice the leaves, a power of two.
    const uint64_t slots = std::bit_ceil(static_cast<uint64_t>(2 * n + 1));
    d.table.assign(4 * slots, -1);   // per slot: the leaf's key (3 int32) and its position
  } catch (const std::bad_alloc&) {
    return ResourceExhausted("Volume: out of host memory for " + std::to_string(n) + " leaves");
  }
  const int64_t mask = static_cast<int64_t>(d.table.size() / 4) - 1;
  int64_t active = 0;
  for (int64_t i = 0; i < n; ++i) {
    const int32_t* o = origins + 3 * i;
    for (int k = 0; k < 3; ++k) {
      if (o[k] % 8 != 0 || o[k] < -kLimit || o[k] > kLimit)
        return InvalidArgument("Volume: leaf " + std::to_string(i) + " has origin (" + std::to_string(o[0]) + ", " +
                               std::to_string(o[1]) + ", " + std::to_string(o[2]) +
                               "): coordinates must be multiples of 8 within +-2^30");
    }
    const int32_t kx = o[0] / 8, ky = o[1] / 8, kz = o[2] / 8;
    int64_t slot = wp::volume_leaf_hash(kx, ky, kz, mask);
    int32_t probes = 1;
    for (int32_t* e = &d.table[4 * static_cast<size_t>(slot)]; e[3] >= 0; e = &d.table[4 * static_cast<size_t>(slot)]) {
      if (e[0] == kx && e[1] == ky && e[2] == kz)
        return InvalidArgument("Volume: leaves " + std::to_string(e[3]) + " and " + std::to_string(i) +
                               " have the same origin (" + std::to_string(o[0]) + ", " + std::to_string(o[1]) + ", " +
                               std::to_string(o[2]) + ")");
      slot = (slot + 1) & mask;
      ++probes;
    }
    int32_t* e = &d.table[4 * static_cast<size_t>(slot)];
    e[0] = kx;
    e[1] = ky;
    e[2] = kz;
    e[3] = static_cast<int32_t>(i);
    if (probes > d.max_probe) d.max_probe = probes;
    d.prefix[static_cast<size_t>(i)] = active;
    for (int w = 0; w < 8; ++w) active += std::popcount(d.masks[static_cast<size_t>(8 * i + w)]);
  }
  d.active = active;
  *out = std::move(d);
  return Status::Ok();
}

}  // namespace weft::geometry
