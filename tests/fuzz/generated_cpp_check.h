// Cheap well-formedness checks of a generated module (what the compile fuzzer asserts about
// every successful GenerateModule): the C++ text is lexically closed and carries no client
// text outside string literals and comments, and the kernel argument layouts are consistent.
#pragma once

#include <string>

#include "engine/codegen/generate_module.h"

namespace weft::fuzz {

// "" when `m` passes; otherwise what is wrong, with the offending line.
//  - every "..." and '...' literal ends on its line; every /* */ comment is closed;
//  - (), [] and {} balance outside literals and comments, never going negative;
//  - no line ends in a backslash (a line splice would swallow the next line into a // comment)
//    and there is no \r, \v, \f or NUL byte anywhere (clang ends a // comment at a \r);
//  - bytes >= 0x80 only inside literals and comments (client names reach code mangled);
//  - preprocessor lines are only the two native-library includes and #line "file" markers;
//  - each kernel's parameters lie inside its argument block at offsets aligned to a power of
//    two, and its entry-point symbols are C identifiers.
std::string CheckGeneratedModule(const GeneratedModule& m);

}  // namespace weft::fuzz
