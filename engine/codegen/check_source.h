// The checks a compile request (ModuleSource) passes before it is hashed, parsed or emitted:
// every name a client chose is a Python identifier (dotted where the protocol says so), and the
// module is within the daemon's compile limits. A name that fails is refused, never repaired:
// the error names the field ("structs[0].fields[2].name") and quotes the offending name.
// Text that is not a name (sources, file names, type strings, constant literals) is not
// restricted here: the parser, the type reader and the escaping of engine/codegen/emit_text.h
// handle it.
#pragma once

#include <cstdint>
#include <string_view>

#include "engine/core/module_source.h"
#include "engine/core/status.h"

namespace weft::codegen {

struct CompileLimits {
  // Every string of the module together, plus 16 bytes per function, parameter, symbol,
  // struct, field and option.
  uint64_t max_module_bytes = 2u << 20;
  uint32_t max_functions = 2000;      // kernels and funcs of one module
  int max_block_depth = 100;          // nested blocks; at most 100 (lang::kMaxBlockDepth)
  int max_expression_depth = 1000;    // expression recursion; at most 1000 (lang::kMaxExpressionDepth)
};

// Longest name accepted anywhere in a module, in bytes.
inline constexpr size_t kMaxNameBytes = 1024;

// Python's identifier grammar: a letter or '_' then letters, digits or '_', not a keyword.
// ASCII letters, and non-ASCII letters in well-formed UTF-8: code points that never occur
// in a Python identifier (controls, spaces, punctuation and symbol blocks, format characters
// such as bidirectional overrides and zero-width spaces, private use) are refused.
bool IsPythonIdentifier(std::string_view name);

// Identifiers joined by '.': "mymod.Particle", "wp".
bool IsDottedName(std::string_view name);

// InvalidArgument naming the field and the name when a name is bad; ResourceExhausted naming
// the limit when the module is too big. The parse depth limits are applied by the parser
// (CodegenOptions), not here.
Status CheckModuleSource(const ModuleSource& module, const CompileLimits& limits);

}  // namespace weft::codegen
