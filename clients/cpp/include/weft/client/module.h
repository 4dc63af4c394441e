// Kernel modules from C++: the same kernel language the Python client sends (Warp's Python
// subset, as source text), with the names the body uses resolved by the caller. The daemon
// compiles (ModuleService.Compile); launches name the returned module id. The fields mirror
// ModuleSource in proto/weft/v1/module.proto; docs/protocol.md says how to fill them.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace weft {
inline namespace client_v1 {

// One @wp.kernel or @wp.func as written.
struct FunctionDef {
  std::string name;
  std::string source;                     // the dedented `def`, decorators removed
  std::string file = "<c++>";             // reported in diagnostics and command errors
  std::uint32_t first_line = 1;           // line of the `def` in `file`
  bool is_kernel = true;
  std::vector<std::string> param_names;
  std::vector<std::string> param_types;   // canonical type strings: "array(float32,1)", "float32"
  std::string return_type;                // funcs only; empty = inferred
  std::string key;                        // unique name; empty = "<module>.<name>"
};

// A global name a body uses, resolved by the caller.
struct SymbolDef {
  enum class Kind { kBuiltinModule, kConstant, kFunction, kType };
  std::string name;                       // as written: "N", "wp", "helper"
  Kind kind = Kind::kConstant;
  std::string value;        // kBuiltinModule: "warp"; kConstant: literal text ("3", "1.5");
                            // kFunction: the FunctionDef key; kType: a type string
  std::string constant_type;   // kConstant only: "int32", "float32", ...
};

struct StructFieldDef {
  std::string name;
  std::string type;
};
struct StructDefinition {
  std::string name;                       // canonical: "module.Qualname"
  std::vector<StructFieldDef> fields;
};

struct ModuleDef {
  std::string name = "cpp_module";
  std::vector<FunctionDef> functions;
  std::vector<SymbolDef> symbols;
  std::vector<StructDefinition> structs;
  std::map<std::string, std::string> options;   // "mode": "debug", "enable_backward": "true"
  // Names bound to the Warp builtins module (`wp.tid()`); set to {} to send none.
  std::vector<std::string> warp_aliases = {"wp"};

  // Adds a kernel; returns *this for chaining.
  ModuleDef& AddKernel(std::string kernel_name, std::string kernel_source,
                       std::vector<std::string> names, std::vector<std::string> types);
  ModuleDef& AddConstant(std::string symbol, std::string type, std::string literal);
};

struct KernelParamInfo {
  std::string name;
  std::string type;
  std::uint32_t offset = 0;
  std::uint32_t size = 0;
};
struct KernelInfo {
  std::string name;
  std::vector<KernelParamInfo> params;
  std::uint32_t args_size = 0;
};

struct CompiledModule {
  std::string module_id;                  // content hash; LaunchSpec::module_id
  std::vector<KernelInfo> kernels;
  std::vector<std::string> warnings;      // non-error diagnostics, "file:line: message"
  bool cache_hit = false;
  double compile_ms = 0;

  const KernelInfo* Find(const std::string& kernel) const {
    for (const auto& k : kernels)
      if (k.name == kernel) return &k;
    return nullptr;
  }
};

}  // namespace client_v1
}  // namespace weft
