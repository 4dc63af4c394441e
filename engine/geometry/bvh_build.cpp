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

void BuildBvh(int64_t n, const ItemBounds& bounds, BvhData* out, const int32_t* groups) {
  out->nodes.clear();
  out->levels.clear();
  out->level_starts.clear();
  out->group_ids.clear();
  out->group_roots.clear();
  out->prim_ids.resize(static_cast<size_t>(n));
  if (n <= 0) return;
  std::vector<float> lo(3 * n), hi(3 * n), centroid(3 * n);
  for (int64_t i = 0; i < n; ++i) {
    bounds(i, &lo[3 * i], &hi[3 * i]);
    for (int k = 0; k < 3; ++k) centroid[3 * i + k] = Clean(0.5f * (lo[3 * i + k] + hi[3 * i + k]));
    out->prim_ids[i] = static_cast<int32_t>(i);
  }
  if (groups)   // each group's items contiguous, groups ascending (spatial splits keep this)
    std::stable_sort(out->prim_ids.begin(), out->prim_ids.end(),
                     [groups](int32_t a, int32_t b) { return groups[a] < groups[b]; });
  auto group_of = [&](int32_t pos) { return groups[out->prim_ids[pos]]; };
  out->nodes.reserve(static_cast<size_t>(2 * (n / kBvhLeafSize + 1)));
  struct Task {
    int32_t node, begin, end;
    bool whole_group;   // grouped builds: the range is one group's items, all of them, or mixed
  };
  std::vector<Task> stack;
  out->nodes.push_back({});
  stack.push_back({0, 0, static_cast<int32_t>(n), true});
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
    const bool mixed = groups && group_of(t.begin) != group_of(t.end - 1);
    if (groups && !mixed && t.whole_group) {   // the first node holding only this group: its root
      out->group_ids.push_back(group_of(t.begin));
      out->group_roots.push_back(t.node);
    }
    if (!mixed && t.end - t.begin <= kBvhLeafSize) {
      node.left = t.begin;
      node.right = -(t.end - t.begin);
      out->nodes[t.node] = node;
      continue;
    }
    int32_t mid = t.begin + (t.end - t.begin) / 2;
    if (mixed) {   // split at the group boundary nearest the middle
      const int32_t g = group_of(mid);
      int32_t first = mid, last = mid;
      while (first > t.begin && group_of(first - 1) == g) --first;
      while (last < t.end && group_of(last) == g) ++last;
      mid = (first > t.begin && (mid - first <= last - mid || last == t.end)) ? first : last;
    } else {
      int axis = 0;
      for (int k = 1; k < 3; ++k)
        if (chi[k] - clo[k] > chi[axis] - clo[axis]) axis = k;
      std::nth_element(out->prim_ids.begin() + t.begin, out->prim_ids.begin() + mid, out->prim_ids.begin() + t.end,
                       [&](int32_t a, int32_t b) { return centroid[3 * a + axis] < centroid[3 * b + axis]; });
    }
    int32_t left = static_cast<int32_t>(out->nodes.size());
    out->nodes.push_back({});
    int32_t right = static_cast<int32_t>(out->nodes.size());
    out->nodes.push_back({});
    node.left = left;
    node.right = right;
    out->nodes[t.node] = node;
    // Pre-order indices are not needed for correctness; children > parent is (refit).
    stack.push_back({right, mid, t.end, mixed});
    stack.push_back({left, t.begin, mid, mixed});
  }
  if (groups) {   // ascending group ids for the kernel's binary search
    std::vector<size_t> order(out->group_ids.size());
    for (size_t k = 0; k < order.size(); ++k) order[k] = k;
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return out->group_ids[a] < out->group_ids[b]; });
    std::vector<int32_t> ids, roots;
    for (size_t k : order) {
      ids.push_back(out->group_ids[k]);
      roots.push_back(out->group_roots[k]);
    }
    out->group_ids = std::move(ids);
    out->group_roots = std::move(roots);
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
