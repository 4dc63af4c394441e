// Host-side definitions of the callbacks that generated CPU code calls (print.h:
// weft_host_snprintf), for weft::jit::CpuJitOptions::host_symbols. Included by the daemon's
// C++ (runtime / JIT setup), never by generated code, so it may use the standard library.
#pragma once

#include <cstdarg>
#include <cstdio>
#include <map>
#include <string>

namespace weft::native {

// snprintf with the signature print.h declares.
inline int HostSnprintf(char* buf, unsigned long size, const char* fmt, ...) {
  va_list args;
  va_start(args, fmt);
  int written = std::vsnprintf(buf, size, fmt, args);
  va_end(args);
  return written;
}

// name -> address, to merge into CpuJitOptions::host_symbols.
inline std::map<std::string, void*> HostSymbols() {
  return {{"weft_host_snprintf", reinterpret_cast<void*>(&HostSnprintf)}};
}

}  // namespace weft::native
