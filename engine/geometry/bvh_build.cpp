// BVH build (median split) and refit; see bvh_build.h.
#include "engine/geometry/bvh_build.h"

#include <algorithm>

namespace weft::geometry {

namespace {

void Grow(wp::bvh_node_t& n, const float* lo, const float* hi) {
  for (int k = 0; k < 3; ++k) {
    n.lower[k] = std::min(n.lower[k], lo[k]);
    n.upper[k] = std::max(n.upper[k], hi[k]);
  }
}

void Empty(wp::bvh_node_t& n) {
  for (int k = 0; k < 3; ++k) {
    n.lower[k] = 3.0e38f;
    n.upper[k] = -3.0e38f;
  }
}

float Clean(float x) { return x == x ? x : 0.0f; }   // NaN sorts as 0

}  // namespace

void BuildBvh(int64_t n, const ItemBounds& bounds, BvhData* out) {
  out->nodes.clear();
  out->levels.clear();
  out->level_starts.clear();
  out->prim_ids.resize(static_cast<size_t>(n));
  if (n <= 0) return;
  std::vector<float> lo(3 * n), hi(3 * n), centroid(3 * n);
  for (int64_t i = 0; i < n; ++i) {
    bounds(i, &lo[3 * i], &hi[3 * i]);
    for (int k = 0; k < 3; ++k) centroid[3 * i + k] = Clean(0.5f * (lo[3 * i + k] + hi[3 * i + k]));
    out->prim_ids[i] = static_cast<int32_t>(i);
  }
  out->nodes.reserve(static_cast<size_t>(2 * (n / kBvhLeafSize + 1)));
  struct Task {
    int32_t node, begin, end;
  };
  std::vector<Task> stack;
  out->nodes.push_back({});
  stack.push_back({0, 0, static_cast<int32_t>(n)});
  while (!stack.empty()) {
    Task t = stack.back();
    stack.pop_back();
    wp::bvh_node_t node{};
    Empty(node);
    float clo[3] = {3.0e38f, 3.0e38f, 3.0e38f}, chi[3] = {-3.0e38f, -3.0e38f, -3.0e38f};
    for (int32_t i = t.begin; i < t.end; ++i) {
      int32_t p = out->prim_ids[i];
      Grow(node, &lo[3 * p], &hi[3 * p]);
      for (int k = 0; k < 3; ++k) {
        clo[k] = std::min(clo[k], centroid[3 * p + k]);
        chi[k] = std::max(chi[k], centroid[3 * p + k]);
      }
    }
    if (t.end - t.begin <= kBvhLeafSize) {
      node.left = t.begin;
      node.right = -(t.end - t.begin);
      out->nodes[t.node] = node;
      continue;
    }
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (chi[k] - clo[k] > chi[axis] - clo[axis]) axis = k;
    int32_t mid = t.begin + (t.end - t.begin) / 2;
    std::nth_element(out->prim_ids.begin() + t.begin, out->prim_ids.begin() + mid, out->prim_ids.begin() + t.end,
                     [&](int32_t a, int32_t b) { return centroid[3 * a + axis] < centroid[3 * b + axis]; });
    int32_t left = static_cast<int32_t>(out->nodes.size());
    out->nodes.push_back({});
    int32_t right = static_cast<int32_t>(out->nodes.size());
    out->nodes.push_back({});
    node.left = left;
    node.right = right;
    out->nodes[t.node] = node;
    // Pre-order indices are not needed for correctness; children > parent is (refit).
    stack.push_back({right, mid, t.end});
    stack.push_back({left, t.begin, mid});
  }
  OrderLevels(out);
}

void OrderLevels(BvhData* bvh) {
  const size_t n = bvh->nodes.size();
  std::vector<int32_t> depth(n, 0);
  int32_t deepest = 0;
  for (size_t k = 0; k < n; ++k) {   // children come after their parent
    const wp::bvh_node_t& node = bvh->nodes[k];
    if (node.right >= 0) {
      depth[node.left] = depth[node.right] = depth[k] + 1;
      deepest = std::max(deepest, depth[k] + 1);
    }
  }
  std::vector<int64_t> count(static_cast<size_t>(deepest) + 2, 0);
  for (size_t k = 0; k < n; ++k) ++count[deepest - depth[k] + 1];   // slot of level d: deepest - d
  for (size_t l = 1; l < count.size(); ++l) count[l] += count[l - 1];
  bvh->level_starts = count;
  bvh->levels.assign(n, 0);
  std::vector<int64_t> cursor(count.begin(), count.end() - 1);
  for (size_t k = 0; k < n; ++k) bvh->levels[cursor[deepest - depth[k]]++] = static_cast<int32_t>(k);
}

void RefitBvh(const ItemBounds& bounds, BvhData* bvh) {
  for (size_t k = bvh->nodes.size(); k-- > 0;) {
    wp::bvh_node_t& n = bvh->nodes[k];
    Empty(n);
    if (n.right < 0) {
      for (int32_t i = n.left; i < n.left - n.right; ++i) {
        float lo[3], hi[3];
        bounds(bvh->prim_ids[i], lo, hi);
        Grow(n, lo, hi);
      }
    } else {
      Grow(n, bvh->nodes[n.left].lower, bvh->nodes[n.left].upper);
      Grow(n, bvh->nodes[n.right].lower, bvh->nodes[n.right].upper);
    }
  }
}

}  // namespace weft::geometry
