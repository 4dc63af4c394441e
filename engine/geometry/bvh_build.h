// Daemon-side BVH construction and refit for wp.Bvh and wp.Mesh: a median split on the longest
// axis of the item centroids (leaves of up to kBvhLeafSize items), nodes in pre-order so every
// child index is greater than its parent's (refit walks the nodes backwards). Depth is at most
// ceil(log2(items)) + 1, well inside the kernel-side traversal stack (BVH_STACK).
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "engine/native/geometry_abi.h"

namespace weft::geometry {

constexpr int32_t kBvhLeafSize = 4;

struct BvhData {
  std::vector<wp::bvh_node_t> nodes;
  std::vector<int32_t> prim_ids;
};

// Bounds of item i into lo[3], hi[3].
using ItemBounds = std::function<void(int64_t i, float* lo, float* hi)>;

// Builds over items [0, n) (n < 2^31). NaN bounds sort as 0 and never break the build.
void BuildBvh(int64_t n, const ItemBounds& bounds, BvhData* out);
// Recomputes every node's bounds from the items' current bounds (same tree).
void RefitBvh(const ItemBounds& bounds, BvhData* bvh);

}  // namespace weft::geometry
