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

}  // namespace weft
