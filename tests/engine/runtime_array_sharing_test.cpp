// Engine arrays: creation checks that change nothing, refcounting across sessions through IPC
// tokens (memory lives until every holder frees it or closes), token and credential checks,
// gradients freed with their arrays, reads/writes with range checks.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include "runtime_test_support.h"

namespace weft {
namespace {

using namespace weft::testing;

bool ShmExists(const std::string& name) {
  struct stat st {};
  return stat(("/dev/shm" + name).c_str(), &st) == 0;
}

TEST(ArraySharing, BadCreatesFailCleanlyAndAllocateNothing) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  CreateArrayParams neg;
  neg.dtype = F32();
  neg.shape = {4, -2};
  CreateArrayParams huge;
  huge.dtype = F32();
  huge.shape = {1ll << 40, 1ll << 20};
  CreateArrayParams nodtype;
  nodtype.shape = {3};
  CreateArrayParams wrong_bytes = FromFloats({1, 2, 3});
  wrong_bytes.value.pop_back();
  CreateArrayParams noshape;
  noshape.dtype = F32();
  CreateArrayParams gpu = FromFloats({1});
  gpu.device = "tpu:0";
  struct Case { CreateArrayParams p; StatusCode code; };
  for (auto& c : std::vector<Case>{{neg, StatusCode::kInvalidArgument},
                                   {huge, StatusCode::kResourceExhausted},
                                   {nodtype, StatusCode::kInvalidArgument},
                                   {wrong_bytes, StatusCode::kInvalidArgument},
                                   {noshape, StatusCode::kInvalidArgument},
                                   {gpu, StatusCode::kInvalidArgument}}) {
    auto r = e->CreateArray(*s, c.p);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), c.code) << r.status().ToString();
  }
  EXPECT_EQ(e->Stats().arrays, 0u);
  EXPECT_EQ(e->Stats().cpu_slabs, 0u);
}

TEST(ArraySharing, ImportedArrayLivesUntilEveryHolderLetsGo) {
  auto e = MakeEngine();
  auto a = e->OpenSession(Local("a"));
  auto b = e->OpenSession(Local("b"));
  auto info = e->CreateArray(*a, FromFloats({1, 2, 3, 4}, /*requires_grad=*/true));
  ASSERT_TRUE(info.ok());
  EXPECT_NE(info->grad_handle, 0u);
  EXPECT_FALSE(info->shm_name.empty());
  auto token = e->ExportArray(*a, info->handle);
  ASSERT_TRUE(token.ok());
  auto imported = e->ImportArray(*b, *token);
  ASSERT_TRUE(imported.ok()) << imported.status().ToString();
  EXPECT_EQ(imported->handle, info->handle);
  // The first export moved the array out of its owner's shared slab into a slab of its own;
  // the exporter and the importer both see the new place.
  auto moved = e->DescribeArray(*a, info->handle);
  ASSERT_TRUE(moved.ok());
  EXPECT_NE(moved->shm_name, info->shm_name);
  EXPECT_EQ(imported->shm_name, moved->shm_name);
  EXPECT_EQ(imported->shm_offset, moved->shm_offset);
  EXPECT_EQ(e->Stats().arrays, 2u);   // the array and its gradient

  // The exporter frees: the importer still reads the data.
  ASSERT_TRUE(e->FreeArray(*a, info->handle).ok());
  EXPECT_EQ(e->FreeArray(*a, info->handle).code(), StatusCode::kNotFound);   // double free
  EXPECT_EQ(ReadFloats(*e, *b, info->handle), (std::vector<float>{1, 2, 3, 4}));
  EXPECT_TRUE(ShmExists(moved->shm_name));
  // The importer's session closes: everything is gone, slab unlinked.
  ASSERT_TRUE(e->CloseSession(b->id(), /*reaped=*/true).ok());
  EXPECT_EQ(e->Stats().arrays, 0u);
  EXPECT_EQ(e->Stats().cpu_slabs, 0u);
  EXPECT_EQ(e->Stats().sessions_reaped_total, 1u);
  EXPECT_FALSE(ShmExists(info->shm_name));
  EXPECT_FALSE(ShmExists(moved->shm_name));
  // The token is dead now.
  EXPECT_EQ(e->ImportArray(*a, *token).status().code(), StatusCode::kNotFound);
}

TEST(ArraySharing, TokensNeedTheSecretAndTheSameCredentials) {
  auto e = MakeEngine();
  auto a = e->OpenSession(Local("a"));
  SessionOptions remote;
  remote.principal = "tcp-token";
  auto r = e->OpenSession(remote);
  auto info = e->CreateArray(*a, FromFloats({5}));
  auto token = e->ExportArray(*a, info->handle);
  ASSERT_TRUE(token.ok());
  std::string forged = *token;
  forged.back() = forged.back() == '0' ? '1' : '0';
  EXPECT_EQ(e->ImportArray(*a, forged).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(e->ImportArray(*a, "garbage").status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(e->ImportArray(*r, *token).status().code(), StatusCode::kPermissionDenied);
  // Handles of other sessions are invisible without a token.
  EXPECT_EQ(e->DescribeArray(*r, info->handle).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(e->FreeArray(*r, info->handle).code(), StatusCode::kNotFound);
  // Remote sessions never see shared-memory names.
  auto rinfo = e->CreateArray(*r, FromFloats({1, 2}));
  ASSERT_TRUE(rinfo.ok());
  EXPECT_TRUE(rinfo->shm_name.empty());
}

TEST(ArraySharing, ReadWriteRangesAreChecked) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto info = e->CreateArray(*s, FromFloats({0, 0, 0, 0}));
  float v[2] = {7, 8};
  EXPECT_EQ(e->WriteArray(*s, info->handle, 12, v, 8).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(e->WriteArray(*s, info->handle, 1ull << 63, v, 8).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(e->WriteArray(*s, 999, 0, v, 8).code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadFloats(*e, *s, info->handle), (std::vector<float>{0, 0, 0, 0}));   // nothing changed
  ASSERT_TRUE(e->WriteArray(*s, info->handle, 8, v, 8).ok());
  EXPECT_EQ(ReadFloats(*e, *s, info->handle), (std::vector<float>{0, 0, 7, 8}));
  // Chunked reads cover the range exactly once, in order.
  std::vector<uint64_t> offsets;
  ASSERT_TRUE(e->ReadArray(*s, info->handle, 4, 0, 5, [&](uint64_t off, const char*, size_t n) {
                 offsets.push_back(off);
                 EXPECT_LE(n, 5u);
                 return true;
               }).ok());
  EXPECT_EQ(offsets, (std::vector<uint64_t>{4, 9, 14}));
  EXPECT_EQ(e->ReadArray(*s, info->handle, 8, 9, 0, [](uint64_t, const char*, size_t) { return true; }).code(),
            StatusCode::kOutOfRange);
}

TEST(ArraySharing, FreedHandleStaysValidForQueuedCommands) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto src = e->CreateArray(*s, FromFloats({1, 2, 3}));
  auto dst = e->CreateArray(*s, FromFloats({0, 0, 0}));
  Command c;
  c.kind = CopyCommand{ArrayRef{dst->handle, 0, {}, {}}, ArrayRef{src->handle, 0, {}, {}}};
  ASSERT_TRUE(e->Submit(*s, {c}).ok());
  ASSERT_TRUE(e->FreeArray(*s, src->handle).ok());   // may run before the copy executes
  auto r = e->Synchronize(*s);
  EXPECT_TRUE(r.error.ok()) << r.error.ToString();
  EXPECT_EQ(ReadFloats(*e, *s, dst->handle), (std::vector<float>{1, 2, 3}));
}

TEST(ArraySharing, FirstErrorIsReportedAtSyncAndLaterCommandsSkipped) {
  auto e = MakeEngine();
  auto s = e->OpenSession(Local());
  auto a = e->CreateArray(*s, FromFloats({1, 2, 3}));
  Command bad;
  bad.kind = FillCommand{ArrayRef{a->handle, 0, {4}, {}}, std::string(4, '\0')};
  bad.origin = {"prog.py", 42, 0};
  Command good;
  float nine = 9;
  good.kind = FillCommand{ArrayRef{a->handle, 0, {}, {}}, std::string(reinterpret_cast<char*>(&nine), 4)};
  Command unknown;
  unknown.kind = FillCommand{ArrayRef{12345, 0, {}, {}}, std::string(4, '\0')};
  ASSERT_TRUE(e->Submit(*s, {bad, good}).ok());
  auto r = e->Synchronize(*s);
  EXPECT_EQ(r.error.code(), StatusCode::kOutOfRange);
  EXPECT_EQ(r.origin.file, "prog.py");
  EXPECT_EQ(r.origin.line, 42u);
  EXPECT_NE(r.error.message().find("skipped"), std::string::npos);
  EXPECT_EQ(ReadFloats(*e, *s, a->handle), (std::vector<float>{1, 2, 3}));
  // The error was consumed: the next batch runs.
  ASSERT_TRUE(e->Submit(*s, {good}).ok());
  EXPECT_TRUE(e->Synchronize(*s).error.ok());
  EXPECT_EQ(ReadFloats(*e, *s, a->handle), (std::vector<float>{9, 9, 9}));
  ASSERT_TRUE(e->Submit(*s, {unknown}).ok());
  auto u = e->Synchronize(*s);
  EXPECT_EQ(u.error.code(), StatusCode::kNotFound);
  EXPECT_NE(u.error.message().find("12345"), std::string::npos);
}

}  // namespace
}  // namespace weft
