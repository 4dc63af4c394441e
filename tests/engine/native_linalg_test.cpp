// Forward values of the vector, matrix, quaternion, transform and spatial builtins and of the
// decompositions (svd3, svd2, qr3, eig3) against float64 references written out here (loops,
// Rodrigues' formula, closed-form cubic roots), on random and hard inputs: zero vectors,
// singular matrices, nearly identical rotations, half-turns, huge and tiny magnitudes.
// Decomposition adjoints are checked against finite differences.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "engine/native/weft.h"

namespace {

using vec2d = wp::vec_t<2, double>;
using vec3d = wp::vec_t<3, double>;
using vec3f = wp::vec_t<3, float>;
using vec4d = wp::vec_t<4, double>;
using vec6d = wp::vec_t<6, double>;
using mat22d = wp::mat_t<2, 2, double>;
using mat33d = wp::mat_t<3, 3, double>;
using mat33f = wp::mat_t<3, 3, float>;
using mat44d = wp::mat_t<4, 4, double>;
using quatd = wp::quat_t<double>;
using xformd = wp::transform_t<double>;

std::mt19937& Rng() {
  static std::mt19937 rng(777);
  return rng;
}
double U(double lo = -1, double hi = 1) { return std::uniform_real_distribution<double>(lo, hi)(Rng()); }
template <unsigned N> wp::vec_t<N, double> RandVec() {
  wp::vec_t<N, double> v;
  for (unsigned i = 0; i < N; ++i) v.c[i] = U();
  return v;
}
template <unsigned R, unsigned C> wp::mat_t<R, C, double> RandMat() {
  wp::mat_t<R, C, double> m;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) m.data[i][j] = U();
  return m;
}
quatd RandQuat() { return wp::normalize(quatd(U(), U(), U(), U())); }

template <unsigned N> void ExpectVecNear(const wp::vec_t<N, double>& a, const wp::vec_t<N, double>& b, double tol) {
  for (unsigned i = 0; i < N; ++i) EXPECT_NEAR(a.c[i], b.c[i], tol) << "component " << i;
}
template <unsigned R, unsigned C> void ExpectMatNear(const wp::mat_t<R, C, double>& a, const wp::mat_t<R, C, double>& b, double tol) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) EXPECT_NEAR(a.data[i][j], b.data[i][j], tol) << "entry " << i << "," << j;
}

// Rotation matrix of a unit quaternion, from the textbook formula.
mat33d RefRotation(const quatd& q) {
  double x = q.x, y = q.y, z = q.z, w = q.w;
  return mat33d(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), 2 * (x * y + z * w), 1 - 2 * (x * x + z * z),
                2 * (y * z - x * w), 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y));
}
// Rodrigues: rotate v about the unit axis k by angle.
vec3d RefRodrigues(vec3d k, double angle, vec3d v) {
  vec3d kxv(k.c[1] * v.c[2] - k.c[2] * v.c[1], k.c[2] * v.c[0] - k.c[0] * v.c[2], k.c[0] * v.c[1] - k.c[1] * v.c[0]);
  double kv = k.c[0] * v.c[0] + k.c[1] * v.c[1] + k.c[2] * v.c[2];
  vec3d r;
  for (int i = 0; i < 3; ++i) r.c[i] = v.c[i] * std::cos(angle) + kxv.c[i] * std::sin(angle) + k.c[i] * kv * (1 - std::cos(angle));
  return r;
}

TEST(NativeLinalg, VectorOps) {
  for (int rep = 0; rep < 100; ++rep) {
    vec4d a = RandVec<4>(), b = RandVec<4>();
    double s = U(0.5, 2);
    double dot = 0;
    for (int i = 0; i < 4; ++i) dot += a.c[i] * b.c[i];
    EXPECT_NEAR(wp::dot(a, b), dot, 1e-15);
    EXPECT_NEAR(wp::length(a), std::sqrt(wp::dot(a, a)), 1e-15);
    ExpectVecNear(wp::normalize(a), wp::div(a, std::sqrt(wp::dot(a, a))), 1e-15);
    for (int i = 0; i < 4; ++i) {
      EXPECT_EQ(wp::add(a, b).c[i], a.c[i] + b.c[i]);
      EXPECT_EQ(wp::mul(a, s).c[i], a.c[i] * s);
      EXPECT_EQ(wp::div(s, a).c[i], s / a.c[i]);
      EXPECT_EQ(wp::cw_mul(a, b).c[i], a.c[i] * b.c[i]);
      EXPECT_EQ(wp::min(a, b).c[i], std::min(a.c[i], b.c[i]));
      EXPECT_EQ(wp::abs(a).c[i], std::fabs(a.c[i]));
    }
    EXPECT_EQ(wp::min(a), *std::min_element(a.c, a.c + 4));
    EXPECT_EQ(wp::max(a), *std::max_element(a.c, a.c + 4));
    EXPECT_EQ(a.c[wp::argmin(a)], wp::min(a));
    EXPECT_EQ(a.c[wp::argmax(a)], wp::max(a));
    vec3d p = RandVec<3>(), q = RandVec<3>();
    vec3d c = wp::cross(p, q);
    EXPECT_NEAR(wp::dot(c, p), 0, 1e-15);
    EXPECT_NEAR(wp::dot(c, q), 0, 1e-15);
    EXPECT_NEAR(wp::length_sq(c), wp::length_sq(p) * wp::length_sq(q) - wp::dot(p, q) * wp::dot(p, q), 1e-14);
  }
  // Hard inputs: zero, huge and tiny vectors, NaN.
  EXPECT_EQ(wp::normalize(vec3d()), vec3d());
  EXPECT_EQ(wp::normalize(vec3f()), vec3f());
  // The squared length of a tiny vector underflows to 0, so it normalizes to zero (as Warp);
  // one that stays representable normalizes exactly.
  EXPECT_EQ(wp::normalize(vec3d(1e-200, 0, 0)), vec3d());
  ExpectVecNear(wp::normalize(vec3d(3e-150, 4e-150, 0)), vec3d(0.6, 0.8, 0.0), 1e-15);
  vec3f big(3e19f, 4e19f, 0);
  EXPECT_TRUE(std::isinf(wp::length(big)));  // float32 overflow of the squared length, as Warp
  vec3f nanv(NAN, 1, 2);
  EXPECT_TRUE(wp::isnan(wp::normalize(nanv)) || wp::normalize(nanv) == vec3f());
  EXPECT_TRUE(wp::isnan(nanv));
  EXPECT_FALSE(wp::isfinite(nanv));
  // Component access and out-of-range indices.
  vec3d v(1.0, 2.0, 3.0);
  EXPECT_EQ(wp::extract(v, 2), 3.0);
  EXPECT_EQ(wp::extract(v, 3), 0.0);
  EXPECT_EQ(wp::extract(v, -1), 0.0);
  EXPECT_EQ(wp::assign(v, 1, 9.0), vec3d(1.0, 9.0, 3.0));
  EXPECT_EQ(wp::assign(v, 7, 9.0), v);
  // Constructors: fill, conversion, spatial concatenation.
  EXPECT_EQ(vec3d(2.0), vec3d(2.0, 2.0, 2.0));
  EXPECT_EQ(vec3d(vec3f(1.5f, 2.5f, 3.5f)), vec3d(1.5, 2.5, 3.5));
  EXPECT_EQ(vec6d(v, vec3d(4.0, 5.0, 6.0)), vec6d(1.0, 2.0, 3.0, 4.0, 5.0, 6.0));
  // Integer vectors: bit ops and wrap-around.
  wp::vec_t<2, wp::int32> iv(2147483647, 5), jv(1, 3);
  EXPECT_EQ(wp::add(iv, jv), (wp::vec_t<2, wp::int32>(-2147483647 - 1, 8)));
  EXPECT_EQ(wp::bit_and(iv, jv), (wp::vec_t<2, wp::int32>(1, 1)));
  EXPECT_EQ(wp::dot(iv, wp::vec_t<2, wp::int32>(2, 1)), 3);  // 2 * INT_MAX wraps to -2, + 5
  wp::mat_t<2, 2, wp::int32> im(2147483647, 1, 0, 1);
  EXPECT_EQ(wp::mul(im, wp::vec_t<2, wp::int32>(2, 0)), (wp::vec_t<2, wp::int32>(-2, 0)));
  EXPECT_EQ(wp::div(iv, wp::int32(0)), (wp::vec_t<2, wp::int32>(0, 0)));  // no trap
}

TEST(NativeLinalg, MatrixOps) {
  for (int rep = 0; rep < 50; ++rep) {
    mat33d a = RandMat<3, 3>(), b = RandMat<3, 3>();
    vec3d v = RandVec<3>();
    mat33d ab, at;
    vec3d av;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        for (int k = 0; k < 3; ++k) ab.data[i][j] += a.data[i][k] * b.data[k][j];
        av.c[i] += a.data[i][j] * v.c[j];
        at.data[j][i] = a.data[i][j];
      }
    }
    ExpectMatNear(wp::mul(a, b), ab, 1e-15);
    ExpectVecNear(wp::mul(a, v), av, 1e-15);
    ExpectVecNear(wp::mul(v, a), wp::mul(at, v), 1e-15);
    EXPECT_EQ(wp::transpose(a), at);
    EXPECT_NEAR(wp::trace(a), a.data[0][0] + a.data[1][1] + a.data[2][2], 1e-15);
    EXPECT_NEAR(wp::ddot(a, b), wp::trace(wp::mul(at, b)), 1e-14);
    // det by the rule of Sarrus; inverse by A A^-1 = I.
    double det = a.data[0][0] * a.data[1][1] * a.data[2][2] + a.data[0][1] * a.data[1][2] * a.data[2][0] +
                 a.data[0][2] * a.data[1][0] * a.data[2][1] - a.data[0][2] * a.data[1][1] * a.data[2][0] -
                 a.data[0][0] * a.data[1][2] * a.data[2][1] - a.data[0][1] * a.data[1][0] * a.data[2][2];
    EXPECT_NEAR(wp::determinant(a), det, 1e-14);
    ExpectMatNear(wp::mul(a, wp::inverse(a)), wp::identity<3, double>(), 1e-9 / std::fabs(det));
    mat44d m4 = RandMat<4, 4>();
    ExpectMatNear(wp::mul(wp::inverse(m4), m4), wp::identity<4, double>(), 1e-9 / std::fabs(wp::determinant(m4)));
    EXPECT_NEAR(wp::determinant(wp::mul(m4, m4)), wp::determinant(m4) * wp::determinant(m4), 1e-12);
    mat22d m2 = RandMat<2, 2>();
    EXPECT_NEAR(wp::determinant(m2), m2.data[0][0] * m2.data[1][1] - m2.data[0][1] * m2.data[1][0], 1e-15);
    ExpectMatNear(wp::mul(m2, wp::inverse(m2)), wp::identity<2, double>(), 1e-9 / std::fabs(wp::determinant(m2)));
    // skew(a) b == cross(a, b); outer; diag.
    vec3d w = RandVec<3>();
    ExpectVecNear(wp::mul(wp::skew(v), w), wp::cross(v, w), 1e-15);
    EXPECT_EQ(wp::outer(v, w).data[1][2], v.c[1] * w.c[2]);
    EXPECT_EQ(wp::get_diag(wp::diag(v)), v);
  }
  // Constructors: row-major scalars, column vectors, rows/cols helpers.
  mat22d r(1.0, 2.0, 3.0, 4.0);
  EXPECT_EQ(r.data[0][1], 2.0);
  EXPECT_EQ(r.data[1][0], 3.0);
  mat22d c(vec2d(1.0, 2.0), vec2d(3.0, 4.0));  // columns (Warp's legacy rule)
  EXPECT_EQ(c.data[1][0], 2.0);
  EXPECT_EQ(c.data[0][1], 3.0);
  EXPECT_EQ(wp::matrix_from_rows(vec2d(1.0, 2.0), vec2d(3.0, 4.0)), r);
  EXPECT_EQ(wp::matrix_from_cols(vec2d(1.0, 2.0), vec2d(3.0, 4.0)), c);
  EXPECT_EQ(wp::extract(r, 1), vec2d(3.0, 4.0));
  EXPECT_EQ(wp::extract(r, 0, 1), 2.0);
  EXPECT_EQ(wp::extract(r, 2, 0), 0.0);
  // Singular matrices: inverse gives zeros (Warp), determinant 0.
  mat33d sing(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0);
  EXPECT_EQ(wp::determinant(sing), 0.0);
  EXPECT_EQ(wp::inverse(sing), mat33d());
  EXPECT_EQ(wp::inverse(mat22d(1.0, 2.0, 2.0, 4.0)), mat22d());
  EXPECT_EQ(wp::inverse(mat44d()), mat44d());
  // Nearly singular but invertible: the inverse is still right.
  mat22d ns(1.0, 1.0, 1.0, 1.0 + 1e-10);
  ExpectMatNear(wp::mul(ns, wp::inverse(ns)), wp::identity<2, double>(), 1e-5);
  // Huge / tiny scales.
  mat33d big = wp::mul(RandMat<3, 3>(), 1e100);
  EXPECT_NEAR(wp::determinant(big) / 1e300, wp::determinant(wp::div(big, 1e100)), 1e-12);
  mat33f tinyf = wp::mul(mat33f(1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 1.0f), 1e-10f);
  EXPECT_FLOAT_EQ(wp::determinant(tinyf), 1e-30f);
  EXPECT_FLOAT_EQ(wp::inverse(tinyf).data[1][1], 1e10f);
  EXPECT_EQ(wp::inverse(tinyf).data[0][1], 0.0f);
}

TEST(NativeLinalg, Quaternions) {
  for (int rep = 0; rep < 100; ++rep) {
    quatd q = RandQuat(), r = RandQuat();
    vec3d v = RandVec<3>();
    // Rotation agrees with the matrix formula and with Rodrigues.
    // |entries| <= 1 after ~10 float64 operations each: a bound of ~18 ulp of 1.0 (where the
    // compiler contracts a*b+c into an FMA differs between builds: clang's ASan build is 5 ulp off)
    ExpectMatNear(wp::quat_to_matrix(q), RefRotation(q), 4e-15);
    ExpectVecNear(wp::quat_rotate(q, v), wp::mul(RefRotation(q), v), 4e-15);
    ExpectVecNear(wp::quat_rotate_inv(q, wp::quat_rotate(q, v)), v, 4e-15);
    vec3d axis = wp::normalize(RandVec<3>());
    double angle = U(-3, 3);
    ExpectVecNear(wp::quat_rotate(wp::quat_from_axis_angle(axis, angle), v), RefRodrigues(axis, angle, v), 1e-14);
    // Composition: (q r) v == q (r v).
    ExpectVecNear(wp::quat_rotate(wp::mul(q, r), v), wp::quat_rotate(q, wp::quat_rotate(r, v)), 1e-14);
    // Round trips.
    quatd back = wp::quat_from_matrix(wp::quat_to_matrix(q));
    if (wp::dot(back, q) < 0) back = wp::neg(back);
    EXPECT_NEAR(wp::length(wp::sub(back, q)), 0, 1e-14);
    vec3d ax;
    double an;
    wp::quat_to_axis_angle(wp::quat_from_axis_angle(axis, std::fabs(angle)), ax, an);
    EXPECT_NEAR(an, std::fabs(angle), 1e-13);
    ExpectVecNear(ax, axis, 1e-13);
    // rpy: roll about x, then pitch about y, then yaw about z (extrinsic), as Warp.
    double roll = U(-3, 3), pitch = U(-1.5, 1.5), yaw = U(-3, 3);
    quatd rpy = wp::quat_rpy(roll, pitch, yaw);
    quatd ref = wp::mul(wp::mul(wp::quat_from_axis_angle(vec3d(0.0, 0.0, 1.0), yaw), wp::quat_from_axis_angle(vec3d(0.0, 1.0, 0.0), pitch)),
                        wp::quat_from_axis_angle(vec3d(1.0, 0.0, 0.0), roll));
    EXPECT_NEAR(std::fabs(wp::dot(rpy, ref)), 1.0, 1e-14);
    // slerp endpoints and midpoint angle.
    if (wp::dot(q, r) < 0) r = wp::neg(r);
    EXPECT_NEAR(std::fabs(wp::dot(wp::quat_slerp(q, r, 0.0), q)), 1.0, 1e-13);
    EXPECT_NEAR(std::fabs(wp::dot(wp::quat_slerp(q, r, 1.0), r)), 1.0, 1e-13);
    quatd mid = wp::quat_slerp(q, r, 0.5);
    EXPECT_NEAR(wp::dot(mid, q), wp::dot(mid, r), 1e-13);
    EXPECT_NEAR(wp::length(mid), 1.0, 1e-14);
  }
  // Nearly identical rotations: slerp stays on the path, no NaN.
  quatd q = RandQuat();
  quatd q2 = wp::normalize(wp::add(q, quatd(1e-12, -1e-12, 0.0, 0.0)));
  quatd s = wp::quat_slerp(q, q2, 0.5);
  EXPECT_TRUE(wp::isfinite(s));
  EXPECT_NEAR(std::fabs(wp::dot(s, q)), 1.0, 1e-12);
  quatd same = wp::quat_slerp(q, q, 0.3);
  EXPECT_NEAR(std::fabs(wp::dot(same, q)), 1.0, 1e-15);
  // Half turns about each axis exercise every quat_from_matrix branch.
  for (int axis = 0; axis < 3; ++axis) {
    vec3d k;
    k.c[axis] = 1;
    quatd h = wp::quat_from_axis_angle(k, 3.14159);
    quatd back = wp::quat_from_matrix(wp::quat_to_matrix(h));
    EXPECT_NEAR(std::fabs(wp::dot(back, h)), 1.0, 1e-12) << axis;
  }
  // Zero quaternion normalizes to zero; inverse is the conjugate.
  EXPECT_EQ(wp::normalize(quatd()), quatd());
  EXPECT_EQ(wp::quat_inverse(quatd(1.0, 2.0, 3.0, 4.0)), quatd(-1.0, -2.0, -3.0, 4.0));
  vec3d ax;
  double an;
  wp::quat_to_axis_angle(wp::quat_identity<double>(), ax, an);
  EXPECT_EQ(an, 0.0);
  EXPECT_EQ(ax, vec3d());
}

TEST(NativeLinalg, TransformsAndSpatial) {
  for (int rep = 0; rep < 50; ++rep) {
    xformd a(RandVec<3>(), RandQuat()), b(RandVec<3>(), RandQuat());
    vec3d p = RandVec<3>();
    ExpectVecNear(wp::transform_point(a, p), wp::add(wp::mul(RefRotation(a.q), p), a.p), 1e-15);
    ExpectVecNear(wp::transform_vector(a, p), wp::mul(RefRotation(a.q), p), 1e-15);
    ExpectVecNear(wp::transform_point(wp::transform_multiply(a, b), p), wp::transform_point(a, wp::transform_point(b, p)), 1e-14);
    ExpectVecNear(wp::transform_point(wp::transform_inverse(a), wp::transform_point(a, p)), p, 1e-14);
    vec3d scale(U(0.5, 2), U(0.5, 2), U(0.5, 2));
    mat44d m = wp::matrix(a.p, a.q, scale);
    ExpectVecNear(wp::transform_point(m, p), wp::transform_point(a, wp::cw_mul(scale, p)), 1e-14);
    ExpectVecNear(wp::transform_vector(m, p), wp::transform_vector(a, wp::cw_mul(scale, p)), 1e-14);
    EXPECT_NEAR(std::fabs(wp::dot(wp::quat_from_matrix(wp::matrix(a.p, a.q, vec3d(1.0))), a.q)), 1.0, 1e-13);
    // Spatial algebra: cross products against their 6x6 matrix forms.
    vec6d x = RandVec<6>(), y = RandVec<6>();
    vec3d w = wp::spatial_top(x), v = wp::spatial_bottom(x);
    mat33d sw = wp::skew(w), sv = wp::skew(v);
    wp::mat_t<6, 6, double> crm, crf;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        crm.data[i][j] = sw.data[i][j];
        crm.data[i + 3][j + 3] = sw.data[i][j];
        crm.data[i + 3][j] = sv.data[i][j];
        crf.data[i][j] = sw.data[i][j];
        crf.data[i][j + 3] = sv.data[i][j];
        crf.data[i + 3][j + 3] = sw.data[i][j];
      }
    ExpectVecNear(wp::spatial_cross(x, y), wp::mul(crm, y), 1e-15);
    ExpectVecNear(wp::spatial_cross_dual(x, y), wp::mul(crf, y), 1e-15);
    EXPECT_NEAR(wp::spatial_dot(x, y), wp::dot(x, y), 1e-15);
    mat33d r3 = RandMat<3, 3>(), s3 = RandMat<3, 3>();
    wp::mat_t<6, 6, double> adj = wp::spatial_adjoint(r3, s3);
    EXPECT_EQ(adj.data[4][1], s3.data[1][1]);
    EXPECT_EQ(adj.data[5][5], r3.data[2][2]);
    EXPECT_EQ(adj.data[1][4], 0.0);
  }
  EXPECT_EQ(wp::transform_point(wp::transform_identity<double>(), vec3d(1.0, 2.0, 3.0)), vec3d(1.0, 2.0, 3.0));
  xformd t(1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0);
  EXPECT_EQ(wp::extract(t, 2), 3.0);
  EXPECT_EQ(wp::extract(t, 6), 1.0);
  wp::transform_set_translation(t, vec3d(4.0, 5.0, 6.0));
  EXPECT_EQ(wp::transform_get_translation(t), vec3d(4.0, 5.0, 6.0));
}

// Eigenvalues of a symmetric 3x3 matrix by the trigonometric closed form, ascending.
vec3d RefSymEigenvalues(const mat33d& a) {
  double p1 = a.data[0][1] * a.data[0][1] + a.data[0][2] * a.data[0][2] + a.data[1][2] * a.data[1][2];
  double q = wp::trace(a) / 3;
  double p2 = (a.data[0][0] - q) * (a.data[0][0] - q) + (a.data[1][1] - q) * (a.data[1][1] - q) + (a.data[2][2] - q) * (a.data[2][2] - q) + 2 * p1;
  double p = std::sqrt(p2 / 6);
  mat33d b = wp::div(wp::sub(a, wp::mul(wp::identity<3, double>(), q)), p);
  double r = std::clamp(wp::determinant(b) / 2, -1.0, 1.0);
  double phi = std::acos(r) / 3;
  double e1 = q + 2 * p * std::cos(phi), e3 = q + 2 * p * std::cos(phi + 2 * M_PI / 3), e2 = 3 * q - e1 - e3;
  vec3d e(e3, e2, e1);
  std::sort(e.c, e.c + 3);
  return e;
}

template <unsigned N> double OrthoError(const wp::mat_t<N, N, double>& m) {
  auto d = wp::sub(wp::mul(wp::transpose(m), m), wp::identity<N, double>());
  return std::sqrt(wp::ddot(d, d));
}

TEST(NativeLinalg, Decompositions) {
  for (int rep = 0; rep < 100; ++rep) {
    mat33d a = RandMat<3, 3>();
    if (rep % 10 == 0) a = wp::mul(a, 1e-8);  // tiny
    double scale = std::sqrt(wp::ddot(a, a));
    mat33d u, v;
    vec3d s;
    wp::svd3(a, u, s, v);
    ExpectMatNear(wp::mul(wp::mul(u, wp::diag(s)), wp::transpose(v)), a, 1e-12 * scale);
    EXPECT_LT(OrthoError(u), 1e-12);
    EXPECT_LT(OrthoError(v), 1e-12);
    EXPECT_NEAR(wp::determinant(u), 1.0, 1e-12);
    EXPECT_NEAR(wp::determinant(v), 1.0, 1e-12);
    EXPECT_GE(s.c[0], s.c[1]);
    EXPECT_GE(s.c[1], std::fabs(s.c[2]) - 1e-12 * scale);
    EXPECT_GE(s.c[1], 0.0);
    // |sigma| are the square roots of the eigenvalues of A^T A; the sign of sigma3 is det(A)'s.
    vec3d lam = RefSymEigenvalues(wp::mul(wp::transpose(a), a));
    EXPECT_NEAR(s.c[0], std::sqrt(lam.c[2]), 1e-7 * scale);
    EXPECT_NEAR(std::fabs(s.c[2]), std::sqrt(std::max(lam.c[0], 0.0)), 1e-7 * scale);
    EXPECT_EQ(s.c[2] < 0, wp::determinant(a) < 0);

    mat33d sym = wp::add(a, wp::transpose(a));
    mat33d q;
    vec3d d;
    wp::eig3(sym, q, d);
    ExpectVecNear(d, RefSymEigenvalues(sym), 1e-10 * scale);
    ExpectMatNear(wp::mul(wp::mul(q, wp::diag(d)), wp::transpose(q)), sym, 1e-12 * scale);
    EXPECT_LT(OrthoError(q), 1e-12);

    mat33d qq, rr;
    wp::qr3(a, qq, rr);
    ExpectMatNear(wp::mul(qq, rr), a, 1e-13 * scale);
    EXPECT_LT(OrthoError(qq), 1e-12);
    for (int i = 0; i < 3; ++i) {
      EXPECT_GE(rr.data[i][i], 0.0);
      for (int j = 0; j < i; ++j) EXPECT_EQ(rr.data[i][j], 0.0);
    }

    mat22d a2 = RandMat<2, 2>(), u2, v2;
    wp::vec_t<2, double> s2;
    wp::svd2(a2, u2, s2, v2);
    ExpectMatNear(wp::mul(wp::mul(u2, wp::diag(s2)), wp::transpose(v2)), a2, 1e-13);
    EXPECT_LT(OrthoError(u2), 1e-13);
    EXPECT_NEAR(wp::determinant(v2), 1.0, 1e-13);
    EXPECT_GE(s2.c[0], std::fabs(s2.c[1]));
  }
  // Rank-deficient and zero inputs stay finite and reconstruct.
  for (mat33d a : {mat33d(), mat33d(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 3.0, 6.0, 9.0), mat33d(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)}) {
    mat33d u, v, q, r;
    vec3d s;
    wp::svd3(a, u, s, v);
    EXPECT_TRUE(wp::isfinite(u) && wp::isfinite(v) && wp::isfinite(s));
    ExpectMatNear(wp::mul(wp::mul(u, wp::diag(s)), wp::transpose(v)), a, 1e-12);
    EXPECT_LT(OrthoError(u), 1e-12);
    wp::qr3(a, q, r);
    EXPECT_TRUE(wp::isfinite(q) && wp::isfinite(r));
    ExpectMatNear(wp::mul(q, r), a, 1e-12);
    EXPECT_LT(OrthoError(q), 1e-12);
  }
  // float32 works too.
  mat33f af(2.0f, -1.0f, 0.5f, 0.3f, 1.0f, -2.0f, 1.5f, 0.2f, 0.7f), uf, vf;
  wp::vec_t<3, float> sf;
  wp::svd3(af, uf, sf, vf);
  auto rec = wp::sub(wp::mul(wp::mul(uf, wp::diag(sf)), wp::transpose(vf)), af);
  EXPECT_LT(std::sqrt(wp::ddot(rec, rec)), 1e-5f);
}

// Adjoints of the decompositions against finite differences of a random linear functional of
// all outputs.
TEST(NativeLinalg, DecompositionAdjoints) {
  auto frob = [](const mat33d& a, const mat33d& b) { return wp::ddot(a, b); };
  for (int rep = 0; rep < 10; ++rep) {
    mat33d a = RandMat<3, 3>();
    mat33d wu = RandMat<3, 3>(), wv = RandMat<3, 3>();
    vec3d ws = RandVec<3>();
    auto svd_loss = [&](const mat33d& m) {
      mat33d u, v;
      vec3d s;
      wp::svd3(m, u, s, v);
      return frob(u, wu) + wp::dot(s, ws) + frob(v, wv);
    };
    auto qr_loss = [&](const mat33d& m) {
      mat33d q, r;
      wp::qr3(m, q, r);
      return frob(q, wu) + frob(r, wv);
    };
    mat33d sym = wp::add(a, wp::transpose(a));
    auto eig_loss = [&](const mat33d& m) {
      mat33d q;
      vec3d d;
      wp::eig3(m, q, d);
      return frob(q, wu) + wp::dot(d, ws);
    };
    mat33d u, v, q, r, qe;
    vec3d s, d;
    wp::svd3(a, u, s, v);
    wp::qr3(a, q, r);
    wp::eig3(sym, qe, d);
    mat33d g_svd, g_qr, g_eig;
    wp::adj_svd3(a, u, s, v, g_svd, wu, ws, wv);
    wp::adj_qr3(a, q, r, g_qr, wu, wv);
    wp::adj_eig3(sym, qe, d, g_eig, wu, ws);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        const double h = 1e-6;
        mat33d p = a, m = a;
        p.data[i][j] += h;
        m.data[i][j] -= h;
        double num = (svd_loss(p) - svd_loss(m)) / (2 * h);
        EXPECT_NEAR(g_svd.data[i][j], num, 1e-5 * (1 + std::fabs(num))) << "svd3 " << i << j;
        num = (qr_loss(p) - qr_loss(m)) / (2 * h);
        EXPECT_NEAR(g_qr.data[i][j], num, 1e-5 * (1 + std::fabs(num))) << "qr3 " << i << j;
        // eig3's gradient is Warp's, as a function of a symmetric matrix: along a symmetric
        // perturbation (E_ij + E_ji) the derivative is g_ij + g_ji (g_ii on the diagonal).
        if (j < i) continue;
        p = sym;
        m = sym;
        p.data[i][j] += h;
        m.data[i][j] -= h;
        if (i != j) {
          p.data[j][i] += h;
          m.data[j][i] -= h;
        }
        num = (eig_loss(p) - eig_loss(m)) / (2 * h);
        const double along = i == j ? g_eig.data[i][j] : g_eig.data[i][j] + g_eig.data[j][i];
        EXPECT_NEAR(along, num, 1e-5 * (1 + std::fabs(num))) << "eig3 " << i << j;
      }
    mat22d a2 = RandMat<2, 2>(), u2, v2, w2u = RandMat<2, 2>(), w2v = RandMat<2, 2>();
    vec2d s2, w2s = RandVec<2>();
    auto svd2_loss = [&](const mat22d& m) {
      mat22d uu, vv;
      vec2d ss;
      wp::svd2(m, uu, ss, vv);
      return wp::ddot(uu, w2u) + wp::dot(ss, w2s) + wp::ddot(vv, w2v);
    };
    wp::svd2(a2, u2, s2, v2);
    mat22d g2;
    wp::adj_svd2(a2, u2, s2, v2, g2, w2u, w2s, w2v);
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        mat22d p = a2, m = a2;
        p.data[i][j] += 1e-6;
        m.data[i][j] -= 1e-6;
        double num = (svd2_loss(p) - svd2_loss(m)) / 2e-6;
        EXPECT_NEAR(g2.data[i][j], num, 1e-5 * (1 + std::fabs(num))) << "svd2 " << i << j;
      }
  }
}

}  // namespace

namespace {

// float16 composites compute through float32 and round per operation: results stay within
// half precision of the float32 results.
TEST(NativeLinalg, Float16Composites) {
  using vec3h = wp::vec_t<3, wp::half>;
  using mat33h = wp::mat_t<3, 3, wp::half>;
  using quath = wp::quat_t<wp::half>;
  for (int rep = 0; rep < 50; ++rep) {
    wp::vec_t<3, float> a((float)U(), (float)U(), (float)U()), b((float)U(), (float)U(), (float)U());
    vec3h ah(a), bh(b);
    auto near = [](float got, float want) { EXPECT_NEAR(got, want, 4e-3f * (1 + std::fabs(want))); };
    near(float(wp::dot(ah, bh)), wp::dot(a, b));
    for (int i = 0; i < 3; ++i) {
      near(float(wp::cross(ah, bh).c[i]), wp::cross(a, b).c[i]);
      near(float(wp::normalize(ah).c[i]), wp::normalize(a).c[i]);
    }
    wp::mat_t<3, 3, float> m(a, b, wp::vec_t<3, float>(0.5f, -0.25f, 1.0f));
    mat33h mh(m);
    near(float(wp::determinant(mh)), wp::determinant(m));
    near(float(wp::mul(mh, ah).c[1]), wp::mul(m, a).c[1]);
    wp::quat_t<float> q = wp::normalize(wp::quat_t<float>((float)U(), (float)U(), (float)U(), (float)U()));
    quath qh(q);
    near(float(wp::quat_rotate(qh, ah).c[2]), wp::quat_rotate(q, a).c[2]);
    vec3h g;
    wp::adj_normalize(ah, g, bh);
    EXPECT_TRUE(wp::isfinite(g));
  }
}

}  // namespace
