// CheckGeneratedModule: lexical and layout invariants of generated C++ (see the header).
#include "tests/fuzz/generated_cpp_check.h"

#include <string_view>

namespace weft::fuzz {
namespace {

std::string LineAt(std::string_view s, size_t pos) {
  size_t b = s.rfind('\n', pos == 0 ? 0 : pos - 1);
  b = (b == std::string_view::npos || pos == 0) ? 0 : b + 1;
  size_t e = s.find('\n', pos);
  if (e == std::string_view::npos) e = s.size();
  return std::string(s.substr(b, e - b));
}

bool IsIdent(const std::string& s) {
  if (s.empty()) return false;
  for (size_t i = 0; i < s.size(); ++i) {
    char c = s[i];
    bool ok = c == '_' || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (i > 0 && c >= '0' && c <= '9');
    if (!ok) return false;
  }
  return true;
}

// A string literal "..." with only escaped quotes/backslashes inside, then end of text.
bool IsQuotedRest(std::string_view s) {
  if (s.size() < 2 || s.front() != '"' || s.back() != '"') return false;
  for (size_t i = 1; i + 1 < s.size(); ++i) {
    if (s[i] == '\\') {
      ++i;
      if (i + 1 >= s.size()) return false;
    } else if (s[i] == '"') {
      return false;
    }
  }
  return true;
}

std::string CheckDirective(std::string_view line) {
  size_t i = line.find('#');
  std::string_view d = line.substr(i);
  if (d == "#include \"weft.h\"" || d == "#include \"codegen_support.h\"") return "";
  if (d.substr(0, 6) == "#line ") {
    size_t j = 6;
    while (j < d.size() && d[j] >= '0' && d[j] <= '9') ++j;
    if (j > 6 && j < d.size() && d[j] == ' ' && IsQuotedRest(d.substr(j + 1))) return "";
  }
  return "unexpected preprocessor line: " + std::string(line);
}

std::string CheckText(std::string_view s) {
  enum class State { kCode, kLineComment, kBlockComment, kString, kChar };
  State st = State::kCode;
  int paren = 0, bracket = 0, brace = 0;
  bool line_start = true;   // only whitespace so far on this line (in code)
  for (size_t i = 0; i < s.size(); ++i) {
    unsigned char c = static_cast<unsigned char>(s[i]);
    if (c == '\r' || c == '\v' || c == '\f' || c == 0) return "control byte " + std::to_string(c) + " in: " + LineAt(s, i);
    if (c == '\\' && (i + 1 == s.size() || s[i + 1] == '\n')) return "line ends in a backslash: " + LineAt(s, i);
    switch (st) {
      case State::kCode:
        if (c == '\n') {
          line_start = true;
          continue;
        }
        if (c == '#' && line_start) {
          std::string err = CheckDirective(LineAt(s, i));
          if (!err.empty()) return err;
          size_t e = s.find('\n', i);
          i = (e == std::string_view::npos ? s.size() : e) - 1;
          continue;
        }
        if (c != ' ' && c != '\t') line_start = false;
        if (c >= 0x80) return "non-ASCII byte in code: " + LineAt(s, i);
        if (c == '/' && i + 1 < s.size() && s[i + 1] == '/') { st = State::kLineComment; ++i; }
        else if (c == '/' && i + 1 < s.size() && s[i + 1] == '*') { st = State::kBlockComment; ++i; }
        else if (c == '"') st = State::kString;
        else if (c == '\'') st = State::kChar;
        else if (c == '(') ++paren;
        else if (c == ')') { if (--paren < 0) return "unbalanced ): " + LineAt(s, i); }
        else if (c == '[') ++bracket;
        else if (c == ']') { if (--bracket < 0) return "unbalanced ]: " + LineAt(s, i); }
        else if (c == '{') ++brace;
        else if (c == '}') { if (--brace < 0) return "unbalanced }: " + LineAt(s, i); }
        break;
      case State::kLineComment:
        if (c == '\n') { st = State::kCode; line_start = true; }
        break;
      case State::kBlockComment:
        if (c == '*' && i + 1 < s.size() && s[i + 1] == '/') { st = State::kCode; ++i; }
        break;
      case State::kString:
      case State::kChar:
        if (c == '\n') return "literal not closed on its line: " + LineAt(s, i - 1);
        if (c == '\\') ++i;
        else if ((st == State::kString && c == '"') || (st == State::kChar && c == '\'')) st = State::kCode;
        break;
    }
  }
  if (st == State::kBlockComment) return "unclosed /* comment";
  if (st == State::kString || st == State::kChar) return "unclosed literal at the end";
  if (paren || bracket || brace)
    return "unbalanced at the end: () " + std::to_string(paren) + ", [] " + std::to_string(bracket) + ", {} " +
           std::to_string(brace);
  return "";
}

std::string CheckParams(const std::string& kernel, const std::vector<ParamLayout>& params, uint64_t block) {
  for (const auto& p : params) {
    if (p.align == 0 || (p.align & (p.align - 1)) != 0)
      return "kernel " + kernel + ": parameter " + p.name + " has alignment " + std::to_string(p.align);
    if (p.offset % p.align != 0)
      return "kernel " + kernel + ": parameter " + p.name + " at misaligned offset " + std::to_string(p.offset);
    if (uint64_t{p.offset} + p.size > block)
      return "kernel " + kernel + ": parameter " + p.name + " [" + std::to_string(p.offset) + ", +" +
             std::to_string(p.size) + ") outside its block of " + std::to_string(block);
    std::string err = CheckParams(kernel, p.fields, p.size);
    if (!err.empty()) return err;
  }
  return "";
}

}  // namespace

std::string CheckGeneratedModule(const GeneratedModule& m) {
  std::string err = CheckText(m.source);
  if (!err.empty()) return err;
  for (const auto& k : m.kernels) {
    if (!IsIdent(k.forward_symbol)) return "forward symbol is not an identifier: " + k.forward_symbol;
    if (!k.backward_symbol.empty() && !IsIdent(k.backward_symbol))
      return "backward symbol is not an identifier: " + k.backward_symbol;
    if (m.source.find(k.forward_symbol) == std::string::npos) return "forward symbol not in source: " + k.forward_symbol;
    err = CheckParams(k.name, k.params, k.args_size);
    if (!err.empty()) return err;
  }
  return "";
}

}  // namespace weft::fuzz
