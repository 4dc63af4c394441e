// What a client sends to compile a module (engine-side twin of weft.v1.ModuleSource) and the
// diagnostics a compile returns. Plain data; the server converts protobuf to and from it.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace weft {

struct SourceLocation {
  std::string file;
  uint32_t line = 0;
  uint32_t column = 0;
};

struct Diagnostic {
  enum class Severity { kError, kWarning, kNote };
  Severity severity = Severity::kError;
  std::string message;
  SourceLocation location;
  std::string source_line;
  // The class of error for clients that raise typed exceptions: "" (a general compile error),
  // "type" (an operand or argument of the wrong type), "value" (a value out of the allowed
  // set, e.g. a non-constant slice bound), "attribute", "index", "key".
  std::string kind;
  std::string ToString() const;  // "file:line:col: error: message\n  source\n  ^"
};

struct FunctionSource {
  std::string name;
  std::string source;      // dedented `def ...` text, decorators removed
  std::string file;
  uint32_t first_line = 1; // line of the `def` in `file`
  bool is_kernel = false;
  std::vector<std::string> param_types;  // canonical type strings, see docs/protocol.md
  std::vector<std::string> param_names;
  std::string return_type;               // funcs; empty = inferred
  std::string key;                       // unique key (overloads, generics)
};

struct ConstantValue {
  std::string type;    // canonical type string
  std::string value;   // Python literal text
};

struct Symbol {
  enum class Kind { kConstant, kFunction, kType, kBuiltinModule };
  std::string name;    // as written in source: "N", "mymod.N", "wp"
  Kind kind = Kind::kConstant;
  ConstantValue constant;   // kConstant
  std::string target;       // kFunction: FunctionSource key; kType: type string; kBuiltinModule: "warp"
};

struct StructField {
  std::string name;
  std::string type;
};

struct StructDef {
  std::string name;    // canonical, e.g. "mymod.Particle"
  std::vector<StructField> fields;
};

struct ModuleSource {
  std::string name;
  std::vector<FunctionSource> functions;
  std::vector<Symbol> symbols;
  std::vector<StructDef> structs;
  std::map<std::string, std::string> options;
};

// The lanes of a cooperative CPU block the module is compiled for: its option "cpu_block_dim"
// (wp.config.enable_cpu_blocks with a launch's block_dim), an integer from 1 to 1024. 1 when
// absent; 0 when present but not such an integer (the compiler refuses the module).
int CpuLanesOption(const ModuleSource& source);

}  // namespace weft
