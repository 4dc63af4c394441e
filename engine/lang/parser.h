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

// Deepest nesting a parse accepts; deeper input is a syntax error at the line that goes too
// deep. Values above the defaults are lowered to them: the defaults are what the parser and
// every later pass (which recurse over the tree) can take on a daemon thread's stack.
inline constexpr int kMaxBlockDepth = 100;        // CPython's "too many statically nested blocks"
inline constexpr int kMaxExpressionDepth = 1000;  // recursion units (parens, unary chains, ternaries)
struct ParseLimits {
  int max_block_depth = kMaxBlockDepth;            // nested if/for/while blocks
  int max_expression_depth = kMaxExpressionDepth;  // ~2 units per level of parentheses
};

// `diags` may be null (the message is still in the returned Status).
Expected<std::unique_ptr<ast::FunctionDef>> ParseFunction(const FunctionSource& fn,
                                                          std::vector<Diagnostic>* diags,
                                                          const ParseLimits& limits = {});

}  // namespace weft::lang
