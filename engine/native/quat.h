// Native library: quat_t<T> (x, y, z, w; Warp's layout) and the quaternion builtins with their
// adjoints: constructors, arithmetic, dot/length/normalize, quat_inverse, quat_rotate(_inv),
// quat_from_axis_angle, quat_to_axis_angle, quat_from_matrix, quat_to_matrix, quat_rpy,
// quat_slerp, lerp, component access.
#pragma once

#include "mat.h"

namespace wp {

template <typename T>
struct quat_t {
  T x, y, z, w;

  WP_CALLABLE quat_t() : x(0), y(0), z(0), w(0) {}
  WP_CALLABLE explicit quat_t(cg_uninit_t) {}   // components left uninitialised (scalar.h)
  WP_CALLABLE quat_t(T x_, T y_, T z_, T w_) : x(x_), y(y_), z(z_), w(w_) {}
  WP_CALLABLE quat_t(const vec_t<3, T>& ijk, T real) : x(ijk.c[0]), y(ijk.c[1]), z(ijk.c[2]), w(real) {}
  template <typename U>
  WP_CALLABLE explicit quat_t(const quat_t<U>& o) : x(T(o.x)), y(T(o.y)), z(T(o.z)), w(T(o.w)) {}

  WP_CALLABLE T& operator[](int i) { return (&x)[i]; }
  WP_CALLABLE const T& operator[](int i) const { return (&x)[i]; }
};
typedef quat_t<float32> quat;
typedef quat_t<float32> quatf;
typedef quat_t<float64> quatd;
typedef quat_t<half> quath;

template <typename T> WP_FUNC quat_t<T> quat_identity() { return quat_t<T>(T(0), T(0), T(0), T(1)); }
template <typename T> WP_FUNC vec_t<3, T> quat_imag(const quat_t<T>& q) { return vec_t<3, T>(q.x, q.y, q.z); }

template <typename T> WP_FUNC T extract(const quat_t<T>& q, int32 i) { return (unsigned)i < 4u ? q[i] : T(0); }
template <typename T> WP_FUNC quat_t<T> assign(const quat_t<T>& q, int32 i, T value) {
  quat_t<T> r = q;
  if ((unsigned)i < 4u) r[i] = value;
  return r;
}
template <typename T> WP_FUNC void assign_inplace(quat_t<T>& q, int32 i, T value) { if ((unsigned)i < 4u) q[i] = value; }
template <typename T> WP_FUNC int32 len(const quat_t<T>&) { return 4; }
template <typename T, typename IA> WP_FUNC void adj_extract(const quat_t<T>&, int32 i, quat_t<T>& adj_q, IA&, T adj_ret) {
  if ((unsigned)i < 4u) adj_q[i] += adj_ret;
}
template <typename T, typename IA>
WP_FUNC void adj_assign(const quat_t<T>&, int32 i, T, quat_t<T>& adj_q, IA&, T& adj_value, const quat_t<T>& adj_ret) {
  for (int k = 0; k < 4; ++k) {
    if (k == i) adj_value += adj_ret[k];
    else adj_q[k] += adj_ret[k];
  }
}

// ---------------------------------------------------------------------------------------------
// Arithmetic.
template <typename T> WP_FUNC quat_t<T> add(const quat_t<T>& a, const quat_t<T>& b) { return quat_t<T>(T(a.x + b.x), T(a.y + b.y), T(a.z + b.z), T(a.w + b.w)); }
template <typename T> WP_FUNC quat_t<T> sub(const quat_t<T>& a, const quat_t<T>& b) { return quat_t<T>(T(a.x - b.x), T(a.y - b.y), T(a.z - b.z), T(a.w - b.w)); }
template <typename T> WP_FUNC quat_t<T> neg(const quat_t<T>& a) { return quat_t<T>(T(-a.x), T(-a.y), T(-a.z), T(-a.w)); }
template <typename T> WP_FUNC quat_t<T> pos(const quat_t<T>& a) { return a; }
template <typename T> WP_FUNC quat_t<T> mul(const quat_t<T>& a, T s) { return quat_t<T>(T(a.x * s), T(a.y * s), T(a.z * s), T(a.w * s)); }
template <typename T> WP_FUNC quat_t<T> mul(T s, const quat_t<T>& a) { return mul(a, s); }
template <typename T> WP_FUNC quat_t<T> div(const quat_t<T>& a, T s) { return quat_t<T>(T(a.x / s), T(a.y / s), T(a.z / s), T(a.w / s)); }
template <typename T> WP_FUNC quat_t<T> div(T s, const quat_t<T>& a) { return quat_t<T>(T(s / a.x), T(s / a.y), T(s / a.z), T(s / a.w)); }
template <typename T> WP_FUNC quat_t<T> div_approx(const quat_t<T>& a, T s) { return div(a, s); }
template <typename T> WP_FUNC quat_t<T> div_approx(T s, const quat_t<T>& a) { return div(s, a); }
// Hamilton product.
template <typename T> WP_FUNC quat_t<T> mul(const quat_t<T>& a, const quat_t<T>& b) {
  return quat_t<T>(T(a.w * b.x + b.w * a.x + a.y * b.z - b.y * a.z), T(a.w * b.y + b.w * a.y + a.z * b.x - b.z * a.x),
                   T(a.w * b.z + b.w * a.z + a.x * b.y - b.x * a.y), T(a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z));
}
template <typename T> WP_FUNC quat_t<T> operator+(const quat_t<T>& a, const quat_t<T>& b) { return add(a, b); }
template <typename T> WP_FUNC quat_t<T> operator-(const quat_t<T>& a, const quat_t<T>& b) { return sub(a, b); }
template <typename T> WP_FUNC quat_t<T> operator-(const quat_t<T>& a) { return neg(a); }
template <typename T> WP_FUNC quat_t<T> operator*(const quat_t<T>& a, const quat_t<T>& b) { return mul(a, b); }
template <typename T> WP_FUNC quat_t<T> operator*(const quat_t<T>& a, T s) { return mul(a, s); }
template <typename T> WP_FUNC quat_t<T>& operator+=(quat_t<T>& a, const quat_t<T>& b) {
  a.x += b.x; a.y += b.y; a.z += b.z; a.w += b.w;
  return a;
}
template <typename T> WP_FUNC quat_t<T>& operator-=(quat_t<T>& a, const quat_t<T>& b) {
  a.x -= b.x; a.y -= b.y; a.z -= b.z; a.w -= b.w;
  return a;
}
template <typename T> WP_FUNC bool operator==(const quat_t<T>& a, const quat_t<T>& b) { return a.x == b.x && a.y == b.y && a.z == b.z && a.w == b.w; }
template <typename T> WP_FUNC bool operator!=(const quat_t<T>& a, const quat_t<T>& b) { return !(a == b); }

template <typename T> WP_FUNC T dot(const quat_t<T>& a, const quat_t<T>& b) { return T(a.x * b.x + a.y * b.y + a.z * b.z + a.w * b.w); }
template <typename T> WP_FUNC T length_sq(const quat_t<T>& a) { return dot(a, a); }
template <typename T> WP_FUNC T length(const quat_t<T>& a) { return sqrt(dot(a, a)); }
// Zero quaternion -> zero quaternion (Warp).
template <typename T> WP_FUNC quat_t<T> normalize(const quat_t<T>& a) {
  T l = length(a);
  if (l > T(0)) return div(a, l);
  return quat_t<T>();
}
// Conjugate (the inverse of a unit quaternion, as Warp).
template <typename T> WP_FUNC quat_t<T> quat_inverse(const quat_t<T>& q) { return quat_t<T>(T(-q.x), T(-q.y), T(-q.z), q.w); }
template <typename T> WP_FUNC quat_t<T> lerp(const quat_t<T>& a, const quat_t<T>& b, T t) { return add(mul(a, T(T(1) - t)), mul(b, t)); }
template <typename T> WP_FUNC bool isfinite(const quat_t<T>& q) { return isfinite(q.x) && isfinite(q.y) && isfinite(q.z) && isfinite(q.w); }
template <typename T> WP_FUNC bool isnan(const quat_t<T>& q) { return isnan(q.x) || isnan(q.y) || isnan(q.z) || isnan(q.w); }
template <typename T> WP_FUNC bool isinf(const quat_t<T>& q) { return isinf(q.x) || isinf(q.y) || isinf(q.z) || isinf(q.w); }

// ---------------------------------------------------------------------------------------------
// Rotations. quat_rotate(q, v) = q v q^-1 for unit q: v (2w^2 - 1) + 2 u (u.v) + 2 w (u x v).
template <typename T> WP_FUNC vec_t<3, T> quat_rotate(const quat_t<T>& q, const vec_t<3, T>& v) {
  vec_t<3, T> u = quat_imag(q);
  T c = T(T(2) * q.w * q.w - T(1));
  T d = T(T(2) * dot(u, v));
  return add(add(mul(v, c), mul(u, d)), mul(cross(u, v), T(T(2) * q.w)));
}
template <typename T> WP_FUNC vec_t<3, T> quat_rotate_inv(const quat_t<T>& q, const vec_t<3, T>& v) {
  vec_t<3, T> u = quat_imag(q);
  T c = T(T(2) * q.w * q.w - T(1));
  T d = T(T(2) * dot(u, v));
  return sub(add(mul(v, c), mul(u, d)), mul(cross(u, v), T(T(2) * q.w)));
}
template <typename T> WP_FUNC quat_t<T> quat_from_axis_angle(const vec_t<3, T>& axis, T angle) {
  T h = T(angle * T(0.5));
  T s = sin(h);
  return quat_t<T>(T(axis.c[0] * s), T(axis.c[1] * s), T(axis.c[2] * s), cos(h));
}
// axis = normalize(imag) (flipped when w < 0), angle = 2 atan2(|imag|, |w|) in [0, pi].
template <typename T> WP_FUNC void quat_to_axis_angle(const quat_t<T>& q, vec_t<3, T>& axis, T& angle) {
  vec_t<3, T> v = quat_imag(q);
  axis = q.w < T(0) ? neg(normalize(v)) : normalize(v);
  angle = T(T(2) * atan2(length(v), abs(q.w)));
}
// Columns are the rotated basis vectors.
template <typename T> WP_FUNC mat_t<3, 3, T> quat_to_matrix(const quat_t<T>& q) {
  vec_t<3, T> c0 = quat_rotate(q, vec_t<3, T>(T(1), T(0), T(0)));
  vec_t<3, T> c1 = quat_rotate(q, vec_t<3, T>(T(0), T(1), T(0)));
  vec_t<3, T> c2 = quat_rotate(q, vec_t<3, T>(T(0), T(0), T(1)));
  return mat_t<3, 3, T>(c0, c1, c2);
}

// Shepperd's method (Warp's branches): the unnormalized quaternion from the largest of trace and
// the diagonal, then normalized. `branch` reports the choice (-1: trace, 0..2: diagonal index).
template <typename T> WP_FUNC quat_t<T> quat_from_matrix_raw(const mat_t<3, 3, T>& m, int& branch, T& h) {
  const T tr = T(m.data[0][0] + m.data[1][1] + m.data[2][2]);
  if (tr >= T(0)) {
    branch = -1;
    h = sqrt(T(tr + T(1)));
    T g = T(T(0.5) / h);
    return quat_t<T>(T((m.data[2][1] - m.data[1][2]) * g), T((m.data[0][2] - m.data[2][0]) * g),
                     T((m.data[1][0] - m.data[0][1]) * g), T(T(0.5) * h));
  }
  int a = 0;
  if (m.data[1][1] > m.data[0][0]) a = 1;
  if (m.data[2][2] > m.data[a][a]) a = 2;
  int b = (a + 1) % 3, c = (a + 2) % 3;
  branch = a;
  h = sqrt(T(m.data[a][a] - T(m.data[b][b] + m.data[c][c]) + T(1)));
  T g = T(T(0.5) / h);
  quat_t<T> r;
  r[a] = T(T(0.5) * h);
  r[b] = T((m.data[a][b] + m.data[b][a]) * g);
  r[c] = T((m.data[c][a] + m.data[a][c]) * g);
  r.w = T((m.data[c][b] - m.data[b][c]) * g);
  return r;
}
template <typename T> WP_FUNC quat_t<T> quat_from_matrix(const mat_t<3, 3, T>& m) {
  int branch;
  T h;
  return normalize(quat_from_matrix_raw(m, branch, h));
}
template <typename T> WP_FUNC mat_t<3, 3, T> mat33_of(const mat_t<4, 4, T>& m) {
  mat_t<3, 3, T> r;
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) r.data[i][j] = m.data[i][j];
  return r;
}
template <typename T> WP_FUNC quat_t<T> quat_from_matrix(const mat_t<4, 4, T>& m) { return quat_from_matrix(mat33_of(m)); }

// Roll about x, pitch about y, yaw about z (Warp's order).
template <typename T> WP_FUNC quat_t<T> quat_rpy(T roll, T pitch, T yaw) {
  T cy = cos(T(yaw * T(0.5))), sy = sin(T(yaw * T(0.5)));
  T cr = cos(T(roll * T(0.5))), sr = sin(T(roll * T(0.5)));
  T cp = cos(T(pitch * T(0.5))), sp = sin(T(pitch * T(0.5)));
  return quat_t<T>(T(cy * sr * cp - sy * cr * sp), T(cy * cr * sp + sy * sr * cp), T(sy * cr * cp - cy * sr * sp),
                   T(cy * cr * cp + sy * sr * sp));
}
// Warp's slerp: q0 * exp(t * log(q0^-1 q1)) through axis-angle. For nearly identical rotations
// the relative axis is tiny and the result stays q0-continuous.
template <typename T> WP_FUNC quat_t<T> quat_slerp(const quat_t<T>& q0, const quat_t<T>& q1, T t) {
  vec_t<3, T> axis;
  T angle;
  quat_to_axis_angle(mul(quat_inverse(q0), q1), axis, angle);
  return mul(q0, quat_from_axis_angle(axis, T(t * angle)));
}

// ---------------------------------------------------------------------------------------------
// Adjoints.
template <typename T> WP_FUNC void adj_add(const quat_t<T>&, const quat_t<T>&, quat_t<T>& adj_a, quat_t<T>& adj_b, const quat_t<T>& adj_ret) { adj_a += adj_ret; adj_b += adj_ret; }
template <typename T> WP_FUNC void adj_sub(const quat_t<T>&, const quat_t<T>&, quat_t<T>& adj_a, quat_t<T>& adj_b, const quat_t<T>& adj_ret) { adj_a += adj_ret; adj_b -= adj_ret; }
template <typename T> WP_FUNC void adj_neg(const quat_t<T>&, quat_t<T>& adj_a, const quat_t<T>& adj_ret) { adj_a -= adj_ret; }
template <typename T> WP_FUNC void adj_pos(const quat_t<T>&, quat_t<T>& adj_a, const quat_t<T>& adj_ret) { adj_a += adj_ret; }
template <typename T> WP_FUNC void adj_mul(const quat_t<T>& a, T s, quat_t<T>& adj_a, T& adj_s, const quat_t<T>& adj_ret) {
  adj_a += mul(adj_ret, s);
  adj_s += dot(a, adj_ret);
}
template <typename T> WP_FUNC void adj_mul(T s, const quat_t<T>& a, T& adj_s, quat_t<T>& adj_a, const quat_t<T>& adj_ret) { adj_mul(a, s, adj_a, adj_s, adj_ret); }
template <typename T> WP_FUNC void adj_div(const quat_t<T>& a, T s, quat_t<T>& adj_a, T& adj_s, const quat_t<T>& adj_ret) {
  adj_a += div(adj_ret, s);
  adj_s -= dot(a, adj_ret) / T(s * s);
}
template <typename T> WP_FUNC void adj_div(T s, const quat_t<T>& a, T& adj_s, quat_t<T>& adj_a, const quat_t<T>& adj_ret) {
  for (int i = 0; i < 4; ++i) adj_div(s, a[i], adj_s, adj_a[i], adj_ret[i]);
}
template <typename T> WP_FUNC void adj_div_approx(const quat_t<T>& a, T s, quat_t<T>& adj_a, T& adj_s, const quat_t<T>& adj_ret) { adj_div(a, s, adj_a, adj_s, adj_ret); }
template <typename T> WP_FUNC void adj_div_approx(T s, const quat_t<T>& a, T& adj_s, quat_t<T>& adj_a, const quat_t<T>& adj_ret) { adj_div(s, a, adj_s, adj_a, adj_ret); }
// r = a b: adj_a += adj_r conj(b), adj_b += conj(a) adj_r.
template <typename T> WP_FUNC void adj_mul(const quat_t<T>& a, const quat_t<T>& b, quat_t<T>& adj_a, quat_t<T>& adj_b, const quat_t<T>& adj_ret) {
  adj_a += mul(adj_ret, quat_inverse(b));
  adj_b += mul(quat_inverse(a), adj_ret);
}
template <typename T> WP_FUNC void adj_dot(const quat_t<T>& a, const quat_t<T>& b, quat_t<T>& adj_a, quat_t<T>& adj_b, T adj_ret) {
  adj_a += mul(b, adj_ret);
  adj_b += mul(a, adj_ret);
}
template <typename T> WP_FUNC void adj_length_sq(const quat_t<T>& a, quat_t<T>& adj_a, T adj_ret) { adj_a += mul(a, T(T(2) * adj_ret)); }
template <typename T> WP_FUNC void adj_length(const quat_t<T>& a, quat_t<T>& adj_a, T adj_ret) {
  T l = length(a);
  if (l > T(0)) adj_a += mul(a, T(adj_ret / l));
}
template <typename T> WP_FUNC void adj_normalize(const quat_t<T>& a, quat_t<T>& adj_a, const quat_t<T>& adj_ret) {
  T l = length(a);
  if (l > T(0)) {
    quat_t<T> n = div(a, l);
    adj_a += div(sub(adj_ret, mul(n, dot(n, adj_ret))), l);
  }
}
template <typename T> WP_FUNC void adj_quat_inverse(const quat_t<T>&, quat_t<T>& adj_q, const quat_t<T>& adj_ret) { adj_q += quat_inverse(adj_ret); }
template <typename T> WP_FUNC void adj_lerp(const quat_t<T>& a, const quat_t<T>& b, T t, quat_t<T>& adj_a, quat_t<T>& adj_b, T& adj_t, const quat_t<T>& adj_ret) {
  adj_a += mul(adj_ret, T(T(1) - t));
  adj_b += mul(adj_ret, t);
  adj_t += dot(sub(b, a), adj_ret);
}
template <typename T> WP_FUNC void adj_quat(T, T, T, T, T& ax, T& ay, T& az, T& aw, const quat_t<T>& r) { ax += r.x; ay += r.y; az += r.z; aw += r.w; }
template <typename T> WP_FUNC void adj_quat(const vec_t<3, T>&, T, vec_t<3, T>& adj_ijk, T& adj_real, const quat_t<T>& r) {
  adj_ijk += quat_imag(r);
  adj_real += r.w;
}

// Shared by quat_rotate (s = +1) and quat_rotate_inv (s = -1).
template <typename T> WP_FUNC void adj_quat_rotate_signed(const quat_t<T>& q, const vec_t<3, T>& v, T s, quat_t<T>& adj_q,
                                                          vec_t<3, T>& adj_v, const vec_t<3, T>& adj_r) {
  vec_t<3, T> u = quat_imag(q);
  T c = T(T(2) * q.w * q.w - T(1));
  T d = T(T(2) * dot(u, v));
  T k = T(s * T(2) * q.w);  // cross coefficient
  // r = v c + u d + k (u x v)
  T adj_d = dot(u, adj_r);
  vec_t<3, T> ak = mul(adj_r, k);
  vec_t<3, T> av = add(add(mul(adj_r, c), mul(u, T(T(2) * adj_d))), cross(ak, u));
  vec_t<3, T> au = add(add(mul(adj_r, d), mul(v, T(T(2) * adj_d))), cross(v, ak));
  adj_v += av;
  adj_q.x += au.c[0];
  adj_q.y += au.c[1];
  adj_q.z += au.c[2];
  adj_q.w += T(T(4) * q.w) * dot(v, adj_r) + T(s * T(2)) * dot(cross(u, v), adj_r);
}
template <typename T> WP_FUNC void adj_quat_rotate(const quat_t<T>& q, const vec_t<3, T>& v, quat_t<T>& adj_q, vec_t<3, T>& adj_v, const vec_t<3, T>& adj_ret) {
  adj_quat_rotate_signed(q, v, T(1), adj_q, adj_v, adj_ret);
}
template <typename T> WP_FUNC void adj_quat_rotate_inv(const quat_t<T>& q, const vec_t<3, T>& v, quat_t<T>& adj_q, vec_t<3, T>& adj_v, const vec_t<3, T>& adj_ret) {
  adj_quat_rotate_signed(q, v, T(-1), adj_q, adj_v, adj_ret);
}
template <typename T> WP_FUNC void adj_quat_from_axis_angle(const vec_t<3, T>& axis, T angle, vec_t<3, T>& adj_axis, T& adj_angle, const quat_t<T>& adj_ret) {
  T h = T(angle * T(0.5));
  T s = sin(h), c = cos(h);
  vec_t<3, T> ai = quat_imag(adj_ret);
  adj_axis += mul(ai, s);
  adj_angle += T(T(0.5) * (c * dot(axis, ai) - s * adj_ret.w));
}
// Gradient through axis = +-normalize(imag) and angle = 2 atan2(|imag|, |w|); |w|'(0) = 1.
template <typename T> WP_FUNC void adj_quat_to_axis_angle(const quat_t<T>& q, const vec_t<3, T>&, T, quat_t<T>& adj_q, vec_t<3, T>& adj_axis, T& adj_angle) {
  vec_t<3, T> v = quat_imag(q);
  vec_t<3, T> adj_v;
  adj_normalize(v, adj_v, q.w < T(0) ? neg(adj_axis) : adj_axis);
  T l = length(v), aw = abs(q.w);
  T den = T(l * l + aw * aw);
  if (den > T(0)) {
    T dl = T(T(2) * aw / den) * adj_angle;
    T daw = T(T(-2) * l / den) * adj_angle;
    if (l > T(0)) adj_v += mul(v, T(dl / l));
    adj_q.w += q.w < T(0) ? T(-daw) : daw;
  }
  adj_q.x += adj_v.c[0];
  adj_q.y += adj_v.c[1];
  adj_q.z += adj_v.c[2];
}
template <typename T> WP_FUNC void adj_quat_to_matrix(const quat_t<T>& q, quat_t<T>& adj_q, const mat_t<3, 3, T>& adj_ret) {
  for (int j = 0; j < 3; ++j) {
    vec_t<3, T> e;
    e.c[j] = T(1);
    vec_t<3, T> adj_e;
    adj_quat_rotate(q, e, adj_q, adj_e, adj_ret.get_col(j));
  }
}
template <typename T> WP_FUNC void adj_quat_from_matrix(const mat_t<3, 3, T>& m, mat_t<3, 3, T>& adj_m, const quat_t<T>& adj_ret) {
  int branch;
  T h;
  quat_t<T> raw = quat_from_matrix_raw(m, branch, h);
  quat_t<T> ar;
  adj_normalize(raw, ar, adj_ret);
  T g = T(T(0.5) / h);
  T adj_g = T(0), adj_h;
  if (branch < 0) {
    adj_m.data[2][1] += ar.x * g; adj_m.data[1][2] -= ar.x * g;
    adj_m.data[0][2] += ar.y * g; adj_m.data[2][0] -= ar.y * g;
    adj_m.data[1][0] += ar.z * g; adj_m.data[0][1] -= ar.z * g;
    adj_g = T(ar.x * (m.data[2][1] - m.data[1][2]) + ar.y * (m.data[0][2] - m.data[2][0]) + ar.z * (m.data[1][0] - m.data[0][1]));
    adj_h = T(T(0.5) * ar.w - adj_g * T(0.5) / T(h * h));
    T adj_s = T(adj_h * T(0.5) / h);
    for (int i = 0; i < 3; ++i) adj_m.data[i][i] += adj_s;
    return;
  }
  int a = branch, b = (a + 1) % 3, c = (a + 2) % 3;
  adj_m.data[a][b] += ar[b] * g; adj_m.data[b][a] += ar[b] * g;
  adj_m.data[c][a] += ar[c] * g; adj_m.data[a][c] += ar[c] * g;
  adj_m.data[c][b] += ar.w * g;  adj_m.data[b][c] -= ar.w * g;
  adj_g = T(ar[b] * (m.data[a][b] + m.data[b][a]) + ar[c] * (m.data[c][a] + m.data[a][c]) + ar.w * (m.data[c][b] - m.data[b][c]));
  adj_h = T(T(0.5) * ar[a] - adj_g * T(0.5) / T(h * h));
  T adj_s = T(adj_h * T(0.5) / h);
  adj_m.data[a][a] += adj_s;
  adj_m.data[b][b] -= adj_s;
  adj_m.data[c][c] -= adj_s;
}
template <typename T> WP_FUNC void adj_quat_from_matrix(const mat_t<4, 4, T>& m, mat_t<4, 4, T>& adj_m, const quat_t<T>& adj_ret) {
  mat_t<3, 3, T> a3;
  adj_quat_from_matrix(mat33_of(m), a3, adj_ret);
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) adj_m.data[i][j] += a3.data[i][j];
}
template <typename T> WP_FUNC void adj_quat_rpy(T roll, T pitch, T yaw, T& adj_roll, T& adj_pitch, T& adj_yaw, const quat_t<T>& ar) {
  T cy = cos(T(yaw * T(0.5))), sy = sin(T(yaw * T(0.5)));
  T cr = cos(T(roll * T(0.5))), sr = sin(T(roll * T(0.5)));
  T cp = cos(T(pitch * T(0.5))), sp = sin(T(pitch * T(0.5)));
  // Partial derivatives w.r.t. the half angles (r, p, y) of (x, y, z, w).
  T dxr = T(cy * cr * cp + sy * sr * sp), dyr = T(-cy * sr * sp + sy * cr * cp), dzr = T(-sy * sr * cp - cy * cr * sp), dwr = T(-cy * sr * cp + sy * cr * sp);
  T dxp = T(-cy * sr * sp - sy * cr * cp), dyp = T(cy * cr * cp - sy * sr * sp), dzp = T(-sy * cr * sp - cy * sr * cp), dwp = T(-cy * cr * sp + sy * sr * cp);
  T dxy = T(-sy * sr * cp - cy * cr * sp), dyy = T(-sy * cr * sp + cy * sr * cp), dzy = T(cy * cr * cp + sy * sr * sp), dwy = T(-sy * cr * cp + cy * sr * sp);
  adj_roll += T(0.5) * T(dxr * ar.x + dyr * ar.y + dzr * ar.z + dwr * ar.w);
  adj_pitch += T(0.5) * T(dxp * ar.x + dyp * ar.y + dzp * ar.z + dwp * ar.w);
  adj_yaw += T(0.5) * T(dxy * ar.x + dyy * ar.y + dzy * ar.z + dwy * ar.w);
}
// Replays the forward steps and chains their adjoints.
template <typename T> WP_FUNC void adj_quat_slerp(const quat_t<T>& q0, const quat_t<T>& q1, T t, quat_t<T>& adj_q0, quat_t<T>& adj_q1, T& adj_t,
                                                  const quat_t<T>& adj_ret) {
  quat_t<T> inv0 = quat_inverse(q0);
  quat_t<T> rel = mul(inv0, q1);
  vec_t<3, T> axis;
  T angle;
  quat_to_axis_angle(rel, axis, angle);
  quat_t<T> step = quat_from_axis_angle(axis, T(t * angle));
  quat_t<T> adj_step, adj_rel, adj_inv0;
  adj_mul(q0, step, adj_q0, adj_step, adj_ret);
  vec_t<3, T> adj_axis;
  T adj_ta = T(0), adj_angle = T(0);
  adj_quat_from_axis_angle(axis, T(t * angle), adj_axis, adj_ta, adj_step);
  adj_t += adj_ta * angle;
  adj_angle += adj_ta * t;
  adj_quat_to_axis_angle(rel, axis, angle, adj_rel, adj_axis, adj_angle);
  adj_mul(inv0, q1, adj_inv0, adj_q1, adj_rel);
  adj_quat_inverse(q0, adj_q0, adj_inv0);
}

}  // namespace wp
