// Module cache keys, artifact serialization and the verified disk files: keys change with every
// input that decides the code and with nothing else; a corrupted, truncated or foreign file is
// detected and removed, never loaded.
#include "engine/runtime/module_cache.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <chrono>

namespace weft {
namespace {

namespace fs = std::filesystem;

ModuleSource SampleSource() {
  ModuleSource m;
  m.name = "tests.sample";
  FunctionSource k;
  k.name = "saxpy";
  k.key = "saxpy";
  k.file = "sample.py";
  k.first_line = 10;
  k.is_kernel = true;
  k.param_types = {"float32", "array(float32,1)", "array(float32,1)"};
  k.param_names = {"a", "x", "y"};
  k.source = "def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):\n"
             "    i = wp.tid()\n    y[i] = a * x[i] + y[i]\n";
  m.functions.push_back(k);
  Symbol wp_module;
  wp_module.name = "wp";
  wp_module.kind = Symbol::Kind::kBuiltinModule;
  wp_module.target = "warp";
  Symbol n;
  n.name = "N";
  n.kind = Symbol::Kind::kConstant;
  n.constant = {"int32", "4"};
  m.symbols = {wp_module, n};
  m.options["bounds_checks"] = "true";
  return m;
}

ModuleArtifact SampleArtifact(std::mt19937& rng) {
  ModuleArtifact a;
  a.object.resize(1000 + rng() % 5000);
  for (char& c : a.object) c = char(rng());
  KernelLayout k;
  k.name = "saxpy";
  k.forward_symbol = "weft_saxpy_cpu_forward";
  k.args_size = 184;
  k.args_align = 8;
  ParamLayout a_param{"a", "float32", 0, 4, 4, false, "", 0, {}, 0};
  ParamLayout x_param{"x", "array(float32,1)", 8, 88, 8, true, "float32", 1, {}, 4};
  ParamLayout s_param{"s", "struct(m.S)", 96, 88, 8, false, "", 0,
                      {ParamLayout{"f", "vec(3,float32)", 0, 12, 4, false, "", 0, {}, 0}}, 0};
  k.params = {a_param, x_param, s_param};
  a.kernels = {k, k};
  a.kernels[1].name = "other";
  a.kernels[1].backward_symbol = "weft_other_cpu_backward";
  a.kernels[0].adjoint_refused = "k.py:3:5: error: no adjoint here";
  a.kernels[1].tid_indexed_params = {1};
  a.kernels[1].coarse_symbol = "weft_other_cuda_forward_x4";
  a.kernels[1].coarse_loaded_bytes = 8;
  a.function_names = {"sample.py:saxpy", "sample.py:other"};
  a.generated_source = "// generated\n#include \"weft.h\"\n";
  return a;
}

void ExpectSameParams(const std::vector<ParamLayout>& a, const std::vector<ParamLayout>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].name, b[i].name);
    EXPECT_EQ(a[i].type, b[i].type);
    EXPECT_EQ(a[i].offset, b[i].offset);
    EXPECT_EQ(a[i].size, b[i].size);
    EXPECT_EQ(a[i].align, b[i].align);
    EXPECT_EQ(a[i].is_array, b[i].is_array);
    EXPECT_EQ(a[i].array_dtype, b[i].array_dtype);
    EXPECT_EQ(a[i].array_ndim, b[i].array_ndim);
    EXPECT_EQ(a[i].array_elem_size, b[i].array_elem_size);
    ExpectSameParams(a[i].fields, b[i].fields);
  }
}

void ExpectSameArtifact(const ModuleArtifact& a, const ModuleArtifact& b) {
  EXPECT_EQ(a.object, b.object);
  EXPECT_EQ(a.function_names, b.function_names);
  EXPECT_EQ(a.generated_source, b.generated_source);
  ASSERT_EQ(a.kernels.size(), b.kernels.size());
  for (size_t i = 0; i < a.kernels.size(); ++i) {
    EXPECT_EQ(a.kernels[i].name, b.kernels[i].name);
    EXPECT_EQ(a.kernels[i].forward_symbol, b.kernels[i].forward_symbol);
    EXPECT_EQ(a.kernels[i].backward_symbol, b.kernels[i].backward_symbol);
    EXPECT_EQ(a.kernels[i].adjoint_refused, b.kernels[i].adjoint_refused);
    EXPECT_EQ(a.kernels[i].args_size, b.kernels[i].args_size);
    EXPECT_EQ(a.kernels[i].args_align, b.kernels[i].args_align);
    EXPECT_EQ(a.kernels[i].tid_indexed_params, b.kernels[i].tid_indexed_params);
    EXPECT_EQ(a.kernels[i].coarse_symbol, b.kernels[i].coarse_symbol);
    EXPECT_EQ(a.kernels[i].coarse_loaded_bytes, b.kernels[i].coarse_loaded_bytes);
    ExpectSameParams(a.kernels[i].params, b.kernels[i].params);
  }
}

TEST(CacheKey, StableAndSensitiveToEveryInput) {
  ModuleKeyContext context{"native-v1", "triple=x86_64;cpu=znver3", "build-1", false};
  CodegenOptions codegen;
  const ModuleSource base = SampleSource();
  const std::string key = ModuleCacheKey(base, codegen, context);
  EXPECT_EQ(key.size(), 64u);
  EXPECT_EQ(key, ModuleCacheKey(SampleSource(), codegen, context));

  // Symbol order does not matter.
  ModuleSource reordered = base;
  std::swap(reordered.symbols[0], reordered.symbols[1]);
  EXPECT_EQ(ModuleCacheKey(reordered, codegen, context), key);

  std::vector<ModuleSource> variants;
  auto vary = [&](auto change) {
    ModuleSource m = base;
    change(m);
    variants.push_back(m);
  };
  vary([](ModuleSource& m) { m.functions[0].source += " "; });
  vary([](ModuleSource& m) { m.functions[0].first_line = 11; });
  vary([](ModuleSource& m) { m.functions[0].file = "other.py"; });
  vary([](ModuleSource& m) { m.functions[0].param_types[0] = "float64"; });
  vary([](ModuleSource& m) { m.functions[0].key = "saxpy_1"; });
  vary([](ModuleSource& m) { m.symbols[1].constant.value = "5"; });
  vary([](ModuleSource& m) { m.options["bounds_checks"] = "false"; });
  vary([](ModuleSource& m) { m.structs.push_back({"m.S", {{"x", "float32"}}}); });
  vary([](ModuleSource& m) { m.name = "tests.other"; });
  // Moving text between fields must not collide (length prefixes).
  vary([](ModuleSource& m) {
    m.functions[0].param_names[0] = "ax";
    m.functions[0].param_names[1] = "";
  });
  for (size_t i = 0; i < variants.size(); ++i)
    EXPECT_NE(ModuleCacheKey(variants[i], codegen, context), key) << "variant " << i;

  CodegenOptions backward = codegen;
  backward.enable_backward = true;
  EXPECT_NE(ModuleCacheKey(base, backward, context), key);
  CodegenOptions unchecked = codegen;
  unchecked.bounds_checks = false;
  EXPECT_NE(ModuleCacheKey(base, unchecked, context), key);
  CodegenOptions cuda = codegen;
  cuda.target = Target::kCuda;
  EXPECT_NE(ModuleCacheKey(base, cuda, context), key);
  for (auto change : {+[](ModuleKeyContext& c) { c.native_version = "native-v2"; },
                      +[](ModuleKeyContext& c) { c.target_id = "sm_90"; },
                      +[](ModuleKeyContext& c) { c.build_id = "build-2"; },
                      +[](ModuleKeyContext& c) { c.verified_for_cuda = true; }}) {
    ModuleKeyContext other = context;
    change(other);
    EXPECT_NE(ModuleCacheKey(base, codegen, other), key);
  }
}

TEST(CacheKey, NativeLibraryVersionFollowsHeaderContents) {
  fs::path dir = fs::temp_directory_path() / ("weft-native-" + std::to_string(::getpid()));
  fs::create_directories(dir / "sub");
  std::ofstream(dir / "a.h") << "int a;";
  std::ofstream(dir / "sub" / "b.h") << "int b;";
  auto v1 = NativeLibraryVersion(dir.string());
  ASSERT_TRUE(v1.ok()) << v1.status().ToString();
  EXPECT_EQ(*v1, *NativeLibraryVersion(dir.string()));
  std::ofstream(dir / "sub" / "b.h") << "int b2;";
  auto v2 = NativeLibraryVersion(dir.string());
  ASSERT_TRUE(v2.ok());
  EXPECT_NE(*v1, *v2);
  EXPECT_FALSE(NativeLibraryVersion((dir / "missing").string()).ok());
  fs::remove_all(dir);
  // The real library hashes too.
  EXPECT_TRUE(NativeLibraryVersion(WEFT_NATIVE_DIR).ok());
}

TEST(CacheArtifact, RoundTrips) {
  std::mt19937 rng(std::random_device{}());
  ModuleArtifact a = SampleArtifact(rng);
  auto back = DeserializeArtifact(SerializeArtifact(a));
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ExpectSameArtifact(a, *back);
}

TEST(CacheArtifact, RejectsEveryTruncation) {
  std::mt19937 rng(std::random_device{}());
  std::string payload = SerializeArtifact(SampleArtifact(rng));
  for (size_t n = 0; n < payload.size(); n += 1 + payload.size() / 300) {
    EXPECT_FALSE(DeserializeArtifact(std::string_view(payload).substr(0, n)).ok()) << n;
  }
}

class CacheDisk : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("weft-disk-cache-" + std::to_string(::getpid()) + "-" +
                                         ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
  std::mt19937 rng_{std::random_device{}()};
};

TEST_F(CacheDisk, StoresAndLoads) {
  DiskModuleCache disk(dir_.string());
  ASSERT_TRUE(disk.Init().ok());
  const std::string key(64, 'a');
  EXPECT_EQ(disk.Load(key).status().code(), StatusCode::kNotFound);
  ModuleArtifact a = SampleArtifact(rng_);
  ASSERT_TRUE(disk.Store(key, a).ok());
  auto back = disk.Load(key);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ExpectSameArtifact(a, *back);
  // The generated source is kept next to it; no temporary files are left behind.
  EXPECT_TRUE(fs::exists(dir_ / (key + ".cpp")));
  for (const auto& entry : fs::directory_iterator(dir_))
    EXPECT_EQ(entry.path().string().find(".tmp."), std::string::npos) << entry.path();
}

// The directory stays under its bound: storing past it removes the least recently used keys
// (a Load counts as a use), never the key just stored.
TEST_F(CacheDisk, BoundedByBytesWithLeastRecentlyUsedEviction) {
  ModuleArtifact a = SampleArtifact(rng_);
  a.object.assign(10000, 'x');
  a.generated_source.assign(1000, 'y');
  DiskModuleCache probe(dir_.string());
  ASSERT_TRUE(probe.Init().ok());
  ASSERT_TRUE(probe.Store(std::string(64, 'p'), a).ok());
  uint64_t per_key = 0;
  for (const auto& entry : fs::directory_iterator(dir_)) per_key += entry.file_size();
  fs::remove_all(dir_);

  DiskModuleCache disk(dir_.string(), 3 * per_key + per_key / 2);   // room for 3 keys
  ASSERT_TRUE(disk.Init().ok());
  auto key = [](char c) { return std::string(64, c); };
  auto tick = [] { std::this_thread::sleep_for(std::chrono::milliseconds(20)); };   // distinct mtimes
  for (char c : {'a', 'b', 'c'}) {
    ASSERT_TRUE(disk.Store(key(c), a).ok());
    tick();
  }
  ASSERT_TRUE(disk.Load(key('a')).ok());   // 'a' is now the most recently used
  tick();
  ASSERT_TRUE(disk.Store(key('d'), a).ok());   // over the bound: 'b' (least recent) goes
  EXPECT_TRUE(disk.Load(key('a')).ok());
  EXPECT_EQ(disk.Load(key('b')).status().code(), StatusCode::kNotFound);
  EXPECT_FALSE(fs::exists(dir_ / (key('b') + ".cpp")));
  EXPECT_TRUE(disk.Load(key('c')).ok());
  EXPECT_TRUE(disk.Load(key('d')).ok());
  uint64_t total = 0;
  for (const auto& entry : fs::directory_iterator(dir_)) total += entry.file_size();
  EXPECT_LE(total, 3 * per_key + per_key / 2);

  // A bound smaller than one module keeps just the newest.
  DiskModuleCache tiny(dir_.string(), 1);
  ASSERT_TRUE(tiny.Store(key('e'), a).ok());
  EXPECT_TRUE(tiny.Load(key('e')).ok());
  for (char c : {'a', 'c', 'd'}) EXPECT_EQ(tiny.Load(key(c)).status().code(), StatusCode::kNotFound);
}

TEST_F(CacheDisk, CorruptedFileIsDetectedAndRemoved) {
  DiskModuleCache disk(dir_.string());
  const std::string key(64, 'b');
  ASSERT_TRUE(disk.Store(key, SampleArtifact(rng_)).ok());
  const std::string path = disk.PathFor(key);
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  // Flip one random byte of the payload (past the 56-byte header).
  size_t at = 56 + rng_() % (bytes.size() - 56);
  bytes[at] = char(bytes[at] ^ 0x40);
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
  auto loaded = disk.Load(key);
  EXPECT_EQ(loaded.status().code(), StatusCode::kDataLoss) << loaded.status().ToString();
  EXPECT_FALSE(fs::exists(path));
  EXPECT_EQ(disk.Load(key).status().code(), StatusCode::kNotFound);
}

TEST_F(CacheDisk, TruncatedFileIsDetected) {
  DiskModuleCache disk(dir_.string());
  const std::string key(64, 'c');
  ASSERT_TRUE(disk.Store(key, SampleArtifact(rng_)).ok());
  const std::string path = disk.PathFor(key);
  for (int which = 0; which < 5; ++which) {
    ASSERT_TRUE(disk.Store(key, SampleArtifact(rng_)).ok());
    const uintmax_t size = fs::file_size(path);   // this artifact's (sample sizes vary)
    const uintmax_t cuts[] = {0, 10, 56, size / 2, size - 1};
    fs::resize_file(path, cuts[which]);
    EXPECT_EQ(disk.Load(key).status().code(), StatusCode::kDataLoss) << "cut at " << cuts[which] << " of " << size;
  }
}

TEST_F(CacheDisk, ForeignFileIsDetected) {
  DiskModuleCache disk(dir_.string());
  ASSERT_TRUE(disk.Init().ok());
  const std::string key(64, 'd');
  std::ofstream(disk.PathFor(key)) << std::string(200, 'x');
  EXPECT_EQ(disk.Load(key).status().code(), StatusCode::kDataLoss);
}

}  // namespace
}  // namespace weft
