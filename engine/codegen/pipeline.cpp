// The compiler pipeline, in order: lang::ParseFunction (each function) -> sema::Check
// (names, types, overloads; lowers to SSA IR) -> verify -> codegen::EmitCpp (forward, and
// adjoint when asked). WEFT_DUMP_IR=1 prints each stage's output and time to stderr.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>

#include "engine/codegen/emit_cpp.h"
#include "engine/codegen/generate_module.h"
#include "engine/lang/ast_printer.h"
#include "engine/lang/parser.h"
#include "engine/sema/check.h"

namespace weft {
namespace {

class StageTimer {
 public:
  explicit StageTimer(bool dump) : dump_(dump), t0_(std::chrono::steady_clock::now()) {}
  void Done(const char* stage, const std::string& text) {
    if (!dump_) return;
    auto t1 = std::chrono::steady_clock::now();
    double ms = std::chrono::duration<double, std::milli>(t1 - t0_).count();
    std::fprintf(stderr, "=== weft: %s (%.3f ms) ===\n%s\n", stage, ms, text.c_str());
    t0_ = t1;
  }

 private:
  bool dump_;
  std::chrono::steady_clock::time_point t0_;
};

// Internal consistency of the IR (an internal error, never a user one).
Status VerifyModule(const sema::Module& m) {
  for (const auto& f : m.functions) {
    for (const auto& v : f.vars)
      if (sema::ContainsAny(v.type)) return Internal("IR verify: " + f.name + " has a generic variable %" + std::to_string(v.id));
  }
  for (int k : m.kernels)
    if (k < 0 || k >= static_cast<int>(m.functions.size()) || !m.functions[k].is_kernel)
      return Internal("IR verify: bad kernel index");
  return Status::Ok();
}

Expected<GeneratedModule> RunPipeline(const ModuleSource& module, const CodegenOptions& options,
                                      std::vector<Diagnostic>* diags) {
  const char* env = std::getenv("WEFT_DUMP_IR");
  StageTimer timer(env && *env && *env != '0');
  std::vector<Diagnostic> local;
  if (!diags) diags = &local;

  std::vector<std::unique_ptr<ast::FunctionDef>> defs;
  std::vector<sema::ParsedFunction> parsed;
  bool parse_failed = false;
  std::string ast_text;
  for (const auto& fn : module.functions) {
    auto def = lang::ParseFunction(fn, diags);
    if (!def.ok()) {
      if (def.status().code() != StatusCode::kInvalidArgument) return def.status();
      parse_failed = true;
      continue;
    }
    ast_text += lang::PrintFunction(**def) + "\n";
    defs.push_back(std::move(*def));
    parsed.push_back({&fn, defs.back().get()});
  }
  timer.Done("parse", ast_text);
  if (parse_failed) return InvalidArgument("the module has syntax errors");

  auto checked = sema::Check(module, parsed, diags);
  if (!checked.ok()) return checked.status();
  timer.Done("check + lower to SSA IR", sema::DumpModule(*checked));

  WEFT_RETURN_IF_ERROR(VerifyModule(*checked));
  auto out = codegen::EmitCpp(*checked, options);
  if (!out.ok()) return out.status();
  timer.Done("emit C++", out->source);
  return out;
}

}  // namespace

Expected<GeneratedModule> GenerateModule(const ModuleSource& module, const CodegenOptions& options,
                                         std::vector<Diagnostic>* diags) {
  // Errors are values; a bug that throws (std::out_of_range, bad_alloc) must not take the
  // daemon down: it becomes an internal error with a bug hint.
  try {
    return RunPipeline(module, options, diags);
  } catch (const std::exception& e) {
    return Internal(std::string("weft compiler bug (please report): ") + e.what());
  }
}

}  // namespace weft
