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

// Internal consistency of the IR. A violation is a weft bug; it is still reported at the
// function it concerns (a Diagnostic with the user's file:line), never without a location.
Status VerifyModule(const sema::Module& m, std::vector<Diagnostic>* diags) {
  auto fail = [&](const sema::Function& f, const std::string& what) {
    Diagnostic d;
    d.location = {f.file, static_cast<uint32_t>(f.def_line), 1};
    d.message = "weft cannot compile '" + f.name + "' (internal compiler error: " + what + "; please report it)";
    diags->push_back(d);
    return InvalidArgument(d.ToString());
  };
  for (const auto& f : m.functions) {
    for (const auto& v : f.vars)
      if (sema::ContainsAny(v.type)) return fail(f, "IR verify: generic variable %" + std::to_string(v.id));
  }
  for (int k : m.kernels)
    if (k < 0 || k >= static_cast<int>(m.functions.size()) || !m.functions[k].is_kernel)
      return Internal("IR verify: bad kernel index");  // not reachable from user input
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
  lang::ParseLimits limits;
  limits.max_block_depth = options.max_block_depth;
  limits.max_expression_depth = options.max_expression_depth;
  for (const auto& fn : module.functions) {
    auto def = lang::ParseFunction(fn, diags, limits);
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

  WEFT_RETURN_IF_ERROR(VerifyModule(*checked, diags));
  auto out = codegen::EmitCpp(*checked, options, diags);
  if (!out.ok()) return out.status();
  timer.Done("emit C++", out->source);
  return out;
}

}  // namespace

Expected<GeneratedModule> GenerateModule(const ModuleSource& module, const CodegenOptions& options,
                                         std::vector<Diagnostic>* diags) {
  // Errors are values; a bug that throws (std::out_of_range, bad_alloc) must not take the
  // daemon down: it becomes an internal error with a bug hint.
  // The checker and the emitter already turn their own bugs into located errors; this is
  // the last resort, located at the module's first function.
  try {
    return RunPipeline(module, options, diags);
  } catch (const std::exception& e) {
    Diagnostic d;
    if (!module.functions.empty())
      d.location = {module.functions[0].file, module.functions[0].first_line, 1};
    d.message = std::string("weft cannot compile module '") + module.name + "' (internal compiler error: " + e.what() +
                "; please report it)";
    if (diags) diags->push_back(d);
    return InvalidArgument(d.ToString());
  }
}

}  // namespace weft
