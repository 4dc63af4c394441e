// The only ways client text enters generated C++: one function per context. Every name,
// file name, message or format a client sent reaches the translation unit through one of
// these, so no byte a client chooses can end a comment, a string literal or a directive,
// start a preprocessor line or name something the daemon did not declare.
// Guarantees (tested in tests/engine/codegen_emit_text_test.cpp): the output of each is pure
// printable ASCII with no newline, whatever the input (NULs, non-ASCII, `*/`, `??/`,
// backslashes, very long text).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace weft::codegen {

// An identifier fragment, to be appended to a fixed prefix such as "weft_kernel_" (it may
// start with a digit). Bytes [A-Za-z0-9_] other than 'Z' are kept, 'Z' becomes "ZZ" and
// every other byte "Z" + two uppercase hex digits ("mymod.Particle" -> "mymodZ2EParticle").
// Injective: distinct names never collide. Output: only [A-Za-z0-9_].
std::string MangleIdentifier(std::string_view name);

// A complete C++ string literal, quotes included. Printable ASCII other than \ " ? is kept;
// \ " ? newline tab and CR get their short escapes (`\?` so no trigraph can form), every
// other byte (NUL, control, non-ASCII) a three-digit octal escape. The literal's bytes equal
// `text`'s exactly.
std::string CppStringLiteral(std::string_view text);

// Text for the body of a `// ...` comment (one line). Printable ASCII is kept except '\'
// (a line splice at the end of a line) and '%'; those, every other byte, the '/' of "*/" and
// the second '?' of "??" are written as %HH. Text past `max_bytes` is cut and "..." added.
std::string CommentText(std::string_view text, size_t max_bytes = 200);

// A complete `#line <line> "<file>"` directive (no newline). The file name is written like
// CommentText (printable ASCII except \ " % ?, the rest as %HH), never as escapes the
// preprocessor would interpret.
std::string LineDirective(uint32_t line, std::string_view file);

}  // namespace weft::codegen
