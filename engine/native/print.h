// Native library: kernel output. wp::print(ctx, value) for every value type (Warp's formats) and
// wp::printf(ctx, fmt, args...), which re-checks its format against its arguments' types and
// prints "[weft: wp.printf format rejected]" instead of formatting a mismatch.
// CPU: text is formatted by the host callback weft_host_snprintf (exported by the daemon process, resolved by the JIT) and appended to
// ctx->print, one reservation per call (atomic add on `used`) so lines of different threads never
// interleave; text past `capacity` is dropped (used > capacity tells the reader it overflowed).
// CUDA: each line is one binary record (print_record: the format pieces and their argument
// values) appended to ctx->print (device memory) with one atomic reservation; the daemon turns
// the records into text with the host's snprintf at the next synchronize
// (engine/device/cuda_print.h), so a line reads the same on both devices. The daemon re-checks
// every piece's format against its argument kinds (printf_check.h) before formatting.
#pragma once

#include "printf_check.h"
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
WP_FUNC float64 print_arg(bfloat16 v) { return (float64)(float32)v; }
WP_FUNC int32 print_arg(bool v) { return v ? 1 : 0; }
WP_FUNC int32 print_arg(int8 v) { return v; }
WP_FUNC int32 print_arg(int16 v) { return v; }
WP_FUNC uint32 print_arg(uint8 v) { return v; }
WP_FUNC uint32 print_arg(uint16 v) { return v; }

// ---- GPU print records ---------------------------------------------------------------------
// A record: u32 size (the whole record, this field included), then its pieces, each
//   u16 fmt_len, the format's bytes (no NUL), u8 nargs, nargs kind bytes, then the arguments:
//   'i' (32-bit integer, widened to 8 bytes), 'I' (64-bit integer), 'f' (double): 8 bytes
//   little-endian; 's' (a string: only as the single argument of the format "%s"): u16 length
//   and the bytes. Unaligned; built in the thread's own memory, then copied in one piece.
constexpr int PRINT_RECORD_MAX = 1024;

WP_FUNC char print_record_kind(int32) { return 'i'; }
WP_FUNC char print_record_kind(uint32) { return 'i'; }
WP_FUNC char print_record_kind(int64) { return 'I'; }
WP_FUNC char print_record_kind(uint64) { return 'I'; }
WP_FUNC char print_record_kind(float64) { return 'f'; }
WP_FUNC char print_record_kind(const char*) { return 's'; }

struct print_record {
  char buf[PRINT_RECORD_MAX];
  int n;       // bytes used, the size field included
  bool full;   // a piece did not fit: it and every later one are left out
  WP_CALLABLE print_record() : n(4), full(false) {}
  WP_CALLABLE bool put(const void* p, int k) {
    if (full || k < 0 || n + k > PRINT_RECORD_MAX) return false;
    for (int i = 0; i < k; ++i) buf[n + i] = static_cast<const char*>(p)[i];
    n += k;
    return true;
  }
  WP_CALLABLE bool put_arg(int32 v) { int64 w = v; return put(&w, 8); }
  WP_CALLABLE bool put_arg(uint32 v) { int64 w = (int64)(int32)v; return put(&w, 8); }
  WP_CALLABLE bool put_arg(int64 v) { return put(&v, 8); }
  WP_CALLABLE bool put_arg(uint64 v) { return put(&v, 8); }
  WP_CALLABLE bool put_arg(float64 v) { return put(&v, 8); }
  WP_CALLABLE bool put_arg(const char* s) {
    int len = 0;
    while (s && s[len] && len < PRINT_RECORD_MAX) ++len;
    uint16 l = (uint16)len;
    return put(&l, 2) && put(s, len);
  }
  template <typename... A>
  WP_CALLABLE void add(const char* fmt, A... args) {
    if (full) return;
    const int saved = n;
    int len = 0;
    while (fmt[len] && len < PRINT_RECORD_MAX) ++len;
    const uint16 flen = (uint16)len;
    const uint8 nargs = (uint8)sizeof...(A);
    const char kinds[] = {print_record_kind(print_arg(args))..., '\0'};
    bool ok = put(&flen, 2) && put(fmt, len) && put(&nargs, 1) && put(kinds, (int)nargs);
    ok = ok && (put_arg(print_arg(args)) && ...);
    if (!ok) {
      n = saved;
      full = true;
    }
  }
  // The finished record (size field filled in); size() bytes.
  WP_CALLABLE const char* bytes() {
    const uint32 size = (uint32)n;
    for (int i = 0; i < 4; ++i) buf[i] = (char)((size >> (8 * i)) & 0xffu);
    return buf;
  }
  WP_CALLABLE int size() const { return n; }
};

// Appends a finished record to the launch's print buffer with one reservation. A record that
// would run past `capacity` is left out (only its size field is written when it fits, so the
// reader knows where the text ends); `used` keeps counting, and used > capacity tells the
// reader that output was dropped.
WP_FUNC void print_record_flush(const launch_context_t* ctx, print_record& r) {
#if WP_DEVICE_CODE
  if (!ctx || !ctx->print || !ctx->print->data || r.size() <= 4) return;
  print_buffer_t* pb = ctx->print;
  const char* src = r.bytes();
  const uint64 n = (uint64)r.size();
  const uint64 off = atomicAdd((unsigned long long*)&pb->used, (unsigned long long)n);
  if (ctx->report_flag) *(volatile int32*)ctx->report_flag = 1;   // read back at the synchronize
  if (off >= pb->capacity || pb->capacity - off < 4) return;
  const uint64 m = pb->capacity - off < n ? 4 : n;
  for (uint64 i = 0; i < m; ++i) pb->data[off + i] = src[i];
#else
  (void)ctx;
  (void)r;
#endif
}

// A line built piecewise: text formatted at once on the CPU, a record on a GPU.
struct print_line {
#if WP_DEVICE_CODE
  print_record rec;
#else
  char buf[1024];
  int n;
#endif
  WP_CALLABLE print_line() {
#if !WP_DEVICE_CODE
    n = 0;
    buf[0] = '\0';
#endif
  }
  template <typename... A>
  WP_CALLABLE void add(const char* fmt, A... args) {
#if WP_DEVICE_CODE
    rec.add(fmt, args...);
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
#if WP_DEVICE_CODE
    print_record_flush(ctx, rec);
#else
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
WP_FUNC void print_value(print_line& l, bfloat16 v) { l.add("%g", v); }
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
// Arrays have no printed form in Warp either (its placeholder).
template <typename T> WP_FUNC void print_value(print_line& l, const array_t<T>&) {
  l.add("<type without print implementation>");
}

// print(): Warp's layout puts a space after every component of a vector (and of each matrix
// row, one row per line); other values as print_value.
template <typename T> WP_FUNC void print_spaced(print_line& l, const T& v) { print_value(l, v); }
template <unsigned N, typename T> WP_FUNC void print_spaced(print_line& l, const vec_t<N, T>& v) {
  for (unsigned i = 0; i < N; ++i) {
    print_value(l, v.c[i]);
    l.add(" ");
  }
}
template <unsigned R, unsigned C, typename T> WP_FUNC void print_spaced(print_line& l, const mat_t<R, C, T>& m) {
  for (unsigned i = 0; i < R; ++i) {
    if (i) l.add("\n");
    print_spaced(l, m.get_row(i));
  }
}

template <typename T>
WP_FUNC void print(const launch_context_t* ctx, const T& value) {
  print_line line;
  print_spaced(line, value);
  line.add("\n");
  line.flush(ctx);
}

// The reverse code of print(value): one "adj: <adjoint>" line (Warp's adj_print); a matrix's
// later rows are indented under the first.
template <typename T>
WP_FUNC void adj_print(const launch_context_t* ctx, const T&, const T& adj) {
  print_line line;
  line.add("adj: ");
  print_value(line, adj);
  line.add("\n");
  line.flush(ctx);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_print(const launch_context_t* ctx, const mat_t<R, C, T>&, const mat_t<R, C, T>& adj) {
  print_line line;
  for (unsigned i = 0; i < R; ++i) {
    line.add(i ? "     " : "adj: ");
    print_value(line, adj.get_row(i));
    line.add("\n");
  }
  line.flush(ctx);
}

}  // namespace wp
