// The compile fuzzer's committed corpus (tests/fuzz/corpus/compile) replayed in the normal build:
// every seed compiles to well-formed C++ (tests/fuzz/generated_cpp_check.h) or fails with a user
// error, never an internal one. Catches a codegen change that the fuzz checks would reject
// without needing the libFuzzer build.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "engine/codegen/generate_module.h"
#include "tests/fuzz/generated_cpp_check.h"
#include "tests/fuzz/module_text.h"

namespace weft::fuzz {
namespace {

namespace fs = std::filesystem;

TEST(FuzzCorpusReplay, CompileSeedsGiveWellFormedCodeOrUserErrors) {
  const fs::path dir = fs::path(WEFT_NATIVE_DIR) / ".." / ".." / "tests" / "fuzz" / "corpus" / "compile";
  ASSERT_TRUE(fs::is_directory(dir)) << dir;
  int seeds = 0, generated = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    FuzzModule fm = ParseModuleText(text.str());
    std::vector<Diagnostic> diags;
    auto out = GenerateModule(fm.module, fm.options, &diags);
    ++seeds;
    if (out.ok()) {
      ++generated;
      EXPECT_EQ(CheckGeneratedModule(*out), "") << entry.path();
    } else {
      EXPECT_TRUE(out.status().code() == StatusCode::kInvalidArgument ||
                  out.status().code() == StatusCode::kResourceExhausted)
          << entry.path() << ": " << out.status().ToString();
    }
  }
  EXPECT_GT(seeds, 50);
  EXPECT_GT(generated, seeds / 2);
}

}  // namespace
}  // namespace weft::fuzz
