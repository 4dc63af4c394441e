// Memory between sessions: every slab belongs to one session (two sessions' arrays never share
// one, freed memory is reused only by its owner, so a new array never holds another session's
// data); the first export moves an array into a slab of its own and an importer is told only
// that slab; quotas count reserved bytes per session, per principal and daemon-wide.
#include <gtest/gtest.h>

#include <cstring>

#include "engine/runtime/memory_quota.h"
#include "runtime_test_support.h"

namespace weft {
namespace {

using namespace weft::testing;

CreateArrayParams EmptyFloats(int64_t n) {
  CreateArrayParams p;
  p.dtype = F32();
  p.shape = {n};
  return p;
}

TEST(MemoryIsolation, SessionsNeverShareASlab) {
  auto e = MakeEngine();
  auto a = e->OpenSession(Local("a"));
  auto b = e->OpenSession(Local("b"));
  auto a1 = e->CreateArray(*a, EmptyFloats(16));
  auto a2 = e->CreateArray(*a, EmptyFloats(16));
  auto b1 = e->CreateArray(*b, EmptyFloats(16));
  ASSERT_TRUE(a1.ok() && a2.ok() && b1.ok());
  EXPECT_EQ(a1->shm_name, a2->shm_name);   // one session's small arrays share its slab
  EXPECT_NE(a1->shm_name, b1->shm_name);
}

TEST(MemoryIsolation, ANewArrayNeverHoldsAnotherSessionsData) {
  auto e = MakeEngine();
  auto a = e->OpenSession(Local("a"));
  auto b = e->OpenSession(Local("b"));
  auto keep = e->CreateArray(*a, EmptyFloats(4));   // keeps a's slab alive
  ASSERT_TRUE(keep.ok());
  std::vector<float> secret(1024, 1234.5f);
  for (int i = 0; i < 4; ++i) {
    auto s = e->CreateArray(*a, FromFloats(secret));
    ASSERT_TRUE(s.ok());
    ASSERT_TRUE(e->FreeArray(*a, s->handle).ok());
  }
  for (int i = 0; i < 4; ++i) {
    auto fresh = e->CreateArray(*b, EmptyFloats(1024));
    ASSERT_TRUE(fresh.ok());
    for (float v : ReadFloats(*e, *b, fresh->handle)) ASSERT_NE(v, 1234.5f);
  }
  // Within one session, freed memory is reused (Warp's `empty` semantics).
  auto again = e->CreateArray(*a, EmptyFloats(1024));
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->shm_name, keep->shm_name);
}

TEST(MemoryIsolation, ExportMovesTheArrayIntoASlabOfItsOwn) {
  auto e = MakeEngine();
  auto a = e->OpenSession(Local("a"));
  auto b = e->OpenSession(Local("b"));
  auto x = e->CreateArray(*a, FromFloats({1, 2, 3, 4}, /*requires_grad=*/true));
  auto neighbour = e->CreateArray(*a, FromFloats({9, 9}));
  ASSERT_TRUE(x.ok() && neighbour.ok());
  ASSERT_EQ(x->shm_name, neighbour->shm_name);
  auto token = e->ExportArray(*a, x->handle);
  ASSERT_TRUE(token.ok());
  auto moved = e->DescribeArray(*a, x->handle);
  ASSERT_TRUE(moved.ok());
  EXPECT_NE(moved->shm_name, neighbour->shm_name);
  EXPECT_LE(moved->shm_size, 4096u);   // the array's page, nothing else
  EXPECT_EQ(ReadFloats(*e, *a, x->handle), (std::vector<float>{1, 2, 3, 4}));
  auto imported = e->ImportArray(*b, *token);
  ASSERT_TRUE(imported.ok());
  EXPECT_EQ(imported->shm_name, moved->shm_name);
  // The gradient moved too: the importer may describe it and gets a slab of its own.
  auto grad = e->DescribeArray(*b, imported->grad_handle);
  ASSERT_TRUE(grad.ok()) << grad.status().ToString();
  EXPECT_FALSE(grad->shm_name.empty());
  EXPECT_NE(grad->shm_name, neighbour->shm_name);
  // Exporting again changes nothing.
  ASSERT_TRUE(e->ExportArray(*a, x->handle).ok());
  EXPECT_EQ(e->DescribeArray(*a, x->handle)->shm_name, moved->shm_name);
}

TEST(MemoryQuota, CountsAndNamesTheLimit) {
  MemoryLimits l;
  l.per_session = 100;
  l.per_principal = 150;
  l.daemon = 180;
  MemoryQuota q(l);
  EXPECT_TRUE(q.Reserve("s1", "p", 60).ok());
  Status s = q.Reserve("s1", "p", 50);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_NE(s.message().find("per-session"), std::string::npos) << s.ToString();
  EXPECT_TRUE(q.Reserve("s2", "p", 80).ok());
  s = q.Reserve("s3", "p", 20);
  EXPECT_NE(s.message().find("per-principal"), std::string::npos) << s.ToString();
  EXPECT_TRUE(q.Reserve("s4", "other", 40).ok());
  s = q.Reserve("s5", "other", 1);
  EXPECT_NE(s.message().find("daemon-wide"), std::string::npos) << s.ToString();
  // A reservation that would overflow 64 bits is refused, not wrapped.
  EXPECT_FALSE(q.Reserve("s6", "x", ~uint64_t{0}).ok());
  q.Release("s1", "p", 60);
  EXPECT_EQ(q.Usage("s1", "p").session, 0u);
  EXPECT_EQ(q.Usage("s1", "p").principal, 80u);
  EXPECT_TRUE(q.Reserve("s5", "other", 50).ok());
}

TEST(MemoryQuota, EngineChargesReservedBytesAndReleasesThemOnFree) {
  auto store = std::make_unique<FakeModuleStore>();
  EngineOptions o;
  o.cpu_threads = 1;
  o.remove_stale_slabs = false;
  o.memory.per_session = 1 << 20;
  auto created = Engine::Create(o, std::move(store));
  ASSERT_TRUE(created.ok());
  auto& e = *created;
  auto s = e->OpenSession(Local());
  auto big = e->CreateArray(*s, EmptyFloats(200 * 1024));   // 800 KiB, never touched
  ASSERT_TRUE(big.ok());
  EXPECT_EQ(e->MemoryUsageOf(*s).session, 800u * 1024);
  auto over = e->CreateArray(*s, EmptyFloats(100 * 1024));
  ASSERT_FALSE(over.ok());
  EXPECT_EQ(over.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(over.status().message().find("per-session memory limit"), std::string::npos);
  EXPECT_EQ(e->Stats().arrays, 1u);
  ASSERT_TRUE(e->FreeArray(*s, big->handle).ok());
  EXPECT_EQ(e->MemoryUsageOf(*s).session, 0u);
  EXPECT_TRUE(e->CreateArray(*s, EmptyFloats(100 * 1024)).ok());
}

}  // namespace
}  // namespace weft
