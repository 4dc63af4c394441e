// Lexer for the kernel language: Python source text -> tokens, following Python's tokenizer
// (INDENT/DEDENT from indentation, NEWLINE ending logical lines, line joining inside brackets
// and after a backslash, comments, int/float/string literals, operators).
// Expects: one function's source (the client dedents it; if not, the first logical line's
// indentation is taken as the base level). Guarantees: on success the token list ends with
// NEWLINE, balancing DEDENTs and one kEndOfFile; string tokens carry their decoded value and
// int tokens their exact decimal value. On failure the Status message is the user-facing
// text and *error_at the position it points at. Never aborts on any input.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "engine/core/status.h"

namespace weft::lang {

enum class TokenKind {
  kName,       // identifiers (soft keywords such as `match` and `type` are names)
  kKeyword,    // Python's hard keywords: if, for, def, True, None, lambda, ...
  kInt,        // 42, 0x2A, 0o52, 0b101010, 1_000
  kFloat,      // 1.5, 1., .5, 1e-3, 1_0.0_1
  kString,     // 'a', "a", '''a''', r"a", u"a" (one token per literal; the parser joins them)
  kOperator,   // + - ** // -> := ... ( ) [ ] etc. (text holds the spelling)
  kNewline,    // end of a logical line
  kIndent,
  kDedent,
  kEndOfFile,
};

const char* TokenKindName(TokenKind kind);

// A position in the lexed text: 1-based line, 1-based column counted in characters (UTF-8
// code points) so a caret printed under the source line lands on the right character.
struct TextPosition {
  uint32_t line = 0;
  uint32_t column = 0;
};

struct Token {
  TokenKind kind = TokenKind::kEndOfFile;
  std::string text;        // the spelling as written (for kString: with prefix and quotes)
  TextPosition pos;        // first character
  // kInt: exact value in decimal digits (arbitrary precision); int_value holds it when
  // int_fits_u64. kFloat: value as the nearest double.
  std::string int_decimal;
  uint64_t int_value = 0;
  bool int_fits_u64 = true;
  double float_value = 0.0;
  std::string string_value;  // kString: decoded contents
};

// On failure returns InvalidArgument(message) and sets *error_at (if non-null); the tokens
// scanned before the error go to *tokens_before_error (if non-null), so a caller can report
// an earlier syntax error first, as Python's on-demand tokenizer does. `first_line` is the
// user's line of source line 1, used only for line numbers quoted inside messages.
Expected<std::vector<Token>> Tokenize(std::string_view source, TextPosition* error_at,
                                      std::vector<Token>* tokens_before_error = nullptr,
                                      uint32_t first_line = 1);

// Python's hard keywords.
bool IsPythonKeyword(std::string_view word);

}  // namespace weft::lang
