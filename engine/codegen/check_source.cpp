// Compile-request checks: names (Python identifier grammar) and compile limits (see
// check_source.h).
#include "engine/codegen/check_source.h"

#include <algorithm>
#include <string>

#include "engine/lang/unparse.h"

namespace weft::codegen {
namespace {

bool IsAsciiLetter(unsigned char c) { return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || c == '_'; }
bool IsAsciiDigit(unsigned char c) { return c >= '0' && c <= '9'; }

// Decodes one well-formed UTF-8 sequence at s[*i] (not ASCII); false when malformed,
// overlong, a surrogate or past U+10FFFF.
bool DecodeUtf8(std::string_view s, size_t* i, uint32_t* cp) {
  auto b0 = static_cast<unsigned char>(s[*i]);
  int n = 0;
  uint32_t v = 0, min = 0;
  if (b0 >= 0xC2 && b0 <= 0xDF) n = 1, v = b0 & 0x1F, min = 0x80;
  else if (b0 >= 0xE0 && b0 <= 0xEF) n = 2, v = b0 & 0x0F, min = 0x800;
  else if (b0 >= 0xF0 && b0 <= 0xF4) n = 3, v = b0 & 0x07, min = 0x10000;
  else return false;
  if (*i + n >= s.size()) return false;
  for (int k = 1; k <= n; ++k) {
    auto b = static_cast<unsigned char>(s[*i + k]);
    if ((b & 0xC0) != 0x80) return false;
    v = (v << 6) | (b & 0x3F);
  }
  if (v < min || v > 0x10FFFF || (v >= 0xD800 && v <= 0xDFFF)) return false;
  *i += n + 1;
  *cp = v;
  return true;
}

// Non-ASCII code points that never belong in a Python identifier: controls, spaces,
// punctuation and symbol blocks, format characters (bidi overrides, zero-width spaces, BOM),
// private use, noncharacters and tags.
bool IsRefusedCodePoint(uint32_t c) {
  struct Range {
    uint32_t lo, hi;
  };
  static constexpr Range kRefused[] = {
      {0x80, 0x9F},     {0xA0, 0xA9},     {0xAB, 0xB4},     {0xB6, 0xB6},     {0xB8, 0xB9},
      {0xBB, 0xBF},     {0xD7, 0xD7},     {0xF7, 0xF7},     {0x2000, 0x206F}, {0x20A0, 0x20FF},
      {0x2190, 0x2BFF}, {0x2E00, 0x2E7F}, {0x3000, 0x3004}, {0x3008, 0x3020}, {0xE000, 0xF8FF},
      {0xFDD0, 0xFDEF}, {0xFE10, 0xFE1F}, {0xFE30, 0xFE6F}, {0xFEFF, 0xFEFF}, {0xFF01, 0xFF0F},
      {0xFF1A, 0xFF20}, {0xFF3B, 0xFF3E}, {0xFF40, 0xFF40}, {0xFF5B, 0xFF65}, {0xFFF0, 0xFFFF},
      {0x1F000, 0x1FAFF}, {0xE0000, 0xE00FF}, {0xF0000, 0x10FFFF},
  };
  if ((c & 0xFFFE) == 0xFFFE) return true;  // U+xFFFE / U+xFFFF in every plane
  for (const Range& r : kRefused)
    if (c >= r.lo && c <= r.hi) return true;
  return false;
}

bool IsPythonKeyword(std::string_view s) {
  static constexpr std::string_view kKeywords[] = {
      "False", "None",   "True",    "and",      "as",       "assert", "async",  "await",
      "break", "class",  "continue", "def",     "del",      "elif",   "else",   "except",
      "finally", "for",  "from",    "global",   "if",       "import", "in",     "is",
      "lambda", "nonlocal", "not",  "or",       "pass",     "raise",  "return", "try",
      "while", "with",   "yield"};
  return std::find(std::begin(kKeywords), std::end(kKeywords), s) != std::end(kKeywords);
}

std::string Quote(std::string_view name) {
  constexpr size_t kShown = 80;
  std::string shown(name.substr(0, kShown));
  return lang::QuotePythonString(shown, '\'') + (name.size() > kShown ? "..." : "");
}

class Checker {
 public:
  explicit Checker(const CompileLimits& limits) : limits_(limits) {}

  Status Run(const ModuleSource& m) {
    if (m.functions.size() > limits_.max_functions)
      return ResourceExhausted("module " + Quote(m.name) + " has " +
                               std::to_string(m.functions.size()) + " functions; this daemon compiles at most " +
                               std::to_string(limits_.max_functions) + " per module (max_functions)");
    uint64_t bytes = m.name.size();
    auto add = [&](const std::string& s) { bytes += s.size(); };
    constexpr uint64_t kEntry = 16;
    for (const auto& f : m.functions) {
      bytes += kEntry;
      add(f.name), add(f.source), add(f.file), add(f.return_type), add(f.key);
      for (const auto& t : f.param_types) bytes += kEntry, add(t);
      for (const auto& n : f.param_names) add(n);
    }
    for (const auto& s : m.symbols) bytes += kEntry, add(s.name), add(s.target), add(s.constant.type), add(s.constant.value);
    for (const auto& s : m.structs) {
      bytes += kEntry, add(s.name);
      for (const auto& f : s.fields) bytes += kEntry, add(f.name), add(f.type);
    }
    for (const auto& [k, v] : m.options) bytes += kEntry, add(k), add(v);
    if (bytes > limits_.max_module_bytes)
      return ResourceExhausted("module " + Quote(m.name) + " is " + std::to_string(bytes) +
                               " bytes of source; this daemon compiles at most " +
                               std::to_string(limits_.max_module_bytes) + " bytes per module (max_module_bytes)");

    if (!m.name.empty()) WEFT_RETURN_IF_ERROR(Dotted("name", m.name));
    for (size_t i = 0; i < m.functions.size(); ++i) {
      const auto& f = m.functions[i];
      const std::string at = "functions[" + std::to_string(i) + "]";
      WEFT_RETURN_IF_ERROR(Identifier(at + ".name", f.name));
      if (!f.key.empty()) WEFT_RETURN_IF_ERROR(Dotted(at + ".key", f.key));
      for (size_t p = 0; p < f.param_names.size(); ++p)
        WEFT_RETURN_IF_ERROR(Identifier(at + ".param_names[" + std::to_string(p) + "]", f.param_names[p]));
      if (f.file.size() > 4096)
        return InvalidArgument("compile request refused: " + at + ".file is " + std::to_string(f.file.size()) +
                               " bytes long (at most 4096)");
    }
    for (size_t i = 0; i < m.symbols.size(); ++i) {
      const auto& s = m.symbols[i];
      const std::string at = "symbols[" + std::to_string(i) + "]";
      WEFT_RETURN_IF_ERROR(Dotted(at + ".name", s.name));
      if (s.kind == Symbol::Kind::kFunction) WEFT_RETURN_IF_ERROR(Dotted(at + ".function", s.target));
    }
    for (size_t i = 0; i < m.structs.size(); ++i) {
      const auto& s = m.structs[i];
      const std::string at = "structs[" + std::to_string(i) + "]";
      WEFT_RETURN_IF_ERROR(Dotted(at + ".name", s.name));
      for (size_t k = 0; k < s.fields.size(); ++k)
        WEFT_RETURN_IF_ERROR(Identifier(at + ".fields[" + std::to_string(k) + "].name", s.fields[k].name));
    }
    for (const auto& [k, v] : m.options) {
      WEFT_RETURN_IF_ERROR(Identifier("options key", k));
      bool printable = v.size() <= 256 && std::all_of(v.begin(), v.end(), [](char c) {
                         return static_cast<unsigned char>(c) >= 0x20 && static_cast<unsigned char>(c) < 0x7f;
                       });
      if (!printable)
        return InvalidArgument("compile request refused: options['" + k + "'] = " + Quote(v) +
                               " is not a short printable ASCII value");
    }
    return Status::Ok();
  }

 private:
  static Status Refuse(const std::string& field, std::string_view name, const char* what) {
    return InvalidArgument("compile request refused: " + field + " " + Quote(name) + " is not " + what);
  }
  static Status Identifier(const std::string& field, std::string_view name) {
    if (name.size() > kMaxNameBytes) return Refuse(field, name, "a name of at most 1024 bytes");
    if (!IsPythonIdentifier(name)) return Refuse(field, name, "a Python identifier");
    return Status::Ok();
  }
  static Status Dotted(const std::string& field, std::string_view name) {
    if (name.size() > kMaxNameBytes) return Refuse(field, name, "a name of at most 1024 bytes");
    if (!IsDottedName(name)) return Refuse(field, name, "a dotted name of Python identifiers");
    return Status::Ok();
  }

  const CompileLimits& limits_;
};

}  // namespace

bool IsPythonIdentifier(std::string_view name) {
  if (name.empty() || IsPythonKeyword(name)) return false;
  size_t i = 0;
  bool first = true;
  while (i < name.size()) {
    auto c = static_cast<unsigned char>(name[i]);
    if (c < 0x80) {
      if (!(IsAsciiLetter(c) || (!first && IsAsciiDigit(c)))) return false;
      ++i;
    } else {
      uint32_t cp = 0;
      if (!DecodeUtf8(name, &i, &cp) || IsRefusedCodePoint(cp)) return false;
    }
    first = false;
  }
  return true;
}

bool IsDottedName(std::string_view name) {
  size_t start = 0;
  while (true) {
    size_t dot = name.find('.', start);
    std::string_view part = name.substr(start, dot == std::string_view::npos ? std::string_view::npos : dot - start);
    if (!IsPythonIdentifier(part)) return false;
    if (dot == std::string_view::npos) return true;
    start = dot + 1;
  }
}

Status CheckModuleSource(const ModuleSource& module, const CompileLimits& limits) {
  return Checker(limits).Run(module);
}

}  // namespace weft::codegen
