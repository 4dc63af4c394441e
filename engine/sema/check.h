// Semantic analysis: resolves names against the client's symbols, infers types with Warp's
// literal rules, resolves builtin and @wp.func overloads (instantiating generic funcs per
// argument types), and lowers each kernel and the funcs it calls to the SSA IR (ir.h) in
// the same walk (as Warp's Adjoint builder does).
// Expects: every FunctionSource of the module parsed (same order as module.functions).
// Guarantees: on success a Module whose every variable has a concrete type and whose
// functions come callees-first; on failure InvalidArgument and one Diagnostic per broken
// function at the user's file:line:col. Never aborts on user input.
#pragma once

#include <memory>
#include <vector>

#include "engine/core/module_source.h"
#include "engine/core/status.h"
#include "engine/lang/ast.h"
#include "engine/sema/ir.h"

namespace weft::sema {

struct ParsedFunction {
  const FunctionSource* source = nullptr;
  const ast::FunctionDef* def = nullptr;
};

Expected<Module> Check(const ModuleSource& module, const std::vector<ParsedFunction>& parsed,
                       std::vector<Diagnostic>* diags);

}  // namespace weft::sema
