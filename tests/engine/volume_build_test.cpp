// The daemon-side build of wp.Volume (engine/geometry/volume_build.h): every leaf is found by the
// kernel-side search (volume_leaf_hash within max_probe probes), keys that are not leaves are
// not found, the prefix counts are the active voxels before each leaf, the transform's inverse is
// exact; and hostile descriptions (unaligned or far origins, duplicates, too many leaves, a
// background of the wrong size, a singular or non-finite transform, unknown types) are refused.
#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <cmath>
#include <random>
#include <set>
#include <tuple>

#include "engine/geometry/volume_build.h"
#include "engine/native/geometry_abi.h"

namespace weft::geometry {
namespace {

const std::vector<double> kScale{0.25, 0, 0, 0, 0.5, 0, 0, 0, 2.0, 1, -2, 3};

// The kernel-side leaf search (engine/native/volume.h volume_find_leaf), over the host build;
// with `origins`, also checks that a found entry's key is the origin given for that leaf.
int32_t FindLeaf(const VolumeData& d, int32_t i, int32_t j, int32_t k, const int32_t* origins = nullptr) {
  const int64_t mask = static_cast<int64_t>(d.table.size() / 4) - 1;
  int64_t slot = wp::volume_leaf_hash(i >> 3, j >> 3, k >> 3, mask);
  for (int32_t p = 0; p < d.max_probe; ++p) {
    const int32_t* e = &d.table[4 * static_cast<size_t>(slot)];
    if (e[3] < 0) return -1;
    if (e[0] == (i >> 3) && e[1] == (j >> 3) && e[2] == (k >> 3)) {
      if (origins) {
        const int32_t* o = origins + 3 * static_cast<size_t>(e[3]);   // the entry names that leaf
        EXPECT_TRUE(o[0] == 8 * e[0] && o[1] == 8 * e[1] && o[2] == 8 * e[2]);
      }
      return e[3];
    }
    slot = (slot + 1) & mask;
  }
  return -1;
}

std::string Bytes(float v) { return std::string(reinterpret_cast<const char*>(&v), 4); }

TEST(VolumeBuild, EveryLeafIsFoundAndOthersAreNot) {
  std::mt19937 rng(12345u + static_cast<uint32_t>(std::random_device{}()));
  std::uniform_int_distribution<int32_t> coord(-5000, 5000);
  std::set<std::tuple<int32_t, int32_t, int32_t>> keys;
  while (keys.size() < 5000) keys.insert({coord(rng), coord(rng), coord(rng)});
  std::vector<int32_t> origins;
  for (const auto& [x, y, z] : keys) {
    origins.push_back(8 * x);
    origins.push_back(8 * y);
    origins.push_back(8 * z);
  }
  const int64_t n = static_cast<int64_t>(keys.size());
  std::vector<uint64_t> masks(8 * n);
  std::uniform_int_distribution<uint64_t> bits;
  for (auto& m : masks) m = bits(rng);
  VolumeData d;
  ASSERT_TRUE(BuildVolume(wp::VOLUME_FLOAT, origins.data(), masks.data(), n, Bytes(0.5f), kScale, &d).ok());
  ASSERT_TRUE(std::has_single_bit(d.table.size() / 4));
  ASSERT_GE(d.table.size() / 4, static_cast<size_t>(2 * n));
  for (size_t s = 0; s < d.table.size(); s += 4) ASSERT_LT(d.table[s + 3], n);
  int64_t active = 0;
  for (int64_t l = 0; l < n; ++l) {
    EXPECT_EQ(d.prefix[l], active);
    for (int w = 0; w < 8; ++w) active += std::popcount(masks[8 * l + w]);
    const int32_t* o = &origins[3 * l];
    // Any voxel of the leaf finds it, including the far corner.
    EXPECT_EQ(FindLeaf(d, o[0], o[1], o[2], origins.data()), l);
    EXPECT_EQ(FindLeaf(d, o[0] + 7, o[1] + 3, o[2] + 5, origins.data()), l);
    // The neighbour along z is a leaf only if its key was drawn.
    const bool neighbour = keys.count({o[0] / 8, o[1] / 8, o[2] / 8 + 1}) != 0;
    EXPECT_EQ(FindLeaf(d, o[0], o[1], o[2] + 8) >= 0, neighbour);
  }
  EXPECT_EQ(d.active, active);
  // Far and negative coordinates outside every leaf.
  EXPECT_EQ(FindLeaf(d, 1 << 30, -(1 << 30), 12345678), -1);
  // The inverse of the transform.
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) {
      double s = 0;
      for (int k = 0; k < 3; ++k) s += d.xform[3 * r + k] * d.inverse[3 * k + c];
      EXPECT_NEAR(s, r == c ? 1.0 : 0.0, 1e-14);
    }
  EXPECT_EQ(d.translation[1], -2.0);
  float bg;
  std::memcpy(&bg, d.background, 4);
  EXPECT_EQ(bg, 0.5f);
}

TEST(VolumeBuild, HostileDescriptionsAreRefused) {
  std::vector<int32_t> one{0, 8, -16};
  std::vector<uint64_t> m(16, ~uint64_t{0});
  VolumeData d;
  auto build = [&](uint32_t type, const std::vector<int32_t>& o, int64_t n, const std::string& bg,
                   const std::vector<double>& t) {
    return BuildVolume(type, o.data(), m.data(), n, bg, t, &d);
  };
  EXPECT_TRUE(build(wp::VOLUME_FLOAT, one, 1, Bytes(1), kScale).ok());
  EXPECT_TRUE(build(wp::VOLUME_ONINDEX, one, 1, "", kScale).ok());
  // Origins not multiples of 8, or beyond +-2^30.
  EXPECT_NE(build(wp::VOLUME_FLOAT, {0, 4, 0}, 1, Bytes(1), kScale).message().find("multiples of 8"), std::string::npos);
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, {0, 0, (1 << 30) + 8}, 1, Bytes(1), kScale).ok());
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, {0, 0, -2147483640}, 1, Bytes(1), kScale).ok());
  // Two leaves at one origin.
  EXPECT_NE(build(wp::VOLUME_FLOAT, {8, 8, 8, 8, 8, 8}, 2, Bytes(1), kScale).message().find("same origin"),
            std::string::npos);
  // No leaves: an empty volume whose searches end at once; past the limit: refused before
  // anything is read or allocated.
  ASSERT_TRUE(build(wp::VOLUME_FLOAT, one, 0, Bytes(1), kScale).ok());
  EXPECT_EQ(d.max_probe, 0);
  EXPECT_EQ(FindLeaf(d, 0, 8, -16), -1);
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, one, -1, Bytes(1), kScale).ok());
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, one, kMaxVolumeLeaves + 1, Bytes(1), kScale).ok());
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, one, int64_t{1} << 62, Bytes(1), kScale).ok());
  // Background of the wrong size; an index grid with one.
  EXPECT_FALSE(build(wp::VOLUME_VEC3F, one, 1, Bytes(1), kScale).ok());
  EXPECT_FALSE(build(wp::VOLUME_INDEX, one, 1, Bytes(1), kScale).ok());
  // Unknown or unsupported types (NanoVDB's half, fp4).
  EXPECT_FALSE(build(9, one, 1, "ab", kScale).ok());
  EXPECT_FALSE(build(13, one, 1, "", kScale).ok());
  EXPECT_FALSE(build(0xffffffffu, one, 1, "", kScale).ok());
  // Transforms: wrong length, singular, not finite.
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, one, 1, Bytes(1), {1, 0, 0, 0, 1, 0, 0, 0, 1}).ok());
  EXPECT_NE(build(wp::VOLUME_FLOAT, one, 1, Bytes(1), {1, 2, 3, 2, 4, 6, 0, 0, 1, 0, 0, 0}).message().find("singular"),
            std::string::npos);
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, one, 1, Bytes(1), {1, 0, 0, 0, 1, 0, 0, 0, 1e-300, 0, 0, 0}).ok());
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, one, 1, Bytes(1), {1, 0, 0, 0, NAN, 0, 0, 0, 1, 0, 0, 0}).ok());
  EXPECT_FALSE(build(wp::VOLUME_FLOAT, one, 1, Bytes(1), {1, 0, 0, 0, 1, 0, 0, 0, 1, INFINITY, 0, 0}).ok());
}

}  // namespace
}  // namespace weft::geometry
