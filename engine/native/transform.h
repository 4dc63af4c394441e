// Native library: transform_t<T> (p: translation vec3, q: rotation quat; 7 components in that
// order) and the transform builtins with their adjoints: constructors, get/set translation and
// rotation, multiply, inverse, transform_point / transform_vector (also for 4x4 matrices),
// matrix(pos, rot, scale), add/sub/scale, lerp, component access.
#pragma once

#include "quat.h"

namespace wp {

template <typename T>
struct transform_t {
  vec_t<3, T> p;
  quat_t<T> q;

  WP_CALLABLE transform_t() : p(), q() {}
  WP_CALLABLE explicit transform_t(cg_uninit_t u) : p(u), q(u) {}   // left uninitialised (scalar.h)
  WP_CALLABLE transform_t(const vec_t<3, T>& p_, const quat_t<T>& q_) : p(p_), q(q_) {}
  WP_CALLABLE transform_t(T px, T py, T pz, T qx, T qy, T qz, T qw) : p(px, py, pz), q(qx, qy, qz, qw) {}
  template <typename U>
  WP_CALLABLE explicit transform_t(const transform_t<U>& o) : p(o.p), q(o.q) {}

  WP_CALLABLE T& operator[](int i) { return i < 3 ? p.c[i] : q[i - 3]; }
  WP_CALLABLE const T& operator[](int i) const { return i < 3 ? p.c[i] : q[i - 3]; }
};
typedef transform_t<float32> transform;
typedef transform_t<float32> transformf;
typedef transform_t<float64> transformd;
typedef transform_t<half> transformh;

template <typename T> WP_FUNC transform_t<T> transform_identity() { return transform_t<T>(vec_t<3, T>(), quat_identity<T>()); }
template <typename T> WP_FUNC transform_t<T> transformation(const vec_t<3, T>& p, const quat_t<T>& q) { return transform_t<T>(p, q); }
template <typename T> WP_FUNC vec_t<3, T> transform_get_translation(const transform_t<T>& t) { return t.p; }
template <typename T> WP_FUNC quat_t<T> transform_get_rotation(const transform_t<T>& t) { return t.q; }
template <typename T> WP_FUNC void transform_set_translation(transform_t<T>& t, const vec_t<3, T>& p) { t.p = p; }
template <typename T> WP_FUNC void transform_set_rotation(transform_t<T>& t, const quat_t<T>& q) { t.q = q; }

// Value forms of the set_* builtins (weft rebinds the variable instead of writing in place).
template <typename T> WP_FUNC transform_t<T> transform_with_translation(const transform_t<T>& t, const vec_t<3, T>& p) { return transform_t<T>(p, t.q); }
template <typename T> WP_FUNC transform_t<T> transform_with_rotation(const transform_t<T>& t, const quat_t<T>& q) { return transform_t<T>(t.p, q); }
template <typename T> WP_FUNC void adj_transform_with_translation(const transform_t<T>&, const vec_t<3, T>&, transform_t<T>& adj_t, vec_t<3, T>& adj_p, const transform_t<T>& adj_ret) {
  adj_t.q += adj_ret.q;
  adj_p += adj_ret.p;
}
template <typename T> WP_FUNC void adj_transform_with_rotation(const transform_t<T>&, const quat_t<T>&, transform_t<T>& adj_t, quat_t<T>& adj_q, const transform_t<T>& adj_ret) {
  adj_t.p += adj_ret.p;
  adj_q += adj_ret.q;
}

template <typename T> WP_FUNC T extract(const transform_t<T>& t, int32 i) { return (unsigned)i < 7u ? t[i] : T(0); }
template <typename T> WP_FUNC transform_t<T> assign(const transform_t<T>& t, int32 i, T value) {
  transform_t<T> r = t;
  if ((unsigned)i < 7u) r[i] = value;
  return r;
}
template <typename T> WP_FUNC void assign_inplace(transform_t<T>& t, int32 i, T value) { if ((unsigned)i < 7u) t[i] = value; }
template <typename T> WP_FUNC int32 len(const transform_t<T>&) { return 7; }
template <typename T, typename IA> WP_FUNC void adj_extract(const transform_t<T>&, int32 i, transform_t<T>& adj_t, IA&, T adj_ret) {
  if ((unsigned)i < 7u) adj_t[i] += adj_ret;
}
template <typename T, typename IA>
WP_FUNC void adj_assign(const transform_t<T>&, int32 i, T, transform_t<T>& adj_t, IA&, T& adj_value, const transform_t<T>& adj_ret) {
  for (int k = 0; k < 7; ++k) {
    if (k == i) adj_value += adj_ret[k];
    else adj_t[k] += adj_ret[k];
  }
}

template <typename T> WP_FUNC transform_t<T> add(const transform_t<T>& a, const transform_t<T>& b) { return transform_t<T>(add(a.p, b.p), add(a.q, b.q)); }
template <typename T> WP_FUNC transform_t<T> sub(const transform_t<T>& a, const transform_t<T>& b) { return transform_t<T>(sub(a.p, b.p), sub(a.q, b.q)); }
template <typename T> WP_FUNC transform_t<T> neg(const transform_t<T>& a) { return transform_t<T>(neg(a.p), neg(a.q)); }
template <typename T> WP_FUNC transform_t<T> pos(const transform_t<T>& a) { return a; }
template <typename T> WP_FUNC transform_t<T> mul(const transform_t<T>& a, T s) { return transform_t<T>(mul(a.p, s), mul(a.q, s)); }
template <typename T> WP_FUNC transform_t<T> mul(T s, const transform_t<T>& a) { return mul(a, s); }
template <typename T> WP_FUNC transform_t<T> lerp(const transform_t<T>& a, const transform_t<T>& b, T t) { return add(mul(a, T(T(1) - t)), mul(b, t)); }
template <typename T> WP_FUNC transform_t<T>& operator+=(transform_t<T>& a, const transform_t<T>& b) {
  a.p += b.p;
  a.q += b.q;
  return a;
}
template <typename T> WP_FUNC transform_t<T>& operator-=(transform_t<T>& a, const transform_t<T>& b) {
  a.p -= b.p;
  a.q -= b.q;
  return a;
}
template <typename T> WP_FUNC bool operator==(const transform_t<T>& a, const transform_t<T>& b) { return a.p == b.p && a.q == b.q; }
template <typename T> WP_FUNC bool operator!=(const transform_t<T>& a, const transform_t<T>& b) { return !(a == b); }
template <typename T> WP_FUNC bool isfinite(const transform_t<T>& t) { return isfinite(t.p) && isfinite(t.q); }
template <typename T> WP_FUNC bool isnan(const transform_t<T>& t) { return isnan(t.p) || isnan(t.q); }
template <typename T> WP_FUNC bool isinf(const transform_t<T>& t) { return isinf(t.p) || isinf(t.q); }

// a * b: apply b, then a.
template <typename T> WP_FUNC transform_t<T> transform_multiply(const transform_t<T>& a, const transform_t<T>& b) {
  return transform_t<T>(add(quat_rotate(a.q, b.p), a.p), mul(a.q, b.q));
}
template <typename T> WP_FUNC transform_t<T> mul(const transform_t<T>& a, const transform_t<T>& b) { return transform_multiply(a, b); }
template <typename T> WP_FUNC transform_t<T> transform_inverse(const transform_t<T>& t) {
  quat_t<T> qi = quat_inverse(t.q);
  return transform_t<T>(neg(quat_rotate(qi, t.p)), qi);
}
template <typename T> WP_FUNC vec_t<3, T> transform_point(const transform_t<T>& t, const vec_t<3, T>& x) { return add(t.p, quat_rotate(t.q, x)); }
template <typename T> WP_FUNC vec_t<3, T> transform_vector(const transform_t<T>& t, const vec_t<3, T>& x) { return quat_rotate(t.q, x); }
// 4x4 matrices act on column vectors (x, 1) and (x, 0).
template <typename T> WP_FUNC vec_t<3, T> transform_point(const mat_t<4, 4, T>& m, const vec_t<3, T>& x) {
  vec_t<3, T> r;
  for (unsigned i = 0; i < 3; ++i) r.c[i] = T(m.data[i][0] * x.c[0] + m.data[i][1] * x.c[1] + m.data[i][2] * x.c[2] + m.data[i][3]);
  return r;
}
template <typename T> WP_FUNC vec_t<3, T> transform_vector(const mat_t<4, 4, T>& m, const vec_t<3, T>& x) {
  vec_t<3, T> r;
  for (unsigned i = 0; i < 3; ++i) r.c[i] = T(m.data[i][0] * x.c[0] + m.data[i][1] * x.c[1] + m.data[i][2] * x.c[2]);
  return r;
}
// wp.matrix(pos, rot, scale): [R diag(scale), pos; 0 0 0 1].
template <typename T> WP_FUNC mat_t<4, 4, T> matrix_from_transform(const vec_t<3, T>& pos, const quat_t<T>& rot, const vec_t<3, T>& scale) {
  mat_t<3, 3, T> r = quat_to_matrix(rot);
  mat_t<4, 4, T> m;
  for (unsigned i = 0; i < 3; ++i) {
    for (unsigned j = 0; j < 3; ++j) m.data[i][j] = T(r.data[i][j] * scale.c[j]);
    m.data[i][3] = pos.c[i];
  }
  m.data[3][3] = T(1);
  return m;
}
template <typename T> WP_FUNC mat_t<4, 4, T> matrix(const vec_t<3, T>& pos, const quat_t<T>& rot, const vec_t<3, T>& scale) {
  return matrix_from_transform(pos, rot, scale);
}

// ---------------------------------------------------------------------------------------------
// Adjoints.
template <typename T> WP_FUNC void adj_transformation(const vec_t<3, T>&, const quat_t<T>&, vec_t<3, T>& adj_p, quat_t<T>& adj_q, const transform_t<T>& adj_ret) {
  adj_p += adj_ret.p;
  adj_q += adj_ret.q;
}
template <typename T> WP_FUNC void adj_transform_get_translation(const transform_t<T>&, transform_t<T>& adj_t, const vec_t<3, T>& adj_ret) { adj_t.p += adj_ret; }
template <typename T> WP_FUNC void adj_transform_get_rotation(const transform_t<T>&, transform_t<T>& adj_t, const quat_t<T>& adj_ret) { adj_t.q += adj_ret; }
// set_*: the overwritten part's adjoint moves to the argument and is cleared in the transform.
template <typename T> WP_FUNC void adj_transform_set_translation(transform_t<T>&, const vec_t<3, T>&, transform_t<T>& adj_t, vec_t<3, T>& adj_p) {
  adj_p += adj_t.p;
  adj_t.p = vec_t<3, T>();
}
template <typename T> WP_FUNC void adj_transform_set_rotation(transform_t<T>&, const quat_t<T>&, transform_t<T>& adj_t, quat_t<T>& adj_q) {
  adj_q += adj_t.q;
  adj_t.q = quat_t<T>();
}
template <typename T> WP_FUNC void adj_add(const transform_t<T>&, const transform_t<T>&, transform_t<T>& adj_a, transform_t<T>& adj_b, const transform_t<T>& adj_ret) { adj_a += adj_ret; adj_b += adj_ret; }
template <typename T> WP_FUNC void adj_sub(const transform_t<T>&, const transform_t<T>&, transform_t<T>& adj_a, transform_t<T>& adj_b, const transform_t<T>& adj_ret) { adj_a += adj_ret; adj_b -= adj_ret; }
template <typename T> WP_FUNC void adj_neg(const transform_t<T>&, transform_t<T>& adj_a, const transform_t<T>& adj_ret) { adj_a -= adj_ret; }
template <typename T> WP_FUNC void adj_pos(const transform_t<T>&, transform_t<T>& adj_a, const transform_t<T>& adj_ret) { adj_a += adj_ret; }
template <typename T> WP_FUNC void adj_mul(const transform_t<T>& a, T s, transform_t<T>& adj_a, T& adj_s, const transform_t<T>& adj_ret) {
  adj_a += mul(adj_ret, s);
  adj_s += T(dot(a.p, adj_ret.p) + dot(a.q, adj_ret.q));
}
template <typename T> WP_FUNC void adj_mul(T s, const transform_t<T>& a, T& adj_s, transform_t<T>& adj_a, const transform_t<T>& adj_ret) { adj_mul(a, s, adj_a, adj_s, adj_ret); }
template <typename T> WP_FUNC void adj_lerp(const transform_t<T>& a, const transform_t<T>& b, T t, transform_t<T>& adj_a, transform_t<T>& adj_b, T& adj_t,
                                            const transform_t<T>& adj_ret) {
  adj_a += mul(adj_ret, T(T(1) - t));
  adj_b += mul(adj_ret, t);
  adj_t += T(dot(sub(b.p, a.p), adj_ret.p) + dot(sub(b.q, a.q), adj_ret.q));
}
template <typename T> WP_FUNC void adj_transform_multiply(const transform_t<T>& a, const transform_t<T>& b, transform_t<T>& adj_a, transform_t<T>& adj_b,
                                                          const transform_t<T>& adj_ret) {
  adj_quat_rotate(a.q, b.p, adj_a.q, adj_b.p, adj_ret.p);
  adj_a.p += adj_ret.p;
  adj_mul(a.q, b.q, adj_a.q, adj_b.q, adj_ret.q);
}
template <typename T> WP_FUNC void adj_mul(const transform_t<T>& a, const transform_t<T>& b, transform_t<T>& adj_a, transform_t<T>& adj_b, const transform_t<T>& adj_ret) {
  adj_transform_multiply(a, b, adj_a, adj_b, adj_ret);
}
template <typename T> WP_FUNC void adj_transform_inverse(const transform_t<T>& t, transform_t<T>& adj_t, const transform_t<T>& adj_ret) {
  quat_t<T> qi = quat_inverse(t.q);
  quat_t<T> adj_qi = adj_ret.q;
  adj_quat_rotate(qi, t.p, adj_qi, adj_t.p, neg(adj_ret.p));
  adj_quat_inverse(t.q, adj_t.q, adj_qi);
}
template <typename T> WP_FUNC void adj_transform_point(const transform_t<T>& t, const vec_t<3, T>& x, transform_t<T>& adj_t, vec_t<3, T>& adj_x, const vec_t<3, T>& adj_ret) {
  adj_t.p += adj_ret;
  adj_quat_rotate(t.q, x, adj_t.q, adj_x, adj_ret);
}
template <typename T> WP_FUNC void adj_transform_vector(const transform_t<T>& t, const vec_t<3, T>& x, transform_t<T>& adj_t, vec_t<3, T>& adj_x, const vec_t<3, T>& adj_ret) {
  adj_quat_rotate(t.q, x, adj_t.q, adj_x, adj_ret);
}
template <typename T> WP_FUNC void adj_transform_point(const mat_t<4, 4, T>& m, const vec_t<3, T>& x, mat_t<4, 4, T>& adj_m, vec_t<3, T>& adj_x, const vec_t<3, T>& adj_ret) {
  for (unsigned i = 0; i < 3; ++i) {
    for (unsigned j = 0; j < 3; ++j) {
      adj_m.data[i][j] += x.c[j] * adj_ret.c[i];
      adj_x.c[j] += m.data[i][j] * adj_ret.c[i];
    }
    adj_m.data[i][3] += adj_ret.c[i];
  }
}
template <typename T> WP_FUNC void adj_transform_vector(const mat_t<4, 4, T>& m, const vec_t<3, T>& x, mat_t<4, 4, T>& adj_m, vec_t<3, T>& adj_x, const vec_t<3, T>& adj_ret) {
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) {
      adj_m.data[i][j] += x.c[j] * adj_ret.c[i];
      adj_x.c[j] += m.data[i][j] * adj_ret.c[i];
    }
}
template <typename T> WP_FUNC void adj_matrix_from_transform(const vec_t<3, T>&, const quat_t<T>& rot, const vec_t<3, T>& scale, vec_t<3, T>& adj_pos,
                                                             quat_t<T>& adj_rot, vec_t<3, T>& adj_scale, const mat_t<4, 4, T>& adj_ret) {
  mat_t<3, 3, T> r = quat_to_matrix(rot);
  mat_t<3, 3, T> adj_r;
  for (unsigned i = 0; i < 3; ++i) {
    for (unsigned j = 0; j < 3; ++j) {
      adj_r.data[i][j] += scale.c[j] * adj_ret.data[i][j];
      adj_scale.c[j] += r.data[i][j] * adj_ret.data[i][j];
    }
    adj_pos.c[i] += adj_ret.data[i][3];
  }
  adj_quat_to_matrix(rot, adj_rot, adj_r);
}
template <typename T> WP_FUNC void adj_matrix(const vec_t<3, T>& pos, const quat_t<T>& rot, const vec_t<3, T>& scale, vec_t<3, T>& adj_pos,
                                              quat_t<T>& adj_rot, vec_t<3, T>& adj_scale, const mat_t<4, 4, T>& adj_ret) {
  adj_matrix_from_transform(pos, rot, scale, adj_pos, adj_rot, adj_scale, adj_ret);
}

}  // namespace wp
