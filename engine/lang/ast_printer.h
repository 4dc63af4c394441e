// Text form of the AST, for tests (parse -> print -> compare) and for WEFT_DUMP_AST=1.
// Expressions print as one-line S-expressions: `(+ a (* b c))`, `(call (. wp tid))`,
// `([] a i j)`, `(cmp a < b <= c)`; statements one per line, bodies indented two spaces:
//   def saxpy(x: ([] (. wp array) float), a: float) -> None
//     assign i = (call (. wp tid))
//     if (< i n)
//       augassign ([] x i) += a
// The format is documented in docs/language.md ("AST dump").
#pragma once

#include <string>

#include "engine/lang/ast.h"

namespace weft::lang {

struct PrintOptions {
  bool with_locations = false;  // append "  @line:col" to every statement line
};

std::string PrintExpr(const ast::Expr& expr);
// `indent` is the number of leading two-space steps; the result ends with a newline.
std::string PrintStmt(const ast::Stmt& stmt, int indent = 0, const PrintOptions& options = {});
std::string PrintFunction(const ast::FunctionDef& fn, const PrintOptions& options = {});

}  // namespace weft::lang
