// Native library: mat_t<R,C,T> (row-major `T data[R][C]`, incl. spatial_matrix = mat_t<6,6,T>)
// and the matrix builtins with their adjoints: constructors (scalars row-major, vectors as
// columns, matrix_from_rows/cols, identity, diag), component access, arithmetic, products,
// transpose, determinant, inverse (singular -> zero matrix, as Warp), trace, outer, skew, ddot.
#pragma once

#include "vec.h"

namespace wp {

template <unsigned R, unsigned C, typename T>
struct mat_t {
  T data[R > 0 ? R : 1][C > 0 ? C : 1];   // zero rows or columns (a slice) keep one unused slot

  WP_CALLABLE mat_t() : data() {}
  WP_CALLABLE explicit mat_t(cg_uninit_t) {}   // entries left uninitialised (scalar.h)
  // Fill: every entry = s.
  WP_CALLABLE explicit mat_t(T s) {
    for (unsigned i = 0; i < R; ++i)
      for (unsigned j = 0; j < C; ++j) data[i][j] = s;
  }
  // R*C scalars, row-major: mat_t<2,2,float32>(m00, m01, m10, m11).
  template <typename... A>
  WP_CALLABLE mat_t(T a0, T a1, A... rest) {
    static_assert(sizeof...(A) + 2 == R * C, "mat_t: wrong number of entries");
    const T v[R * C] = {a0, a1, T(rest)...};
    for (unsigned i = 0; i < R; ++i)
      for (unsigned j = 0; j < C; ++j) data[i][j] = v[i * C + j];
  }
  // C column vectors (Warp's legacy rule for wp.matrix(v0, v1, ...)).
  template <typename... V>
  WP_CALLABLE mat_t(const vec_t<R, T>& c0, const V&... rest) {
    static_assert(sizeof...(V) + 1 == C, "mat_t: wrong number of column vectors");
    const vec_t<R, T> cols[C] = {c0, rest...};
    for (unsigned i = 0; i < R; ++i)
      for (unsigned j = 0; j < C; ++j) data[i][j] = cols[j].c[i];
  }
  template <typename U>
  WP_CALLABLE explicit mat_t(const mat_t<R, C, U>& o) {
    for (unsigned i = 0; i < R; ++i)
      for (unsigned j = 0; j < C; ++j) data[i][j] = T(o.data[i][j]);
  }

  WP_CALLABLE vec_t<C, T> get_row(int i) const {
    vec_t<C, T> r;
    for (unsigned j = 0; j < C; ++j) r.c[j] = data[i][j];
    return r;
  }
  WP_CALLABLE vec_t<R, T> get_col(int j) const {
    vec_t<R, T> r;
    for (unsigned i = 0; i < R; ++i) r.c[i] = data[i][j];
    return r;
  }
};

typedef mat_t<2, 2, float32> mat22;
typedef mat_t<3, 3, float32> mat33;
typedef mat_t<4, 4, float32> mat44;
typedef mat_t<2, 2, float32> mat22f;
typedef mat_t<3, 3, float32> mat33f;
typedef mat_t<4, 4, float32> mat44f;
typedef mat_t<2, 2, float64> mat22d;
typedef mat_t<3, 3, float64> mat33d;
typedef mat_t<4, 4, float64> mat44d;

template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> matrix_from_rows(const vec_t<C, T>* rows) {
  mat_t<R, C, T> m;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) m.data[i][j] = rows[i].c[j];
  return m;
}
// matrix_from_rows(r0, r1, ...) / matrix_from_cols(c0, c1, ...): 2..4 vectors.
template <unsigned C, typename T>
WP_FUNC mat_t<2, C, T> matrix_from_rows(const vec_t<C, T>& r0, const vec_t<C, T>& r1) {
  const vec_t<C, T> r[2] = {r0, r1};
  return matrix_from_rows<2, C, T>(r);
}
template <unsigned C, typename T>
WP_FUNC mat_t<3, C, T> matrix_from_rows(const vec_t<C, T>& r0, const vec_t<C, T>& r1, const vec_t<C, T>& r2) {
  const vec_t<C, T> r[3] = {r0, r1, r2};
  return matrix_from_rows<3, C, T>(r);
}
template <unsigned C, typename T>
WP_FUNC mat_t<4, C, T> matrix_from_rows(const vec_t<C, T>& r0, const vec_t<C, T>& r1, const vec_t<C, T>& r2,
                                        const vec_t<C, T>& r3) {
  const vec_t<C, T> r[4] = {r0, r1, r2, r3};
  return matrix_from_rows<4, C, T>(r);
}
template <unsigned R, typename T>
WP_FUNC mat_t<R, 2, T> matrix_from_cols(const vec_t<R, T>& c0, const vec_t<R, T>& c1) { return mat_t<R, 2, T>(c0, c1); }
template <unsigned R, typename T>
WP_FUNC mat_t<R, 3, T> matrix_from_cols(const vec_t<R, T>& c0, const vec_t<R, T>& c1, const vec_t<R, T>& c2) {
  return mat_t<R, 3, T>(c0, c1, c2);
}
template <unsigned R, typename T>
WP_FUNC mat_t<R, 4, T> matrix_from_cols(const vec_t<R, T>& c0, const vec_t<R, T>& c1, const vec_t<R, T>& c2,
                                        const vec_t<R, T>& c3) {
  return mat_t<R, 4, T>(c0, c1, c2, c3);
}

template <unsigned N, typename T>
WP_FUNC mat_t<N, N, T> identity() {
  mat_t<N, N, T> m;
  for (unsigned i = 0; i < N; ++i) m.data[i][i] = T(1);
  return m;
}
template <unsigned N, typename T>
WP_FUNC mat_t<N, N, T> diag(const vec_t<N, T>& d) {
  mat_t<N, N, T> m;
  for (unsigned i = 0; i < N; ++i) m.data[i][i] = d.c[i];
  return m;
}
template <unsigned N, typename T>
WP_FUNC vec_t<N, T> get_diag(const mat_t<N, N, T>& m) {
  vec_t<N, T> d;
  for (unsigned i = 0; i < N; ++i) d.c[i] = m.data[i][i];
  return d;
}

// ---------------------------------------------------------------------------------------------
// Component access: m[i] is row i, m[i, j] an entry; out-of-range indices read 0 / write nothing.
template <unsigned R, unsigned C, typename T>
WP_FUNC vec_t<C, T> extract(const mat_t<R, C, T>& m, int32 i) {
  return (unsigned)i < R ? m.get_row(i) : vec_t<C, T>();
}
template <unsigned R, unsigned C, typename T>
WP_FUNC T extract(const mat_t<R, C, T>& m, int32 i, int32 j) {
  return ((unsigned)i < R && (unsigned)j < C) ? m.data[i][j] : T(0);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> assign(const mat_t<R, C, T>& m, int32 i, int32 j, T value) {
  mat_t<R, C, T> r = m;
  if ((unsigned)i < R && (unsigned)j < C) r.data[i][j] = value;
  return r;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> assign(const mat_t<R, C, T>& m, int32 i, const vec_t<C, T>& row) {
  mat_t<R, C, T> r = m;
  if ((unsigned)i < R)
    for (unsigned j = 0; j < C; ++j) r.data[i][j] = row.c[j];
  return r;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void assign_inplace(mat_t<R, C, T>& m, int32 i, int32 j, T value) {
  if ((unsigned)i < R && (unsigned)j < C) m.data[i][j] = value;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void assign_inplace(mat_t<R, C, T>& m, int32 i, const vec_t<C, T>& row) {
  if ((unsigned)i < R)
    for (unsigned j = 0; j < C; ++j) m.data[i][j] = row.c[j];
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void add_inplace(mat_t<R, C, T>& m, int32 i, int32 j, T value) {
  if ((unsigned)i < R && (unsigned)j < C) m.data[i][j] += value;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void sub_inplace(mat_t<R, C, T>& m, int32 i, int32 j, T value) {
  if ((unsigned)i < R && (unsigned)j < C) m.data[i][j] -= value;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC int32 len(const mat_t<R, C, T>&) { return (int32)R; }

template <unsigned R, unsigned C, typename T, typename IA>
WP_FUNC void adj_extract(const mat_t<R, C, T>&, int32 i, mat_t<R, C, T>& adj_m, IA&, const vec_t<C, T>& adj_ret) {
  if ((unsigned)i < R)
    for (unsigned j = 0; j < C; ++j) adj_m.data[i][j] += adj_ret.c[j];
}
template <unsigned R, unsigned C, typename T, typename IA>
WP_FUNC void adj_extract(const mat_t<R, C, T>&, int32 i, int32 j, mat_t<R, C, T>& adj_m, IA&, IA&, T adj_ret) {
  if ((unsigned)i < R && (unsigned)j < C) adj_m.data[i][j] += adj_ret;
}
template <unsigned R, unsigned C, typename T, typename IA>
WP_FUNC void adj_assign(const mat_t<R, C, T>&, int32 i, int32 j, T, mat_t<R, C, T>& adj_m, IA&, IA&, T& adj_value,
                        const mat_t<R, C, T>& adj_ret) {
  for (unsigned a = 0; a < R; ++a)
    for (unsigned b = 0; b < C; ++b) {
      if ((int32)a == i && (int32)b == j) adj_value += adj_ret.data[a][b];
      else adj_m.data[a][b] += adj_ret.data[a][b];
    }
}
template <unsigned R, unsigned C, typename T, typename IA>
WP_FUNC void adj_assign(const mat_t<R, C, T>&, int32 i, const vec_t<C, T>&, mat_t<R, C, T>& adj_m, IA&, vec_t<C, T>& adj_row,
                        const mat_t<R, C, T>& adj_ret) {
  for (unsigned a = 0; a < R; ++a)
    for (unsigned b = 0; b < C; ++b) {
      if ((int32)a == i) adj_row.c[b] += adj_ret.data[a][b];
      else adj_m.data[a][b] += adj_ret.data[a][b];
    }
}

// ---------------------------------------------------------------------------------------------
// Arithmetic.
#define WP_MAT_BINARY(name, op) \
  template <unsigned R, unsigned C, typename T> \
  WP_FUNC mat_t<R, C, T> name(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b) { \
    mat_t<R, C, T> r; \
    for (unsigned i = 0; i < R; ++i) \
      for (unsigned j = 0; j < C; ++j) r.data[i][j] = op(a.data[i][j], b.data[i][j]); \
    return r; \
  }
WP_MAT_BINARY(add, add)
WP_MAT_BINARY(sub, sub)
WP_MAT_BINARY(cw_mul, mul)
WP_MAT_BINARY(cw_div, div)
WP_MAT_BINARY(bit_and, bit_and)
WP_MAT_BINARY(bit_or, bit_or)
WP_MAT_BINARY(bit_xor, bit_xor)
WP_MAT_BINARY(lshift, lshift)
WP_MAT_BINARY(rshift, rshift)
#undef WP_MAT_BINARY
#define WP_MAT_UNARY(name) \
  template <unsigned R, unsigned C, typename T> \
  WP_FUNC mat_t<R, C, T> name(const mat_t<R, C, T>& a) { \
    mat_t<R, C, T> r; \
    for (unsigned i = 0; i < R; ++i) \
      for (unsigned j = 0; j < C; ++j) r.data[i][j] = name(a.data[i][j]); \
    return r; \
  }
WP_MAT_UNARY(neg)
WP_MAT_UNARY(pos)
WP_MAT_UNARY(invert)
#undef WP_MAT_UNARY

template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> mul(const mat_t<R, C, T>& a, T s) {
  mat_t<R, C, T> r;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) r.data[i][j] = mul(a.data[i][j], s);
  return r;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> mul(T s, const mat_t<R, C, T>& a) { return mul(a, s); }
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> div(const mat_t<R, C, T>& a, T s) {
  mat_t<R, C, T> r;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) r.data[i][j] = div(a.data[i][j], s);
  return r;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> div(T s, const mat_t<R, C, T>& a) {
  mat_t<R, C, T> r;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) r.data[i][j] = div(s, a.data[i][j]);
  return r;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> div_approx(const mat_t<R, C, T>& a, T s) { return div(a, s); }
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> div_approx(T s, const mat_t<R, C, T>& a) { return div(s, a); }
template <unsigned R, unsigned C, typename T>
WP_FUNC vec_t<R, T> mul(const mat_t<R, C, T>& m, const vec_t<C, T>& v) {
  vec_t<R, T> r;
  for (unsigned i = 0; i < R; ++i) {
    T s = T(0);
    for (unsigned j = 0; j < C; ++j) s = add(s, mul(m.data[i][j], v.c[j]));
    r.c[i] = s;
  }
  return r;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC vec_t<C, T> mul(const vec_t<R, T>& v, const mat_t<R, C, T>& m) {
  vec_t<C, T> r;
  for (unsigned j = 0; j < C; ++j) {
    T s = T(0);
    for (unsigned i = 0; i < R; ++i) s = add(s, mul(v.c[i], m.data[i][j]));
    r.c[j] = s;
  }
  return r;
}
template <unsigned R, unsigned K, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> mul(const mat_t<R, K, T>& a, const mat_t<K, C, T>& b) {
  mat_t<R, C, T> r;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) {
      T s = T(0);
      for (unsigned k = 0; k < K; ++k) s = add(s, mul(a.data[i][k], b.data[k][j]));
      r.data[i][j] = s;
    }
  return r;
}
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T> operator+(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b) { return add(a, b); }
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T> operator-(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b) { return sub(a, b); }
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T> operator-(const mat_t<R, C, T>& a) { return neg(a); }
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T> operator*(const mat_t<R, C, T>& a, T s) { return mul(a, s); }
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T> operator*(T s, const mat_t<R, C, T>& a) { return mul(a, s); }
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T>& operator+=(mat_t<R, C, T>& a, const mat_t<R, C, T>& b) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) a.data[i][j] += b.data[i][j];
  return a;
}
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T>& operator-=(mat_t<R, C, T>& a, const mat_t<R, C, T>& b) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) a.data[i][j] -= b.data[i][j];
  return a;
}
template <unsigned R, unsigned C, typename T> WP_FUNC bool operator==(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j)
      if (!(a.data[i][j] == b.data[i][j])) return false;
  return true;
}
template <unsigned R, unsigned C, typename T> WP_FUNC bool operator!=(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b) { return !(a == b); }

// ---------------------------------------------------------------------------------------------
// Matrix functions.
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<C, R, T> transpose(const mat_t<R, C, T>& a) {
  mat_t<C, R, T> r;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) r.data[j][i] = a.data[i][j];
  return r;
}
template <unsigned N, typename T>
WP_FUNC T trace(const mat_t<N, N, T>& a) {
  T s = T(0);
  for (unsigned i = 0; i < N; ++i) s = add(s, a.data[i][i]);
  return s;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC T ddot(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b) {
  T s = T(0);
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) s = add(s, mul(a.data[i][j], b.data[i][j]));
  return s;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> outer(const vec_t<R, T>& a, const vec_t<C, T>& b) {
  mat_t<R, C, T> r;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) r.data[i][j] = mul(a.c[i], b.c[j]);
  return r;
}
template <typename T>
WP_FUNC mat_t<3, 3, T> skew(const vec_t<3, T>& v) {
  return mat_t<3, 3, T>(T(0), neg(v.c[2]), v.c[1], v.c[2], T(0), neg(v.c[0]), neg(v.c[1]), v.c[0], T(0));
}
template <unsigned R, unsigned C, typename T>
WP_FUNC mat_t<R, C, T> lerp(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b, T t) {
  return add(mul(a, T(T(1) - t)), mul(b, t));
}
template <unsigned R, unsigned C, typename T>
WP_FUNC bool isfinite(const mat_t<R, C, T>& a) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j)
      if (!isfinite(a.data[i][j])) return false;
  return true;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC bool isnan(const mat_t<R, C, T>& a) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j)
      if (isnan(a.data[i][j])) return true;
  return false;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC bool isinf(const mat_t<R, C, T>& a) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j)
      if (isinf(a.data[i][j])) return true;
  return false;
}

// Determinants by cofactor expansion (N <= 4), computed in T.
template <typename T>
WP_FUNC T determinant(const mat_t<1, 1, T>& m) { return m.data[0][0]; }
template <typename T>
WP_FUNC T determinant(const mat_t<2, 2, T>& m) { return T(m.data[0][0] * m.data[1][1] - m.data[0][1] * m.data[1][0]); }
template <typename T>
WP_FUNC T determinant(const mat_t<3, 3, T>& m) {
  return T(m.data[0][0] * T(m.data[1][1] * m.data[2][2] - m.data[1][2] * m.data[2][1]) -
           m.data[0][1] * T(m.data[1][0] * m.data[2][2] - m.data[1][2] * m.data[2][0]) +
           m.data[0][2] * T(m.data[1][0] * m.data[2][1] - m.data[1][1] * m.data[2][0]));
}
// Minor: m without row i and column j.
template <unsigned N, typename T>
WP_FUNC mat_t<N - 1, N - 1, T> minor_of(const mat_t<N, N, T>& m, unsigned i, unsigned j) {
  mat_t<N - 1, N - 1, T> r;
  for (unsigned a = 0, ra = 0; a < N; ++a) {
    if (a == i) continue;
    for (unsigned b = 0, rb = 0; b < N; ++b) {
      if (b == j) continue;
      r.data[ra][rb++] = m.data[a][b];
    }
    ++ra;
  }
  return r;
}
// 4x4: expanded in float64 and rounded once to T, whatever T is: in float32 or float16 the 24
// products cancel and lose most of the determinant's digits (and a finite difference of it
// its meaning); Warp's 4x4 determinant keeps its 2x2 minors in double for the same reason.
WP_FUNC float64 determinant_f64(const mat_t<4, 4, float64>& m) {
  float64 s = 0.0;
  for (unsigned j = 0; j < 4; ++j) {
    const float64 c = m.data[0][j] * determinant(minor_of(m, 0, j));
    s = (j & 1u) ? s - c : s + c;
  }
  return s;
}
template <typename T>
WP_FUNC T determinant(const mat_t<4, 4, T>& m) {
  return T(determinant_f64(mat_t<4, 4, float64>(m)));
}
// Cofactor matrix: cof[i][j] = (-1)^(i+j) det(minor(i, j)); d det(A)/dA = cof(A), valid also
// for singular A. adjugate = transpose(cof).
template <typename T>
WP_FUNC mat_t<1, 1, T> cofactor(const mat_t<1, 1, T>&) { return mat_t<1, 1, T>(T(1)); }
template <unsigned N, typename T>
WP_FUNC mat_t<N, N, T> cofactor(const mat_t<N, N, T>& m) {
  mat_t<N, N, T> r;
  for (unsigned i = 0; i < N; ++i)
    for (unsigned j = 0; j < N; ++j) {
      T d = determinant(minor_of(m, i, j));
      r.data[i][j] = ((i + j) & 1u) ? T(-d) : d;
    }
  return r;
}
// Singular (det == 0) -> zero matrix (Warp).
template <unsigned N, typename T>
WP_FUNC mat_t<N, N, T> inverse(const mat_t<N, N, T>& m) {
  T det = determinant(m);
  if (det == T(0)) return mat_t<N, N, T>();
  return div(transpose(cofactor(m)), det);
}
// 4x4 of float16/float32: in float64, rounded once (the determinant's reason, above).
template <>
WP_FUNC mat_t<4, 4, float32> inverse(const mat_t<4, 4, float32>& m) {
  return mat_t<4, 4, float32>(inverse(mat_t<4, 4, float64>(m)));
}
template <>
WP_FUNC mat_t<4, 4, half> inverse(const mat_t<4, 4, half>& m) {
  return mat_t<4, 4, half>(inverse(mat_t<4, 4, float64>(m)));
}
template <unsigned N, typename T>
WP_FUNC mat_t<N, N, T> inverse_approx(const mat_t<N, N, T>& m) { return inverse(m); }

// ---------------------------------------------------------------------------------------------
// Adjoints.
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_add(const mat_t<R, C, T>&, const mat_t<R, C, T>&, mat_t<R, C, T>& adj_a, mat_t<R, C, T>& adj_b, const mat_t<R, C, T>& adj_ret) {
  adj_a += adj_ret;
  adj_b += adj_ret;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_sub(const mat_t<R, C, T>&, const mat_t<R, C, T>&, mat_t<R, C, T>& adj_a, mat_t<R, C, T>& adj_b, const mat_t<R, C, T>& adj_ret) {
  adj_a += adj_ret;
  adj_b -= adj_ret;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_neg(const mat_t<R, C, T>&, mat_t<R, C, T>& adj_a, const mat_t<R, C, T>& adj_ret) { adj_a -= adj_ret; }
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_pos(const mat_t<R, C, T>&, mat_t<R, C, T>& adj_a, const mat_t<R, C, T>& adj_ret) { adj_a += adj_ret; }
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_mul(const mat_t<R, C, T>& a, T s, mat_t<R, C, T>& adj_a, T& adj_s, const mat_t<R, C, T>& adj_ret) {
  adj_a += mul(adj_ret, s);
  adj_s += ddot(a, adj_ret);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_mul(T s, const mat_t<R, C, T>& a, T& adj_s, mat_t<R, C, T>& adj_a, const mat_t<R, C, T>& adj_ret) {
  adj_mul(a, s, adj_a, adj_s, adj_ret);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_div(const mat_t<R, C, T>& a, T s, mat_t<R, C, T>& adj_a, T& adj_s, const mat_t<R, C, T>& adj_ret) {
  adj_a += div(adj_ret, s);
  adj_s -= ddot(a, adj_ret) / T(s * s);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_div(T s, const mat_t<R, C, T>& a, T& adj_s, mat_t<R, C, T>& adj_a, const mat_t<R, C, T>& adj_ret) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) adj_div(s, a.data[i][j], adj_s, adj_a.data[i][j], adj_ret.data[i][j]);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_div_approx(const mat_t<R, C, T>& a, T s, mat_t<R, C, T>& adj_a, T& adj_s, const mat_t<R, C, T>& adj_ret) { adj_div(a, s, adj_a, adj_s, adj_ret); }
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_div_approx(T s, const mat_t<R, C, T>& a, T& adj_s, mat_t<R, C, T>& adj_a, const mat_t<R, C, T>& adj_ret) { adj_div(s, a, adj_s, adj_a, adj_ret); }
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_cw_mul(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b, mat_t<R, C, T>& adj_a, mat_t<R, C, T>& adj_b, const mat_t<R, C, T>& adj_ret) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) adj_mul(a.data[i][j], b.data[i][j], adj_a.data[i][j], adj_b.data[i][j], adj_ret.data[i][j]);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_cw_div(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b, mat_t<R, C, T>& adj_a, mat_t<R, C, T>& adj_b, const mat_t<R, C, T>& adj_ret) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) adj_div(a.data[i][j], b.data[i][j], adj_a.data[i][j], adj_b.data[i][j], adj_ret.data[i][j]);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_mul(const mat_t<R, C, T>& m, const vec_t<C, T>& v, mat_t<R, C, T>& adj_m, vec_t<C, T>& adj_v, const vec_t<R, T>& adj_ret) {
  adj_m += outer(adj_ret, v);
  adj_v += mul(adj_ret, m);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_mul(const vec_t<R, T>& v, const mat_t<R, C, T>& m, vec_t<R, T>& adj_v, mat_t<R, C, T>& adj_m, const vec_t<C, T>& adj_ret) {
  adj_m += outer(v, adj_ret);
  adj_v += mul(m, adj_ret);
}
template <unsigned R, unsigned K, unsigned C, typename T>
WP_FUNC void adj_mul(const mat_t<R, K, T>& a, const mat_t<K, C, T>& b, mat_t<R, K, T>& adj_a, mat_t<K, C, T>& adj_b, const mat_t<R, C, T>& adj_ret) {
  adj_a += mul(adj_ret, transpose(b));
  adj_b += mul(transpose(a), adj_ret);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_transpose(const mat_t<R, C, T>&, mat_t<R, C, T>& adj_a, const mat_t<C, R, T>& adj_ret) { adj_a += transpose(adj_ret); }
template <unsigned N, typename T>
WP_FUNC void adj_trace(const mat_t<N, N, T>&, mat_t<N, N, T>& adj_a, T adj_ret) {
  for (unsigned i = 0; i < N; ++i) adj_a.data[i][i] += adj_ret;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_ddot(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b, mat_t<R, C, T>& adj_a, mat_t<R, C, T>& adj_b, T adj_ret) {
  adj_a += mul(b, adj_ret);
  adj_b += mul(a, adj_ret);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_outer(const vec_t<R, T>& a, const vec_t<C, T>& b, vec_t<R, T>& adj_a, vec_t<C, T>& adj_b, const mat_t<R, C, T>& adj_ret) {
  adj_a += mul(adj_ret, b);
  adj_b += mul(a, adj_ret);
}
template <typename T>
WP_FUNC void adj_skew(const vec_t<3, T>&, vec_t<3, T>& adj_v, const mat_t<3, 3, T>& adj_ret) {
  adj_v.c[0] += adj_ret.data[2][1] - adj_ret.data[1][2];
  adj_v.c[1] += adj_ret.data[0][2] - adj_ret.data[2][0];
  adj_v.c[2] += adj_ret.data[1][0] - adj_ret.data[0][1];
}
template <unsigned N, typename T>
WP_FUNC void adj_diag(const vec_t<N, T>&, vec_t<N, T>& adj_d, const mat_t<N, N, T>& adj_ret) { adj_d += get_diag(adj_ret); }
template <unsigned N, typename T>
WP_FUNC void adj_get_diag(const mat_t<N, N, T>&, mat_t<N, N, T>& adj_m, const vec_t<N, T>& adj_ret) { adj_m += diag(adj_ret); }
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_lerp(const mat_t<R, C, T>& a, const mat_t<R, C, T>& b, T t, mat_t<R, C, T>& adj_a, mat_t<R, C, T>& adj_b, T& adj_t,
                      const mat_t<R, C, T>& adj_ret) {
  adj_a += mul(adj_ret, T(T(1) - t));
  adj_b += mul(adj_ret, t);
  adj_t += ddot(sub(b, a), adj_ret);
}
// d det(A) = cof(A) : dA (valid for singular A too).
template <unsigned N, typename T>
WP_FUNC void adj_determinant(const mat_t<N, N, T>& m, mat_t<N, N, T>& adj_m, T adj_ret) { adj_m += mul(cofactor(m), adj_ret); }
// d inv(A) = -inv(A) dA inv(A)  =>  adj_A += -inv^T adj_ret inv^T. Singular: no gradient.
template <unsigned N, typename T>
WP_FUNC void adj_inverse(const mat_t<N, N, T>& m, mat_t<N, N, T>& adj_m, const mat_t<N, N, T>& adj_ret) {
  mat_t<N, N, T> inv = inverse(m);
  mat_t<N, N, T> it = transpose(inv);
  adj_m -= mul(mul(it, adj_ret), it);
}
template <unsigned N, typename T>
WP_FUNC void adj_inverse_approx(const mat_t<N, N, T>& m, mat_t<N, N, T>& adj_m, const mat_t<N, N, T>& adj_ret) { adj_inverse(m, adj_m, adj_ret); }
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_mat_fill(T, T& adj_s, const mat_t<R, C, T>& adj_ret) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) adj_s += adj_ret.data[i][j];
}

}  // namespace wp
