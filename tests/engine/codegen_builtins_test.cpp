// Every row of the builtin registry, instantiated with concrete types (float32 and float64,
// integers where the builtin needs them), is called from a generated kernel with the
// backward pass enabled; the module must compile with clang against engine/native, so every
// registry row has its native function and (when differentiable) its adjoint.
#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <regex>
#include <set>
#include <string>

#include "engine/codegen/generate_module.h"
#include "engine/sema/builtins.h"

namespace weft {
namespace {

std::string Concrete(const std::string& pattern, const std::string& fl, bool int_only) {
  std::string s = pattern;
  const std::string scalar = int_only ? "int32" : fl;
  s = std::regex_replace(s, std::regex("\\bFloat\\b"), fl);
  s = std::regex_replace(s, std::regex("\\bScalar\\b"), scalar);
  s = std::regex_replace(s, std::regex("\\bX\\b"), scalar);
  s = std::regex_replace(s, std::regex("\\bInt\\b"), "int32");
  s = std::regex_replace(s, std::regex("\\bIndex\\b"), "int32");
  s = std::regex_replace(s, std::regex("\\bCond\\b"), "bool");
  s = std::regex_replace(s, std::regex("\\b[NMK]\\b"), "3");
  return s;
}

std::string BuildModuleSource(const std::string& fl, ModuleSource* m, int* count) {
  static const std::set<std::string> kIntOnly = {"bit_and", "bit_or",     "bit_xor",    "lshift", "rshift",
                                                 "invert",  "atomic_and", "atomic_or",  "atomic_xor"};
  Symbol wp;
  wp.name = "wp";
  wp.kind = Symbol::Kind::kBuiltinModule;
  m->symbols.push_back(wp);
  int k = 0;
  for (const auto& row : sema::BuiltinRegistry::Get().rows()) {
    bool skip = false;
    // printf formats; geometry query structs, tiles and the struct arithmetic of struct tiles
    // (locals only: they cannot be kernel parameters; test_geometry_objects.py and
    // test_lang_tiles.py run those rows, the latter on the CPU and through NVRTC)
    for (const auto& p : row.param_patterns)
      skip |= p == "str" || p == "S" || p.rfind("struct(", 0) == 0 || p.find("tile(") != std::string::npos ||
              p.find("tile_stack(") != std::string::npos;
    if (skip) continue;
    bool int_only = kIntOnly.count(row.name) != 0;
    if (int_only && fl == "float64") continue;
    FunctionSource f;
    f.name = "k" + std::to_string(k++);
    f.file = "builtins.py";
    f.first_line = 1;
    f.is_kernel = true;
    f.key = f.name;
    std::string src = "def " + f.name + "(";
    std::string call = "    wp." + row.name + "(";
    for (size_t i = 0; i < row.param_patterns.size(); ++i) {
      std::string t = Concrete(row.param_patterns[i], fl, int_only);
      f.param_types.push_back(t);
      f.param_names.push_back("a" + std::to_string(i));
      src += (i ? ", " : "") + std::string("a") + std::to_string(i);
      call += (i ? ", " : "") + std::string("a") + std::to_string(i);
    }
    f.source = src + "):\n" + call + ")\n";
    m->functions.push_back(f);
  }
  *count = k;
  return "";
}

void CompileAll(const std::string& fl) {
  ModuleSource m;
  int count = 0;
  BuildModuleSource(fl, &m, &count);
  ASSERT_GT(count, 150);
  CodegenOptions o;
  o.enable_backward = true;
  std::vector<Diagnostic> diags;
  auto gm = GenerateModule(m, o, &diags);
  std::string all;
  for (const auto& d : diags) all += d.ToString() + "\n";
  ASSERT_TRUE(gm.ok()) << gm.status().message() << "\n" << all;
  std::string base = ::testing::TempDir() + "/weft_builtins_" + fl + "_" + std::to_string(::getpid());
  std::ofstream(base + ".cpp") << gm->source;
  std::string cmd = "clang++-19 -std=c++17 -fsyntax-only -ferror-limit=50 -I" WEFT_NATIVE_DIR " " + base + ".cpp > " +
                    base + ".log 2>&1";
  int rc = std::system(cmd.c_str());
  std::ifstream in(base + ".log");
  std::string log((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(rc, 0) << base << ".cpp\n" << log.substr(0, 20000);
}

TEST(CodegenBuiltins, EveryRegistryRowCompilesFloat32) { CompileAll("float32"); }
TEST(CodegenBuiltins, EveryRegistryRowCompilesFloat64) { CompileAll("float64"); }

}  // namespace
}  // namespace weft
