// ModuleCache with stand-in load/build steps: memory hits, disk hits, misses, LRU eviction,
// concurrent requests for one key coalescing into one build, errors reaching every waiter,
// corrupted disk files rebuilt.
#include "engine/runtime/module_cache.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>
#include <vector>

namespace weft {
namespace {

namespace fs = std::filesystem;

struct Counters {
  std::atomic<int> builds{0};
  std::atomic<int> loads{0};
};

ModuleCache::Callbacks MakeCallbacks(Counters* counters, std::string payload,
                                     std::chrono::milliseconds build_time = {}) {
  ModuleCache::Callbacks callbacks;
  callbacks.build = [=](std::vector<Diagnostic>*) -> Expected<ModuleArtifact> {
    counters->builds++;
    std::this_thread::sleep_for(build_time);
    ModuleArtifact a;
    a.object = payload;
    a.function_names = {"f"};
    return a;
  };
  callbacks.load = [=](const ModuleArtifact& a) -> Expected<ModuleCache::Module> {
    counters->loads++;
    auto m = std::make_shared<LoadedModule>();
    m->id = a.object;
    return ModuleCache::Module(m);
  };
  return callbacks;
}

class CacheMemory : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("weft-cache-mem-" + std::to_string(::getpid()) + "-" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(CacheMemory, MissThenMemoryHitThenDiskHitInANewCache) {
  Counters counters;
  auto callbacks = MakeCallbacks(&counters, "object-1");
  {
    ModuleCache cache(dir_.string(), 8);
    ModuleCache::Source source;
    auto first = cache.Get("k1", callbacks, &source, nullptr);
    ASSERT_TRUE(first.ok());
    EXPECT_EQ(source, ModuleCache::Source::kBuilt);
    EXPECT_EQ((*first)->id, "object-1");
    auto second = cache.Get("k1", callbacks, &source, nullptr);
    ASSERT_TRUE(second.ok());
    EXPECT_EQ(source, ModuleCache::Source::kMemory);
    EXPECT_EQ(first->get(), second->get());
    auto stats = cache.stats();
    EXPECT_EQ(stats.misses, 1u);
    EXPECT_EQ(stats.memory_hits, 1u);
    EXPECT_EQ(stats.disk_hits, 0u);
  }
  ModuleCache restarted(dir_.string(), 8);
  ModuleCache::Source source;
  auto third = restarted.Get("k1", callbacks, &source, nullptr);
  ASSERT_TRUE(third.ok());
  EXPECT_EQ(source, ModuleCache::Source::kDisk);
  EXPECT_EQ((*third)->id, "object-1");
  EXPECT_EQ(counters.builds, 1);
  EXPECT_EQ(restarted.stats().disk_hits, 1u);
  EXPECT_EQ(restarted.stats().misses, 0u);
}

TEST_F(CacheMemory, LruEvictsTheLeastRecentlyUsed) {
  Counters counters;
  ModuleCache cache("", 2);  // memory only
  auto callbacks = MakeCallbacks(&counters, "x");
  ASSERT_TRUE(cache.Get("a", callbacks, nullptr, nullptr).ok());
  ASSERT_TRUE(cache.Get("b", callbacks, nullptr, nullptr).ok());
  ASSERT_TRUE(cache.Get("a", callbacks, nullptr, nullptr).ok());  // a is now most recent
  ASSERT_TRUE(cache.Get("c", callbacks, nullptr, nullptr).ok());  // evicts b
  EXPECT_NE(cache.Peek("a"), nullptr);
  EXPECT_EQ(cache.Peek("b"), nullptr);
  EXPECT_NE(cache.Peek("c"), nullptr);
  EXPECT_EQ(counters.builds, 3);
  ASSERT_TRUE(cache.Get("b", callbacks, nullptr, nullptr).ok());
  EXPECT_EQ(counters.builds, 4);
}

TEST_F(CacheMemory, ConcurrentRequestsCoalesceIntoOneBuild) {
  Counters counters;
  ModuleCache cache(dir_.string(), 8);
  auto callbacks = MakeCallbacks(&counters, "shared", std::chrono::milliseconds(200));
  constexpr int kThreads = 8;
  std::vector<const LoadedModule*> got(kThreads, nullptr);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      auto m = cache.Get("same-key", callbacks, nullptr, nullptr);
      if (m.ok()) got[t] = m->get();
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(counters.builds, 1);
  EXPECT_EQ(counters.loads, 1);
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(got[t], got[0]) << t;
  EXPECT_NE(got[0], nullptr);
  auto stats = cache.stats();
  EXPECT_EQ(stats.misses, 1u);
  EXPECT_EQ(stats.memory_hits, uint64_t(kThreads - 1));
}

TEST_F(CacheMemory, BuildErrorsReachEveryWaiterAndAreNotCached) {
  std::atomic<int> builds{0};
  ModuleCache cache("", 8);
  ModuleCache::Callbacks callbacks;
  callbacks.build = [&](std::vector<Diagnostic>* diags) -> Expected<ModuleArtifact> {
    builds++;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    Diagnostic d;
    d.message = "unknown name 'q'";
    d.location = {"k.py", 3, 5};
    diags->push_back(d);
    return InvalidArgument("k.py:3: unknown name 'q'");
  };
  callbacks.load = [](const ModuleArtifact&) -> Expected<ModuleCache::Module> {
    return Internal("never called");
  };
  std::vector<std::vector<Diagnostic>> diags(4);
  std::vector<StatusCode> codes(4, StatusCode::kOk);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      auto m = cache.Get("bad", callbacks, nullptr, &diags[t]);
      codes[t] = m.status().code();
    });
  }
  for (auto& t : threads) t.join();
  for (int t = 0; t < 4; ++t) {
    EXPECT_EQ(codes[t], StatusCode::kInvalidArgument);
    ASSERT_EQ(diags[t].size(), 1u);
    EXPECT_EQ(diags[t][0].location.line, 3u);
  }
  EXPECT_LE(builds, 4);
  int before = builds;
  EXPECT_FALSE(cache.Get("bad", callbacks, nullptr, nullptr).ok());
  EXPECT_EQ(builds, before + 1);  // failures are retried, not cached
}

TEST_F(CacheMemory, CorruptedOrTruncatedDiskFileIsRebuilt) {
  Counters counters;
  auto callbacks = MakeCallbacks(&counters, "object-2");
  { ASSERT_TRUE(ModuleCache(dir_.string(), 8).Get("k2", callbacks, nullptr, nullptr).ok()); }
  const std::string path = DiskModuleCache(dir_.string()).PathFor("k2");
  ASSERT_TRUE(fs::exists(path));

  // Truncated: a new cache rebuilds instead of loading it, and rewrites a good file.
  fs::resize_file(path, fs::file_size(path) - 3);
  {
    ModuleCache cache(dir_.string(), 8);
    ModuleCache::Source source;
    auto m = cache.Get("k2", callbacks, &source, nullptr);
    ASSERT_TRUE(m.ok());
    EXPECT_EQ(source, ModuleCache::Source::kBuilt);
    EXPECT_EQ((*m)->id, "object-2");
  }
  EXPECT_EQ(counters.builds, 2);

  // Corrupted: one flipped byte in the middle.
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(fs::file_size(path) / 2 + 30);
    char c;
    f.get(c);
    f.seekp(fs::file_size(path) / 2 + 30);
    f.put(char(c ^ 1));
  }
  {
    ModuleCache cache(dir_.string(), 8);
    ModuleCache::Source source;
    ASSERT_TRUE(cache.Get("k2", callbacks, &source, nullptr).ok());
    EXPECT_EQ(source, ModuleCache::Source::kBuilt);
  }
  EXPECT_EQ(counters.builds, 3);

  // And the rewritten file is good again.
  ModuleCache cache(dir_.string(), 8);
  ModuleCache::Source source;
  ASSERT_TRUE(cache.Get("k2", callbacks, &source, nullptr).ok());
  EXPECT_EQ(source, ModuleCache::Source::kDisk);
  EXPECT_EQ(counters.builds, 3);
}

}  // namespace
}  // namespace weft
