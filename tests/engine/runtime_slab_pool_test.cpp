// ShmSlabPool: alignment, reuse after free, coalescing, dedicated slabs, unlink of empty slabs,
// and a random alloc/free workload checked against a shadow model (no overlaps, no leaks).
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#include <sanitizer/lsan_interface.h>
#endif
#endif
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <map>
#include <random>

#include "engine/runtime/shm_slab_pool.h"

namespace weft {
namespace {

bool ShmExists(const std::string& name) {
  struct stat st {};
  return stat(("/dev/shm" + name).c_str(), &st) == 0;
}

ShmSlabPoolOptions SmallPool() {
  ShmSlabPoolOptions o;
  o.name_prefix = "/weft-" + std::to_string(getpid()) + "-slabtest-";
  o.slab_size = 1 << 20;
  o.dedicated_threshold = 512 << 10;
  return o;
}

TEST(SlabPool, AlignsAndReusesFreedSpace) {
  ShmSlabPool pool(SmallPool());
  auto a = pool.Allocate(1);
  auto b = pool.Allocate(300);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->size, 256u);
  EXPECT_EQ(b->size, 512u);
  EXPECT_EQ(a->offset % 256, 0u);
  EXPECT_EQ(b->offset % 256, 0u);
  EXPECT_EQ(a->slab_name, b->slab_name);
  pool.Free(*a);
  auto c = pool.Allocate(200);
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->offset, a->offset);   // first fit takes the hole
  pool.Free(*b);
  pool.Free(*c);
  EXPECT_EQ(pool.stats().slabs, 0u);
}

TEST(SlabPool, CoalescesNeighbours) {
  ShmSlabPool pool(SmallPool());
  auto keep = pool.Allocate(256);   // keeps the slab alive
  std::vector<ShmSlabPool::Block> blocks;
  for (int i = 0; i < 3; ++i) blocks.push_back(*pool.Allocate(128 << 10));
  // Free the middle, then its neighbours: the three holes must merge into one range that fits
  // a request of their total size at the first block's offset.
  pool.Free(blocks[1]);
  pool.Free(blocks[0]);
  pool.Free(blocks[2]);
  auto big = pool.Allocate(3 * (128 << 10));
  ASSERT_TRUE(big.ok());
  EXPECT_EQ(big->slab_name, keep->slab_name);
  EXPECT_EQ(big->offset, blocks[0].offset);
  pool.Free(*big);
  pool.Free(*keep);
}

TEST(SlabPool, BigRequestsGetTheirOwnSlabAndEmptySlabsAreUnlinked) {
  ShmSlabPool pool(SmallPool());
  auto small = pool.Allocate(1000);
  auto big = pool.Allocate(3 << 20);
  ASSERT_TRUE(small.ok() && big.ok());
  EXPECT_NE(small->slab_name, big->slab_name);
  EXPECT_EQ(big->offset, 0u);
  EXPECT_GE(big->slab_size, 3u << 20);
  EXPECT_TRUE(big->zeroed);
  for (uint64_t i = 0; i < big->size; i += 4096) ASSERT_EQ(static_cast<char*>(big->data)[i], 0);
  auto carved = pool.Allocate(10);   // from the existing regular slab: may hold old data
  EXPECT_FALSE(carved->zeroed);
  pool.Free(*carved);
  EXPECT_TRUE(ShmExists(big->slab_name));
  struct stat st {};
  ASSERT_EQ(stat(("/dev/shm" + big->slab_name).c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  pool.Free(*big);
  EXPECT_FALSE(ShmExists(big->slab_name));
  EXPECT_TRUE(ShmExists(small->slab_name));
  std::string name = small->slab_name;
  pool.Free(*small);
  EXPECT_FALSE(ShmExists(name));
  // Names are never reused.
  auto again = pool.Allocate(10);
  EXPECT_NE(again->slab_name, name);
  pool.Free(*again);
}

TEST(SlabPool, DestructorUnlinksEverything) {
  std::vector<std::string> names;
  {
    ShmSlabPool pool(SmallPool());
    for (int i = 0; i < 5; ++i) names.push_back(pool.Allocate(600 << 10)->slab_name);
  }
  for (auto& n : names) EXPECT_FALSE(ShmExists(n)) << n;
}

TEST(SlabPool, RandomWorkloadNeverOverlapsAndReturnsEverything) {
  ShmSlabPool pool(SmallPool());
  std::mt19937_64 rng(12345);
  std::map<std::pair<std::string, uint64_t>, ShmSlabPool::Block> live;  // (slab, offset)
  uint64_t live_bytes = 0;
  for (int step = 0; step < 4000; ++step) {
    bool alloc = live.empty() || rng() % 100 < 55;
    if (alloc) {
      uint64_t size = (rng() % 4 == 0) ? rng() % (700 << 10) : rng() % 5000;
      auto b = pool.Allocate(size);
      ASSERT_TRUE(b.ok()) << b.status().ToString();
      ASSERT_GE(b->size, size);
      ASSERT_EQ(b->offset % 256, 0u);
      ASSERT_LE(b->offset + b->size, b->slab_size);
      // No overlap with a live block of the same slab.
      auto key = std::make_pair(b->slab_name, b->offset);
      auto it = live.lower_bound(key);
      if (it != live.end() && it->first.first == b->slab_name) {
        ASSERT_GE(it->first.second, b->offset + b->size);
      }
      if (it != live.begin()) {
        auto p = std::prev(it);
        if (p->first.first == b->slab_name) {
          ASSERT_LE(p->first.second + p->second.size, b->offset);
        }
      }
      std::memset(b->data, static_cast<int>(step & 0xff), b->size);   // memory is really mapped
      live[key] = *b;
      live_bytes += b->size;
    } else {
      auto it = live.begin();
      std::advance(it, rng() % live.size());
      live_bytes -= it->second.size;
      pool.Free(it->second);
      live.erase(it);
    }
    ASSERT_EQ(pool.stats().block_bytes, live_bytes);
  }
  for (auto& [k, b] : live) pool.Free(b);
  EXPECT_EQ(pool.stats().slabs, 0u);
  EXPECT_EQ(pool.stats().block_bytes, 0u);
}

// Tells LeakSanitizer (when present) that `p` and what it owns are leaked on purpose.
void IgnoreDeliberateLeak(const void* p) {
#if defined(__has_feature)
#if __has_feature(address_sanitizer)
  __lsan_ignore_object(p);
#endif
#endif
  (void)p;
}

TEST(SlabPool, RemovesStaleSlabsOfDeadDaemonsOnly) {
  // A pid that is not running: fork a child that exits at once.
  pid_t dead = fork();
  if (dead == 0) _exit(0);
  int status = 0;
  waitpid(dead, &status, 0);
  ShmSlabPoolOptions o;
  o.name_prefix = "/weft-" + std::to_string(dead) + "-";
  auto* stale = new ShmSlabPool(o);
  auto b = stale->Allocate(10);
  ASSERT_TRUE(b.ok());
  std::string stale_name = b->slab_name;
  ShmSlabPool mine(SmallPool());
  auto m = mine.Allocate(10);
  // Leak `stale` on purpose so its file stays, as after a crash (LeakSanitizer is told).
  IgnoreDeliberateLeak(stale);
  EXPECT_GE(ShmSlabPool::RemoveStaleSlabs(), 1);
  EXPECT_FALSE(ShmExists(stale_name));
  EXPECT_TRUE(ShmExists(m->slab_name));
  mine.Free(*m);
}

}  // namespace
}  // namespace weft
