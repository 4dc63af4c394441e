// Native library: vec_t<N,T> (Warp's vector types, incl. spatial_vector = vec_t<6,T>) and the
// vector builtins with their adjoints: constructors, component access (extract / assign),
// arithmetic, dot, cross, length, normalize, min/max/argmin/argmax, abs/sign, lerp, bit ops.
#pragma once

#include "scalar.h"

namespace wp {

template <unsigned N, typename T>
struct vec_t {
  T c[N > 0 ? N : 1];   // a zero-length vector (a slice selecting nothing) keeps one unused slot

  WP_CALLABLE vec_t() : c() {}
  WP_CALLABLE explicit vec_t(cg_uninit_t) {}   // components left uninitialised (scalar.h)
  // Fill: vec_t<3,float32>(s).
  WP_CALLABLE explicit vec_t(T s) {
    for (unsigned i = 0; i < N; ++i) c[i] = s;
  }
  // Components: vec_t<3,float32>(x, y, z); each argument is converted to T.
  template <typename... A>
  WP_CALLABLE vec_t(T a0, T a1, A... rest) : c{a0, a1, T(rest)...} {
    static_assert(sizeof...(A) + 2 == N, "vec_t: wrong number of components");
  }
  // Conversion between scalar types: vec_t<3,float64>(vec3f).
  template <typename U>
  WP_CALLABLE explicit vec_t(const vec_t<N, U>& o) {
    for (unsigned i = 0; i < N; ++i) c[i] = T(o.c[i]);
  }
  // Spatial vector from its two halves: vec_t<6,T>(w, v).
  template <unsigned M, typename = typename enable_if_t_<M * 2 == N>::type>
  WP_CALLABLE vec_t(const vec_t<M, T>& top, const vec_t<M, T>& bottom) {
    for (unsigned i = 0; i < M; ++i) {
      c[i] = top.c[i];
      c[i + M] = bottom.c[i];
    }
  }

  WP_CALLABLE T& operator[](int i) { return c[i]; }
  WP_CALLABLE const T& operator[](int i) const { return c[i]; }
};

template <typename T> using vec2_t = vec_t<2, T>;
template <typename T> using vec3_t = vec_t<3, T>;
template <typename T> using vec4_t = vec_t<4, T>;
typedef vec_t<2, float32> vec2;
typedef vec_t<3, float32> vec3;
typedef vec_t<4, float32> vec4;
typedef vec_t<2, float32> vec2f;
typedef vec_t<3, float32> vec3f;
typedef vec_t<4, float32> vec4f;
typedef vec_t<2, float64> vec2d;
typedef vec_t<3, float64> vec3d;
typedef vec_t<4, float64> vec4d;
typedef vec_t<2, half> vec2h;
typedef vec_t<3, half> vec3h;
typedef vec_t<4, half> vec4h;
typedef vec_t<2, int32> vec2i;
typedef vec_t<3, int32> vec3i;
typedef vec_t<4, int32> vec4i;

// wp.vector(*args, length, dtype) / fill forms: the code generator emits the constructor;
// these helpers exist for generic code.
template <unsigned N, typename T> WP_FUNC vec_t<N, T> vector_fill(T s) { return vec_t<N, T>(s); }

// ---------------------------------------------------------------------------------------------
// Component access. extract() with an index outside [0, N) returns 0 (and assign() ignores the
// write) instead of touching memory outside the value.
template <unsigned N, typename T>
WP_FUNC T extract(const vec_t<N, T>& v, int32 i) { return (unsigned)i < N ? v.c[i] : T(0); }
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> assign(const vec_t<N, T>& v, int32 i, T value) {
  vec_t<N, T> r = v;
  if ((unsigned)i < N) r.c[i] = value;
  return r;
}
// In-place forms used for `v[i] = x` and `v[i] += x` on local variables.
template <unsigned N, typename T>
WP_FUNC void assign_inplace(vec_t<N, T>& v, int32 i, T value) { if ((unsigned)i < N) v.c[i] = value; }
template <unsigned N, typename T>
WP_FUNC void add_inplace(vec_t<N, T>& v, int32 i, T value) { if ((unsigned)i < N) v.c[i] += value; }
template <unsigned N, typename T>
WP_FUNC void sub_inplace(vec_t<N, T>& v, int32 i, T value) { if ((unsigned)i < N) v.c[i] -= value; }
template <unsigned N, typename T>
WP_FUNC int32 len(const vec_t<N, T>&) { return (int32)N; }

template <unsigned N, typename T, typename IA>
WP_FUNC void adj_extract(const vec_t<N, T>&, int32 i, vec_t<N, T>& adj_v, IA&, T adj_ret) {
  if ((unsigned)i < N) adj_v.c[i] += adj_ret;
}
template <unsigned N, typename T, typename IA>
WP_FUNC void adj_assign(const vec_t<N, T>&, int32 i, T, vec_t<N, T>& adj_v, IA&, T& adj_value,
                        const vec_t<N, T>& adj_ret) {
  for (unsigned k = 0; k < N; ++k)
    if ((int32)k != i) adj_v.c[k] += adj_ret.c[k];
  if ((unsigned)i < N) adj_value += adj_ret.c[i];
}

// ---------------------------------------------------------------------------------------------
// Element-wise helpers.
#define WP_VEC_BINARY(name) \
  template <unsigned N, typename T> \
  WP_FUNC vec_t<N, T> name(const vec_t<N, T>& a, const vec_t<N, T>& b) { \
    vec_t<N, T> r; \
    for (unsigned i = 0; i < N; ++i) r.c[i] = name(a.c[i], b.c[i]); \
    return r; \
  }
#define WP_VEC_UNARY(name) \
  template <unsigned N, typename T> \
  WP_FUNC vec_t<N, T> name(const vec_t<N, T>& a) { \
    vec_t<N, T> r; \
    for (unsigned i = 0; i < N; ++i) r.c[i] = name(a.c[i]); \
    return r; \
  }
WP_VEC_BINARY(add)
WP_VEC_BINARY(sub)
WP_VEC_BINARY(mod)
WP_VEC_BINARY(min)
WP_VEC_BINARY(max)
WP_VEC_BINARY(bit_and)
WP_VEC_BINARY(bit_or)
WP_VEC_BINARY(bit_xor)
WP_VEC_BINARY(lshift)
WP_VEC_BINARY(rshift)
WP_VEC_BINARY(floordiv)
WP_VEC_UNARY(neg)
WP_VEC_UNARY(pos)
WP_VEC_UNARY(abs)
WP_VEC_UNARY(sign)
WP_VEC_UNARY(invert)
#undef WP_VEC_BINARY
#undef WP_VEC_UNARY

template <unsigned N, typename T>
WP_FUNC vec_t<N, T> cw_mul(const vec_t<N, T>& a, const vec_t<N, T>& b) {
  vec_t<N, T> r;
  for (unsigned i = 0; i < N; ++i) r.c[i] = mul(a.c[i], b.c[i]);
  return r;
}
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> cw_div(const vec_t<N, T>& a, const vec_t<N, T>& b) {
  vec_t<N, T> r;
  for (unsigned i = 0; i < N; ++i) r.c[i] = div(a.c[i], b.c[i]);
  return r;
}
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> mul(const vec_t<N, T>& a, T s) {
  vec_t<N, T> r;
  for (unsigned i = 0; i < N; ++i) r.c[i] = mul(a.c[i], s);
  return r;
}
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> mul(T s, const vec_t<N, T>& a) { return mul(a, s); }
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> div(const vec_t<N, T>& a, T s) {
  vec_t<N, T> r;
  for (unsigned i = 0; i < N; ++i) r.c[i] = div(a.c[i], s);
  return r;
}
// Warp: scalar / vector divides the scalar by each component.
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> div(T s, const vec_t<N, T>& a) {
  vec_t<N, T> r;
  for (unsigned i = 0; i < N; ++i) r.c[i] = div(s, a.c[i]);
  return r;
}
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> div_approx(const vec_t<N, T>& a, T s) { return div(a, s); }
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> div_approx(T s, const vec_t<N, T>& a) { return div(s, a); }

// C++ operators for convenience inside the library.
template <unsigned N, typename T> WP_FUNC vec_t<N, T> operator+(const vec_t<N, T>& a, const vec_t<N, T>& b) { return add(a, b); }
template <unsigned N, typename T> WP_FUNC vec_t<N, T> operator-(const vec_t<N, T>& a, const vec_t<N, T>& b) { return sub(a, b); }
template <unsigned N, typename T> WP_FUNC vec_t<N, T> operator-(const vec_t<N, T>& a) { return neg(a); }
template <unsigned N, typename T> WP_FUNC vec_t<N, T> operator*(const vec_t<N, T>& a, T s) { return mul(a, s); }
template <unsigned N, typename T> WP_FUNC vec_t<N, T> operator*(T s, const vec_t<N, T>& a) { return mul(a, s); }
template <unsigned N, typename T> WP_FUNC vec_t<N, T> operator/(const vec_t<N, T>& a, T s) { return div(a, s); }
template <unsigned N, typename T> WP_FUNC vec_t<N, T>& operator+=(vec_t<N, T>& a, const vec_t<N, T>& b) {
  for (unsigned i = 0; i < N; ++i) a.c[i] += b.c[i];
  return a;
}
template <unsigned N, typename T> WP_FUNC vec_t<N, T>& operator-=(vec_t<N, T>& a, const vec_t<N, T>& b) {
  for (unsigned i = 0; i < N; ++i) a.c[i] -= b.c[i];
  return a;
}
template <unsigned N, typename T> WP_FUNC bool operator==(const vec_t<N, T>& a, const vec_t<N, T>& b) {
  for (unsigned i = 0; i < N; ++i)
    if (!(a.c[i] == b.c[i])) return false;
  return true;
}
template <unsigned N, typename T> WP_FUNC bool operator!=(const vec_t<N, T>& a, const vec_t<N, T>& b) { return !(a == b); }

// ---------------------------------------------------------------------------------------------
// Reductions and geometry.
template <unsigned N, typename T>
WP_FUNC T dot(const vec_t<N, T>& a, const vec_t<N, T>& b) {
  T r = T(0);
  for (unsigned i = 0; i < N; ++i) r = add(r, mul(a.c[i], b.c[i]));  // wraps for integers
  return r;
}
template <unsigned N, typename T>
WP_FUNC T length_sq(const vec_t<N, T>& a) { return dot(a, a); }
template <unsigned N, typename T>
WP_FUNC T length(const vec_t<N, T>& a) { return sqrt(dot(a, a)); }
// Zero vector -> zero vector (Warp).
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> normalize(const vec_t<N, T>& a) {
  T l = length(a);
  if (l > T(0)) return div(a, l);
  return vec_t<N, T>();
}
template <typename T>
WP_FUNC vec_t<3, T> cross(const vec_t<3, T>& a, const vec_t<3, T>& b) {
  return vec_t<3, T>(sub(mul(a.c[1], b.c[2]), mul(a.c[2], b.c[1])), sub(mul(a.c[2], b.c[0]), mul(a.c[0], b.c[2])),
                     sub(mul(a.c[0], b.c[1]), mul(a.c[1], b.c[0])));
}
template <unsigned N, typename T>
WP_FUNC T min(const vec_t<N, T>& a) {
  T r = a.c[0];
  for (unsigned i = 1; i < N; ++i) r = min(r, a.c[i]);
  return r;
}
template <unsigned N, typename T>
WP_FUNC T max(const vec_t<N, T>& a) {
  T r = a.c[0];
  for (unsigned i = 1; i < N; ++i) r = max(r, a.c[i]);
  return r;
}
// First index of the extreme value; NaN components are skipped unless all are NaN (as min/max).
template <unsigned N, typename T>
WP_FUNC uint32 argmin(const vec_t<N, T>& a) {
  uint32 k = 0;
  for (unsigned i = 1; i < N; ++i)
    if (!isnan(a.c[i]) && (isnan(a.c[k]) || a.c[i] < a.c[k])) k = i;
  return k;
}
template <unsigned N, typename T>
WP_FUNC uint32 argmax(const vec_t<N, T>& a) {
  uint32 k = 0;
  for (unsigned i = 1; i < N; ++i)
    if (!isnan(a.c[i]) && (isnan(a.c[k]) || a.c[i] > a.c[k])) k = i;
  return k;
}
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> lerp(const vec_t<N, T>& a, const vec_t<N, T>& b, T t) {
  return add(mul(a, T(T(1) - t)), mul(b, t));
}
template <unsigned N, typename T>
WP_FUNC bool isfinite(const vec_t<N, T>& a) {
  for (unsigned i = 0; i < N; ++i)
    if (!isfinite(a.c[i])) return false;
  return true;
}
template <unsigned N, typename T>
WP_FUNC bool isnan(const vec_t<N, T>& a) {
  for (unsigned i = 0; i < N; ++i)
    if (isnan(a.c[i])) return true;
  return false;
}
template <unsigned N, typename T>
WP_FUNC bool isinf(const vec_t<N, T>& a) {
  for (unsigned i = 0; i < N; ++i)
    if (isinf(a.c[i])) return true;
  return false;
}

// ---------------------------------------------------------------------------------------------
// Adjoints.
template <unsigned N, typename T>
WP_FUNC void adj_add(const vec_t<N, T>&, const vec_t<N, T>&, vec_t<N, T>& adj_a, vec_t<N, T>& adj_b, const vec_t<N, T>& adj_ret) {
  adj_a += adj_ret;
  adj_b += adj_ret;
}
template <unsigned N, typename T>
WP_FUNC void adj_sub(const vec_t<N, T>&, const vec_t<N, T>&, vec_t<N, T>& adj_a, vec_t<N, T>& adj_b, const vec_t<N, T>& adj_ret) {
  adj_a += adj_ret;
  adj_b -= adj_ret;
}
template <unsigned N, typename T>
WP_FUNC void adj_neg(const vec_t<N, T>&, vec_t<N, T>& adj_a, const vec_t<N, T>& adj_ret) { adj_a -= adj_ret; }
template <unsigned N, typename T>
WP_FUNC void adj_pos(const vec_t<N, T>&, vec_t<N, T>& adj_a, const vec_t<N, T>& adj_ret) { adj_a += adj_ret; }
template <unsigned N, typename T>
WP_FUNC void adj_mul(const vec_t<N, T>& a, T s, vec_t<N, T>& adj_a, T& adj_s, const vec_t<N, T>& adj_ret) {
  for (unsigned i = 0; i < N; ++i) adj_a.c[i] += s * adj_ret.c[i];
  adj_s += dot(a, adj_ret);
}
template <unsigned N, typename T>
WP_FUNC void adj_mul(T s, const vec_t<N, T>& a, T& adj_s, vec_t<N, T>& adj_a, const vec_t<N, T>& adj_ret) {
  adj_mul(a, s, adj_a, adj_s, adj_ret);
}
template <unsigned N, typename T>
WP_FUNC void adj_div(const vec_t<N, T>& a, T s, vec_t<N, T>& adj_a, T& adj_s, const vec_t<N, T>& adj_ret) {
  for (unsigned i = 0; i < N; ++i) adj_a.c[i] += adj_ret.c[i] / s;
  adj_s -= dot(a, adj_ret) / T(s * s);
}
template <unsigned N, typename T>
WP_FUNC void adj_div(T s, const vec_t<N, T>& a, T& adj_s, vec_t<N, T>& adj_a, const vec_t<N, T>& adj_ret) {
  for (unsigned i = 0; i < N; ++i) {
    adj_s += adj_ret.c[i] / a.c[i];
    adj_a.c[i] -= adj_ret.c[i] * s / T(a.c[i] * a.c[i]);
  }
}
template <unsigned N, typename T>
WP_FUNC void adj_div_approx(const vec_t<N, T>& a, T s, vec_t<N, T>& adj_a, T& adj_s, const vec_t<N, T>& adj_ret) { adj_div(a, s, adj_a, adj_s, adj_ret); }
template <unsigned N, typename T>
WP_FUNC void adj_div_approx(T s, const vec_t<N, T>& a, T& adj_s, vec_t<N, T>& adj_a, const vec_t<N, T>& adj_ret) { adj_div(s, a, adj_s, adj_a, adj_ret); }
template <unsigned N, typename T>
WP_FUNC void adj_cw_mul(const vec_t<N, T>& a, const vec_t<N, T>& b, vec_t<N, T>& adj_a, vec_t<N, T>& adj_b, const vec_t<N, T>& adj_ret) {
  for (unsigned i = 0; i < N; ++i) adj_mul(a.c[i], b.c[i], adj_a.c[i], adj_b.c[i], adj_ret.c[i]);
}
template <unsigned N, typename T>
WP_FUNC void adj_cw_div(const vec_t<N, T>& a, const vec_t<N, T>& b, vec_t<N, T>& adj_a, vec_t<N, T>& adj_b, const vec_t<N, T>& adj_ret) {
  for (unsigned i = 0; i < N; ++i) adj_div(a.c[i], b.c[i], adj_a.c[i], adj_b.c[i], adj_ret.c[i]);
}
#define WP_VEC_ADJ_BINARY(name) \
  template <unsigned N, typename T> \
  WP_FUNC void adj_##name(const vec_t<N, T>& a, const vec_t<N, T>& b, vec_t<N, T>& adj_a, vec_t<N, T>& adj_b, const vec_t<N, T>& adj_ret) { \
    for (unsigned i = 0; i < N; ++i) adj_##name(a.c[i], b.c[i], adj_a.c[i], adj_b.c[i], adj_ret.c[i]); \
  }
#define WP_VEC_ADJ_UNARY(name) \
  template <unsigned N, typename T> \
  WP_FUNC void adj_##name(const vec_t<N, T>& a, vec_t<N, T>& adj_a, const vec_t<N, T>& adj_ret) { \
    for (unsigned i = 0; i < N; ++i) adj_##name(a.c[i], adj_a.c[i], adj_ret.c[i]); \
  }
WP_VEC_ADJ_BINARY(mod)
WP_VEC_ADJ_BINARY(min)
WP_VEC_ADJ_BINARY(max)
WP_VEC_ADJ_UNARY(abs)
WP_VEC_ADJ_UNARY(sign)
#undef WP_VEC_ADJ_BINARY
#undef WP_VEC_ADJ_UNARY
template <unsigned N, typename T>
WP_FUNC void adj_floordiv(const vec_t<N, T>&, const vec_t<N, T>&, vec_t<N, T>&, vec_t<N, T>&, const vec_t<N, T>&) {}

template <unsigned N, typename T>
WP_FUNC void adj_dot(const vec_t<N, T>& a, const vec_t<N, T>& b, vec_t<N, T>& adj_a, vec_t<N, T>& adj_b, T adj_ret) {
  for (unsigned i = 0; i < N; ++i) {
    adj_a.c[i] += b.c[i] * adj_ret;
    adj_b.c[i] += a.c[i] * adj_ret;
  }
}
template <unsigned N, typename T>
WP_FUNC void adj_length_sq(const vec_t<N, T>& a, vec_t<N, T>& adj_a, T adj_ret) {
  for (unsigned i = 0; i < N; ++i) adj_a.c[i] += T(2) * a.c[i] * adj_ret;
}
// length'(0) = 0 (Warp).
template <unsigned N, typename T>
WP_FUNC void adj_length(const vec_t<N, T>& a, vec_t<N, T>& adj_a, T adj_ret) {
  T l = length(a);
  if (l > T(0))
    for (unsigned i = 0; i < N; ++i) adj_a.c[i] += a.c[i] / l * adj_ret;
}
// normalize'(0) = 0.
template <unsigned N, typename T>
WP_FUNC void adj_normalize(const vec_t<N, T>& a, vec_t<N, T>& adj_a, const vec_t<N, T>& adj_ret) {
  T l = length(a);
  if (l > T(0)) {
    vec_t<N, T> n = div(a, l);
    T d = dot(n, adj_ret);
    for (unsigned i = 0; i < N; ++i) adj_a.c[i] += T(adj_ret.c[i] - n.c[i] * d) / l;
  }
}
template <typename T>
WP_FUNC void adj_cross(const vec_t<3, T>& a, const vec_t<3, T>& b, vec_t<3, T>& adj_a, vec_t<3, T>& adj_b, const vec_t<3, T>& adj_ret) {
  adj_a += cross(b, adj_ret);
  adj_b += cross(adj_ret, a);
}
// Reduction min/max: the gradient goes to the chosen (first extreme) component.
template <unsigned N, typename T>
WP_FUNC void adj_min(const vec_t<N, T>& a, vec_t<N, T>& adj_a, T adj_ret) { adj_a.c[argmin(a)] += adj_ret; }
template <unsigned N, typename T>
WP_FUNC void adj_max(const vec_t<N, T>& a, vec_t<N, T>& adj_a, T adj_ret) { adj_a.c[argmax(a)] += adj_ret; }
template <unsigned N, typename T>
WP_FUNC void adj_lerp(const vec_t<N, T>& a, const vec_t<N, T>& b, T t, vec_t<N, T>& adj_a, vec_t<N, T>& adj_b, T& adj_t,
                      const vec_t<N, T>& adj_ret) {
  for (unsigned i = 0; i < N; ++i) {
    adj_a.c[i] += T(T(1) - t) * adj_ret.c[i];
    adj_b.c[i] += t * adj_ret.c[i];
  }
  adj_t += dot(sub(b, a), adj_ret);
}
template <unsigned N, typename T, typename U>
WP_FUNC void adj_vec_cast(const vec_t<N, U>&, vec_t<N, U>& adj_a, const vec_t<N, T>& adj_ret) { adj_a += vec_t<N, U>(adj_ret); }

// Adjoints of the component constructors (2, 3, 4 components).
template <typename T>
WP_FUNC void adj_vec(T, T, T& a0, T& a1, const vec_t<2, T>& r) { a0 += r.c[0]; a1 += r.c[1]; }
template <typename T>
WP_FUNC void adj_vec(T, T, T, T& a0, T& a1, T& a2, const vec_t<3, T>& r) { a0 += r.c[0]; a1 += r.c[1]; a2 += r.c[2]; }
template <typename T>
WP_FUNC void adj_vec(T, T, T, T, T& a0, T& a1, T& a2, T& a3, const vec_t<4, T>& r) {
  a0 += r.c[0]; a1 += r.c[1]; a2 += r.c[2]; a3 += r.c[3];
}
// Fill constructor adjoint: the sum of the components.
template <unsigned N, typename T>
WP_FUNC void adj_vec_fill(T, T& adj_s, const vec_t<N, T>& adj_ret) {
  for (unsigned i = 0; i < N; ++i) adj_s += adj_ret.c[i];
}

}  // namespace wp
