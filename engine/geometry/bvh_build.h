// Daemon-side BVH construction and refit for wp.Bvh and wp.Mesh: a median split on the longest
// axis of the item centroids (leaves of up to kBvhLeafSize items), nodes in pre-order so every
// child index is greater than its parent's (refit walks the nodes backwards). Depth is at most
// ceil(log2(items)) + 1, well inside the kernel-side traversal stack (BVH_STACK). A grouped build
// (an int32 group id per item) first splits the items by group, so each group's items are one
// subtree whose root node bvh_get_group_root finds; depth grows by at most log2(groups) + 1.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "engine/geometry/device_sort.h"
#include "engine/native/geometry_abi.h"

namespace weft::geometry {

constexpr int32_t kBvhLeafSize = 4;

struct BvhData {
  std::vector<wp::bvh_node_t> nodes;
  std::vector<int32_t> prim_ids;
  // The nodes level by level, deepest level first (levels[level_starts[k] .. level_starts[k+1])
  // is one level): a device refit recomputes one level per launch, every child before its parent.
  std::vector<int32_t> levels;
  std::vector<int64_t> level_starts;
  // Grouped builds: the groups present, ascending, and the root node of each one's subtree.
  std::vector<int32_t> group_ids;
  std::vector<int32_t> group_roots;
};

// Device memory of one BVH refit (engine/geometry): the nodes (wp::bvh_node_t), the leaf item
// order, the nodes level by level and the item arrays: lowers/uppers (a wp.Bvh) or points and
// the checked face indices (a wp.Mesh), all on the device; levels[level_starts[k] ..
// level_starts[k+1]) is one level, deepest first.
// A tree built on the device (BvhBuildJob) has no levels: its refit goes bottom-up from the
// num_items leaves along `parents`, with `arrivals` (num_items int32) as scratch.
struct BvhRefitJob {
  uintptr_t nodes = 0, prim_ids = 0, levels = 0;
  uintptr_t lowers = 0, uppers = 0, points = 0, indices = 0;
  std::vector<int64_t> level_starts;
  uintptr_t parents = 0, arrivals = 0;
  int64_t num_items = 0;
};

// Device memory of one BVH build on a GPU (Device::BuildBvh): a linear BVH (Karras' binary radix
// tree over the 30-bit Morton codes of the item centroids, ties by item id) with leaves of one
// item. Nodes 0 .. n-2 are the inner nodes (0 the root), node n-1+k the leaf of the k-th item in
// Morton order (left = k, right = -1). Items as in BvhRefitJob (lowers/uppers, or points and the
// checked indices). Every address is device memory the session or the object owns.
// A grouped build (item_groups != 0) orders the items by (dense rank of the group, code,
// position) instead, so each group's items are one subtree; group_ids (n int32) receives the
// groups present, ascending, then INT32_MAX, and group_roots (n int32) each group's subtree root
// at the same position, then -1 (the kernel-side lookup searches all n entries).
struct BvhBuildJob {
  int64_t n = 0;   // items, 1 .. 2^31 - 1
  uintptr_t lowers = 0, uppers = 0, points = 0, indices = 0;
  uintptr_t nodes = 0;      // 2n - 1 wp::bvh_node_t
  uintptr_t prim_ids = 0;   // n int32
  uintptr_t parents = 0;    // 2n - 1 int32 (the root's: -1), kept for refits
  uintptr_t scratch = 0;    // BvhBuildScratchBytes(n); its first n int32 are the refit's arrivals
  // Grouped builds: the object's copy of the group ids (n int32), filled from groups_src first
  // when that is another address (the user's array, at creation); 0: not grouped.
  uintptr_t item_groups = 0, groups_src = 0;
  uintptr_t group_ids = 0, group_roots = 0;   // n int32 each
};

// A mesh's indices checked on its GPU (Device::CheckMeshIndices): the count values at src (the
// user's array) copied to dst (the mesh's own copy) and each compared with [0, limit); result
// (two uint64) receives the first position out of range (~0: none) and the value there.
struct MeshIndicesJob {
  uintptr_t src = 0, dst = 0, result = 0;
  int64_t count = 0;
  int32_t limit = 0;
};

// Scratch of a device build of n items: the arrival counters, two key buffers, a second id
// buffer, the sort's digit counts and the centroid bounds, each 256-byte aligned.
inline uint64_t BvhBuildScratchBytes(int64_t n) {
  return 4 * RoundTo256(static_cast<uint64_t>(n) * 4) + SortHistogramBytes(n) + 256;
}

// Bounds of item i into lo[3], hi[3].
using ItemBounds = std::function<void(int64_t i, float* lo, float* hi)>;

// Builds over items [0, n) (n < 2^31). NaN bounds sort as 0 and never break the build. With
// `groups` (n values), each group's items form one subtree (BvhData::group_roots).
void BuildBvh(int64_t n, const ItemBounds& bounds, BvhData* out, const int32_t* groups = nullptr);
// Recomputes every node's bounds from the items' current bounds (same tree).
void RefitBvh(const ItemBounds& bounds, BvhData* bvh);
// Fills bvh->levels / level_starts from the nodes (BuildBvh calls it).
void OrderLevels(BvhData* bvh);

}  // namespace weft::geometry
