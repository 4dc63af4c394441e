// Geometry objects in the engine: the BVH build (every item in exactly one leaf, children after
// their parent, bounds containing their items, depth within the kernel traversal stack), refit,
// the hash grid's cell sort, and the id registry (stale, foreign and forged ids refused; the
// per-launch table holds only live objects of the device).
#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <random>

#include "engine/geometry/bvh_build.h"
#include "engine/geometry/geometry_object.h"
#include "engine/geometry/geometry_registry.h"

namespace weft::geometry {
namespace {

struct Boxes {
  std::vector<float> lo, hi;
  ItemBounds bounds() const {
    return [this](int64_t i, float* l, float* h) {
      for (int k = 0; k < 3; ++k) {
        l[k] = lo[3 * i + k];
        h[k] = hi[3 * i + k];
      }
    };
  }
};

Boxes RandomBoxes(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> c(-10.f, 10.f), h(0.f, 1.f);
  Boxes b;
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      float x = c(rng), e = h(rng);
      b.lo.push_back(x - e);
      b.hi.push_back(x + e);
    }
  return b;
}

int Depth(const BvhData& d, int node) {
  const auto& n = d.nodes[node];
  if (n.right < 0) return 1;
  return 1 + std::max(Depth(d, n.left), Depth(d, n.right));
}

void CheckTree(const BvhData& d, const Boxes& b, int n) {
  std::vector<int> seen(n, 0);
  for (size_t k = 0; k < d.nodes.size(); ++k) {
    const auto& node = d.nodes[k];
    if (node.right < 0) {
      ASSERT_GE(node.left, 0);
      ASSERT_LE(node.left - node.right, n);
      for (int i = node.left; i < node.left - node.right; ++i) {
        int p = d.prim_ids[i];
        ASSERT_GE(p, 0);
        ASSERT_LT(p, n);
        ++seen[p];
        for (int c = 0; c < 3; ++c) {
          EXPECT_LE(node.lower[c], b.lo[3 * p + c]);
          EXPECT_GE(node.upper[c], b.hi[3 * p + c]);
        }
      }
    } else {
      ASSERT_GT(node.left, static_cast<int>(k));
      ASSERT_GT(node.right, static_cast<int>(k));
      ASSERT_LT(node.left, static_cast<int>(d.nodes.size()));
      ASSERT_LT(node.right, static_cast<int>(d.nodes.size()));
    }
  }
  for (int i = 0; i < n; ++i) EXPECT_EQ(seen[i], 1) << i;
}

TEST(GeometryBvh, BuildCoversEveryItemOnceAndIsShallow) {
  for (int n : {1, 2, 3, 5, 17, 1000, 4097}) {
    Boxes b = RandomBoxes(n, 7u + n);
    BvhData d;
    BuildBvh(n, b.bounds(), &d);
    CheckTree(d, b, n);
    int bound = 2;
    while ((1 << (bound - 2)) < n) ++bound;
    EXPECT_LE(Depth(d, 0), bound) << n;
    EXPECT_LT(Depth(d, 0), wp::BVH_STACK_DEPTH_LIMIT);
  }
  BvhData empty;
  BuildBvh(0, RandomBoxes(0, 1).bounds(), &empty);
  EXPECT_TRUE(empty.nodes.empty());
}

// The level order a device refit walks: every node once, each level a contiguous run, every
// child in an earlier run than its parent; refitting run by run (as the device does, one launch
// per run) gives exactly the host refit's bounds.
TEST(GeometryBvh, LevelOrderPutsChildrenBeforeParents) {
  for (int n : {1, 2, 5, 17, 1000, 4097}) {
    Boxes b = RandomBoxes(n, 11u + n);
    BvhData d;
    BuildBvh(n, b.bounds(), &d);
    ASSERT_EQ(d.levels.size(), d.nodes.size());
    ASSERT_GE(d.level_starts.size(), 2u);
    EXPECT_EQ(d.level_starts.front(), 0);
    EXPECT_EQ(d.level_starts.back(), static_cast<int64_t>(d.nodes.size()));
    std::vector<int> run_of(d.nodes.size(), -1);
    for (size_t r = 0; r + 1 < d.level_starts.size(); ++r) {
      ASSERT_LE(d.level_starts[r], d.level_starts[r + 1]);
      for (int64_t k = d.level_starts[r]; k < d.level_starts[r + 1]; ++k) {
        ASSERT_EQ(run_of[d.levels[k]], -1) << "node listed twice";
        run_of[d.levels[k]] = static_cast<int>(r);
      }
    }
    for (size_t k = 0; k < d.nodes.size(); ++k) {
      ASSERT_GE(run_of[k], 0);
      if (d.nodes[k].right >= 0) {
        EXPECT_LT(run_of[d.nodes[k].left], run_of[k]);
        EXPECT_LT(run_of[d.nodes[k].right], run_of[k]);
      }
    }
    EXPECT_EQ(d.levels[d.level_starts[d.level_starts.size() - 2]], 0);   // the root alone, last
    // Move the boxes, refit on the host, and refit again run by run on a copy.
    for (auto& v : b.lo) v += 0.5f;
    for (auto& v : b.hi) v += 1.5f;
    BvhData by_level = d;
    RefitBvh(b.bounds(), &d);
    for (size_t r = 0; r + 1 < by_level.level_starts.size(); ++r) {
      for (int64_t k = by_level.level_starts[r]; k < by_level.level_starts[r + 1]; ++k) {
        wp::bvh_node_t& node = by_level.nodes[by_level.levels[k]];
        float lo[3] = {3.0e38f, 3.0e38f, 3.0e38f}, hi[3] = {-3.0e38f, -3.0e38f, -3.0e38f};
        auto grow = [&](const float* l, const float* h) {
          for (int a = 0; a < 3; ++a) {
            lo[a] = l[a] < lo[a] ? l[a] : lo[a];
            hi[a] = hi[a] < h[a] ? h[a] : hi[a];
          }
        };
        if (node.right < 0) {
          for (int i = node.left; i < node.left - node.right; ++i) {
            int p = by_level.prim_ids[i];
            grow(&b.lo[3 * p], &b.hi[3 * p]);
          }
        } else {
          grow(by_level.nodes[node.left].lower, by_level.nodes[node.left].upper);
          grow(by_level.nodes[node.right].lower, by_level.nodes[node.right].upper);
        }
        for (int a = 0; a < 3; ++a) {
          node.lower[a] = lo[a];
          node.upper[a] = hi[a];
        }
      }
    }
    for (size_t k = 0; k < d.nodes.size(); ++k)
      for (int a = 0; a < 3; ++a) {
        EXPECT_EQ(by_level.nodes[k].lower[a], d.nodes[k].lower[a]);
        EXPECT_EQ(by_level.nodes[k].upper[a], d.nodes[k].upper[a]);
      }
  }
}

TEST(GeometryBvh, NanBoundsAndIdenticalCentroidsStillBuild) {
  Boxes b = RandomBoxes(300, 3);
  for (int i = 0; i < 300; i += 3) b.lo[3 * i] = std::numeric_limits<float>::quiet_NaN();
  for (int i = 1; i < 300; i += 3)
    for (int k = 0; k < 3; ++k) b.lo[3 * i + k] = b.hi[3 * i + k] = 1.0f;
  BvhData d;
  BuildBvh(300, b.bounds(), &d);
  std::vector<int> seen(300, 0);
  for (int p : d.prim_ids) ++seen[p];
  for (int i = 0; i < 300; ++i) EXPECT_EQ(seen[i], 1);
}

TEST(GeometryBvh, RefitFollowsMovedItems) {
  Boxes b = RandomBoxes(500, 11);
  BvhData d;
  BuildBvh(500, b.bounds(), &d);
  for (auto& x : b.lo) x += 100.0f;
  for (auto& x : b.hi) x += 100.0f;
  RefitBvh(b.bounds(), &d);
  CheckTree(d, b, 500);
}

TEST(GeometryRegistry, IdsAreCheckedAndTablesHoldOnlyLiveObjects) {
  GeometryRegistry reg, other;
  auto g1 = GeometryObject::NewHashGrid("cpu", 4, 4, 4);
  auto g2 = GeometryObject::NewHashGrid("cpu", 2, 2, 2);
  auto g3 = GeometryObject::NewHashGrid("cuda:0", 2, 2, 2);
  ASSERT_TRUE(g1.ok() && g2.ok() && g3.ok());
  auto id1 = reg.Add(*g1);
  auto id2 = reg.Add(*g2);
  auto foreign = other.Add(*g3);
  ASSERT_TRUE(id1.ok() && id2.ok() && foreign.ok());
  EXPECT_NE(*id1, *id2);
  EXPECT_TRUE(reg.Find(*id1).ok());
  EXPECT_FALSE(reg.Find(*foreign).ok());    // another registry's id: different generation
  EXPECT_FALSE(reg.Find(0).ok());
  EXPECT_FALSE(reg.Find(*id1 + (1ull << 32)).ok());   // forged generation
  EXPECT_FALSE(reg.Find(*id1 + 5).ok());    // slot out of range
  ASSERT_TRUE(reg.Remove(*id1).ok());
  EXPECT_FALSE(reg.Find(*id1).ok());        // stale
  EXPECT_FALSE(reg.Remove(*id1).ok());
  auto id3 = reg.Add(*g1);                  // reuses the slot with a new generation
  ASSERT_TRUE(id3.ok());
  EXPECT_EQ(*id3 & 0xffffffffull, *id1 & 0xffffffffull);
  EXPECT_NE(*id3, *id1);
  auto table = reg.TableFor("cpu");
  ASSERT_TRUE(table);
  ASSERT_EQ(table->table.count, 2u);
  for (uint32_t i = 0; i < table->table.count; ++i) EXPECT_EQ(table->slots[i].kind, wp::GEOMETRY_HASH_GRID);
  auto gpu_table = other.TableFor("cpu");
  ASSERT_TRUE(gpu_table);
  EXPECT_EQ(gpu_table->slots[0].kind, wp::GEOMETRY_NONE);   // a cuda:0 object is not in a CPU table
  GeometryRegistry none;
  EXPECT_FALSE(none.TableFor("cpu"));
}

TEST(GeometryHashGrid, DimsAreOverflowChecked) {
  EXPECT_FALSE(GeometryObject::NewHashGrid("cpu", 0, 1, 1).ok());
  EXPECT_FALSE(GeometryObject::NewHashGrid("cpu", -1, 1, 1).ok());
  EXPECT_FALSE(GeometryObject::NewHashGrid("cpu", 1 << 30, 1 << 30, 1 << 30).ok());
  EXPECT_FALSE(GeometryObject::NewHashGrid("cpu", 2147483647, 2147483647, 2147483647).ok());
  EXPECT_TRUE(GeometryObject::NewHashGrid("cpu", 1 << 26, 1, 1).ok());
  EXPECT_FALSE(GeometryObject::NewHashGrid("cpu", (1 << 26) + 1, 1, 1).ok());
}

TEST(GeometryHashGrid, CellCoordinatesClampAndWrap) {
  EXPECT_EQ(wp::hash_grid_coord(-0.5f, 1.0f), -1);
  EXPECT_EQ(wp::hash_grid_coord(2.0f, 1.0f), 2);
  EXPECT_EQ(wp::hash_grid_coord(std::numeric_limits<float>::quiet_NaN(), 1.0f), 0);
  EXPECT_EQ(wp::hash_grid_coord(1e30f, 1.0f), 1000000000);
  EXPECT_EQ(wp::hash_grid_coord(-1e30f, 1.0f), -1000000000);
  const int32_t dim[3] = {3, 5, 7};
  int64_t c = wp::hash_grid_cell(dim, -1000000000, 1000000000, -1);
  EXPECT_GE(c, 0);
  EXPECT_LT(c, 3 * 5 * 7);
}

}  // namespace
}  // namespace weft::geometry
