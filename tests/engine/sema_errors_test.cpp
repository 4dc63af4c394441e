// Must-fail tests: every user error of semantic analysis is one Diagnostic at the user's
// file:line:col with a clear message (and the source line), never an abort.
#include <gtest/gtest.h>

#include <string>

#include "engine/codegen/generate_module.h"

namespace weft {
namespace {

struct Outcome {
  bool ok = false;
  std::vector<Diagnostic> diags;
};

Outcome Compile(const std::string& body, std::vector<std::string> types = {"array(float32,1)", "float32"},
                std::vector<std::string> names = {"a", "x"}, std::vector<FunctionSource> extra = {},
                std::vector<Symbol> syms = {}) {
  ModuleSource m;
  Symbol wp;
  wp.name = "wp";
  wp.kind = Symbol::Kind::kBuiltinModule;
  m.symbols.push_back(wp);
  for (auto& s : syms) m.symbols.push_back(s);
  FunctionSource f;
  f.name = "k";
  f.key = "m.k";
  f.file = "user.py";
  f.first_line = 10;
  f.is_kernel = true;
  f.param_types = types;
  f.param_names = names;
  std::string params;
  for (size_t i = 0; i < names.size(); ++i) params += (i ? ", " : "") + names[i];
  f.source = "def k(" + params + "):\n" + body;
  m.functions.push_back(f);
  for (auto& e : extra) m.functions.push_back(e);
  m.structs.push_back({"m.S", {{"pos", "vec(3,float32)"}}});
  Outcome o;
  auto gm = GenerateModule(m, {}, &o.diags);
  o.ok = gm.ok();
  if (!o.ok) {
    EXPECT_EQ(gm.status().code(), StatusCode::kInvalidArgument);
  }
  return o;
}

void ExpectError(const Outcome& o, uint32_t line, const std::string& fragment) {
  ASSERT_FALSE(o.ok);
  ASSERT_EQ(o.diags.size(), 1u);
  const Diagnostic& d = o.diags[0];
  EXPECT_EQ(d.location.file, "user.py");
  EXPECT_EQ(d.location.line, line) << d.ToString();
  EXPECT_NE(d.message.find(fragment), std::string::npos) << d.ToString();
  EXPECT_FALSE(d.source_line.empty()) << d.ToString();
}

TEST(SemaErrors, UnknownName) {
  ExpectError(Compile("    i = wp.tid()\n    y = foo + 1.0\n"), 12, "unknown name 'foo'");
}

TEST(SemaErrors, MixingFloat64AndFloat32IsAnError) {
  auto o = Compile("    d = wp.float64(2.0)\n    y = d * x\n");
  ExpectError(o, 12, "Couldn't find function overload for 'mul' that accepts (float64, float32)");
}

TEST(SemaErrors, LiteralsAdaptButVariablesDoNot) {
  EXPECT_TRUE(Compile("    d = wp.float64(2.0)\n    y = d * 3.0 + 1\n    z = wp.sin(d) * 2\n").ok);
  ExpectError(Compile("    n = 3\n    y = x * n\n"), 12, "Couldn't find function overload for 'mul' that accepts (float32, int32)");
}

TEST(SemaErrors, WrongArgumentCount) {
  ExpectError(Compile("    y = wp.sin(x, x)\n"), 11, "Couldn't find function overload for 'sin' that accepts (float32, float32)");
}

// Slices are views in expressions (y = a[1:2]); as assignment targets they are refused.
TEST(SemaErrors, SliceTargetsUnsupported) { ExpectError(Compile("    a[1:2] = 1.0\n"), 11, "slices are not supported"); }

TEST(SemaErrors, ArrayIndexCount) {
  ExpectError(Compile("    y = a[0, 1]\n"), 11, "has 1 dimensions but 2 indices");
}

TEST(SemaErrors, ArrayStoreType) {
  ExpectError(Compile("    a[0] = wp.vec3(1.0)\n"), 11, "expected float32");
}

TEST(SemaErrors, VariableKeepsItsType) {
  // straight-line code may bind a name again to another type (as Warp); a branch may not
  ExpectError(Compile("    y = 1.0\n    if x > 0.0:\n        y = 2\n"), 13,
              "'y' has type float32; cannot assign a value of type int32 inside a branch or loop");
}

TEST(SemaErrors, BranchesDisagreeOnType) {
  ExpectError(Compile("    if x > 0.0:\n        y = 1.0\n    else:\n        y = 1\n    a[0] = y\n"), 11,
              "'y' has type float32 in one branch and int32 in the other");
}

TEST(SemaErrors, ForOverNonRange) {
  ExpectError(Compile("    for v in a:\n        pass\n"), 11, "for loops iterate over range(...), reversed(range(...)) or a geometry query");
}

TEST(SemaErrors, RangeNeedsIntegers) {
  ExpectError(Compile("    for i in range(x):\n        pass\n"), 11, "range() arguments must be integers");
}

TEST(SemaErrors, UnknownStructField) {
  Symbol s;
  s.name = "S";
  s.kind = Symbol::Kind::kType;
  s.target = "struct(m.S)";
  ExpectError(Compile("    s = S()\n    y = s.mass\n", {"array(float32,1)", "float32"}, {"a", "x"}, {}, {s}), 12,
              "struct m.S has no field 'mass'");
}

TEST(SemaErrors, UnknownBuiltin) {
  ExpectError(Compile("    y = wp.frobnicate(x)\n"), 11, "'wp.frobnicate' is not a supported builtin");
}

TEST(SemaErrors, ConditionMustBeBoolOrInt) {
  ExpectError(Compile("    if x:\n        a[0] = 1.0\n"), 11, "a condition must be bool, an integer or an array, got float32");
}

TEST(SemaErrors, KernelsReturnNothing) { ExpectError(Compile("    return x\n"), 11, "kernels cannot return a value"); }

TEST(SemaErrors, ComparingDifferentTypes) {
  ExpectError(Compile("    d = wp.float64(1.0)\n    if d < x:\n        pass\n"), 12, "cannot compare float64 < float32");
}

TEST(SemaErrors, VectorComponentOutOfRange) {
  ExpectError(Compile("    v = wp.vec2(1.0, 2.0)\n    y = v.z\n"), 12, "`z` is not an attribute of 'v' (vec(2,float32))");
}

TEST(SemaErrors, ConstructorComponentCount) {
  ExpectError(Compile("    v = wp.vec3(1.0, 2.0)\n"), 11,
              "incompatible number of values given (2) when constructing a vector of length 3");
}

TEST(SemaErrors, UnpackCountMismatch) {
  ExpectError(Compile("    p, q = x, x, x\n"), 11, "cannot unpack 3 values into 2 targets");
}

TEST(SemaErrors, TidInFuncIsTheCallingThreadsIndex) {
  FunctionSource f;
  f.name = "g";
  f.key = "m.g";
  f.file = "user.py";
  f.first_line = 3;
  f.param_types = {"float32"};
  f.param_names = {"v"};
  f.source = "def g(v: float):\n    return v + float(wp.tid())\n";
  Symbol s;
  s.name = "g";
  s.kind = Symbol::Kind::kFunction;
  s.target = "m.g";
  auto o = Compile("    y = g(x)\n", {"array(float32,1)", "float32"}, {"a", "x"}, {f}, {s});
  // Warp allows wp.tid() in @wp.func: codegen passes the thread index to every func.
  EXPECT_TRUE(o.ok) << (o.diags.empty() ? "" : o.diags[0].message);
}

TEST(SemaErrors, UserFuncOverloadMismatchListsCandidates) {
  FunctionSource f;
  f.name = "g";
  f.key = "m.g";
  f.file = "user.py";
  f.first_line = 3;
  f.param_types = {"vec(3,float32)"};
  f.param_names = {"v"};
  f.source = "def g(v: wp.vec3):\n    return v\n";
  Symbol s;
  s.name = "g";
  s.kind = Symbol::Kind::kFunction;
  s.target = "m.g";
  ExpectError(Compile("    y = g(x)\n", {"array(float32,1)", "float32"}, {"a", "x"}, {f}, {s}), 11,
              "no overload of function 'g' accepts (float32); candidates:\n      g(vec(3,float32))");
}

TEST(SemaErrors, BreakOutsideLoop) {
  auto o = Compile("    break\n");
  ASSERT_FALSE(o.ok);
  ASSERT_EQ(o.diags.size(), 1u);
  EXPECT_EQ(o.diags[0].location.line, 11u);
}

TEST(SemaErrors, OneDiagnosticPerBrokenKernel) {
  FunctionSource f;
  f.name = "k2";
  f.key = "m.k2";
  f.file = "user.py";
  f.first_line = 30;
  f.is_kernel = true;
  f.param_types = {"float32"};
  f.param_names = {"x"};
  f.source = "def k2(x: float):\n    y = bar\n";
  auto o = Compile("    y = foo\n", {"array(float32,1)", "float32"}, {"a", "x"}, {f});
  ASSERT_FALSE(o.ok);
  ASSERT_EQ(o.diags.size(), 2u);
  EXPECT_EQ(o.diags[0].location.line, 11u);
  EXPECT_EQ(o.diags[1].location.line, 31u);
}

TEST(SemaErrors, KernelParameterTypeMustParse) {
  auto o = Compile("    pass\n", {"array(float32,7)", "float32"});
  ASSERT_FALSE(o.ok);
  ASSERT_EQ(o.diags.size(), 1u);
  EXPECT_NE(o.diags[0].message.find("arrays have 1 to 4 dimensions"), std::string::npos) << o.diags[0].message;
}

}  // namespace
}  // namespace weft
