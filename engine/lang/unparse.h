// Python source text of an expression (the inverse of the parser, with the fewest parentheses
// Python's precedence needs), for diagnostics that quote user code: "array 'p.pos[i, j]' has
// 1 dimension but 2 indices were given". Guarantees: parsing the result gives the same tree;
// literals keep their source spelling (Constant::text) when they have one.
#pragma once

#include <string>

#include "engine/lang/ast.h"

namespace weft::lang {

std::string UnparseExpr(const ast::Expr& expr);

// `s` as a Python string literal between `quote` characters (' or "), with \\, the quote,
// \n \t \r and \xNN escapes for other control bytes.
std::string QuotePythonString(const std::string& s, char quote);

}  // namespace weft::lang
