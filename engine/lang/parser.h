// Parser for Warp's Python kernel subset: one `def` (FunctionSource.source) -> ast::FunctionDef.
// Expects: the client's dedented source of one function; decorator lines in front of the
// `def` are allowed and skipped. Guarantees: on success a complete tree whose every node has
// a location in the user's file (ast.h); on failure InvalidArgument and exactly one error
// Diagnostic appended to *diags (file:line:col, the source line, a caret). Never aborts,
// never throws, whatever the input.
#pragma once

#include <memory>
#include <vector>

#include "engine/core/module_source.h"
#include "engine/core/status.h"
#include "engine/lang/ast.h"

namespace weft::lang {

// `diags` may be null (the message is still in the returned Status).
Expected<std::unique_ptr<ast::FunctionDef>> ParseFunction(const FunctionSource& fn,
                                                          std::vector<Diagnostic>* diags);

}  // namespace weft::lang
