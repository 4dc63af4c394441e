// The builtin registry: overload resolution by type patterns (scalar classes, sizes, type
// variables, literal adaptation), candidate lists in errors, registry invariants, and
// docs/builtins.md generated from it (WEFT_WRITE_DOCS=1 rewrites the file).
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <set>

#include "engine/sema/builtins.h"

namespace weft::sema {
namespace {

Type T(const char* s) { return *ParseType(s); }

std::string Resolve(const std::string& name, std::vector<Type> args, std::vector<int> lits = {}) {
  auto m = BuiltinRegistry::Get().Resolve(name, args, lits.empty() ? nullptr : &lits);
  if (!m.ok()) return "error: " + m.status().message();
  std::string s = TypeString(m->result) + " <-";
  for (const auto& p : m->param_types) s += " " + TypeString(p);
  return s;
}

TEST(SemaBuiltins, ScalarClassesBindOneType) {
  EXPECT_EQ(Resolve("sin", {T("float64")}), "float64 <- float64");
  EXPECT_EQ(Resolve("atan2", {T("float32"), T("float32")}), "float32 <- float32 float32");
  EXPECT_EQ(Resolve("atan2", {T("float32"), T("float64")}).substr(0, 6), "error:");
  EXPECT_EQ(Resolve("sin", {T("int32")}).substr(0, 6), "error:");
  EXPECT_EQ(Resolve("add", {T("int64"), T("int64")}), "int64 <- int64 int64");
  EXPECT_EQ(Resolve("bit_and", {T("float32"), T("float32")}).substr(0, 6), "error:");
}

TEST(SemaBuiltins, ShapesAndSizes) {
  EXPECT_EQ(Resolve("mul", {T("mat(2,3,float32)"), T("vec(3,float32)")}), "vec(2,float32) <- mat(2,3,float32) vec(3,float32)");
  EXPECT_EQ(Resolve("mul", {T("mat(2,3,float32)"), T("vec(2,float32)")}).substr(0, 6), "error:");
  EXPECT_EQ(Resolve("mul", {T("mat(2,3,float64)"), T("mat(3,4,float64)")}), "mat(2,4,float64) <- mat(2,3,float64) mat(3,4,float64)");
  EXPECT_EQ(Resolve("outer", {T("vec(2,float32)"), T("vec(5,float32)")}), "mat(2,5,float32) <- vec(2,float32) vec(5,float32)");
  EXPECT_EQ(Resolve("transpose", {T("mat(2,5,float32)")}), "mat(5,2,float32) <- mat(2,5,float32)");
  EXPECT_EQ(Resolve("cross", {T("vec(4,float32)"), T("vec(4,float32)")}).substr(0, 6), "error:");
  EXPECT_EQ(Resolve("inverse", {T("mat(3,3,float32)")}), "mat(3,3,float32) <- mat(3,3,float32)");
  EXPECT_EQ(Resolve("inverse", {T("mat(5,5,float32)")}).substr(0, 6), "error:");
  EXPECT_EQ(Resolve("svd3", {T("mat(3,3,float32)")}),
            "tuple(mat(3,3,float32),vec(3,float32),mat(3,3,float32)) <- mat(3,3,float32)");
}

TEST(SemaBuiltins, TypeVariablesAndArrays) {
  EXPECT_EQ(Resolve("atomic_add", {T("array(vec(3,float32),2)"), T("int32"), T("int64"), T("vec(3,float32)")}),
            "vec(3,float32) <- array(vec(3,float32),2) int32 int64 vec(3,float32)");
  EXPECT_EQ(Resolve("atomic_add", {T("array(float32,1)"), T("int32"), T("float64")}).substr(0, 6), "error:");
  EXPECT_EQ(Resolve("where", {T("bool"), T("quat(float32)"), T("quat(float32)")}), "quat(float32) <- bool quat(float32) quat(float32)");
  EXPECT_EQ(Resolve("where", {T("int32"), T("float32"), T("float32")}), "float32 <- int32 float32 float32");
}

TEST(SemaBuiltins, LiteralsAdaptToTheBoundType) {
  // x * 2 with x float64: the int literal becomes float64
  EXPECT_EQ(Resolve("mul", {T("float64"), T("int32")}, {0, 1}), "float64 <- float64 float64");
  // 2.0 * v (vec3d): the float literal becomes float64
  EXPECT_EQ(Resolve("mul", {T("float32"), T("vec(3,float64)")}, {2, 0}), "vec(3,float64) <- float64 vec(3,float64)");
  // a float literal never becomes an integer
  EXPECT_EQ(Resolve("add", {T("int32"), T("float32")}, {0, 2}).substr(0, 6), "error:");
  // atomic_add(float64 array, 0, 1): the index stays int32, the value becomes float64
  EXPECT_EQ(Resolve("atomic_add", {T("array(float64,1)"), T("int32"), T("int32")}, {0, 1, 1}),
            "float64 <- array(float64,1) int32 float64");
  // wp.sin(1): unbound Float takes float32
  EXPECT_EQ(Resolve("sin", {T("int32")}, {1}), "float32 <- float32");
}

TEST(SemaBuiltins, ErrorListsCandidates) {
  std::string e = Resolve("dot", {T("vec(3,float32)"), T("vec(2,float32)")});
  EXPECT_NE(e.find("Couldn't find function overload for 'dot' that accepts (vec(3,float32), vec(2,float32)); candidates:"), std::string::npos) << e;
  EXPECT_NE(e.find("dot(a: vec(N,Scalar), b: vec(N,Scalar)) -> Scalar"), std::string::npos) << e;
  EXPECT_NE(Resolve("nosuchbuiltin", {}).find("unknown builtin"), std::string::npos);
}

TEST(SemaBuiltins, RegistryInvariants) {
  const auto& rows = BuiltinRegistry::Get().rows();
  EXPECT_GT(rows.size(), 200u);
  std::set<std::string> names;
  for (const auto& r : rows) {
    names.insert(r.name);
    EXPECT_FALSE(r.doc.empty()) << r.signature;
    EXPECT_EQ(r.param_names.size(), r.param_patterns.size()) << r.signature;
    EXPECT_EQ(r.differentiable(), !r.adjoint.empty()) << r.signature;
    if (r.side_effect()) {   // writes with adjoints: atomics and the tile stores (their adjoints read the gradient)
      EXPECT_TRUE(r.name.rfind("atomic_", 0) == 0 || r.name.rfind("tile_store", 0) == 0 ||
                  r.name.rfind("tile_atomic_add", 0) == 0 || !r.differentiable())
          << r.signature;
    }
  }
  for (const char* must : {"sin", "cos", "sqrt", "exp", "log", "pow", "atan2", "abs", "sign", "min", "max", "clamp",
                           "dot", "cross", "length", "normalize", "outer", "transpose", "inverse", "determinant",
                           "diag", "quat_rotate", "quat_from_axis_angle", "transform_point", "atomic_add", "atomic_sub",
                           "atomic_min", "atomic_max", "atomic_cas", "atomic_exch", "where", "select", "rand_init",
                           "randi", "randf", "randn", "sample_unit_sphere", "print", "expect_eq", "spatial_cross"})
    EXPECT_TRUE(names.count(must)) << must;
}

TEST(SemaBuiltinsDoc, MarkdownIsGeneratedAndCommitted) {
  std::string md = BuiltinRegistry::Get().Markdown();
  EXPECT_NE(md.find("| `sin(x: Float) -> Float` | `wp::adj_sin` |"), std::string::npos);
  EXPECT_NE(md.find("| `argmin(a: vec(N,Scalar)) -> uint32` | - |"), std::string::npos);
  std::string path = std::string(WEFT_NATIVE_DIR) + "/../../docs/builtins.md";
  const char* write = std::getenv("WEFT_WRITE_DOCS");
  if (write && *write == '1') std::ofstream(path) << md;
  std::ifstream in(path);
  std::string committed((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(committed, md) << "docs/builtins.md is stale: run WEFT_WRITE_DOCS=1 weft_engine_tests --gtest_filter=SemaBuiltinsDoc*";
}

}  // namespace
}  // namespace weft::sema
