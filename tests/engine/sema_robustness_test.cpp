// Robustness: randomly mutated kernels (characters dropped, duplicated or replaced, names
// swapped) never crash the compiler and never produce an internal error: each either compiles
// or fails with InvalidArgument and at least one diagnostic at a line of the user's file.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "engine/codegen/generate_module.h"

namespace weft {
namespace {

const char* kSource =
    "def k(a: wp.array(dtype=float), v: wp.array(dtype=wp.vec3), s: S, n: int):\n"
    "    i = wp.tid()\n"
    "    p = float(1.0)\n"
    "    for j in range(n):\n"
    "        if j % 2 == 0:\n"
    "            continue\n"
    "        p = p * a[j] + wp.length(v[j])\n"
    "    q = wp.vec3(p, 2.0, 3.0)\n"
    "    q[1] = s.mass\n"
    "    m = wp.outer(q, s.pos)\n"
    "    while p > 1.0:\n"
    "        p = p * 0.5\n"
    "    t = g(q, p)\n"
    "    wp.atomic_add(a, i, m[0, 1] + t)\n";

TEST(SemaRobustness, MutatedKernelsFailCleanly) {
  std::mt19937 rng(1234);
  const std::string base = kSource;
  const std::string alphabet = "abcdefghijklmnopqrstuvwxyz_0123456789()[]:,.+-*/%<>=! \n";
  int compiled = 0, failed = 0;
  for (int trial = 0; trial < 400; ++trial) {
    std::string src = base;
    int edits = 1 + static_cast<int>(rng() % 3);
    for (int e = 0; e < edits; ++e) {
      size_t pos = 30 + rng() % (src.size() - 30);
      switch (rng() % 3) {
        case 0: src.erase(pos, 1); break;
        case 1: src.insert(pos, 1, alphabet[rng() % alphabet.size()]); break;
        default: src[pos] = alphabet[rng() % alphabet.size()]; break;
      }
    }
    ModuleSource m;
    Symbol wp;
    wp.name = "wp";
    wp.kind = Symbol::Kind::kBuiltinModule;
    Symbol st;
    st.name = "S";
    st.kind = Symbol::Kind::kType;
    st.target = "struct(m.S)";
    Symbol g;
    g.name = "g";
    g.kind = Symbol::Kind::kFunction;
    g.target = "m.g";
    m.symbols = {wp, st, g};
    m.structs.push_back({"m.S", {{"pos", "vec(3,float32)"}, {"mass", "float32"}}});
    FunctionSource f;
    f.name = "k";
    f.key = "m.k";
    f.file = "fuzz.py";
    f.first_line = 1;
    f.is_kernel = true;
    f.param_types = {"array(float32,1)", "array(vec(3,float32),1)", "struct(m.S)", "int32"};
    f.param_names = {"a", "v", "s", "n"};
    f.source = src;
    FunctionSource gf;
    gf.name = "g";
    gf.key = "m.g";
    gf.file = "fuzz.py";
    gf.first_line = 40;
    gf.param_types = {"vec(3,float32)", "float32"};
    gf.param_names = {"x", "y"};
    gf.source = "def g(x: wp.vec3, y: float):\n    return wp.dot(x, x) * y\n";
    m.functions = {f, gf};
    std::vector<Diagnostic> diags;
    CodegenOptions o;
    o.enable_backward = trial % 2 == 1;
    auto gm = GenerateModule(m, o, &diags);
    if (gm.ok()) {
      ++compiled;
      continue;
    }
    ++failed;
    EXPECT_EQ(gm.status().code(), StatusCode::kInvalidArgument) << gm.status().message() << "\n--- source:\n" << src;
    ASSERT_FALSE(diags.empty()) << src;
    EXPECT_EQ(diags[0].location.file, "fuzz.py");
    EXPECT_GE(diags[0].location.line, 1u);
  }
  EXPECT_GT(failed, 100);
  EXPECT_GT(compiled, 5);
}

}  // namespace
}  // namespace weft
