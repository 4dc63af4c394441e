// ParseModuleText: the compile fuzzer's line-oriented ModuleSource format (see module_text.h).
#include "tests/fuzz/module_text.h"

#include <cstdlib>
#include <vector>

namespace weft::fuzz {
namespace {

int HexDigit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

std::string Unescape(std::string_view s) {
  if (s == "-") return "";
  std::string out;
  out.reserve(s.size());
  for (size_t i = 0; i < s.size(); ++i) {
    char c = s[i];
    if (c != '\\' || i + 1 == s.size()) {
      out += c;
      continue;
    }
    char e = s[++i];
    switch (e) {
      case 's': out += ' '; break;
      case 'n': out += '\n'; break;
      case 'r': out += '\r'; break;
      case 't': out += '\t'; break;
      case '0': out += '\0'; break;
      case 'x':
        if (i + 2 < s.size() && HexDigit(s[i + 1]) >= 0 && HexDigit(s[i + 2]) >= 0) {
          out += static_cast<char>(HexDigit(s[i + 1]) * 16 + HexDigit(s[i + 2]));
          i += 2;
        } else {
          out += 'x';
        }
        break;
      default: out += e; break;
    }
  }
  return out;
}

std::vector<std::string> Fields(std::string_view line) {
  std::vector<std::string> out;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && line[i] == ' ') ++i;
    size_t j = i;
    while (j < line.size() && line[j] != ' ') ++j;
    if (j > i) out.push_back(Unescape(line.substr(i, j - i)));
    i = j;
  }
  return out;
}

const std::string& At(const std::vector<std::string>& f, size_t i) {
  static const std::string kEmpty;
  return i < f.size() ? f[i] : kEmpty;
}

}  // namespace

std::string EscapeField(std::string_view field) {
  if (field.empty()) return "-";
  std::string out;
  for (unsigned char c : field) {
    switch (c) {
      case ' ': out += "\\s"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      case '\\': out += "\\\\"; break;
      default:
        if (c < 0x20 || c == 0x7f) {
          static const char* kHex = "0123456789abcdef";
          out += "\\x";
          out += kHex[c >> 4];
          out += kHex[c & 15];
        } else {
          out += static_cast<char>(c);
        }
    }
  }
  if (out == "-") out = "\\-";
  return out;
}

FuzzModule ParseModuleText(std::string_view text) {
  FuzzModule fm;
  ModuleSource& m = fm.module;
  size_t pos = 0;
  auto next_line = [&](std::string_view* line) {
    if (pos >= text.size()) return false;
    size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    *line = text.substr(pos, end - pos);
    pos = end + 1;
    return true;
  };
  std::string_view line;
  while (next_line(&line)) {
    if (line.empty() || line[0] == '#') continue;
    if (line == "source") {
      std::string src;
      std::string_view body;
      while (next_line(&body) && body != ".end") {
        src.append(body);
        src += '\n';
      }
      if (!m.functions.empty()) m.functions.back().source += src;
      continue;
    }
    auto f = Fields(line);
    if (f.empty()) continue;
    const std::string& rec = f[0];
    if (rec == "module") {
      m.name = At(f, 1);
    } else if (rec == "option") {
      m.options[At(f, 1)] = At(f, 2);
    } else if (rec == "codegen") {
      for (size_t i = 1; i < f.size(); ++i) {
        if (f[i] == "cuda") fm.options.target = Target::kCuda;
        if (f[i] == "cpu") fm.options.target = Target::kCpu;
        if (f[i] == "backward") fm.options.enable_backward = true;
        if (f[i] == "nobounds") fm.options.bounds_checks = false;
      }
    } else if (rec == "struct") {
      m.structs.push_back({At(f, 1), {}});
    } else if (rec == "field") {
      if (!m.structs.empty()) m.structs.back().fields.push_back({At(f, 1), At(f, 2)});
    } else if (rec == "const" || rec == "func" || rec == "type" || rec == "builtin") {
      Symbol s;
      s.name = At(f, 1);
      if (rec == "const") {
        s.kind = Symbol::Kind::kConstant;
        s.constant.type = At(f, 2);
        s.constant.value = At(f, 3);
      } else {
        s.kind = rec == "func" ? Symbol::Kind::kFunction
                 : rec == "type" ? Symbol::Kind::kType
                                 : Symbol::Kind::kBuiltinModule;
        s.target = At(f, 2);
      }
      m.symbols.push_back(std::move(s));
    } else if (rec == "kernel" || rec == "function") {
      FunctionSource fn;
      fn.is_kernel = rec == "kernel";
      fn.name = At(f, 1);
      fn.key = At(f, 2);
      fn.file = At(f, 3);
      fn.first_line = static_cast<uint32_t>(std::strtoul(At(f, 4).c_str(), nullptr, 10));
      if (fn.first_line == 0) fn.first_line = 1;   // as server/proto_convert.cpp does
      fn.return_type = At(f, 5);
      m.functions.push_back(std::move(fn));
    } else if (rec == "param") {
      if (!m.functions.empty()) {
        m.functions.back().param_names.push_back(At(f, 1));
        m.functions.back().param_types.push_back(At(f, 2));
      }
    }
  }
  return fm;
}

}  // namespace weft::fuzz
