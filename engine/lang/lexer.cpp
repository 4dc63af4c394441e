// Lexer for the kernel language (see lexer.h): a single forward scan over the source with an
// indentation stack and a bracket stack, as in CPython's tokenizer.
#include "engine/lang/lexer.h"

#include <algorithm>
#include <charconv>
#include <cstdlib>
#include <cstring>

namespace weft::lang {
namespace {

constexpr size_t kMaxBracketDepth = 200;  // CPython's MAXLEVEL

const char* const kKeywords[] = {
    "False", "None",   "True",    "and",      "as",     "assert", "async", "await",
    "break", "class",  "continue", "def",     "del",    "elif",   "else",  "except",
    "finally", "for",  "from",    "global",   "if",     "import", "in",    "is",
    "lambda", "nonlocal", "not",  "or",       "pass",   "raise",  "return", "try",
    "while", "with",   "yield",
};

// Longest first within each length class; the scanner tries 3, then 2, then 1 characters.
const char* const kOperators3[] = {"**=", "//=", ">>=", "<<=", "..."};
const char* const kOperators2[] = {"**", "//", "<<", ">>", "<=", ">=", "==", "!=", "->", ":=",
                                   "+=", "-=", "*=", "/=", "%=", "&=", "|=", "^=", "@="};
const char kOperators1[] = "+-*/%@&|^~<>()[]{},:.;=";

bool IsIdentStart(char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_'; }
bool IsDigit(char c) { return c >= '0' && c <= '9'; }
bool IsIdentChar(char c) { return IsIdentStart(c) || IsDigit(c); }
bool IsNonAscii(char c) { return static_cast<unsigned char>(c) >= 0x80; }

int DigitValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'z') return c - 'a' + 10;
  if (c >= 'A' && c <= 'Z') return c - 'A' + 10;
  return 99;
}

void AppendUtf8(std::string* out, uint32_t cp) {
  if (cp < 0x80) {
    out->push_back(static_cast<char>(cp));
  } else if (cp < 0x800) {
    out->push_back(static_cast<char>(0xC0 | (cp >> 6)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else if (cp < 0x10000) {
    out->push_back(static_cast<char>(0xE0 | (cp >> 12)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  } else {
    out->push_back(static_cast<char>(0xF0 | (cp >> 18)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 12) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3F)));
    out->push_back(static_cast<char>(0x80 | (cp & 0x3F)));
  }
}

// Arbitrary-precision conversion of `digits` (already validated, no underscores) in `base`
// to decimal text, plus the value as uint64 when it fits.
void ConvertInteger(std::string_view digits, int base, Token* tok) {
  std::vector<uint32_t> limbs{0};  // little-endian, base 1e9
  constexpr uint64_t kLimb = 1000000000ull;
  uint64_t u64 = 0;
  bool fits = true;
  for (char c : digits) {
    const uint64_t d = static_cast<uint64_t>(DigitValue(c));
    uint64_t carry = d;
    for (uint32_t& limb : limbs) {
      const uint64_t v = static_cast<uint64_t>(limb) * static_cast<uint64_t>(base) + carry;
      limb = static_cast<uint32_t>(v % kLimb);
      carry = v / kLimb;
    }
    while (carry) {
      limbs.push_back(static_cast<uint32_t>(carry % kLimb));
      carry /= kLimb;
    }
    if (fits) {
      uint64_t t;
      if (__builtin_mul_overflow(u64, static_cast<uint64_t>(base), &t) ||
          __builtin_add_overflow(t, d, &u64)) {
        fits = false;
      }
    }
  }
  std::string text = std::to_string(limbs.back());
  for (size_t i = limbs.size() - 1; i-- > 0;) {
    std::string part = std::to_string(limbs[i]);
    text += std::string(9 - part.size(), '0') + part;
  }
  tok->int_decimal = std::move(text);
  tok->int_fits_u64 = fits;
  tok->int_value = fits ? u64 : 0;
}

class Lexer {
 public:
  Lexer(std::string_view src, uint32_t first_line) : src_(src), first_line_(first_line) {}

  Expected<std::vector<Token>> Run(TextPosition* error_at, std::vector<Token>* partial) {
    if (src_.size() >= 3 && std::memcmp(src_.data(), "\xEF\xBB\xBF", 3) == 0) i_ = line_start_ = 3;
    ScanAll();
    if (failed_) {
      if (error_at) *error_at = error_pos_;
      if (partial) *partial = std::move(tokens_);
      return InvalidArgument(error_message_);
    }
    return std::move(tokens_);
  }

 private:
  // ---- helpers -------------------------------------------------------------------------
  bool AtEnd(size_t j) const { return j >= src_.size(); }
  char At(size_t j) const { return j < src_.size() ? src_[j] : '\0'; }

  // Column counting resumes from the previous query on the same line, so a very long line
  // costs linear time, not quadratic.
  TextPosition PosAt(size_t offset) const {
    if (col_cache_line_start_ != line_start_ || offset < col_cache_offset_) {
      col_cache_line_start_ = line_start_;
      col_cache_offset_ = line_start_;
      col_cache_column_ = 1;
    }
    for (size_t j = col_cache_offset_; j < offset && j < src_.size(); ++j) {
      if ((static_cast<unsigned char>(src_[j]) & 0xC0) != 0x80) ++col_cache_column_;
    }
    col_cache_offset_ = std::max(col_cache_offset_, std::min(offset, src_.size()));
    return {line_, col_cache_column_};
  }

  bool Fail(TextPosition pos, std::string message) {
    if (!failed_) {
      failed_ = true;
      error_pos_ = pos;
      error_message_ = std::move(message);
    }
    return false;
  }
  bool FailAt(size_t offset, std::string message) { return Fail(PosAt(offset), std::move(message)); }

  Token& Emit(TokenKind kind, size_t begin, size_t end, TextPosition pos) {
    Token t;
    t.kind = kind;
    t.text = std::string(src_.substr(begin, end - begin));
    t.pos = pos;
    tokens_.push_back(std::move(t));
    return tokens_.back();
  }

  // Consumes one line break at i_ (\n, \r\n or \r) and starts the next line.
  void ConsumeLineBreak() {
    if (At(i_) == '\r' && At(i_ + 1) == '\n') ++i_;
    ++i_;
    ++line_;
    line_start_ = i_;
  }

  bool IsLineBreak(size_t j) const { return At(j) == '\n' || At(j) == '\r'; }

  // A line number as the user sees it, for messages that quote one.
  std::string UserLine(uint32_t line) const { return std::to_string(first_line_ + line - 1); }

  // ---- main scan -----------------------------------------------------------------------
  void ScanAll() {
    bool at_line_start = true;
    while (!failed_) {
      if (at_line_start && brackets_.empty()) {
        if (!ScanIndentation()) break;  // end of input
        at_line_start = false;
      }
      if (AtEnd(i_)) break;
      const char c = src_[i_];
      if (c == ' ' || c == '\t' || c == '\f') {
        ++i_;
      } else if (c == '#') {
        while (!AtEnd(i_) && !IsLineBreak(i_)) ++i_;
      } else if (c == '\n' || c == '\r') {
        // Inside brackets a line break is whitespace and the next line has no indentation.
        const bool ends_logical_line = brackets_.empty();
        if (ends_logical_line) Emit(TokenKind::kNewline, i_, i_, PosAt(i_)).text = "";
        ConsumeLineBreak();
        at_line_start = ends_logical_line;
      } else if (c == '\\') {
        if (IsLineBreak(i_ + 1)) {
          ++i_;
          ConsumeLineBreak();
          if (AtEnd(i_)) FailAt(i_, "unexpected end of input after line continuation character");
        } else {
          FailAt(i_, "unexpected character after line continuation character");
        }
      } else if (IsIdentStart(c)) {
        ScanNameOrPrefixedString();
      } else if (IsDigit(c) || (c == '.' && IsDigit(At(i_ + 1)))) {
        ScanNumber();
      } else if (c == '\'' || c == '"') {
        ScanString(i_, i_, "");
      } else if (IsNonAscii(c)) {
        FailAt(i_, "non-ASCII character outside a string or comment (kernel identifiers must be ASCII)");
      } else {
        ScanOperator();
      }
    }
    if (failed_) return;
    if (!brackets_.empty()) {
      Fail(brackets_.back().pos, std::string("'") + brackets_.back().ch + "' was never closed");
      return;
    }
    const TextPosition end = PosAt(i_);
    if (!tokens_.empty() && tokens_.back().kind != TokenKind::kNewline &&
        tokens_.back().kind != TokenKind::kDedent) {
      Emit(TokenKind::kNewline, i_, i_, end);
    }
    while (indents_.size() > 1) {
      indents_.pop_back();
      Emit(TokenKind::kDedent, i_, i_, end);
    }
    Emit(TokenKind::kEndOfFile, i_, i_, end);
  }

  // At the start of a logical line: skips blank and comment-only lines, then compares the
  // indentation with the stack and emits INDENT/DEDENT. Returns false at end of input.
  bool ScanIndentation() {
    while (!AtEnd(i_)) {
      uint32_t width = 0;
      size_t j = i_;
      while (!AtEnd(j) && (src_[j] == ' ' || src_[j] == '\t' || src_[j] == '\f')) {
        if (src_[j] == ' ') ++width;
        else if (src_[j] == '\t') width = (width / 8 + 1) * 8;
        else width = 0;  // form feed resets, as in CPython
        ++j;
      }
      if (AtEnd(j)) {
        i_ = j;
        return false;
      }
      if (src_[j] == '#') {
        while (!AtEnd(j) && !IsLineBreak(j)) ++j;
      }
      if (AtEnd(j)) {
        i_ = j;
        return false;
      }
      if (IsLineBreak(j)) {  // blank or comment-only line: no tokens
        i_ = j;
        ConsumeLineBreak();
        continue;
      }
      i_ = j;
      const TextPosition pos = PosAt(i_);
      if (indents_.empty()) {
        indents_.push_back(width);  // base level of this source
      } else if (width > indents_.back()) {
        indents_.push_back(width);
        Emit(TokenKind::kIndent, i_, i_, pos);
      } else {
        while (width < indents_.back()) {
          if (indents_.size() == 1) {
            Fail(pos, "unindent does not match any outer indentation level");
            return false;
          }
          indents_.pop_back();
          Emit(TokenKind::kDedent, i_, i_, pos);
        }
        if (width != indents_.back()) {
          Fail(pos, "unindent does not match any outer indentation level");
          return false;
        }
      }
      return true;
    }
    return false;
  }

  void ScanNameOrPrefixedString() {
    const size_t begin = i_;
    size_t j = i_;
    while (IsIdentChar(At(j))) ++j;
    const std::string_view word = src_.substr(begin, j - begin);
    if (At(j) == '\'' || At(j) == '"') {
      std::string lower;
      for (char c : word) lower.push_back(static_cast<char>(c | 0x20));
      if (lower == "r" || lower == "u" || lower == "b" || lower == "br" || lower == "rb" ||
          lower == "f" || lower == "fr" || lower == "rf") {
        ScanString(begin, j, lower);
        return;
      }
    }
    if (IsNonAscii(At(j))) {
      FailAt(j, "non-ASCII character outside a string or comment (kernel identifiers must be ASCII)");
      return;
    }
    const TextPosition pos = PosAt(begin);
    i_ = j;
    Emit(IsPythonKeyword(word) ? TokenKind::kKeyword : TokenKind::kName, begin, j, pos);
  }

  // digitpart = digit (["_"] digit)*   (j at the first digit). Appends digits to *out.
  bool ScanDigitPart(size_t* j, std::string* out, bool (*is_digit)(char), const char* kind) {
    while (true) {
      if (is_digit(At(*j))) {
        out->push_back(At(*j));
        ++*j;
      } else if (At(*j) == '_' && is_digit(At(*j + 1))) {
        ++*j;
      } else if (At(*j) == '_') {
        return FailAt(*j, std::string("invalid ") + kind + " literal");
      } else {
        return true;
      }
    }
  }

  void ScanNumber() {
    const size_t begin = i_;
    const TextPosition pos = PosAt(begin);
    size_t j = i_;
    const char p = static_cast<char>(At(j + 1) | 0x20);
    if (At(j) == '0' && (p == 'x' || p == 'o' || p == 'b')) {
      const int base = p == 'x' ? 16 : p == 'o' ? 8 : 2;
      const char* kind = p == 'x' ? "hexadecimal" : p == 'o' ? "octal" : "binary";
      j += 2;
      std::string digits;
      while (true) {
        const char c = At(j);
        if (c == '_' && DigitValue(At(j + 1)) < base) {
          ++j;
        } else if (DigitValue(c) < base) {
          digits.push_back(c);
          ++j;
        } else {
          break;
        }
      }
      if (IsIdentChar(At(j)) || IsNonAscii(At(j))) {
        if (IsDigit(At(j))) {
          FailAt(j, std::string("invalid digit '") + At(j) + "' in " + kind + " literal");
        } else {
          FailAt(j, std::string("invalid ") + kind + " literal");
        }
        return;
      }
      if (digits.empty()) {
        FailAt(j, std::string("invalid ") + kind + " literal");
        return;
      }
      i_ = j;
      Token& t = Emit(TokenKind::kInt, begin, j, pos);
      ConvertInteger(digits, base, &t);
      return;
    }

    std::string mantissa;  // digits and '.', 'e' for the float conversion (no underscores)
    bool is_float = false;
    if (IsDigit(At(j)) && !ScanDigitPart(&j, &mantissa, IsDigit, "decimal")) return;
    const std::string int_digits = mantissa;
    if (At(j) == '.') {
      is_float = true;
      mantissa.push_back('.');
      ++j;
      if (At(j) == '_') {
        FailAt(j, "invalid decimal literal");
        return;
      }
      if (IsDigit(At(j)) && !ScanDigitPart(&j, &mantissa, IsDigit, "decimal")) return;
    }
    if (At(j) == 'e' || At(j) == 'E') {
      size_t k = j + 1;
      std::string exponent = "e";
      if (At(k) == '+' || At(k) == '-') exponent.push_back(At(k++));
      if (!IsDigit(At(k))) {
        FailAt(j, "invalid decimal literal");
        return;
      }
      if (!ScanDigitPart(&k, &exponent, IsDigit, "decimal")) return;
      mantissa += exponent;
      is_float = true;
      j = k;
    }
    if (At(j) == 'j' || At(j) == 'J') {
      FailAt(begin, "complex (imaginary) number literals are not supported in kernels");
      return;
    }
    if (IsIdentChar(At(j)) || IsNonAscii(At(j))) {
      FailAt(j, "invalid decimal literal");
      return;
    }
    i_ = j;
    if (is_float) {
      Token& t = Emit(TokenKind::kFloat, begin, j, pos);
      double v = 0.0;
      const char* first = mantissa.data();
      const char* last = first + mantissa.size();
      auto [ptr, ec] = std::from_chars(first, last, v, std::chars_format::general);
      if (ec != std::errc() || ptr != last) v = std::strtod(mantissa.c_str(), nullptr);
      t.float_value = v;
      return;
    }
    if (int_digits.size() > 1 && int_digits.find_first_not_of('0') != std::string::npos &&
        int_digits[0] == '0') {
      Fail(pos,
           "leading zeros in decimal integer literals are not permitted; use an 0o prefix for "
           "octal integers");
      return;
    }
    Token& t = Emit(TokenKind::kInt, begin, j, pos);
    ConvertInteger(int_digits, 10, &t);
  }

  // `begin` = start of the prefix, `quote_at` = the opening quote, `prefix` lower-cased.
  void ScanString(size_t begin, size_t quote_at, const std::string& prefix) {
    const TextPosition pos = PosAt(begin);
    if (prefix.find('f') != std::string::npos) {
      Fail(pos,
           "f-strings are not supported in kernels; use print(x) or wp.printf(\"x = %f\\n\", x)");
      return;
    }
    if (prefix.find('b') != std::string::npos) {
      Fail(pos, "bytes literals are not supported in kernels");
      return;
    }
    const bool raw = prefix.find('r') != std::string::npos;
    const char q = src_[quote_at];
    const bool triple = At(quote_at + 1) == q && At(quote_at + 2) == q;
    size_t j = quote_at + (triple ? 3 : 1);
    std::string value;
    while (true) {
      if (AtEnd(j)) {
        Fail(pos, std::string(triple ? "unterminated triple-quoted string literal"
                                     : "unterminated string literal") +
                      " (detected at line " + UserLine(line_) + ")");
        return;
      }
      const char c = src_[j];
      if (c == q && (!triple || (At(j + 1) == q && At(j + 2) == q))) {
        j += triple ? 3 : 1;
        break;
      }
      if (IsLineBreak(j)) {
        if (!triple) {
          Fail(pos, "unterminated string literal (detected at line " + UserLine(line_) + ")");
          return;
        }
        value.push_back('\n');
        i_ = j;
        ConsumeLineBreak();
        j = i_;
        continue;
      }
      if (c != '\\') {
        value.push_back(c);
        ++j;
        continue;
      }
      // Backslash.
      if (IsLineBreak(j + 1)) {  // escaped line break: joined (raw strings keep both)
        if (raw) value += "\\\n";
        i_ = j + 1;
        ConsumeLineBreak();
        j = i_;
        continue;
      }
      if (AtEnd(j + 1)) {
        ++j;
        continue;  // reported as unterminated on the next iteration
      }
      const char e = src_[j + 1];
      if (raw) {
        value.push_back('\\');
        value.push_back(e);
        j += 2;
        continue;
      }
      j += 2;
      switch (e) {
        case '\\': value.push_back('\\'); break;
        case '\'': value.push_back('\''); break;
        case '"': value.push_back('"'); break;
        case 'a': value.push_back('\a'); break;
        case 'b': value.push_back('\b'); break;
        case 'f': value.push_back('\f'); break;
        case 'n': value.push_back('\n'); break;
        case 'r': value.push_back('\r'); break;
        case 't': value.push_back('\t'); break;
        case 'v': value.push_back('\v'); break;
        case '0': case '1': case '2': case '3': case '4': case '5': case '6': case '7': {
          uint32_t v = static_cast<uint32_t>(e - '0');
          for (int n = 0; n < 2 && At(j) >= '0' && At(j) <= '7'; ++n) v = v * 8 + static_cast<uint32_t>(At(j++) - '0');
          AppendUtf8(&value, v);
          break;
        }
        case 'x': case 'u': case 'U': {
          const int count = e == 'x' ? 2 : e == 'u' ? 4 : 8;
          uint32_t v = 0;
          for (int n = 0; n < count; ++n) {
            const int d = DigitValue(At(j));
            if (d >= 16) {
              FailAt(j - 2 - static_cast<size_t>(n),
                     std::string("truncated \\") + e + " escape in string literal");
              return;
            }
            v = v * 16 + static_cast<uint32_t>(d);
            ++j;
          }
          if (v > 0x10FFFF) {
            FailAt(j - 2 - static_cast<size_t>(count), "illegal Unicode character in string literal");
            return;
          }
          AppendUtf8(&value, v);
          break;
        }
        case 'N':
          FailAt(j - 2, "\\N{...} escapes are not supported in kernel strings");
          return;
        default:  // unknown escapes are kept verbatim, as Python does
          value.push_back('\\');
          value.push_back(e);
          break;
      }
    }
    // The token may span lines: compute its text from `begin`, but its position was taken
    // before the scan.
    Token t;
    t.kind = TokenKind::kString;
    t.text = std::string(src_.substr(begin, j - begin));
    t.pos = pos;
    t.string_value = std::move(value);
    tokens_.push_back(std::move(t));
    i_ = j;
  }

  void ScanOperator() {
    const size_t begin = i_;
    const TextPosition pos = PosAt(begin);
    size_t len = 0;
    for (const char* op : kOperators3) {
      if (src_.substr(i_, 3) == op) len = 3;
    }
    if (!len) {
      for (const char* op : kOperators2) {
        if (src_.substr(i_, 2) == op) len = 2;
      }
    }
    if (!len && std::strchr(kOperators1, src_[i_]) != nullptr) len = 1;
    if (!len) {
      const char c = src_[i_];
      if (c == '\0') {
        Fail(pos, "source contains a null byte");
      } else if (static_cast<unsigned char>(c) < 0x20 || c == 0x7F) {
        Fail(pos, "invalid control character in source");
      } else {
        Fail(pos, std::string("invalid character '") + c + "'");
      }
      return;
    }
    const char c = src_[i_];
    if (len == 1 && (c == '(' || c == '[' || c == '{')) {
      if (brackets_.size() >= kMaxBracketDepth) {
        Fail(pos, "too many nested parentheses");
        return;
      }
      brackets_.push_back({c, pos});
    } else if (len == 1 && (c == ')' || c == ']' || c == '}')) {
      if (brackets_.empty()) {
        Fail(pos, std::string("unmatched '") + c + "'");
        return;
      }
      const char open = brackets_.back().ch;
      const char expected = open == '(' ? ')' : open == '[' ? ']' : '}';
      if (c != expected) {
        std::string msg = std::string("closing parenthesis '") + c +
                          "' does not match opening parenthesis '" + open + "'";
        if (brackets_.back().pos.line != pos.line) {
          msg += " on line " + UserLine(brackets_.back().pos.line);
        }
        Fail(pos, std::move(msg));
        return;
      }
      brackets_.pop_back();
    }
    i_ += len;
    Emit(TokenKind::kOperator, begin, i_, pos);
  }

  struct OpenBracket {
    char ch;
    TextPosition pos;
  };

  std::string_view src_;
  uint32_t first_line_ = 1;
  mutable size_t col_cache_line_start_ = static_cast<size_t>(-1);
  mutable size_t col_cache_offset_ = 0;
  mutable uint32_t col_cache_column_ = 1;
  size_t i_ = 0;
  uint32_t line_ = 1;
  size_t line_start_ = 0;
  std::vector<Token> tokens_;
  std::vector<uint32_t> indents_;
  std::vector<OpenBracket> brackets_;
  bool failed_ = false;
  TextPosition error_pos_;
  std::string error_message_;
};

}  // namespace

const char* TokenKindName(TokenKind kind) {
  switch (kind) {
    case TokenKind::kName: return "NAME";
    case TokenKind::kKeyword: return "KEYWORD";
    case TokenKind::kInt: return "INT";
    case TokenKind::kFloat: return "FLOAT";
    case TokenKind::kString: return "STRING";
    case TokenKind::kOperator: return "OP";
    case TokenKind::kNewline: return "NEWLINE";
    case TokenKind::kIndent: return "INDENT";
    case TokenKind::kDedent: return "DEDENT";
    case TokenKind::kEndOfFile: return "EOF";
  }
  return "?";
}

bool IsPythonKeyword(std::string_view word) {
  for (const char* k : kKeywords) {
    if (word == k) return true;
  }
  return false;
}

Expected<std::vector<Token>> Tokenize(std::string_view source, TextPosition* error_at,
                                      std::vector<Token>* tokens_before_error,
                                      uint32_t first_line) {
  return Lexer(source, first_line).Run(error_at, tokens_before_error);
}

}  // namespace weft::lang
