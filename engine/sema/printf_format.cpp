// wp.printf format checking and normalization (see printf_format.h).
#include "engine/sema/printf_format.h"

#include <cstdio>

namespace weft::sema {
namespace {

bool IsIntConversion(char c) { return c == 'd' || c == 'i' || c == 'u' || c == 'x' || c == 'X' || c == 'o'; }
bool IsFloatConversion(char c) {
  return c == 'f' || c == 'F' || c == 'e' || c == 'E' || c == 'g' || c == 'G' || c == 'a' || c == 'A';
}

std::string Shown(char c) {
  auto u = static_cast<unsigned char>(c);
  if (u >= 0x20 && u < 0x7f) return std::string("%") + c;
  char buf[16];
  std::snprintf(buf, sizeof buf, "%%\\x%02x", u);
  return buf;
}

}  // namespace

std::string LiteralFormat(const std::string& text) {
  std::string out;
  for (char c : text) {
    out += c;
    if (c == '%') out += '%';
  }
  return out;
}

Expected<std::string> CheckPrintfFormat(const std::string& format, const std::vector<Type>& args) {
  constexpr const char* kAllowed = "allowed: d i u x X o for integers, f F e E g G a A for floats, and %%";
  if (format.find('\0') != std::string::npos) return InvalidArgument("wp.printf format contains a NUL byte");
  std::string out;
  size_t next_arg = 0;
  for (size_t i = 0; i < format.size(); ++i) {
    char c = format[i];
    if (c != '%') {
      out += c;
      continue;
    }
    if (i + 1 < format.size() && format[i + 1] == '%') {
      out += "%%";
      ++i;
      continue;
    }
    const size_t start = i++;
    std::string spec = "%";
    while (i < format.size() && (format[i] == '-' || format[i] == '+' || format[i] == ' ' || format[i] == '#' ||
                                 format[i] == '0'))
      spec += format[i++];
    auto digits = [&](const char* what) -> Status {
      size_t n = 0;
      while (i < format.size() && format[i] >= '0' && format[i] <= '9') spec += format[i++], ++n;
      if (n > 3) return InvalidArgument("wp.printf format: the " + std::string(what) + " of conversion " +
                                        std::to_string(next_arg + 1) + " has more than 3 digits");
      return Status::Ok();
    };
    if (i < format.size() && format[i] == '*')
      return InvalidArgument("wp.printf format: '*' (width or precision from an argument) is not supported");
    WEFT_RETURN_IF_ERROR(digits("width"));
    if (i < format.size() && format[i] == '.') {
      spec += format[i++];
      if (i < format.size() && format[i] == '*')
        return InvalidArgument("wp.printf format: '*' (width or precision from an argument) is not supported");
      WEFT_RETURN_IF_ERROR(digits("precision"));
    }
    // Length modifiers are accepted and replaced (see printf_format.h).
    if (i < format.size() && (format[i] == 'h' || format[i] == 'l')) {
      char m = format[i++];
      if (i < format.size() && format[i] == m) ++i;
    }
    if (i >= format.size())
      return InvalidArgument("wp.printf format ends inside a conversion ('" + format.substr(start) + "'); write %% for a percent sign");
    char conv = format[i];
    if (!IsIntConversion(conv) && !IsFloatConversion(conv))
      return InvalidArgument("wp.printf format: conversion " + Shown(conv) + " is not supported (" + kAllowed + ")");
    if (next_arg >= args.size())
      return InvalidArgument("wp.printf format has more conversions than arguments (" + std::to_string(args.size()) +
                             " given)");
    const Type& t = args[next_arg];
    if (!t.is_scalar())
      return InvalidArgument("wp.printf argument " + std::to_string(next_arg + 1) + " is not a scalar");
    bool is_float = IsFloat(t.scalar);
    if (IsIntConversion(conv) && is_float)
      return InvalidArgument("wp.printf format: conversion " + Shown(conv) + " expects an integer but argument " +
                             std::to_string(next_arg + 1) + " is " + TypeString(t) + " (use %f, %e or %g)");
    if (IsFloatConversion(conv) && !is_float)
      return InvalidArgument("wp.printf format: conversion " + Shown(conv) + " expects a float but argument " +
                             std::to_string(next_arg + 1) + " is " + TypeString(t) + " (use %d, %u or %x)");
    if (!is_float && t.scalar != ScalarKind::kBool && ScalarSize(t.scalar) == 8) spec += "ll";
    spec += conv;
    out += spec;
    ++next_arg;
  }
  if (next_arg != args.size())
    return InvalidArgument("wp.printf format has " + std::to_string(next_arg) + " conversion(s) but " +
                           std::to_string(args.size()) + " argument(s) were given");
  return out;
}

}  // namespace weft::sema
