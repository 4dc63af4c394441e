// Test support: the ModuleSource of a one-kernel saxpy module, as the Python client sends it
// (the kernel's source, its parameter types and names, the `wp` symbol).
#pragma once

#include <string>

#include "engine/core/module_source.h"

namespace weft::testing {

// `def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float))` whose body stores
// `y[i] = <rhs>` (e.g. "a * x[i] + y[i]"), in module `module_name`, defined at saxpy.py:first_line.
inline ModuleSource SaxpySource(const std::string& module_name, const std::string& rhs, int first_line) {
  ModuleSource m;
  m.name = module_name;
  FunctionSource f;
  f.name = "saxpy";
  f.key = "saxpy";
  f.file = "saxpy.py";
  f.first_line = first_line;
  f.is_kernel = true;
  f.source =
      "def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):\n"
      "    i = wp.tid()\n"
      "    y[i] = " + rhs + "\n";
  f.param_types = {"float32", "array(float32,1)", "array(float32,1)"};
  f.param_names = {"a", "x", "y"};
  m.functions.push_back(f);
  Symbol wp_symbol;
  wp_symbol.name = "wp";
  wp_symbol.kind = Symbol::Kind::kBuiltinModule;
  wp_symbol.target = "warp";
  m.symbols.push_back(wp_symbol);
  return m;
}

}  // namespace weft::testing
