// The daemon-side build of a wp.Volume: from the leaves a client describes (origins, active-voxel
// masks) to the structures kernels read (geometry_abi.h): the leaf hash table, the probe bound,
// the active-voxel prefix counts, and the index/world transforms with the inverse computed here.
// Every value a kernel later uses as an index comes from this build, never from the client: the
// table holds leaf positions < the leaf count, and the probe bound ends every search.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "engine/core/status.h"

namespace weft::geometry {

// At most 2^22 leaves (2^31 voxels: every voxel index fits an int32, as kernels use).
constexpr int64_t kMaxVolumeLeaves = int64_t{1} << 22;

struct VolumeData {
  uint32_t type = 0;          // wp::volume_type
  uint32_t value_size = 0;    // bytes per voxel value (0: index grids)
  std::vector<int32_t> table;     // power-of-two slots of 4 int32: the leaf's key (origin / 8), its position (-1: empty)
  int32_t max_probe = 0;          // linear probes that find every leaf
  std::vector<uint64_t> masks;    // 8 per leaf
  std::vector<int64_t> prefix;    // active voxels before each leaf
  int64_t active = 0;
  double background[4] = {0, 0, 0, 0};
  double xform[9] = {0}, inverse[9] = {0}, translation[3] = {0};
};

// Bytes per value of a volume type (0 for the index types), or an error for a type weft does not
// store (NanoVDB's half, fp4, ... grids).
Expected<uint32_t> VolumeValueSize(uint32_t type);
// The type's name as Warp reports it ("float", "Vec3f", "OnIndex", ...).
std::string VolumeTypeName(uint32_t type);

// Builds `out` from n >= 0 leaves (none: an empty volume, every voxel the background): origins
// (3 int32 per leaf: multiples of 8, distinct, within +-2^30), masks (8 words per leaf), the
// background value's bytes (value_size of them, none for index types) and the index-to-world
// transform (3x3 row-major, then the translation: finite, invertible).
Status BuildVolume(uint32_t type, const int32_t* origins, const uint64_t* masks, int64_t n,
                   const std::string& background, const std::vector<double>& transform, VolumeData* out);

}  // namespace weft::geometry
