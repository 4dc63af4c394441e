// Native library: kernel output. wp::print(ctx, value) for every value type (Warp's formats) and
// wp::printf(ctx, fmt, args...), which re-checks its format against its arguments' types and
// prints "[weft: wp.printf format rejected]" instead of formatting a mismatch.
// CPU: text is formatted by the host callback weft_host_snprintf (exported by the daemon process, resolved by the JIT) and appended to
// ctx->print, one reservation per call (atomic add on `used`) so lines of different threads never
// interleave; text past `capacity` is dropped (used > capacity tells the reader it overflowed).
// CUDA: device printf.
#pragma once

#include "transform.h"

#if !WP_DEVICE_CODE
// snprintf-compatible. Weak so that a process that does not export it still links; prints are
// then dropped.
extern "C" __attribute__((weak)) int weft_host_snprintf(char* buf, unsigned long size, const char* fmt, ...);
#endif

namespace wp {

// Appends n bytes to the launch's print buffer.
WP_FUNC void print_buffer_append(const launch_context_t* ctx, const char* s, uint64 n) {
#if !WP_DEVICE_CODE
  if (!ctx || !ctx->print || !ctx->print->data || n == 0) return;
  print_buffer_t* pb = ctx->print;
  uint64 off = __atomic_fetch_add(&pb->used, n, __ATOMIC_RELAXED);
  if (off >= pb->capacity) return;
  uint64 m = pb->capacity - off < n ? pb->capacity - off : n;
  __builtin_memcpy(pb->data + off, s, m);
#endif
}

// Variadic arguments as C varargs expect them: half -> double, float -> double, bool -> int.
template <typename T> WP_FUNC T print_arg(T v) { return v; }
WP_FUNC float64 print_arg(float32 v) { return (float64)v; }
WP_FUNC float64 print_arg(half v) { return (float64)(float32)v; }
WP_FUNC int32 print_arg(bool v) { return v ? 1 : 0; }
WP_FUNC int32 print_arg(int8 v) { return v; }
WP_FUNC int32 print_arg(int16 v) { return v; }
WP_FUNC uint32 print_arg(uint8 v) { return v; }
WP_FUNC uint32 print_arg(uint16 v) { return v; }

// A line built piecewise; on CUDA each piece goes straight to printf.
struct print_line {
#if !WP_DEVICE_CODE
  char buf[1024];
#endif
  int n;
  WP_CALLABLE print_line() : n(0) {
#if !WP_DEVICE_CODE
    buf[0] = '\0';
#endif
  }
  template <typename... A>
  WP_CALLABLE void add(const char* fmt, A... args) {
#if WP_DEVICE_CODE
    ::printf(fmt, print_arg(args)...);
#else
    buf[n] = '\0';
    // Read through a volatile so the weak symbol's null test is not folded away (or warned about).
    int (*volatile fn)(char*, unsigned long, const char*, ...) = &weft_host_snprintf;
    if (!fn || n >= (int)sizeof(buf) - 1) return;
    int w = fn(buf + n, sizeof(buf) - (unsigned long)n, fmt, print_arg(args)...);
    if (w > 0) n = (n + w < (int)sizeof(buf) - 1) ? n + w : (int)sizeof(buf) - 1;
    buf[n] = '\0';
#endif
  }
  WP_CALLABLE void flush(const launch_context_t* ctx) {
#if !WP_DEVICE_CODE
    print_buffer_append(ctx, buf, (uint64)n);
#endif
  }
  // The text so far (host only; empty on CUDA).
  WP_CALLABLE const char* text() const {
#if !WP_DEVICE_CODE
    return buf;
#else
    return "";
#endif
  }
};

// What a promoted printf argument is, for printf_format_ok: 'i' a 32-bit integer, 'I' a
// 64-bit one, 'f' a double. No other type has a kind, so passing one does not compile.
WP_FUNC char printf_kind(int32) { return 'i'; }
WP_FUNC char printf_kind(uint32) { return 'i'; }
WP_FUNC char printf_kind(int64) { return 'I'; }
WP_FUNC char printf_kind(uint64) { return 'I'; }
WP_FUNC char printf_kind(float64) { return 'f'; }

// Defence in depth behind the compiler's check (engine/sema/printf_format.h): true when `fmt`
// has exactly one conversion per entry of `kinds` (NUL-terminated), each of the form the
// compiler emits: %[-+ #0]*[0-9]{0,3}(.[0-9]{0,3})? then `ll` + d i u x X o for 'I', d i u x X o
// for 'i', f F e E g G a A for 'f'; and `%%`. Nothing else (%s %p %n %c, `*`) passes.
WP_FUNC bool printf_format_ok(const char* fmt, const char* kinds) {
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

template <typename... A>
WP_FUNC void printf(const launch_context_t* ctx, const char* fmt, A... args) {
  const char kinds[] = {printf_kind(print_arg(args))..., '\0'};
  print_line line;
  if (printf_format_ok(fmt, kinds)) line.add(fmt, args...);
  else line.add("[weft: wp.printf format rejected]\n");
  line.flush(ctx);
}

// Scalars, one per line.
WP_FUNC void print_value(print_line& l, float32 v) { l.add("%g", v); }
WP_FUNC void print_value(print_line& l, float64 v) { l.add("%g", v); }
WP_FUNC void print_value(print_line& l, half v) { l.add("%g", v); }
WP_FUNC void print_value(print_line& l, bool v) { l.add("%s", v ? "True" : "False"); }
WP_FUNC void print_value(print_line& l, int8 v) { l.add("%d", v); }
WP_FUNC void print_value(print_line& l, int16 v) { l.add("%d", v); }
WP_FUNC void print_value(print_line& l, int32 v) { l.add("%d", v); }
WP_FUNC void print_value(print_line& l, int64 v) { l.add("%lld", v); }
WP_FUNC void print_value(print_line& l, uint8 v) { l.add("%u", v); }
WP_FUNC void print_value(print_line& l, uint16 v) { l.add("%u", v); }
WP_FUNC void print_value(print_line& l, uint32 v) { l.add("%u", v); }
WP_FUNC void print_value(print_line& l, uint64 v) { l.add("%llu", v); }
WP_FUNC void print_value(print_line& l, const char* s) { l.add("%s", s); }
// Composites: components separated by spaces; matrices one row per line.
template <unsigned N, typename T> WP_FUNC void print_value(print_line& l, const vec_t<N, T>& v) {
  for (unsigned i = 0; i < N; ++i) {
    if (i) l.add(" ");
    print_value(l, v.c[i]);
  }
}
template <typename T> WP_FUNC void print_value(print_line& l, const quat_t<T>& q) {
  for (int i = 0; i < 4; ++i) {
    if (i) l.add(" ");
    print_value(l, q[i]);
  }
}
template <unsigned R, unsigned C, typename T> WP_FUNC void print_value(print_line& l, const mat_t<R, C, T>& m) {
  for (unsigned i = 0; i < R; ++i) {
    if (i) l.add("\n");
    print_value(l, m.get_row(i));
  }
}
template <typename T> WP_FUNC void print_value(print_line& l, const transform_t<T>& t) {
  l.add("(");
  print_value(l, t.p);
  l.add(") (");
  print_value(l, t.q);
  l.add(")");
}
// Types without a printed form (structs): Warp's placeholder text.
template <typename T> WP_FUNC void print_value(print_line& l, const T&) { l.add("<type without print implementation>"); }
template <typename T> WP_FUNC void print_value(print_line& l, const array_t<T>& a) {
  l.add("array(ndim=%d, shape=(%lld", a.ndim, (long long)a.shape[0]);
  for (int d = 1; d < a.ndim && d < ARRAY_MAX_DIMS; ++d) l.add(", %lld", (long long)a.shape[d]);
  l.add("))");
}

template <typename T>
WP_FUNC void print(const launch_context_t* ctx, const T& value) {
  print_line line;
  print_value(line, value);
  line.add("\n");
  line.flush(ctx);
}

}  // namespace wp
