// Every adj_ function of engine/native against central finite differences in float64, at random
// points away from kinks: a random seed adj_ret w, the analytic adjoints from adj_f, and for each
// input component (d/dx_k) <w, f(x)> by (f(x + h e_k) - f(x - h e_k)) / 2h. Plus the documented
// subgradients at kinks (abs at 0, min/max ties, clamp bounds, normalize of zero, ...).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <tuple>
#include <utility>

#include "engine/native/weft.h"

namespace {

using vec2d = wp::vec_t<2, double>;
using vec3d = wp::vec_t<3, double>;
using vec4d = wp::vec_t<4, double>;
using vec6d = wp::vec_t<6, double>;
using mat22d = wp::mat_t<2, 2, double>;
using mat23d = wp::mat_t<2, 3, double>;
using mat33d = wp::mat_t<3, 3, double>;
using mat44d = wp::mat_t<4, 4, double>;
using quatd = wp::quat_t<double>;
using xformd = wp::transform_t<double>;

// Flat view of the float64 components of a value (integers have none).
inline double* Comp(double& x, int& n) { n = 1; return &x; }
inline double* Comp(int& , int& n) { n = 0; return nullptr; }
template <unsigned N> double* Comp(wp::vec_t<N, double>& v, int& n) { n = N; return v.c; }
template <unsigned R, unsigned C> double* Comp(wp::mat_t<R, C, double>& m, int& n) { n = R * C; return &m.data[0][0]; }
inline double* Comp(quatd& q, int& n) { n = 4; return &q.x; }
inline double* Comp(xformd& t, int& n) { n = 7; return &t.p.c[0]; }

template <typename T> double Dot(T a, T b) {
  int n;
  double* pa = Comp(a, n);
  double* pb = Comp(b, n);
  double s = 0;
  for (int i = 0; i < n; ++i) s += pa[i] * pb[i];
  return s;
}

std::mt19937& Rng() {
  static std::mt19937 rng(20261121);
  return rng;
}
template <typename T> T Rand(double lo = -1, double hi = 1) {
  T x{};
  int n;
  double* p = Comp(x, n);
  std::uniform_real_distribution<double> u(lo, hi);
  for (int i = 0; i < n; ++i) p[i] = u(Rng());
  return x;
}
quatd RandUnitQuat() { return wp::normalize(Rand<quatd>()); }

template <typename Tuple, typename Fn, size_t... I>
void ForEachIndex(Tuple& t, Fn fn, std::index_sequence<I...>) {
  (fn(std::get<I>(t), std::integral_constant<size_t, I>()), ...);
}

// f(args...) -> R; adj(args..., adj_args&..., adj_ret).
template <typename F, typename G, typename... A>
void GradCheck(const std::string& name, F f, G adj, A... args) {
  using R = decltype(f(args...));
  std::tuple<A...> x(args...);
  R w = Rand<R>();
  std::tuple<A...> g{};
  std::apply([&](auto&... a) { std::apply([&](auto&... ga) { adj(a..., ga..., w); }, g); }, x);
  ForEachIndex(
      x,
      [&](auto& xi, auto idx) {
        constexpr size_t k = decltype(idx)::value;
        int n;
        double* px = Comp(xi, n);
        int ng;
        double* pg = Comp(std::get<k>(g), ng);
        for (int c = 0; c < n; ++c) {
          double h = 1e-6 * std::max(1.0, std::fabs(px[c]));
          auto xp = x, xm = x;
          int d;
          Comp(std::get<k>(xp), d)[c] += h;
          Comp(std::get<k>(xm), d)[c] -= h;
          double num = (Dot(w, std::apply(f, xp)) - Dot(w, std::apply(f, xm))) / (2 * h);
          EXPECT_NEAR(pg[c], num, 2e-6 * (1 + std::fabs(num))) << name << ": d/d arg" << k << "[" << c << "]";
        }
      },
      std::index_sequence_for<A...>());
}

#define F1(fn) [](auto a) { return wp::fn(a); }
#define A1(fn) [](auto a, auto& ga, auto r) { wp::adj_##fn(a, ga, r); }
#define F2(fn) [](auto a, auto b) { return wp::fn(a, b); }
#define A2(fn) [](auto a, auto b, auto& ga, auto& gb, auto r) { wp::adj_##fn(a, b, ga, gb, r); }
#define F3(fn) [](auto a, auto b, auto c) { return wp::fn(a, b, c); }
#define A3(fn) [](auto a, auto b, auto c, auto& ga, auto& gb, auto& gc, auto r) { wp::adj_##fn(a, b, c, ga, gb, gc, r); }
#define CHECK1(fn, ...) GradCheck(#fn, F1(fn), A1(fn), __VA_ARGS__)
#define CHECK2(fn, ...) GradCheck(#fn, F2(fn), A2(fn), __VA_ARGS__)
#define CHECK3(fn, ...) GradCheck(#fn, F3(fn), A3(fn), __VA_ARGS__)

TEST(NativeAdjoint, Scalar) {
  for (int rep = 0; rep < 5; ++rep) {
    double a = Rand<double>(-2, 2), b = Rand<double>(0.3, 2), p = Rand<double>(0.1, 3), u = Rand<double>(-0.9, 0.9);
    CHECK2(add, a, b);
    CHECK2(sub, a, b);
    CHECK2(mul, a, b);
    CHECK2(div, a, b);
    CHECK2(div, a, -b);
    CHECK2(mod, 5 * a, b);
    CHECK2(min, a, b);
    CHECK2(max, a, b);
    CHECK2(pow, p, a);
    CHECK2(atan2, a, u);
    CHECK2(copysign, a, u);
    CHECK3(clamp, a, -0.5, 0.5);
    CHECK3(lerp, a, b, u);
    CHECK3(smoothstep, -1.0, 1.5, u);
    CHECK1(neg, a);
    CHECK1(pos, a);
    CHECK1(abs, a);
    CHECK1(sin, a);
    CHECK1(cos, a);
    CHECK1(tan, u);
    CHECK1(asin, u);
    CHECK1(acos, u);
    CHECK1(atan, a);
    CHECK1(sinh, a);
    CHECK1(cosh, a);
    CHECK1(tanh, a);
    CHECK1(sqrt, p);
    CHECK1(cbrt, a);
    CHECK1(log, p);
    CHECK1(log2, p);
    CHECK1(log10, p);
    CHECK1(exp, a);
    CHECK1(erf, a);
    CHECK1(erfc, a);
    CHECK1(erfinv, u);
    CHECK1(erfcinv, 1 + u);
    CHECK1(degrees, a);
    CHECK1(radians, a);
    CHECK1(frac, 3 * a);
  }
}

TEST(NativeAdjoint, ScalarSubgradients) {
  double ga = 0, gb = 0, gc = 0;
  wp::adj_abs(0.0, ga, 1.0);
  EXPECT_EQ(ga, 1.0);  // abs'(0) = 1 (Warp)
  ga = gb = 0;
  wp::adj_min(1.0, 1.0, ga, gb, 1.0);
  EXPECT_EQ(ga, 0.0);
  EXPECT_EQ(gb, 1.0);  // ties go to b
  ga = gb = 0;
  wp::adj_max(1.0, 1.0, ga, gb, 1.0);
  EXPECT_EQ(gb, 1.0);
  ga = gb = gc = 0;
  wp::adj_clamp(0.5, 0.5, 1.0, ga, gb, gc, 1.0);
  EXPECT_EQ(ga, 1.0);  // on the bound: to x
  ga = gb = gc = 0;
  wp::adj_clamp(-3.0, 0.5, 1.0, ga, gb, gc, 1.0);
  EXPECT_EQ(gb, 1.0);
  ga = gb = gc = 0;
  wp::adj_clamp(3.0, 0.5, 1.0, ga, gb, gc, 1.0);
  EXPECT_EQ(gc, 1.0);
  ga = 0;
  wp::adj_floor(1.5, ga, 1.0);
  wp::adj_sign(-1.5, ga, 1.0);
  wp::adj_step(-1.5, ga, 1.0);
  EXPECT_EQ(ga, 0.0);
  ga = 0;
  wp::adj_acos(1.0, ga, 1.0);
  EXPECT_EQ(ga, 0.0);
  ga = gb = 0;
  wp::adj_pow(0.0, 2.0, ga, gb, 1.0);
  EXPECT_EQ(ga, 0.0);
  EXPECT_EQ(gb, 0.0);
  // Accumulation: adjoints add to what is there.
  ga = 10;
  wp::adj_sin(0.0, ga, 2.0);
  EXPECT_EQ(ga, 12.0);
  // where: to the chosen branch only.
  int gcond = 0;
  ga = gb = 0;
  wp::adj_where(true, 1.0, 2.0, gcond, ga, gb, 3.0);
  EXPECT_EQ(ga, 3.0);
  EXPECT_EQ(gb, 0.0);
  // Integer adjoints are no-ops (and do not trap on / 0).
  int ia = 0, ib = 0;
  wp::adj_div(1, 0, ia, ib, 1);
  EXPECT_EQ(ia + ib, 0);
  // float16 adjoints accumulate in half.
  wp::half h(0.0f), hg(0.0f);
  wp::adj_sin(h, hg, wp::half(2.0f));
  EXPECT_EQ(float(hg), 2.0f);
}

TEST(NativeAdjoint, Vector) {
  for (int rep = 0; rep < 5; ++rep) {
    vec3d a = Rand<vec3d>(), b = Rand<vec3d>(0.2, 1.5);
    vec4d c = Rand<vec4d>(), d = Rand<vec4d>();
    double s = Rand<double>(0.3, 2), t = Rand<double>();
    CHECK2(add, a, b);
    CHECK2(sub, c, d);
    CHECK2(mul, a, s);
    CHECK2(mul, s, c);
    CHECK2(div, a, s);
    CHECK2(div, s, b);
    CHECK2(cw_mul, c, d);
    CHECK2(cw_div, a, b);
    CHECK2(dot, c, d);
    CHECK2(cross, a, b);
    CHECK2(min, c, d);
    CHECK2(max, a, b);
    CHECK2(mod, a, b);
    CHECK1(neg, a);
    CHECK1(abs, c);
    CHECK1(length, c);
    CHECK1(length_sq, a);
    CHECK1(normalize, a);
    CHECK1(normalize, c);
    CHECK3(lerp, a, b, t);
    GradCheck("min(v)", [](vec4d v) { return wp::min(v); }, [](vec4d v, vec4d& g, double r) { wp::adj_min(v, g, r); }, c);
    GradCheck("max(v)", [](vec4d v) { return wp::max(v); }, [](vec4d v, vec4d& g, double r) { wp::adj_max(v, g, r); }, c);
    GradCheck("extract", [](vec3d v, int i) { return wp::extract(v, i); },
              [](vec3d v, int i, vec3d& g, int& gi, double r) { wp::adj_extract(v, i, g, gi, r); }, a, 1);
    GradCheck("assign", [](vec3d v, int i, double x) { return wp::assign(v, i, x); },
              [](vec3d v, int i, double x, vec3d& g, int& gi, double& gx, vec3d r) { wp::adj_assign(v, i, x, g, gi, gx, r); }, a, 2, t);
    GradCheck("spatial_vector(w, v)", [](vec3d w, vec3d v) { return vec6d(w, v); },
              [](vec3d w, vec3d v, vec3d& gw, vec3d& gv, vec6d r) { wp::adj_spatial_vector(w, v, gw, gv, r); }, a, b);
  }
  // normalize / length of the zero vector: zero result, zero gradient.
  vec3d zero, g;
  EXPECT_EQ(wp::normalize(zero), zero);
  wp::adj_normalize(zero, g, vec3d(1.0, 2.0, 3.0));
  wp::adj_length(zero, g, 1.0);
  EXPECT_EQ(g, zero);
}

TEST(NativeAdjoint, Matrix) {
  for (int rep = 0; rep < 5; ++rep) {
    mat22d m2 = Rand<mat22d>();
    mat33d m3 = Rand<mat33d>(), n3 = Rand<mat33d>();
    mat44d m4 = Rand<mat44d>();
    mat23d r23 = Rand<mat23d>();
    vec3d v3 = Rand<vec3d>();
    vec2d v2 = Rand<vec2d>();
    double s = Rand<double>(0.3, 2), t = Rand<double>();
    CHECK2(add, m3, n3);
    CHECK2(sub, m3, n3);
    CHECK2(mul, m3, s);
    CHECK2(mul, s, m4);
    CHECK2(div, m3, s);
    CHECK2(mul, m3, v3);
    CHECK2(mul, v2, r23);
    CHECK2(mul, r23, v3);
    CHECK2(mul, m3, n3);
    CHECK2(mul, m2, r23);
    CHECK2(cw_mul, m3, n3);
    CHECK2(ddot, m3, n3);
    CHECK2(outer, v2, v3);
    CHECK1(neg, m3);
    CHECK1(transpose, r23);
    CHECK1(trace, m4);
    CHECK1(skew, v3);
    CHECK1(diag, v3);
    CHECK1(get_diag, m3);
    CHECK1(determinant, m2);
    CHECK1(determinant, m3);
    CHECK1(determinant, m4);
    CHECK1(inverse, m2);
    CHECK1(inverse, m3);
    CHECK1(inverse, m4);
    CHECK3(lerp, m3, n3, t);
    GradCheck("extract(m,i,j)", [](mat33d m, int i, int j) { return wp::extract(m, i, j); },
              [](mat33d m, int i, int j, mat33d& g, int& gi, int& gj, double r) { wp::adj_extract(m, i, j, g, gi, gj, r); }, m3, 2, 1);
    GradCheck("extract(m,i)", [](mat33d m, int i) { return wp::extract(m, i); },
              [](mat33d m, int i, mat33d& g, int& gi, vec3d r) { wp::adj_extract(m, i, g, gi, r); }, m3, 1);
    GradCheck("assign(m,i,j,x)", [](mat33d m, int i, int j, double x) { return wp::assign(m, i, j, x); },
              [](mat33d m, int i, int j, double x, mat33d& g, int& gi, int& gj, double& gx, mat33d r) {
                wp::adj_assign(m, i, j, x, g, gi, gj, gx, r);
              },
              m3, 0, 2, t);
  }
  // Singular matrix: determinant gradient is the cofactor matrix (still defined), inverse is 0.
  mat33d sing(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.5, -1.0, 2.0);
  EXPECT_EQ(wp::determinant(sing), 0.0);
  GradCheck("determinant(singular)", F1(determinant), A1(determinant), sing);
  EXPECT_EQ(wp::inverse(sing), mat33d());
  mat33d g;
  wp::adj_inverse(sing, g, Rand<mat33d>());
  EXPECT_EQ(g, mat33d());
}

mat33d RotationAbout(int axis, double angle) {
  vec3d a;
  a.c[axis] = 1;
  return wp::quat_to_matrix(wp::quat_from_axis_angle(a, angle));
}

TEST(NativeAdjoint, Quaternion) {
  for (int rep = 0; rep < 5; ++rep) {
    quatd q = RandUnitQuat(), r = RandUnitQuat(), raw = Rand<quatd>();
    vec3d v = Rand<vec3d>(), axis = wp::normalize(Rand<vec3d>());
    double s = Rand<double>(0.3, 2), t = Rand<double>(0, 1), ang = Rand<double>(-3, 3);
    CHECK2(add, q, r);
    CHECK2(sub, q, raw);
    CHECK2(mul, q, r);
    CHECK2(mul, raw, s);
    CHECK2(div, raw, s);
    CHECK2(dot, q, raw);
    CHECK1(length, raw);
    CHECK1(length_sq, raw);
    CHECK1(normalize, raw);
    CHECK1(quat_inverse, raw);
    CHECK2(quat_rotate, raw, v);
    CHECK2(quat_rotate_inv, raw, v);
    CHECK2(quat_from_axis_angle, axis, ang);
    CHECK1(quat_to_matrix, raw);
    CHECK3(quat_rpy, Rand<double>(-3, 3), Rand<double>(-3, 3), Rand<double>(-3, 3));
    CHECK3(lerp, q, r, t);
    if (wp::dot(q, r) < 0) r = wp::neg(r);
    CHECK3(quat_slerp, q, r, t);
    // quat_from_matrix on each of its four branches (trace, then each diagonal dominant).
    CHECK1(quat_from_matrix, wp::quat_to_matrix(q));
    for (int ax = 0; ax < 3; ++ax) {
      mat33d m = RotationAbout(ax, 2.9 + 0.1 * t);
      CHECK1(quat_from_matrix, m);
    }
    mat44d m4 = wp::matrix(v, q, vec3d(1.0, 1.0, 1.0));
    CHECK1(quat_from_matrix, m4);
    // quat_to_axis_angle has two outputs: check <w_axis, axis> + w_angle * angle.
    vec3d w_axis = Rand<vec3d>();
    double w_angle = Rand<double>();
    auto scalarized = [&](quatd qq) {
      vec3d ax;
      double an;
      wp::quat_to_axis_angle(qq, ax, an);
      return wp::dot(ax, w_axis) + w_angle * an;
    };
    for (quatd qq : {raw, wp::neg(raw)}) {
      vec3d ax;
      double an;
      wp::quat_to_axis_angle(qq, ax, an);
      quatd g;
      wp::adj_quat_to_axis_angle(qq, ax, an, g, w_axis, w_angle);
      for (int c = 0; c < 4; ++c) {
        quatd p = qq, m = qq;
        p[c] += 1e-6;
        m[c] -= 1e-6;
        double num = (scalarized(p) - scalarized(m)) / 2e-6;
        EXPECT_NEAR(g[c], num, 2e-6 * (1 + std::fabs(num))) << "quat_to_axis_angle d/dq[" << c << "]";
      }
    }
  }
}

TEST(NativeAdjoint, TransformAndSpatial) {
  for (int rep = 0; rep < 5; ++rep) {
    xformd a(Rand<vec3d>(), Rand<quatd>()), b(Rand<vec3d>(), Rand<quatd>());
    xformd ua(Rand<vec3d>(), RandUnitQuat());
    vec3d p = Rand<vec3d>(), sc = Rand<vec3d>(0.5, 2);
    mat44d m4 = Rand<mat44d>();
    double s = Rand<double>(0.3, 2), t = Rand<double>();
    CHECK2(transform_point, a, p);
    CHECK2(transform_vector, a, p);
    CHECK2(transform_point, m4, p);
    CHECK2(transform_vector, m4, p);
    CHECK2(transform_multiply, a, b);
    CHECK2(mul, a, b);
    CHECK1(transform_inverse, ua);
    CHECK1(transform_inverse, a);
    CHECK1(transform_get_translation, a);
    CHECK1(transform_get_rotation, a);
    CHECK2(add, a, b);
    CHECK2(sub, a, b);
    CHECK2(mul, a, s);
    CHECK3(lerp, a, b, t);
    CHECK2(transformation, p, ua.q);
    CHECK3(matrix, p, ua.q, sc);
    vec6d x = Rand<vec6d>(), y = Rand<vec6d>();
    mat33d r = Rand<mat33d>(), q = Rand<mat33d>();
    CHECK2(spatial_dot, x, y);
    CHECK2(spatial_cross, x, y);
    CHECK2(spatial_cross_dual, x, y);
    CHECK1(spatial_top, x);
    CHECK1(spatial_bottom, x);
    CHECK2(spatial_adjoint, r, q);
  }
}

}  // namespace
