// Escaping and mangling of client text for generated C++ (see emit_text.h).
#include "engine/codegen/emit_text.h"

namespace weft::codegen {
namespace {

constexpr char kHex[] = "0123456789ABCDEF";

bool IsAlnum(unsigned char c) { return (c >= '0' && c <= '9') || (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z'); }
bool IsPrintable(unsigned char c) { return c >= 0x20 && c < 0x7f; }

void AppendPercentHex(unsigned char c, std::string* out) {
  *out += '%';
  *out += kHex[c >> 4];
  *out += kHex[c & 15];
}

// Printable ASCII except the bytes in `reserved` kept; the rest (and "*/", "??") as %HH.
std::string PercentEncode(std::string_view text, std::string_view reserved, size_t max_bytes) {
  std::string out;
  size_t n = text.size() < max_bytes ? text.size() : max_bytes;
  out.reserve(n + 8);
  for (size_t i = 0; i < n; ++i) {
    auto c = static_cast<unsigned char>(text[i]);
    bool after_star = c == '/' && i > 0 && text[i - 1] == '*';
    bool after_question = c == '?' && i > 0 && text[i - 1] == '?';
    if (!IsPrintable(c) || c == '%' || reserved.find(static_cast<char>(c)) != std::string_view::npos || after_star ||
        after_question) {
      AppendPercentHex(c, &out);
    } else {
      out += static_cast<char>(c);
    }
  }
  if (n < text.size()) out += "...";
  return out;
}

}  // namespace

std::string MangleIdentifier(std::string_view name) {
  std::string out;
  out.reserve(name.size() + 4);
  for (char ch : name) {
    auto c = static_cast<unsigned char>(ch);
    if (c == 'Z') {
      out += "ZZ";
    } else if (IsAlnum(c) || c == '_') {
      out += ch;
    } else {
      out += 'Z';
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  return out;
}

std::string CppStringLiteral(std::string_view text) {
  std::string out = "\"";
  out.reserve(text.size() + 2);
  for (char ch : text) {
    auto c = static_cast<unsigned char>(ch);
    switch (c) {
      case '\\': out += "\\\\"; break;
      case '"': out += "\\\""; break;
      case '?': out += "\\?"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      case '\r': out += "\\r"; break;
      default:
        if (IsPrintable(c)) {
          out += ch;
        } else {
          // Always three digits, so a digit that follows is never read as part of the escape.
          out += '\\';
          out += static_cast<char>('0' + (c >> 6));
          out += static_cast<char>('0' + ((c >> 3) & 7));
          out += static_cast<char>('0' + (c & 7));
        }
    }
  }
  out += '"';
  return out;
}

std::string CommentText(std::string_view text, size_t max_bytes) { return PercentEncode(text, "\\", max_bytes); }

std::string LineDirective(uint32_t line, std::string_view file) {
  return "#line " + std::to_string(line) + " \"" + PercentEncode(file, "\\\"?", 200) + "\"";
}

}  // namespace weft::codegen
