// libFuzzer target: the compile pipeline. Bytes -> ModuleSource + CodegenOptions (module_text.h)
// -> GenerateModule (lex, parse, sema, codegen to C++ text; no JIT). Every outcome must be a
// value: success with well-formed output (generated_cpp_check.h), or InvalidArgument (a user
// error, with a diagnostic) / ResourceExhausted (an input over a limit). An internal error, a
// crash, a sanitizer report or an ill-formed output aborts.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "engine/codegen/generate_module.h"
#include "tests/fuzz/generated_cpp_check.h"
#include "tests/fuzz/module_text.h"

namespace {

[[noreturn]] void Fail(const char* what, const std::string& detail, const weft::ModuleSource& m) {
  std::fprintf(stderr, "fuzz_compile: %s\n%s\n", what, detail.c_str());
  for (const auto& f : m.functions) std::fprintf(stderr, "--- %s\n%s\n", f.name.c_str(), f.source.c_str());
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size > 64 * 1024) return -1;   // keep executions fast; length limits are tested elsewhere
  auto fm = weft::fuzz::ParseModuleText(std::string_view(reinterpret_cast<const char*>(data), size));
  std::vector<weft::Diagnostic> diags;
  auto out = weft::GenerateModule(fm.module, fm.options, &diags);
  if (out.ok()) {
    std::string err = weft::fuzz::CheckGeneratedModule(*out);
    if (!err.empty()) Fail("ill-formed generated module", err + "\n=== source ===\n" + out->source, fm.module);
    return 0;
  }
  switch (out.status().code()) {
    case weft::StatusCode::kInvalidArgument:
      break;
    case weft::StatusCode::kResourceExhausted:
      return 0;
    default:
      Fail("compile failed with a non-user error", out.status().ToString(), fm.module);
  }
  return 0;
}
