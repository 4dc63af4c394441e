// The fuzz input format of the compile-pipeline target: a ModuleSource plus CodegenOptions as
// line-oriented text, so that libFuzzer's byte mutations land in kernel source and in names
// alike. One record per line; fields are separated by spaces and unescaped (\s space, \n, \r,
// \t, \0, \\, \xHH; a lone "-" is the empty string):
//
//   module <name>                        option <key> <value>
//   codegen [cpu|cuda] [backward] [nobounds]
//   struct <name>                        field <name> <type>        (to the last struct)
//   const <name> <type> <value>          func <name> <key>
//   type <name> <type>                   builtin <name> <target>
//   kernel|function <name> <key> <file> <first_line> [<return_type>]
//   param <name> <type>                  (to the last function)
//   source                               raw lines up to a line ".end" (to the last function)
//
// Lines starting with '#' and unknown records are ignored: every byte string parses.
#pragma once

#include <string>
#include <string_view>

#include "engine/codegen/generate_module.h"
#include "engine/core/module_source.h"

namespace weft::fuzz {

struct FuzzModule {
  ModuleSource module;
  CodegenOptions options;
};

FuzzModule ParseModuleText(std::string_view text);

// The inverse for one field (used by tests and seed tools): escapes what ParseModuleText
// unescapes.
std::string EscapeField(std::string_view field);

}  // namespace weft::fuzz
