// Tests of engine/native/scalar.h: float math against float64 references on random and hard
// inputs (NaN/inf propagation, huge/tiny magnitudes), integer semantics (wrap-around, no traps,
// floor division, truncated remainder, shifts), float16 conversions against the compiler's
// _Float16, and classification.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "engine/native/weft.h"

namespace {

std::vector<float> FloatInputs(std::mt19937& rng, float lo, float hi, int n) {
  std::uniform_real_distribution<float> u(lo, hi);
  std::vector<float> v;
  for (int i = 0; i < n; ++i) v.push_back(u(rng));
  return v;
}

// |got - ref| within rel * |ref| + abs (NaN must match NaN, inf must match inf).
void ExpectClose(double got, double ref, double rel, double abs, const char* what, double x) {
  if (std::isnan(ref)) {
    EXPECT_TRUE(std::isnan(got)) << what << "(" << x << ") = " << got << ", want NaN";
    return;
  }
  if (std::isinf(ref)) {
    EXPECT_EQ(got, ref) << what << "(" << x << ")";
    return;
  }
  EXPECT_NEAR(got, ref, rel * std::fabs(ref) + abs) << what << "(" << x << ")";
}

struct Unary {
  const char* name;
  float (*f32)(float);
  double (*f64)(double);
  double (*ref)(double);
  float lo, hi;
};

TEST(NativeScalar, UnaryMathMatchesFloat64) {
  std::mt19937 rng(1234);
  const Unary fns[] = {
      {"sin", [](float x) { return wp::sin(x); }, [](double x) { return wp::sin(x); }, [](double x) { return std::sin(x); }, -10, 10},
      {"cos", [](float x) { return wp::cos(x); }, [](double x) { return wp::cos(x); }, [](double x) { return std::cos(x); }, -10, 10},
      {"tan", [](float x) { return wp::tan(x); }, [](double x) { return wp::tan(x); }, [](double x) { return std::tan(x); }, -1.5f, 1.5f},
      {"asin", [](float x) { return wp::asin(x); }, [](double x) { return wp::asin(x); }, [](double x) { return std::asin(x); }, -1, 1},
      {"acos", [](float x) { return wp::acos(x); }, [](double x) { return wp::acos(x); }, [](double x) { return std::acos(x); }, -1, 1},
      {"atan", [](float x) { return wp::atan(x); }, [](double x) { return wp::atan(x); }, [](double x) { return std::atan(x); }, -100, 100},
      {"sinh", [](float x) { return wp::sinh(x); }, [](double x) { return wp::sinh(x); }, [](double x) { return std::sinh(x); }, -10, 10},
      {"cosh", [](float x) { return wp::cosh(x); }, [](double x) { return wp::cosh(x); }, [](double x) { return std::cosh(x); }, -10, 10},
      {"tanh", [](float x) { return wp::tanh(x); }, [](double x) { return wp::tanh(x); }, [](double x) { return std::tanh(x); }, -10, 10},
      {"sqrt", [](float x) { return wp::sqrt(x); }, [](double x) { return wp::sqrt(x); }, [](double x) { return std::sqrt(x); }, 0, 1e6f},
      {"cbrt", [](float x) { return wp::cbrt(x); }, [](double x) { return wp::cbrt(x); }, [](double x) { return std::cbrt(x); }, -1e6f, 1e6f},
      {"log", [](float x) { return wp::log(x); }, [](double x) { return wp::log(x); }, [](double x) { return std::log(x); }, 1e-6f, 1e6f},
      {"log2", [](float x) { return wp::log2(x); }, [](double x) { return wp::log2(x); }, [](double x) { return std::log2(x); }, 1e-6f, 1e6f},
      {"log10", [](float x) { return wp::log10(x); }, [](double x) { return wp::log10(x); }, [](double x) { return std::log10(x); }, 1e-6f, 1e6f},
      {"exp", [](float x) { return wp::exp(x); }, [](double x) { return wp::exp(x); }, [](double x) { return std::exp(x); }, -50, 50},
      {"erf", [](float x) { return wp::erf(x); }, [](double x) { return wp::erf(x); }, [](double x) { return std::erf(x); }, -4, 4},
      {"erfc", [](float x) { return wp::erfc(x); }, [](double x) { return wp::erfc(x); }, [](double x) { return std::erfc(x); }, -4, 4},
      {"degrees", [](float x) { return wp::degrees(x); }, [](double x) { return wp::degrees(x); }, [](double x) { return x * 180.0 / M_PI; }, -10, 10},
      {"radians", [](float x) { return wp::radians(x); }, [](double x) { return wp::radians(x); }, [](double x) { return x * M_PI / 180.0; }, -1000, 1000},
      {"floor", [](float x) { return wp::floor(x); }, [](double x) { return wp::floor(x); }, [](double x) { return std::floor(x); }, -100, 100},
      {"ceil", [](float x) { return wp::ceil(x); }, [](double x) { return wp::ceil(x); }, [](double x) { return std::ceil(x); }, -100, 100},
      {"trunc", [](float x) { return wp::trunc(x); }, [](double x) { return wp::trunc(x); }, [](double x) { return std::trunc(x); }, -100, 100},
      {"round", [](float x) { return wp::round(x); }, [](double x) { return wp::round(x); }, [](double x) { return std::round(x); }, -100, 100},
      {"rint", [](float x) { return wp::rint(x); }, [](double x) { return wp::rint(x); }, [](double x) { return std::nearbyint(x); }, -100, 100},
      {"frac", [](float x) { return wp::frac(x); }, [](double x) { return wp::frac(x); }, [](double x) { return x - std::trunc(x); }, -100, 100},
  };
  for (const auto& fn : fns) {
    std::vector<float> xs = FloatInputs(rng, fn.lo, fn.hi, 500);
    for (float x : xs) {
      // float32: the reference evaluated at the same float32 input; a few ulp of error.
      ExpectClose(fn.f32(x), fn.ref((double)x), 4e-6, 1e-6, fn.name, x);
      ExpectClose(fn.f64((double)x), fn.ref((double)x), 1e-14, 1e-15, fn.name, x);
    }
    // NaN propagates through every function.
    EXPECT_TRUE(std::isnan(fn.f32(NAN))) << fn.name;
    EXPECT_TRUE(std::isnan(fn.f64(NAN))) << fn.name;
  }
}

TEST(NativeScalar, HardInputs) {
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(wp::sqrt(inf), inf);
  EXPECT_TRUE(std::isnan(wp::sqrt(-1.0f)));
  EXPECT_EQ(wp::log(0.0f), -inf);
  EXPECT_EQ(wp::exp(1000.0f), inf);
  EXPECT_EQ(wp::exp(-1000.0f), 0.0f);
  EXPECT_EQ(wp::tanh(inf), 1.0f);
  EXPECT_EQ(wp::atan(inf), (float)(M_PI / 2));
  EXPECT_EQ(wp::floor(-0.5f), -1.0f);
  EXPECT_EQ(wp::round(2.5f), 3.0f);
  EXPECT_EQ(wp::round(-2.5f), -3.0f);
  EXPECT_EQ(wp::rint(2.5f), 2.0f);
  EXPECT_EQ(wp::rint(3.5f), 4.0f);
  // Tiny and huge magnitudes keep their precision.
  EXPECT_FLOAT_EQ(wp::sqrt(1e-38f), (float)std::sqrt(1e-38));
  EXPECT_FLOAT_EQ(wp::sqrt(3e38f), (float)std::sqrt(3e38));
  EXPECT_DOUBLE_EQ(wp::sqrt(1e-300), std::sqrt(1e-300));
  EXPECT_FLOAT_EQ(wp::cbrt(-8e-30f), (float)std::cbrt(-8e-30));
  EXPECT_FLOAT_EQ(wp::mul(1e30f, 1e30f), inf);
  // asin/acos clamp (Warp), NaN stays NaN.
  EXPECT_FLOAT_EQ(wp::asin(1.5f), (float)(M_PI / 2));
  EXPECT_FLOAT_EQ(wp::acos(-7.0f), (float)M_PI);
  EXPECT_TRUE(std::isnan(wp::acos(NAN)));
  // pow and atan2 edge cases follow IEEE / libm.
  EXPECT_EQ(wp::pow(0.0f, 0.0f), 1.0f);
  EXPECT_EQ(wp::pow(-2.0f, 3.0f), -8.0f);
  EXPECT_TRUE(std::isnan(wp::pow(-2.0f, 0.5f)));
  EXPECT_FLOAT_EQ(wp::atan2(1.0f, -1.0f), (float)std::atan2(1.0, -1.0));
  EXPECT_EQ(wp::atan2(0.0f, 0.0f), 0.0f);
  // copysign, min/max/clamp/abs/sign/step/nonzero.
  EXPECT_EQ(wp::copysign(3.0f, -0.0f), -3.0f);
  EXPECT_EQ(wp::abs(-0.0f), 0.0f);
  EXPECT_FALSE(std::signbit(wp::abs(-0.0f)));
  EXPECT_EQ(wp::abs(-inf), inf);
  EXPECT_EQ(wp::sign(-2.0f), -1.0f);
  EXPECT_EQ(wp::sign(0.0f), 1.0f);
  EXPECT_EQ(wp::step(-1.0f), 1.0f);
  EXPECT_EQ(wp::step(0.0f), 0.0f);
  EXPECT_EQ(wp::nonzero(0.0f), 0.0f);
  EXPECT_EQ(wp::nonzero(-3.0f), 1.0f);
  EXPECT_EQ(wp::clamp(5.0f, -1.0f, 1.0f), 1.0f);
  EXPECT_EQ(wp::clamp(-5.0, -1.0, 1.0), -1.0);
  EXPECT_EQ(wp::min(2.0f, -3.0f), -3.0f);
  EXPECT_EQ(wp::max(2.0, -3.0), 2.0);
  // Float mod is fmod (truncated), floordiv floors.
  EXPECT_FLOAT_EQ(wp::mod(-7.5f, 2.0f), -1.5f);
  EXPECT_FLOAT_EQ(wp::floordiv(-7.5f, 2.0f), -4.0f);
  EXPECT_TRUE(std::isnan(wp::mod(1.0f, 0.0f)));
  EXPECT_EQ(wp::div(1.0f, 0.0f), inf);
  // lerp / smoothstep.
  EXPECT_FLOAT_EQ(wp::lerp(2.0f, 4.0f, 0.25f), 2.5f);
  EXPECT_EQ(wp::smoothstep(0.0f, 1.0f, -1.0f), 0.0f);
  EXPECT_EQ(wp::smoothstep(0.0f, 1.0f, 2.0f), 1.0f);
  EXPECT_FLOAT_EQ(wp::smoothstep(0.0f, 2.0f, 0.5f), 0.25f * 0.25f * (3 - 0.5f));
  // where / select argument orders.
  EXPECT_EQ(wp::where(true, 1.0f, 2.0f), 1.0f);
  EXPECT_EQ(wp::select(true, 1.0f, 2.0f), 2.0f);
  EXPECT_EQ(wp::where(0, 1, 2), 2);
}

TEST(NativeScalar, ErfInverse) {
  std::mt19937 rng(7);
  for (float y : FloatInputs(rng, -0.999f, 0.999f, 300)) {
    double x = wp::erfinv((double)y);
    EXPECT_NEAR(std::erf(x), (double)y, 1e-14) << y;
    float xf = wp::erfinv(y);
    EXPECT_NEAR(std::erf((double)xf), (double)y, 2e-7) << y;
  }
  for (double y : {1e-300, 1e-20, 1e-5, 0.3, 1.0, 1.7, 1.99999}) {
    double x = wp::erfcinv(y);
    EXPECT_NEAR(std::erfc(x) / y, 1.0, 1e-12) << y;
  }
  EXPECT_EQ(wp::erfinv(1.0), std::numeric_limits<double>::infinity());
  EXPECT_EQ(wp::erfinv(-1.0f), -std::numeric_limits<float>::infinity());
  EXPECT_TRUE(std::isnan(wp::erfinv(2.0)));
  EXPECT_EQ(wp::erfcinv(0.0), std::numeric_limits<double>::infinity());
}

TEST(NativeScalar, Classification) {
  const float inf = std::numeric_limits<float>::infinity();
  for (float x : {0.0f, -0.0f, 1.0f, 1e-45f, 3.4e38f}) {
    EXPECT_TRUE(wp::isfinite(x));
    EXPECT_FALSE(wp::isnan(x));
    EXPECT_FALSE(wp::isinf(x));
  }
  EXPECT_TRUE(wp::isnan(NAN));
  EXPECT_TRUE(wp::isnan((double)NAN));
  EXPECT_FALSE(wp::isfinite((double)NAN));
  EXPECT_TRUE(wp::isinf(-inf));
  EXPECT_TRUE(wp::isinf((double)inf));
  EXPECT_FALSE(wp::isfinite(inf));
  EXPECT_TRUE(wp::isnan(wp::half(NAN)));
  EXPECT_TRUE(wp::isinf(wp::half(1e6f)));
  EXPECT_TRUE(wp::isfinite(wp::half(65504.0f)));
  EXPECT_TRUE(wp::isfinite(wp::int32(5)));
}

// Python-style floor division and C-style remainder for one integer type, checked against
// 128-bit arithmetic wrapped back to T.
template <typename T>
void CheckIntOps(std::mt19937_64& rng) {
  using W = __int128;
  std::vector<T> vals = {T(0), T(1), T(2), T(7), std::numeric_limits<T>::min(), std::numeric_limits<T>::max(),
                         T(std::numeric_limits<T>::min() + 1), T(std::numeric_limits<T>::max() - 1)};
  if (std::numeric_limits<T>::is_signed) vals.insert(vals.end(), {T(-1), T(-2), T(-7)});
  for (int i = 0; i < 40; ++i) vals.push_back((T)rng());
  const int bits = sizeof(T) * 8;
  auto wrap = [](W v) { return (T)(unsigned long long)(v & (W)~0ull); };
  for (T a : vals) {
    for (T b : vals) {
      EXPECT_EQ(wp::add(a, b), wrap((W)a + (W)b));
      EXPECT_EQ(wp::sub(a, b), wrap((W)a - (W)b));
      // the low 64 bits of the product, in unsigned arithmetic (uint64 * uint64 overflows __int128)
      EXPECT_EQ(wp::mul(a, b), wrap((W)((unsigned long long)a * (unsigned long long)b)));
      if (b == 0) {
        EXPECT_EQ(wp::div(a, b), T(0));
        EXPECT_EQ(wp::mod(a, b), T(0));
        EXPECT_EQ(wp::floordiv(a, b), T(0));
      } else {
        W q = (W)a / (W)b, r = (W)a % (W)b;  // exact in 128 bits; MIN / -1 wraps back to MIN
        EXPECT_EQ(wp::div(a, b), wrap(q)) << +a << " / " << +b;
        EXPECT_EQ(wp::mod(a, b), wrap(r)) << +a << " % " << +b;
        W fq = (r != 0 && ((r < 0) != ((W)b < 0))) ? q - 1 : q;
        EXPECT_EQ(wp::floordiv(a, b), wrap(fq)) << +a << " // " << +b;
      }
      unsigned s = (unsigned)(unsigned long long)b & (unsigned)(bits - 1);
      EXPECT_EQ(wp::lshift(a, b), wrap((W)((unsigned __int128)(unsigned long long)(W)a << s)));
      EXPECT_EQ(wp::rshift(a, b), wrap((W)a >> s));
      EXPECT_EQ(wp::bit_and(a, b), T(a & b));
      EXPECT_EQ(wp::bit_or(a, b), T(a | b));
      EXPECT_EQ(wp::bit_xor(a, b), T(a ^ b));
      EXPECT_EQ(wp::min(a, b), a < b ? a : b);
      EXPECT_EQ(wp::max(a, b), a > b ? a : b);
    }
    EXPECT_EQ(wp::neg(a), wrap(-(W)a));
    EXPECT_EQ(wp::invert(a), T(~a));
    EXPECT_EQ(wp::abs(a), (W)a < 0 ? wrap(-(W)a) : a);
    EXPECT_EQ(wp::sign(a), (W)a < 0 ? T(-1) : T(1));
    EXPECT_EQ(wp::unot(a), a == 0);
  }
}

TEST(NativeScalar, IntegerSemantics) {
  std::mt19937_64 rng(99);
  CheckIntOps<wp::int8>(rng);
  CheckIntOps<wp::int16>(rng);
  CheckIntOps<wp::int32>(rng);
  CheckIntOps<wp::int64>(rng);
  CheckIntOps<wp::uint8>(rng);
  CheckIntOps<wp::uint16>(rng);
  CheckIntOps<wp::uint32>(rng);
  CheckIntOps<wp::uint64>(rng);
  // Named cases.
  EXPECT_EQ(wp::add(wp::int32(2147483647), wp::int32(1)), wp::int32(-2147483647 - 1));
  EXPECT_EQ(wp::mul(wp::uint16(65535), wp::uint16(65535)), wp::uint16(1));
  EXPECT_EQ(wp::div(wp::int32(-2147483647 - 1), wp::int32(-1)), wp::int32(-2147483647 - 1));
  EXPECT_EQ(wp::floordiv(wp::int32(-7), wp::int32(2)), -4);
  EXPECT_EQ(wp::div(wp::int32(-7), wp::int32(2)), -3);
  EXPECT_EQ(wp::mod(wp::int32(-7), wp::int32(2)), -1);
  EXPECT_EQ(wp::rshift(wp::int32(-8), wp::int32(1)), -4);
  EXPECT_EQ(wp::pow(wp::int32(3), wp::int32(4)), 81);
  EXPECT_EQ(wp::pow(wp::int32(2), wp::int32(31)), wp::int32(-2147483647 - 1));
  EXPECT_EQ(wp::pow(wp::int32(-1), wp::int32(-3)), -1);
  EXPECT_EQ(wp::pow(wp::int32(5), wp::int32(-1)), 0);
  EXPECT_EQ(wp::step(wp::int32(-3)), 1);
  EXPECT_EQ(wp::clamp(wp::int64(10), wp::int64(-2), wp::int64(3)), 3);
}

uint16_t RefHalfBits(float f) {
  _Float16 h = (_Float16)f;
  uint16_t u;
  std::memcpy(&u, &h, 2);
  return u;
}

TEST(NativeScalar, Float16Conversions) {
  // Every half converts to float exactly and back to the same bits (NaNs stay NaN).
  for (uint32_t b = 0; b < 65536; ++b) {
    wp::half h = wp::half::from_bits((uint16_t)b);
    float f = h;
    _Float16 ref;
    uint16_t rb = (uint16_t)b;
    std::memcpy(&ref, &rb, 2);
    if (std::isnan((float)ref)) {
      EXPECT_TRUE(std::isnan(f));
      EXPECT_TRUE(wp::isnan(wp::half(f)));
      continue;
    }
    ASSERT_EQ(f, (float)ref) << std::hex << b;
    ASSERT_EQ(wp::half(f).u, b) << std::hex << b;
  }
  // float -> half rounds to nearest even, like the compiler, across the whole range incl.
  // subnormals, ties, overflow to inf.
  std::mt19937 rng(5);
  std::uniform_int_distribution<uint32_t> bits(0, 0xffffffffu);
  for (int i = 0; i < 200000; ++i) {
    uint32_t u = bits(rng);
    float f;
    std::memcpy(&f, &u, 4);
    if (std::isnan(f)) continue;
    ASSERT_EQ(wp::half(f).u, RefHalfBits(f)) << f;
  }
  for (float f : {65504.0f, 65519.0f, 65520.0f, 1e-8f, 2.98e-8f, 5.96e-8f, -6.1e-5f, 1.0009765625f, 1.00048828125f,
                  1.00146484375f, 0.0f, -0.0f}) {
    EXPECT_EQ(wp::half(f).u, RefHalfBits(f)) << f;
  }
  // Arithmetic on half goes through float32.
  wp::half a(1.5f), b(2.25f);
  EXPECT_EQ(float(wp::add(a, b)), 3.75f);
  EXPECT_EQ(float(wp::mul(a, b)), float(wp::half(3.375f)));
  EXPECT_EQ(float(wp::sqrt(wp::half(4.0f))), 2.0f);
  EXPECT_EQ(wp::int32(wp::half(-3.75f)), -3);
  EXPECT_EQ(float(wp::float16(7)), 7.0f);
}

}  // namespace

namespace {

// min/max/clamp are C's fmin/fmax (Warp): a NaN operand is a missing value. The adjoints send
// the gradient to the operand the forward returned; copysign's adjoint compares sign bits.
template <typename T>
void CheckNanMinMax() {
  const T nan = T(NAN), one = T(1), m1 = T(-1), two = T(2);
  std::mt19937 rng(0x5eed);
  std::uniform_real_distribution<double> u(-4.0, 4.0);
  for (int k = 0; k < 200; ++k) {
    double a = u(rng), b = u(rng);
    bool na = k % 4 == 1 || k % 4 == 3, nb = k % 4 == 2 || k % 4 == 3;
    T ta = na ? nan : T(a), tb = nb ? nan : T(b);
    double fa = na ? NAN : double(T(a)), fb = nb ? NAN : double(T(b));
    double rmin = std::fmin(fa, fb), rmax = std::fmax(fa, fb);
    ExpectClose(double(wp::min(ta, tb)), rmin, 0, 0, "min", a);
    ExpectClose(double(wp::max(ta, tb)), rmax, 0, 0, "max", a);
    ExpectClose(double(wp::clamp(ta, m1, one)), std::fmin(std::fmax(fa, -1.0), 1.0), 0, 0, "clamp", a);
    T ga = T(0), gb = T(0);
    wp::adj_min(ta, tb, ga, gb, one);
    if (!(na && nb)) {
      // the gradient reaches exactly the operand whose value min returned
      bool to_a = !na && (nb || double(ta) < double(tb));
      EXPECT_EQ(double(ga), to_a ? 1.0 : 0.0) << a << " " << b << " " << na << nb;
      EXPECT_EQ(double(gb), to_a ? 0.0 : 1.0) << a << " " << b << " " << na << nb;
    }
  }
  // clamp adjoint through min(max(lo, x), hi) when an operand is NaN
  struct Row { T x, lo, hi; double gx, glo, ghi; };
  const Row rows[] = {{nan, m1, one, 0, 1, 0}, {nan, one, m1, 0, 0, 1}, {T(0.5), nan, one, 1, 0, 0},
                      {two, nan, one, 0, 0, 1}, {T(-2), m1, nan, 0, 1, 0}, {T(0.5), m1, one, 1, 0, 0}};
  for (const Row& r : rows) {
    T gx = T(0), glo = T(0), ghi = T(0);
    wp::adj_clamp(r.x, r.lo, r.hi, gx, glo, ghi, one);
    EXPECT_EQ(double(gx), r.gx);
    EXPECT_EQ(double(glo), r.glo);
    EXPECT_EQ(double(ghi), r.ghi);
  }
  // vector reductions skip NaN components, and so do their adjoints
  wp::vec_t<3, T> v(nan, m1, two);
  EXPECT_EQ(double(wp::min(v)), -1.0);
  EXPECT_EQ(double(wp::max(v)), 2.0);
  wp::vec_t<3, T> gv;
  wp::adj_min(v, gv, one);
  wp::adj_max(v, gv, one);
  EXPECT_EQ(double(gv.c[0]), 0.0);
  EXPECT_EQ(double(gv.c[1]), 1.0);
  EXPECT_EQ(double(gv.c[2]), 1.0);
  // copysign: d/dx is +1 when the sign bits agree; -0.0 is negative
  T g = T(0), gy = T(0);
  wp::adj_copysign(T(-0.0), m1, g, gy, one);
  EXPECT_EQ(double(g), 1.0);
  g = T(0);
  wp::adj_copysign(T(0.0), m1, g, gy, one);
  EXPECT_EQ(double(g), -1.0);
  g = T(0);
  wp::adj_copysign(T(3), T(-0.0), g, gy, one);
  EXPECT_EQ(double(g), -1.0);
  EXPECT_EQ(double(gy), 0.0);
}

}  // namespace

TEST(NativeScalar, MinMaxClampTreatNanAsMissing) {
  CheckNanMinMax<float>();
  CheckNanMinMax<double>();
}
