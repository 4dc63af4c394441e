// Diagnostic formatting: file:line:col, the source line and a caret.
#include "engine/core/module_source.h"

namespace weft {

std::string Diagnostic::ToString() const {
  const char* sev = severity == Severity::kError ? "error" : severity == Severity::kWarning ? "warning" : "note";
  std::string out = location.file + ":" + std::to_string(location.line);
  if (location.column) out += ":" + std::to_string(location.column);
  out += ": " + std::string(sev) + ": " + message;
  if (!source_line.empty()) {
    out += "\n    " + source_line;
    if (location.column) out += "\n    " + std::string(location.column - 1, ' ') + "^";
  }
  return out;
}

int CpuLanesOption(const ModuleSource& source) {
  auto it = source.options.find("cpu_block_dim");
  if (it == source.options.end()) return 1;
  const std::string& v = it->second;
  if (v.empty() || v.size() > 4) return 0;
  int n = 0;
  for (char c : v) {
    if (c < '0' || c > '9') return 0;
    n = n * 10 + (c - '0');
  }
  return n >= 1 && n <= 1024 ? n : 0;
}

}  // namespace weft
