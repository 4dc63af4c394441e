// wp.printf formats, checked when the kernel is compiled: the format must be a literal whose
// conversions match the scalar arguments one to one, with only the conversions Warp's
// printf supports: d i u x X o for integers and bools, f F e E g G a A for floats, each with
// optional flags (- + space # 0), width and precision (up to 3 digits each, no `*`), and `%%`.
// Anything else (%s %p %n %c, `*`, a missing or extra argument, a NUL byte) is a compile
// error. Length modifiers the user wrote (hh h l ll) are replaced by the ones the daemon's
// argument promotion needs (engine/native/print.h: 64-bit integers get `ll`, everything else
// none), so the format that reaches the native printf always matches what is passed.
#pragma once

#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/sema/types.h"

namespace weft::sema {

// The normalized format, or InvalidArgument with a message that names the conversion and the
// argument (the caller adds the file:line).
Expected<std::string> CheckPrintfFormat(const std::string& format, const std::vector<Type>& args);

// `text` printed literally by a format: every '%' doubled.
std::string LiteralFormat(const std::string& text);

}  // namespace weft::sema
