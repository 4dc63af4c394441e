// Native library: the format check behind wp.printf, shared by generated code (print.h, which
// runs it before formatting on the CPU and before recording a GPU line) and the daemon (which
// runs it again on every piece of a GPU print record before formatting it,
// engine/device/cuda_print.cpp). No standard library headers: compiles under clang, g++ and NVRTC.
#pragma once

#include "launch_abi.h"

namespace wp {

// Defence in depth behind the compiler's check (engine/sema/printf_format.h): true when `fmt`
// has exactly one conversion per entry of `kinds` (NUL-terminated), each of the form the
// compiler emits: %[-+ #0]*[0-9]{0,3}(.[0-9]{0,3})? then `ll` + d i u x X o for 'I', d i u x X o
// for 'i', f F e E g G a A for 'f'; and `%%`. Nothing else (%s %p %n %c, `*`) passes.
inline WP_CALLABLE bool printf_format_ok(const char* fmt, const char* kinds) {
  int k = 0;
  for (int i = 0; fmt[i]; ++i) {
    if (fmt[i] != '%') continue;
    ++i;
    if (fmt[i] == '%') continue;
    while (fmt[i] == '-' || fmt[i] == '+' || fmt[i] == ' ' || fmt[i] == '#' || fmt[i] == '0') ++i;
    for (int d = 0; d < 3 && fmt[i] >= '0' && fmt[i] <= '9'; ++d) ++i;
    if (fmt[i] == '.') {
      ++i;
      for (int d = 0; d < 3 && fmt[i] >= '0' && fmt[i] <= '9'; ++d) ++i;
    }
    bool ll = fmt[i] == 'l' && fmt[i + 1] == 'l';
    if (ll) i += 2;
    char c = fmt[i];
    bool is_int = c == 'd' || c == 'i' || c == 'u' || c == 'x' || c == 'X' || c == 'o';
    bool is_float = c == 'f' || c == 'F' || c == 'e' || c == 'E' || c == 'g' || c == 'G' || c == 'a' || c == 'A';
    char kind = kinds[k];
    if (kind == '\0') return false;  // more conversions than arguments
    if (!((is_int && kind == (ll ? 'I' : 'i')) || (is_float && !ll && kind == 'f'))) return false;
    ++k;
  }
  return kinds[k] == '\0';
}

}  // namespace wp
