// Native library: scalar types and scalar builtins with their adjoints.
// Owns: wp::half (float16), wp::bfloat16 and their conversions, bit casts, integer arithmetic with Warp's
// wrap-around semantics (and no traps: x / 0 == 0 for integers), float math over compiler
// builtins (host) or CUDA's device math (NVRTC), and adj_* twins that accumulate with +=.
// No standard library headers: compiles under clang (CPU JIT), g++ (tests) and NVRTC.
#pragma once

#include "launch_abi.h"

#define WP_FUNC inline WP_CALLABLE

#if defined(__CUDA_ARCH__)
#define WP_DEVICE_CODE 1
#else
#define WP_DEVICE_CODE 0
#endif

namespace wp {

// The tag of the constructors that leave a vec/mat/quat/transform uninitialised: generated code
// declares its single-assignment temporaries with it (engine/codegen/emit_cpp.cpp Decls), so the
// compiler sees no zero stores at function entry (clang's SROA grows with their live ranges).
struct cg_uninit_t {};
constexpr cg_uninit_t cg_uninit{};

constexpr float32 kPi = 3.14159265358979323846f;
constexpr float64 kPiD = 3.14159265358979323846;

// ---------------------------------------------------------------------------------------------
// Minimal type traits (no <type_traits>).
template <typename T> struct is_float_t { static constexpr bool value = false; };
template <> struct is_float_t<float32> { static constexpr bool value = true; };
template <> struct is_float_t<float64> { static constexpr bool value = true; };
template <bool B, typename T = void> struct enable_if_t_ {};
template <typename T> struct enable_if_t_<true, T> { typedef T type; };
template <typename A, typename B> struct is_same_t { static constexpr bool value = false; };
template <typename A> struct is_same_t<A, A> { static constexpr bool value = true; };

// ---------------------------------------------------------------------------------------------
// Bit casts.
WP_FUNC uint32 float_to_bits(float32 f) {
#if WP_DEVICE_CODE
  return __float_as_uint(f);
#else
  uint32 u;
  __builtin_memcpy(&u, &f, 4);
  return u;
#endif
}
WP_FUNC float32 bits_to_float(uint32 u) {
#if WP_DEVICE_CODE
  return __uint_as_float(u);
#else
  float32 f;
  __builtin_memcpy(&f, &u, 4);
  return f;
#endif
}
WP_FUNC uint64 double_to_bits(float64 d) {
#if WP_DEVICE_CODE
  return (uint64)__double_as_longlong(d);
#else
  uint64 u;
  __builtin_memcpy(&u, &d, 8);
  return u;
#endif
}
WP_FUNC float64 bits_to_double(uint64 u) {
#if WP_DEVICE_CODE
  return __longlong_as_double((long long)u);
#else
  float64 d;
  __builtin_memcpy(&d, &u, 8);
  return d;
#endif
}

// ---------------------------------------------------------------------------------------------
// IEEE binary16. Arithmetic promotes to float32 (as Warp does) and rounds back on assignment.
WP_FUNC uint16 float_to_half_bits(float32 f) {
#if WP_DEVICE_CODE
  unsigned short h;
  asm("cvt.rn.f16.f32 %0, %1;" : "=h"(h) : "f"(f));
  return h;
#else
  uint32 x = float_to_bits(f);
  uint32 sign = (x >> 16) & 0x8000u;
  uint32 ax = x & 0x7fffffffu;
  if (ax >= 0x7f800000u)  // inf or nan (keep nan quiet)
    return (uint16)(sign | 0x7c00u | (ax > 0x7f800000u ? (0x200u | ((ax >> 13) & 0x3ffu)) : 0u));
  if (ax >= 0x477ff000u) return (uint16)(sign | 0x7c00u);  // rounds to inf
  if (ax < 0x38800000u) {  // half subnormal or zero: let the FPU round (ulp of 0.5f is 2^-24)
    float32 r = bits_to_float(ax) + 0.5f;
    return (uint16)(sign | (float_to_bits(r) - 0x3f000000u));
  }
  uint32 odd = (ax >> 13) & 1u;
  ax += 0xc8000fffu + odd;  // rebias exponent by -112, round to nearest even
  return (uint16)(sign | (ax >> 13));
#endif
}

WP_FUNC float32 half_bits_to_float(uint16 h) {
#if WP_DEVICE_CODE
  float f;
  asm("cvt.f32.f16 %0, %1;" : "=f"(f) : "h"((unsigned short)h));
  return f;
#else
  uint32 sign = (uint32)(h & 0x8000u) << 16;
  uint32 e = (h >> 10) & 0x1fu;
  uint32 m = h & 0x3ffu;
  if (e == 0) {
    float32 v = (float32)m * 5.9604644775390625e-8f;  // m * 2^-24
    return sign ? -v : v;
  }
  if (e == 31) return bits_to_float(sign | 0x7f800000u | (m << 13));
  return bits_to_float(sign | ((e + 112u) << 23) | (m << 13));
#endif
}

struct half {
  uint16 u;

  WP_CALLABLE half() : u(0) {}
  WP_CALLABLE half(float32 f) : u(float_to_half_bits(f)) {}
  WP_CALLABLE half(float64 d) : u(float_to_half_bits((float32)d)) {}
  WP_CALLABLE half(int8 i) : u(float_to_half_bits((float32)i)) {}
  WP_CALLABLE half(uint8 i) : u(float_to_half_bits((float32)i)) {}
  WP_CALLABLE half(int16 i) : u(float_to_half_bits((float32)i)) {}
  WP_CALLABLE half(uint16 i) : u(float_to_half_bits((float32)i)) {}
  WP_CALLABLE half(int32 i) : u(float_to_half_bits((float32)i)) {}
  WP_CALLABLE half(uint32 i) : u(float_to_half_bits((float32)i)) {}
  WP_CALLABLE half(int64 i) : u(float_to_half_bits((float32)i)) {}
  WP_CALLABLE half(uint64 i) : u(float_to_half_bits((float32)i)) {}
  WP_CALLABLE half(bool b) : u(b ? 0x3c00u : 0u) {}
  WP_CALLABLE operator float32() const { return half_bits_to_float(u); }

  WP_CALLABLE half& operator+=(float32 v) { *this = half(float32(*this) + v); return *this; }
  WP_CALLABLE half& operator-=(float32 v) { *this = half(float32(*this) - v); return *this; }
  WP_CALLABLE half& operator*=(float32 v) { *this = half(float32(*this) * v); return *this; }
  WP_CALLABLE half& operator/=(float32 v) { *this = half(float32(*this) / v); return *this; }
  WP_CALLABLE static half from_bits(uint16 b) { half h; h.u = b; return h; }
};
typedef half float16;

template <> struct is_float_t<half> { static constexpr bool value = true; };

// ---------------------------------------------------------------------------------------------
// bfloat16: the upper 16 bits of a float32, rounded to nearest even (a NaN stays a quiet NaN).
// Arithmetic promotes to float32 and rounds back on assignment, as for half.
WP_FUNC uint16 float_to_bfloat16_bits(float32 f) {
  uint32 x = float_to_bits(f);
  if ((x & 0x7fffffffu) > 0x7f800000u) return (uint16)((x >> 16) | 0x40u);
  x += 0x7fffu + ((x >> 16) & 1u);
  return (uint16)(x >> 16);
}
WP_FUNC float32 bfloat16_bits_to_float(uint16 b) { return bits_to_float((uint32)b << 16); }

struct bfloat16 {
  uint16 u;

  WP_CALLABLE bfloat16() : u(0) {}
  WP_CALLABLE bfloat16(float32 f) : u(float_to_bfloat16_bits(f)) {}
  WP_CALLABLE bfloat16(float64 d) : u(float_to_bfloat16_bits((float32)d)) {}
  WP_CALLABLE bfloat16(half h) : u(float_to_bfloat16_bits((float32)h)) {}
  WP_CALLABLE bfloat16(int8 i) : u(float_to_bfloat16_bits((float32)i)) {}
  WP_CALLABLE bfloat16(uint8 i) : u(float_to_bfloat16_bits((float32)i)) {}
  WP_CALLABLE bfloat16(int16 i) : u(float_to_bfloat16_bits((float32)i)) {}
  WP_CALLABLE bfloat16(uint16 i) : u(float_to_bfloat16_bits((float32)i)) {}
  WP_CALLABLE bfloat16(int32 i) : u(float_to_bfloat16_bits((float32)i)) {}
  WP_CALLABLE bfloat16(uint32 i) : u(float_to_bfloat16_bits((float32)i)) {}
  WP_CALLABLE bfloat16(int64 i) : u(float_to_bfloat16_bits((float32)i)) {}
  WP_CALLABLE bfloat16(uint64 i) : u(float_to_bfloat16_bits((float32)i)) {}
  WP_CALLABLE bfloat16(bool b) : u(b ? 0x3f80u : 0u) {}
  WP_CALLABLE operator float32() const { return bfloat16_bits_to_float(u); }

  WP_CALLABLE bfloat16& operator+=(float32 v) { *this = bfloat16(float32(*this) + v); return *this; }
  WP_CALLABLE bfloat16& operator-=(float32 v) { *this = bfloat16(float32(*this) - v); return *this; }
  WP_CALLABLE bfloat16& operator*=(float32 v) { *this = bfloat16(float32(*this) * v); return *this; }
  WP_CALLABLE bfloat16& operator/=(float32 v) { *this = bfloat16(float32(*this) / v); return *this; }
  WP_CALLABLE static bfloat16 from_bits(uint16 b) { bfloat16 h; h.u = b; return h; }
};

template <> struct is_float_t<bfloat16> { static constexpr bool value = true; };

// ---------------------------------------------------------------------------------------------
// Classification (bit tests, valid under fast-math).
// +infinity and a quiet NaN from their bits (NVRTC has no __builtin_inf / __builtin_nan).
WP_FUNC float64 positive_inf() { return bits_to_double(0x7ff0000000000000ull); }
WP_FUNC float64 quiet_nan() { return bits_to_double(0x7ff8000000000000ull); }
WP_FUNC bool isnan(float32 x) { return (float_to_bits(x) & 0x7fffffffu) > 0x7f800000u; }
WP_FUNC bool isinf(float32 x) { return (float_to_bits(x) & 0x7fffffffu) == 0x7f800000u; }
WP_FUNC bool isfinite(float32 x) { return (float_to_bits(x) & 0x7f800000u) != 0x7f800000u; }
WP_FUNC bool isnan(float64 x) { return (double_to_bits(x) & 0x7fffffffffffffffull) > 0x7ff0000000000000ull; }
WP_FUNC bool isinf(float64 x) { return (double_to_bits(x) & 0x7fffffffffffffffull) == 0x7ff0000000000000ull; }
WP_FUNC bool isfinite(float64 x) { return (double_to_bits(x) & 0x7ff0000000000000ull) != 0x7ff0000000000000ull; }
WP_FUNC bool isnan(half x) { return (x.u & 0x7fffu) > 0x7c00u; }
WP_FUNC bool isinf(half x) { return (x.u & 0x7fffu) == 0x7c00u; }
WP_FUNC bool isfinite(half x) { return (x.u & 0x7c00u) != 0x7c00u; }
WP_FUNC bool isnan(bfloat16 x) { return (x.u & 0x7fffu) > 0x7f80u; }
WP_FUNC bool isinf(bfloat16 x) { return (x.u & 0x7fffu) == 0x7f80u; }
WP_FUNC bool isfinite(bfloat16 x) { return (x.u & 0x7f80u) != 0x7f80u; }
#define WP_INT_CLASSIFY(T) \
  WP_FUNC bool isnan(T) { return false; } \
  WP_FUNC bool isinf(T) { return false; } \
  WP_FUNC bool isfinite(T) { return true; }
WP_INT_CLASSIFY(int8) WP_INT_CLASSIFY(uint8) WP_INT_CLASSIFY(int16) WP_INT_CLASSIFY(uint16)
WP_INT_CLASSIFY(int32) WP_INT_CLASSIFY(uint32) WP_INT_CLASSIFY(int64) WP_INT_CLASSIFY(uint64)
#undef WP_INT_CLASSIFY

// ---------------------------------------------------------------------------------------------
// Float math: one function per builtin, float32 / float64 overloads; half goes through float32.
#if WP_DEVICE_CODE
#define WP_MATH1(name, fn32, fn64) \
  WP_FUNC float32 name(float32 x) { return ::fn32(x); } \
  WP_FUNC float64 name(float64 x) { return ::fn64(x); } \
  WP_FUNC half name(half x) { return half(::fn32(float32(x))); } \
  WP_FUNC bfloat16 name(bfloat16 x) { return bfloat16(::fn32(float32(x))); }
#define WP_MATH2(name, fn32, fn64) \
  WP_FUNC float32 name(float32 x, float32 y) { return ::fn32(x, y); } \
  WP_FUNC float64 name(float64 x, float64 y) { return ::fn64(x, y); } \
  WP_FUNC half name(half x, half y) { return half(::fn32(float32(x), float32(y))); } \
  WP_FUNC bfloat16 name(bfloat16 x, bfloat16 y) { return bfloat16(::fn32(float32(x), float32(y))); }
#else
#define WP_MATH1(name, fn32, fn64) \
  WP_FUNC float32 name(float32 x) { return __builtin_##fn32(x); } \
  WP_FUNC float64 name(float64 x) { return __builtin_##fn64(x); } \
  WP_FUNC half name(half x) { return half(__builtin_##fn32(float32(x))); } \
  WP_FUNC bfloat16 name(bfloat16 x) { return bfloat16(__builtin_##fn32(float32(x))); }
#define WP_MATH2(name, fn32, fn64) \
  WP_FUNC float32 name(float32 x, float32 y) { return __builtin_##fn32(x, y); } \
  WP_FUNC float64 name(float64 x, float64 y) { return __builtin_##fn64(x, y); } \
  WP_FUNC half name(half x, half y) { return half(__builtin_##fn32(float32(x), float32(y))); } \
  WP_FUNC bfloat16 name(bfloat16 x, bfloat16 y) { return bfloat16(__builtin_##fn32(float32(x), float32(y))); }
#endif

WP_MATH1(sin, sinf, sin)
WP_MATH1(cos, cosf, cos)
WP_MATH1(tan, tanf, tan)
WP_MATH1(asin_raw, asinf, asin)
WP_MATH1(acos_raw, acosf, acos)
WP_MATH1(atan, atanf, atan)
WP_MATH1(sinh, sinhf, sinh)
WP_MATH1(cosh, coshf, cosh)
WP_MATH1(tanh, tanhf, tanh)
WP_MATH1(sqrt, sqrtf, sqrt)
WP_MATH1(cbrt, cbrtf, cbrt)
WP_MATH1(log, logf, log)
WP_MATH1(log2, log2f, log2)
WP_MATH1(log10, log10f, log10)
WP_MATH1(exp, expf, exp)
WP_MATH1(erf, erff, erf)
WP_MATH1(erfc, erfcf, erfc)
WP_MATH1(floor, floorf, floor)
WP_MATH1(ceil, ceilf, ceil)
WP_MATH1(round, roundf, round)  // halves away from zero
WP_MATH1(rint, rintf, rint)     // halves to even
WP_MATH1(trunc, truncf, trunc)
WP_MATH2(atan2, atan2f, atan2)
WP_MATH2(pow, powf, pow)
WP_MATH2(copysign, copysignf, copysign)
WP_MATH2(fmod, fmodf, fmod)
#undef WP_MATH1
#undef WP_MATH2

// asin/acos clamp their input to [-1, 1] (Warp); NaN stays NaN.
#define WP_ARC(T) \
  WP_FUNC T asin(T x) { return isnan(x) ? x : asin_raw(x < T(-1) ? T(-1) : (x > T(1) ? T(1) : x)); } \
  WP_FUNC T acos(T x) { return isnan(x) ? x : acos_raw(x < T(-1) ? T(-1) : (x > T(1) ? T(1) : x)); }
WP_ARC(float32)
WP_ARC(float64)
WP_ARC(half)
WP_ARC(bfloat16)
#undef WP_ARC

// erfinv / erfcinv: CUDA has them; the host uses Giles' approximation (float) refined by
// Newton steps on erf (so float64 is accurate to a few ulp).
#if WP_DEVICE_CODE
WP_FUNC float32 erfinv(float32 x) { return ::erfinvf(x); }
WP_FUNC float64 erfinv(float64 x) { return ::erfinv(x); }
WP_FUNC float32 erfcinv(float32 x) { return ::erfcinvf(x); }
WP_FUNC float64 erfcinv(float64 x) { return ::erfcinv(x); }
#else
WP_FUNC float64 erfinv_giles(float64 x) {
  float64 w = -__builtin_log((1.0 - x) * (1.0 + x));
  float64 p;
  if (w < 5.0) {
    w = w - 2.5;
    p = 2.81022636e-08;
    p = 3.43273939e-07 + p * w;
    p = -3.5233877e-06 + p * w;
    p = -4.39150654e-06 + p * w;
    p = 0.00021858087 + p * w;
    p = -0.00125372503 + p * w;
    p = -0.00417768164 + p * w;
    p = 0.246640727 + p * w;
    p = 1.50140941 + p * w;
  } else {
    w = __builtin_sqrt(w) - 3.0;
    p = -0.000200214257;
    p = 0.000100950558 + p * w;
    p = 0.00134934322 + p * w;
    p = -0.00367342844 + p * w;
    p = 0.00573950773 + p * w;
    p = -0.0076224613 + p * w;
    p = 0.00943887047 + p * w;
    p = 1.00167406 + p * w;
    p = 2.83297682 + p * w;
  }
  return p * x;
}
WP_FUNC float64 erfinv(float64 x) {
  if (!(x > -1.0 && x < 1.0)) {
    if (x == 1.0) return positive_inf();
    if (x == -1.0) return -positive_inf();
    return quiet_nan();
  }
  float64 y = erfinv_giles(x);
  for (int it = 0; it < 2; ++it) {  // Newton on erf(y) - x
    float64 err = __builtin_erf(y) - x;
    y -= err / (1.1283791670955126 * __builtin_exp(-y * y));
  }
  return y;
}
WP_FUNC float32 erfinv(float32 x) { return (float32)erfinv((float64)x); }
WP_FUNC float64 erfcinv(float64 x) {
  if (!(x > 0.0 && x < 2.0)) {
    if (x == 0.0) return positive_inf();
    if (x == 2.0) return -positive_inf();
    return quiet_nan();
  }
  if (x > 1.0) return -erfcinv(2.0 - x);
  float64 y;
  if (x >= 0.0625) {
    y = erfinv_giles(1.0 - x);
    for (int it = 0; it < 3; ++it) {  // Newton on erfc(y) - x
      float64 err = __builtin_erfc(y) - x;
      y += err / (1.1283791670955126 * __builtin_exp(-y * y));
    }
    return y;
  }
  // Tail: Newton on log(erfc(y)) - log(x), which stays well scaled down to x ~ 1e-300.
  y = __builtin_sqrt(-__builtin_log(x));
  float64 log_x = __builtin_log(x);
  for (int it = 0; it < 60; ++it) {
    float64 e = __builtin_erfc(y);
    if (e == 0.0) break;
    float64 g = __builtin_log(e) - log_x;
    float64 dg = -1.1283791670955126 * __builtin_exp(-y * y) / e;
    float64 step = g / dg;
    y -= step;
    if (__builtin_fabs(step) <= 1e-16 * y) break;
  }
  return y;
}
WP_FUNC float32 erfcinv(float32 x) { return (float32)erfcinv((float64)x); }
#endif
WP_FUNC half erfinv(half x) { return half(erfinv(float32(x))); }
WP_FUNC half erfcinv(half x) { return half(erfcinv(float32(x))); }
WP_FUNC bfloat16 erfinv(bfloat16 x) { return bfloat16(erfinv(float32(x))); }
WP_FUNC bfloat16 erfcinv(bfloat16 x) { return bfloat16(erfcinv(float32(x))); }

// Float-only scalar builtins.
#define WP_FLOAT_OPS(T) \
  WP_FUNC T frac(T x) { return T(float64(x) - float64(trunc(x))); } \
  WP_FUNC T degrees(T x) { return T(float64(x) * (180.0 / kPiD)); } \
  WP_FUNC T radians(T x) { return T(float64(x) * (kPiD / 180.0)); } \
  WP_FUNC T div_approx(T a, T b) { return T(a / b); }
WP_FLOAT_OPS(float32)
WP_FLOAT_OPS(float64)
WP_FLOAT_OPS(half)
WP_FLOAT_OPS(bfloat16)
#undef WP_FLOAT_OPS

// ---------------------------------------------------------------------------------------------
// Arithmetic on floats (float32, float64; half through float32). min/max are C's fmin/fmax
// (Warp): a NaN operand is a missing value, the other operand wins; NaN only when both are.
// clamp(x, lo, hi) = min(max(lo, x), hi) inherits that (clamp(NaN, lo, hi) == min(lo, hi)).
#define WP_FLOAT_ARITH(T) \
  WP_FUNC T add(T a, T b) { return T(a + b); } \
  WP_FUNC T sub(T a, T b) { return T(a - b); } \
  WP_FUNC T mul(T a, T b) { return T(a * b); } \
  WP_FUNC T div(T a, T b) { return T(a / b); } \
  WP_FUNC T mod(T a, T b) { return fmod(a, b); } \
  WP_FUNC T floordiv(T a, T b) { return floor(T(a / b)); } \
  WP_FUNC T neg(T a) { return T(-a); } \
  WP_FUNC T pos(T a) { return a; } \
  WP_FUNC T min(T a, T b) { return isnan(a) ? b : (isnan(b) ? a : (a < b ? a : b)); } \
  WP_FUNC T max(T a, T b) { return isnan(a) ? b : (isnan(b) ? a : (a > b ? a : b)); } \
  WP_FUNC T clamp(T x, T lo, T hi) { return min(max(lo, x), hi); } \
  WP_FUNC T abs(T x) { return x < T(0) ? T(-x) : (x == T(0) ? T(0) : x); } \
  WP_FUNC T sign(T x) { return x < T(0) ? T(-1) : T(1); } \
  WP_FUNC T step(T x) { return x < T(0) ? T(1) : T(0); } \
  WP_FUNC T nonzero(T x) { return x == T(0) ? T(0) : T(1); } \
  WP_FUNC bool unot(T x) { return !(x != T(0)); }
WP_FLOAT_ARITH(float32)
WP_FLOAT_ARITH(float64)
WP_FLOAT_ARITH(half)
WP_FLOAT_ARITH(bfloat16)
#undef WP_FLOAT_ARITH

// ---------------------------------------------------------------------------------------------
// Integers: two's-complement wrap-around (computed in the unsigned twin, so no C++ UB), no
// traps: x / 0 == 0 and x % 0 == 0 (a CPU SIGFPE would kill the daemon), MIN / -1 == MIN.
// floordiv is Python's floor division; mod is C's truncated remainder (Warp: "truncated").
// Shifts use the count modulo the bit width (as x86 and PTX shf do); >> is arithmetic for signed.
// is_neg: x < 0 for signed types, false for unsigned (without -Wtype-limits noise).
#define WP_IS_NEG_S(T) WP_FUNC bool is_neg(T x) { return x < T(0); }
#define WP_IS_NEG_U(T) WP_FUNC bool is_neg(T) { return false; }
WP_IS_NEG_S(int8) WP_IS_NEG_U(uint8) WP_IS_NEG_S(int16) WP_IS_NEG_U(uint16)
WP_IS_NEG_S(int32) WP_IS_NEG_U(uint32) WP_IS_NEG_S(int64) WP_IS_NEG_U(uint64)
#undef WP_IS_NEG_S
#undef WP_IS_NEG_U

// T: the type, U: its unsigned twin, W: the unsigned type arithmetic runs in (at least 32 bits,
// so uint16 * uint16 never promotes to a signed int that overflows).
#define WP_INT_OPS(T, U, W, BITS, IS_SIGNED) \
  WP_FUNC T add(T a, T b) { return T(U(W(a) + W(b))); } \
  WP_FUNC T sub(T a, T b) { return T(U(W(a) - W(b))); } \
  WP_FUNC T mul(T a, T b) { return T(U(W(a) * W(b))); } \
  WP_FUNC T neg(T a) { return T(U(W(0) - W(a))); } \
  WP_FUNC T pos(T a) { return a; } \
  WP_FUNC T div(T a, T b) { \
    if (b == T(0)) return T(0); \
    if (IS_SIGNED && b == T(U(W(0) - W(1)))) return neg(a); \
    return T(a / b); \
  } \
  WP_FUNC T mod(T a, T b) { \
    if (b == T(0)) return T(0); \
    if (IS_SIGNED && b == T(U(W(0) - W(1)))) return T(0); \
    return T(a % b); \
  } \
  WP_FUNC T floordiv(T a, T b) { \
    T q = div(a, b); \
    if (b != T(0) && mod(a, b) != T(0) && (is_neg(a) != is_neg(b))) q = sub(q, T(1)); \
    return q; \
  } \
  WP_FUNC T min(T a, T b) { return a < b ? a : b; } \
  WP_FUNC T max(T a, T b) { return a > b ? a : b; } \
  WP_FUNC T clamp(T x, T lo, T hi) { return min(max(lo, x), hi); } \
  WP_FUNC T abs(T x) { return is_neg(x) ? neg(x) : x; } \
  WP_FUNC T sign(T x) { return is_neg(x) ? T(U(W(0) - W(1))) : T(1); } \
  WP_FUNC T step(T x) { return is_neg(x) ? T(1) : T(0); } \
  WP_FUNC T nonzero(T x) { return x == T(0) ? T(0) : T(1); } \
  WP_FUNC bool unot(T x) { return x == T(0); } \
  WP_FUNC T bit_and(T a, T b) { return T(a & b); } \
  WP_FUNC T bit_or(T a, T b) { return T(a | b); } \
  WP_FUNC T bit_xor(T a, T b) { return T(a ^ b); } \
  WP_FUNC T invert(T a) { return T(U(~W(a))); } \
  WP_FUNC T lshift(T a, T b) { return T(U(W(a) << (W(b) & W(BITS - 1)))); } \
  WP_FUNC T rshift(T a, T b) { return T(a >> (W(b) & W(BITS - 1))); } \
  WP_FUNC T div_approx(T a, T b) { return div(a, b); } \
  /* bit_count: set bits of the BITS-wide two's-complement pattern (Kernighan's loop). */ \
  WP_FUNC int32 bit_count(T a) { \
    W v = W(U(a)); \
    int32 n = 0; \
    while (v) { v &= v - 1u; ++n; } \
    return n; \
  } \
  /* pow: repeated squaring, wraps; negative exponents give 0 unless |a| == 1. */ \
  WP_FUNC T pow(T a, T b) { \
    if (is_neg(b)) { \
      if (a == T(1)) return T(1); \
      if (IS_SIGNED && a == T(U(W(0) - W(1)))) return (W(b) & 1u) ? a : T(1); \
      return T(0); \
    } \
    W r = 1, base = W(a), e = W(U(b)); \
    while (e) { if (e & 1u) r = r * base; base = base * base; e >>= 1; } \
    return T(U(r)); \
  }

WP_INT_OPS(int8, uint8, uint32, 8, true)
WP_INT_OPS(uint8, uint8, uint32, 8, false)
WP_INT_OPS(int16, uint16, uint32, 16, true)
WP_INT_OPS(uint16, uint16, uint32, 16, false)
WP_INT_OPS(int32, uint32, uint32, 32, true)
WP_INT_OPS(uint32, uint32, uint32, 32, false)
WP_INT_OPS(int64, uint64, uint64, 64, true)
WP_INT_OPS(uint64, uint64, uint64, 64, false)
#undef WP_INT_OPS

WP_FUNC bool unot(bool x) { return !x; }
WP_FUNC bool bit_and(bool a, bool b) { return a && b; }
WP_FUNC bool bit_or(bool a, bool b) { return a || b; }
WP_FUNC bool bit_xor(bool a, bool b) { return a != b; }


// where(cond, if_true, if_false) and select(cond, if_false, if_true), for any value type.
template <typename C, typename T>
WP_FUNC T where(C cond, const T& a, const T& b) { return cond ? a : b; }
template <typename C, typename T>
WP_FUNC T select(C cond, const T& if_false, const T& if_true) { return cond ? if_true : if_false; }

// lerp and smoothstep (float scalars; vector/matrix lerp in their headers).
#define WP_FLOAT_INTERP(T) \
  WP_FUNC T lerp(T a, T b, T t) { return T(a * (T(1) - t) + b * t); } \
  WP_FUNC T smoothstep(T e0, T e1, T x) { \
    T t = clamp(T((x - e0) / (e1 - e0)), T(0), T(1)); \
    return T(t * t * (T(3) - T(2) * t)); \
  }
WP_FLOAT_INTERP(float32)
WP_FLOAT_INTERP(float64)
WP_FLOAT_INTERP(half)
WP_FLOAT_INTERP(bfloat16)
#undef WP_FLOAT_INTERP

// Generic cast (wp.cast / constructors like wp.float32(x) are plain C++ casts).
template <typename To, typename From>
WP_FUNC To cast(const From& x) { return To(x); }

// ---------------------------------------------------------------------------------------------
// Adjoints of scalar builtins (Warp's convention: adj_f(args..., adj_args&..., adj_ret), +=).
// Templates cover float32, float64 and half (and only them, so they never compete with the
// vector/matrix overloads); integer overloads below are no-ops.
#define WP_SCALAR_FLOAT_TEMPLATE template <typename T, typename enable_if_t_<is_float_t<T>::value, int>::type = 0>
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_add(T, T, T& adj_a, T& adj_b, T adj_ret) { adj_a += adj_ret; adj_b += adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_sub(T, T, T& adj_a, T& adj_b, T adj_ret) { adj_a += adj_ret; adj_b -= adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_mul(T a, T b, T& adj_a, T& adj_b, T adj_ret) { adj_a += b * adj_ret; adj_b += a * adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_div(T a, T b, T& adj_a, T& adj_b, T adj_ret) {
  adj_a += adj_ret / b;
  adj_b -= adj_ret * (a / b) / b;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_div_approx(T a, T b, T& adj_a, T& adj_b, T adj_ret) { adj_div(a, b, adj_a, adj_b, adj_ret); }
// d fmod(a, b) = da - trunc(a / b) db
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_mod(T a, T b, T& adj_a, T& adj_b, T adj_ret) {
  adj_a += adj_ret;
  adj_b -= trunc(T(a / b)) * adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_floordiv(T, T, T&, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_neg(T, T& adj_a, T adj_ret) { adj_a -= adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_pos(T, T& adj_a, T adj_ret) { adj_a += adj_ret; }
// The gradient goes to the operand the forward returned: a NaN operand never gets it unless
// both are NaN (then b); ties: min -> b, max -> b (Warp).
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_min(T a, T b, T& adj_a, T& adj_b, T adj_ret) {
  if (!isnan(a) && (isnan(b) || a < b)) adj_a += adj_ret; else adj_b += adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_max(T a, T b, T& adj_a, T& adj_b, T adj_ret) {
  if (!isnan(a) && (isnan(b) || a > b)) adj_a += adj_ret; else adj_b += adj_ret;
}
// Below the range -> lo, above -> hi, inside or on a bound -> x (Warp). With a NaN operand,
// the chain rule of min(max(lo, x), hi): the gradient goes to the operand the forward returned.
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_clamp(T x, T lo, T hi, T& adj_x, T& adj_lo, T& adj_hi, T adj_ret) {
  if (isnan(x) || isnan(lo) || isnan(hi)) {
    T m = max(lo, x), adj_m = T(0);
    adj_min(m, hi, adj_m, adj_hi, adj_ret);
    adj_max(lo, x, adj_lo, adj_x, adj_m);
    return;
  }
  if (x < lo) adj_lo += adj_ret;
  else if (x > hi) adj_hi += adj_ret;
  else adj_x += adj_ret;
}
// abs'(0) = 1 (Warp).
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_abs(T x, T& adj_x, T adj_ret) {
  if (x < T(0)) adj_x -= adj_ret; else adj_x += adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_sign(T, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_step(T, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_nonzero(T, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_floor(T, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_ceil(T, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_round(T, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_rint(T, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_trunc(T, T&, T) {}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_frac(T, T& adj_x, T adj_ret) { adj_x += adj_ret; }
// d/dx copysign(x, y) = +1 when the sign bits of x and y agree (-0.0 counts as negative).
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_copysign(T x, T y, T& adj_x, T&, T adj_ret) {
  bool same = (copysign(T(1), x) < T(0)) == (copysign(T(1), y) < T(0));
  if (same) adj_x += adj_ret; else adj_x -= adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_sin(T x, T& adj_x, T adj_ret) { adj_x += cos(x) * adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_cos(T x, T& adj_x, T adj_ret) { adj_x -= sin(x) * adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_tan(T x, T& adj_x, T adj_ret) {
  T c = cos(x);
  adj_x += adj_ret / T(c * c);
}
// asin/acos: zero gradient at |x| >= 1 where the derivative is unbounded (Warp).
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_asin(T x, T& adj_x, T adj_ret) {
  T d = sqrt(T(T(1) - x * x));
  if (d > T(0)) adj_x += adj_ret / d;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_acos(T x, T& adj_x, T adj_ret) {
  T d = sqrt(T(T(1) - x * x));
  if (d > T(0)) adj_x -= adj_ret / d;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_atan(T x, T& adj_x, T adj_ret) { adj_x += adj_ret / T(T(1) + x * x); }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_atan2(T y, T x, T& adj_y, T& adj_x, T adj_ret) {
  T d = T(x * x + y * y);
  if (d > T(0)) {
    adj_y += x / d * adj_ret;
    adj_x -= y / d * adj_ret;
  }
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_sinh(T x, T& adj_x, T adj_ret) { adj_x += cosh(x) * adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_cosh(T x, T& adj_x, T adj_ret) { adj_x += sinh(x) * adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_tanh(T x, T& adj_x, T adj_ret) {
  T t = tanh(x);
  adj_x += T(T(1) - t * t) * adj_ret;
}
// sqrt'(0) = +inf (Warp).
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_sqrt(T x, T& adj_x, T adj_ret) { adj_x += T(0.5f) / sqrt(x) * adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_cbrt(T x, T& adj_x, T adj_ret) {
  T c = cbrt(x);
  adj_x += adj_ret / T(T(3) * c * c);
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_log(T x, T& adj_x, T adj_ret) { adj_x += adj_ret / x; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_log2(T x, T& adj_x, T adj_ret) { adj_x += adj_ret / T(x * T(0.69314718055994530942)); }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_log10(T x, T& adj_x, T adj_ret) { adj_x += adj_ret / T(x * T(2.30258509299404568402)); }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_exp(T x, T& adj_x, T adj_ret) { adj_x += exp(x) * adj_ret; }
// d x^y: dx = y x^(y-1); dy = log(x) x^y for x > 0, and 0 for x <= 0 (undefined there).
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_pow(T x, T y, T& adj_x, T& adj_y, T adj_ret) {
  adj_x += y * pow(x, T(y - T(1))) * adj_ret;
  if (x > T(0)) adj_y += log(x) * pow(x, y) * adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_erf(T x, T& adj_x, T adj_ret) {
  adj_x += T(1.1283791670955126) * exp(T(-x * x)) * adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_erfc(T x, T& adj_x, T adj_ret) {
  adj_x -= T(1.1283791670955126) * exp(T(-x * x)) * adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_erfinv(T x, T& adj_x, T adj_ret) {
  T r = erfinv(x);
  adj_x += T(0.88622692545275801) * exp(T(r * r)) * adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_erfcinv(T x, T& adj_x, T adj_ret) {
  T r = erfcinv(x);
  adj_x -= T(0.88622692545275801) * exp(T(r * r)) * adj_ret;
}
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_degrees(T, T& adj_x, T adj_ret) { adj_x += T(180.0 / kPiD) * adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_radians(T, T& adj_x, T adj_ret) { adj_x += T(kPiD / 180.0) * adj_ret; }
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_lerp(T a, T b, T t, T& adj_a, T& adj_b, T& adj_t, T adj_ret) {
  adj_a += T(T(1) - t) * adj_ret;
  adj_b += t * adj_ret;
  adj_t += T(b - a) * adj_ret;
}
// Zero gradient outside [e0, e1] (clamped region).
WP_SCALAR_FLOAT_TEMPLATE WP_FUNC void adj_smoothstep(T e0, T e1, T x, T& adj_e0, T& adj_e1, T& adj_x, T adj_ret) {
  T w = T(e1 - e0);
  T t = T((x - e0) / w);
  if (t < T(0) || t > T(1)) return;
  T ds = T(T(6) * t * (T(1) - t)) * adj_ret;
  adj_x += ds / w;
  adj_e0 += ds * T((x - e1) / (w * w));
  adj_e1 -= ds * T(t / w);
}
template <typename C, typename CA, typename T>
WP_FUNC void adj_where(C cond, const T&, const T&, CA&, T& adj_a, T& adj_b, const T& adj_ret) {
  if (cond) adj_a += adj_ret; else adj_b += adj_ret;
}
template <typename C, typename CA, typename T>
WP_FUNC void adj_select(C cond, const T&, const T&, CA&, T& adj_f, T& adj_t, const T& adj_ret) {
  if (cond) adj_t += adj_ret; else adj_f += adj_ret;
}
template <typename To, typename From>
WP_FUNC void adj_cast(const From&, From& adj_x, const To& adj_ret) { adj_x += From(adj_ret); }

// Integer adjoints: no-ops (integers carry no gradient; also avoids integer division traps).
#define WP_INT_ADJ(T) \
  WP_FUNC void adj_add(T, T, T&, T&, T) {} \
  WP_FUNC void adj_sub(T, T, T&, T&, T) {} \
  WP_FUNC void adj_mul(T, T, T&, T&, T) {} \
  WP_FUNC void adj_div(T, T, T&, T&, T) {} \
  WP_FUNC void adj_mod(T, T, T&, T&, T) {} \
  WP_FUNC void adj_floordiv(T, T, T&, T&, T) {} \
  WP_FUNC void adj_pow(T, T, T&, T&, T) {} \
  WP_FUNC void adj_neg(T, T&, T) {} \
  WP_FUNC void adj_pos(T, T&, T) {} \
  WP_FUNC void adj_min(T, T, T&, T&, T) {} \
  WP_FUNC void adj_max(T, T, T&, T&, T) {} \
  WP_FUNC void adj_clamp(T, T, T, T&, T&, T&, T) {} \
  WP_FUNC void adj_abs(T, T&, T) {} \
  WP_FUNC void adj_sign(T, T&, T) {} \
  WP_FUNC void adj_step(T, T&, T) {} \
  WP_FUNC void adj_nonzero(T, T&, T) {} \
  WP_FUNC void adj_bit_and(T, T, T&, T&, T) {} \
  WP_FUNC void adj_bit_or(T, T, T&, T&, T) {} \
  WP_FUNC void adj_bit_xor(T, T, T&, T&, T) {} \
  WP_FUNC void adj_lshift(T, T, T&, T&, T) {} \
  WP_FUNC void adj_rshift(T, T, T&, T&, T) {} \
  WP_FUNC void adj_invert(T, T&, T) {}
WP_INT_ADJ(int8) WP_INT_ADJ(uint8) WP_INT_ADJ(int16) WP_INT_ADJ(uint16)
WP_INT_ADJ(int32) WP_INT_ADJ(uint32) WP_INT_ADJ(int64) WP_INT_ADJ(uint64)
#undef WP_INT_ADJ

}  // namespace wp
