// The binary interface of geometry objects (wp.HashGrid, wp.Bvh, wp.Mesh, wp.Volume) between the runtime
// (engine/geometry) and generated kernel code. Owns: the per-launch geometry table a launch
// context points at, one descriptor per live object of the launching session, the BVH node
// layout, the id encoding, the hash grid's cell rule and the volume's leaf hash (each shared by the
// daemon-side build and the kernel-side query so both compute the same cell or slot). Compiled by clang, g++ and NVRTC: no std
// headers. docs/geometry.md describes the design.
#pragma once

#include "launch_abi.h"

namespace wp {

enum geometry_kind : uint32 {
  GEOMETRY_NONE = 0,
  GEOMETRY_HASH_GRID = 1,
  GEOMETRY_BVH = 2,
  GEOMETRY_MESH = 3,
  GEOMETRY_VOLUME = 4,
};

// Value types of volumes: NanoVDB's grid type numbers (what .nvdb files and Warp's type strings use).
enum volume_type : uint32 {
  VOLUME_FLOAT = 1,
  VOLUME_DOUBLE = 2,
  VOLUME_INT32 = 4,
  VOLUME_INT64 = 5,
  VOLUME_VEC3F = 6,
  VOLUME_VEC3D = 7,
  VOLUME_UINT32 = 10,
  VOLUME_VEC4F = 17,
  VOLUME_VEC4D = 18,
  VOLUME_INDEX = 19,     // no values: every voxel of a leaf has an index (leaf * 512 + offset)
  VOLUME_ONINDEX = 20,   // no values: the active voxels have indices 0..active-1 (leaf order, then offset)
};
constexpr int32 VOLUME_LEAF_VOXELS = 512;   // 8 x 8 x 8; voxel offset (x&7)*64 + (y&7)*8 + (z&7)

// A BVH node. Inner node: children `left` and `right` (node indices, both > this node's index).
// Leaf: right < 0 and the items are prim_ids[left .. left - right). Bounds in float32.
struct bvh_node_t {
  float32 lower[3];
  int32 left;
  float32 upper[3];
  int32 right;
};

// One live geometry object as kernels see it. Every pointer targets memory the object keeps
// alive for the launch: the user's arrays (points, velocities, lowers, uppers: contiguous vec3
// float32, validated when the object was built) and the daemon's own build products (nodes,
// prim_ids, indices, the hash grid's cells), whose index values the build guarantees in range.
struct geometry_desc_t {
  uint32 kind;          // geometry_kind; GEOMETRY_NONE for a free slot
  uint32 generation;    // the id's high 32 bits
  // Mesh: points and velocities (num_points each, velocities may be null), indices (3 * num_prims,
  // each < num_points: a daemon-owned copy checked at build). Bvh: lowers / uppers (num_prims).
  const float32* points;
  const float32* velocities;
  const int32* indices;
  const int32* user_indices;   // Mesh: the caller's indices array (what mesh_get exposes; never trusted)
  float32* points_grad;        // Mesh: the points array's gradient (mesh_get's adjoint target), or null
  const float32* lowers;
  const float32* uppers;
  int64 num_points;
  int64 num_prims;
  // Bvh of a Mesh or a Bvh: nodes[0] is the root (num_nodes == 0: no items).
  const bvh_node_t* nodes;
  const int32* prim_ids;   // leaf item order, each < num_prims
  int64 num_nodes;
  // Grouped Bvh / Mesh: the groups present (ascending) and each one's subtree root node.
  const int32* group_ids;
  const int32* group_roots;
  int64 num_groups;
  // HashGrid: cell c holds sorted_ids[cell_starts[c] .. cell_ends[c]) (original point indices).
  // A grid built with groups also has sorted_groups (the group id of each sorted_ids entry),
  // and each cell's entries are ordered by group id (null: built without groups).
  const int32* cell_starts;
  const int32* cell_ends;
  const int32* sorted_ids;
  const int32* sorted_groups;
  int64 num_sorted;        // points of the last build (0 before the first build)
  int32 dim[3];
  float32 cell_width;      // the build's radius (> 0 after a build)
  // Volume: leaves of 8x8x8 voxels (num_prims of them). vol_table (vol_table_mask + 1 slots, a power
  // of two, 4 int32 each: a leaf's key, origin / 8, then its position; -1: empty slot) is found
  // within vol_max_probe linear probes of volume_leaf_hash; vol_masks holds each leaf's active
  // voxels (8 words), vol_prefix the active voxels of the leaves before it.
  // vol_values: the caller's values array (512 per leaf, vol_value_size bytes each; null for index
  // grids), read and written in place. All index values were checked by the daemon's build.
  const int32* vol_table;
  const uint64* vol_masks;
  const int64* vol_prefix;
  void* vol_values;
  int64 vol_table_mask;
  int64 vol_active;         // active voxels in all leaves
  int32 vol_max_probe;
  uint32 vol_type;          // volume_type
  uint32 vol_value_size;
  uint32 _vol_pad;
  float64 vol_background[4];   // the background value's bytes (up to a vec4d)
  float64 vol_xform[9];        // index to world, row-major
  float64 vol_inverse[9];      // world to index
  float64 vol_translation[3];
};

// Entries of the kernel-side traversal stack; trees deeper than BVH_STACK_DEPTH_LIMIT could
// overflow it (the daemon's median-split build stays far below: depth <= log2(items) + 2).
constexpr int32 BVH_STACK = 64;
constexpr int32 BVH_STACK_DEPTH_LIMIT = BVH_STACK - 1;

struct geometry_table_t {
  const geometry_desc_t* slots;
  uint32 count;
  uint32 _pad;
};

// Ids: (generation << 32) | (slot + 1). Generations come from one daemon-wide counter, so an id
// of another session (or of a freed object) never matches a slot of this session. 0 is None.
WP_CALLABLE inline uint64 geometry_make_id(uint32 slot, uint32 generation) {
  return ((uint64)generation << 32) | (uint64)(slot + 1u);
}

// mesh_get_bvh's id: the mesh's id with this bit of the slot part set. BVH queries accept it and
// walk the mesh's face BVH; every other use of it (and a plain mesh id in a BVH query) is refused.
// Slots stay far below 2^31 (the registry's object limit), so the bit never names a slot.
constexpr uint64 GEOMETRY_MESH_BVH_BIT = 1ull << 31;

// The hash grid's cell coordinate of x (Warp's rule: floor(x / cell_width)), clamped to a range
// whose products with the dims cannot overflow; NaN maps to 0.
WP_CALLABLE inline int32 hash_grid_coord(float32 x, float32 cell_width) {
  float32 q = x / cell_width;
  if (!(q == q)) return 0;
  if (q > 1.0e9f) return 1000000000;
  if (q < -1.0e9f) return -1000000000;
  int32 i = (int32)q;
  if ((float32)i > q) --i;   // floor
  return i;
}
// Cell index of integer cell coordinates (periodic in each dim, as Warp's).
WP_CALLABLE inline int64 hash_grid_cell(const int32* dim, int32 x, int32 y, int32 z) {
  int32 cx = x % dim[0]; if (cx < 0) cx += dim[0];
  int32 cy = y % dim[1]; if (cy < 0) cy += dim[1];
  int32 cz = z % dim[2]; if (cz < 0) cz += dim[2];
  return ((int64)cz * dim[1] + cy) * dim[0] + cx;
}

// Slot of the leaf with key (origin / 8) in a table of mask + 1 slots.
WP_CALLABLE inline int64 volume_leaf_hash(int32 kx, int32 ky, int32 kz, int64 mask) {
  uint32 h = (uint32)kx * 73856093u ^ (uint32)ky * 19349663u ^ (uint32)kz * 83492791u;
  h ^= h >> 16;
  h *= 0x45d9f3bu;
  h ^= h >> 16;
  return (int64)h & mask;
}

}  // namespace wp
