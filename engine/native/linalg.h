// Native library: small dense decompositions and their adjoints: svd3, svd2 (A = U diag(sigma)
// V^T with U, V rotations, sigma sorted by decreasing magnitude and only the last one possibly
// negative, the convention of McAdams et al. that Warp follows), qr3 (A = Q R, R with a
// non-negative diagonal), eig3 (symmetric A = Q diag(d) Q^T, d ascending). Outputs are
// trailing reference parameters (Warp's convention). Jacobi sweeps, in the matrix's own type.
#pragma once

#include "mat.h"

namespace wp {

// Cyclic Jacobi on a symmetric 3x3 matrix: s = V diag(d) V^T, d ascending, V a rotation.
template <typename T>
WP_FUNC void jacobi_eig3(mat_t<3, 3, T> s, mat_t<3, 3, T>& v, vec_t<3, T>& d) {
  v = identity<3, T>();
  for (int sweep = 0; sweep < 20; ++sweep) {
    T off = T(abs(s.data[0][1]) + abs(s.data[0][2]) + abs(s.data[1][2]));
    T scale = T(abs(s.data[0][0]) + abs(s.data[1][1]) + abs(s.data[2][2]));
    if (off == T(0) || off <= scale * T(is_same_t<T, float32>::value ? 1e-9f : 1e-19f)) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        T apq = s.data[p][q];
        if (apq == T(0)) continue;
        T theta = T((s.data[q][q] - s.data[p][p]) / T(T(2) * apq));
        T t = T(sign(theta) / T(abs(theta) + sqrt(T(theta * theta + T(1)))));
        if (isinf(theta)) t = T(T(0.5) / theta);
        T c = T(T(1) / sqrt(T(t * t + T(1))));
        T sn = T(t * c);
        // s = J^T s J with J the rotation in the (p, q) plane.
        for (int k = 0; k < 3; ++k) {
          T skp = s.data[k][p], skq = s.data[k][q];
          s.data[k][p] = T(c * skp - sn * skq);
          s.data[k][q] = T(sn * skp + c * skq);
        }
        for (int k = 0; k < 3; ++k) {
          T spk = s.data[p][k], sqk = s.data[q][k];
          s.data[p][k] = T(c * spk - sn * sqk);
          s.data[q][k] = T(sn * spk + c * sqk);
        }
        for (int k = 0; k < 3; ++k) {
          T vkp = v.data[k][p], vkq = v.data[k][q];
          v.data[k][p] = T(c * vkp - sn * vkq);
          v.data[k][q] = T(sn * vkp + c * vkq);
        }
      }
  }
  d = vec_t<3, T>(s.data[0][0], s.data[1][1], s.data[2][2]);
  // Sort ascending (swapping columns keeps V orthogonal; fix the sign to keep det = +1).
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2 - i; ++j)
      if (d.c[j + 1] < d.c[j]) {
        T td = d.c[j];
        d.c[j] = d.c[j + 1];
        d.c[j + 1] = td;
        for (int k = 0; k < 3; ++k) {
          T tv = v.data[k][j];
          v.data[k][j] = v.data[k][j + 1];
          v.data[k][j + 1] = T(-tv);
        }
      }
}

// Symmetric eigendecomposition (the strictly lower triangle is ignored: A is read as symmetric
// from its upper triangle).
template <typename T>
WP_FUNC void eig3(const mat_t<3, 3, T>& a, mat_t<3, 3, T>& q, vec_t<3, T>& d) {
  mat_t<3, 3, T> s = a;
  s.data[1][0] = a.data[0][1];
  s.data[2][0] = a.data[0][2];
  s.data[2][1] = a.data[1][2];
  jacobi_eig3(s, q, d);
}

// Unit vector orthogonal to u (u unit).
template <typename T>
WP_FUNC vec_t<3, T> any_orthogonal(const vec_t<3, T>& u) {
  vec_t<3, T> e = abs(u.c[0]) < T(0.57735) ? vec_t<3, T>(T(1), T(0), T(0)) : vec_t<3, T>(T(0), T(1), T(0));
  return normalize(cross(u, e));
}

template <typename T>
WP_FUNC void svd3(const mat_t<3, 3, T>& a, mat_t<3, 3, T>& u, vec_t<3, T>& sigma, mat_t<3, 3, T>& v) {
  mat_t<3, 3, T> ata = mul(transpose(a), a);
  vec_t<3, T> lam;
  jacobi_eig3(ata, v, lam);  // ascending
  // Reorder to descending singular values; two swaps keep det(V) = +1.
  for (int k = 0; k < 3; ++k) {
    T t = v.data[k][0];
    v.data[k][0] = v.data[k][2];
    v.data[k][2] = T(-t);
  }
  vec_t<3, T> v0 = v.get_col(0), v1 = v.get_col(1), v2 = v.get_col(2);
  vec_t<3, T> a0 = mul(a, v0), a1 = mul(a, v1);
  T s0 = length(a0);
  vec_t<3, T> u0 = s0 > T(0) ? div(a0, s0) : vec_t<3, T>(T(1), T(0), T(0));
  vec_t<3, T> w1 = sub(a1, mul(u0, dot(u0, a1)));
  T l1 = length(w1);
  vec_t<3, T> u1 = l1 > T(1e-30) * (s0 + T(1e-30)) && l1 > T(0) ? div(w1, l1) : any_orthogonal(u0);
  vec_t<3, T> u2 = cross(u0, u1);
  u = mat_t<3, 3, T>(u0, u1, u2);
  sigma = vec_t<3, T>(s0, dot(u1, a1), dot(u2, mul(a, v2)));
}

template <typename T>
WP_FUNC void svd2(const mat_t<2, 2, T>& a, mat_t<2, 2, T>& u, vec_t<2, T>& sigma, mat_t<2, 2, T>& v) {
  mat_t<2, 2, T> ata = mul(transpose(a), a);
  // One Jacobi rotation diagonalizes a symmetric 2x2 matrix exactly.
  T c = T(1), s = T(0);
  if (ata.data[0][1] != T(0)) {
    T theta = T((ata.data[1][1] - ata.data[0][0]) / T(T(2) * ata.data[0][1]));
    T t = T(sign(theta) / T(abs(theta) + sqrt(T(theta * theta + T(1)))));
    c = T(T(1) / sqrt(T(t * t + T(1))));
    s = T(t * c);
  }
  vec_t<2, T> v0(c, T(-s)), v1(s, c);
  T l0 = T(ata.data[0][0] * c * c - T(2) * s * c * ata.data[0][1] + ata.data[1][1] * s * s);
  T l1 = T(ata.data[0][0] * s * s + T(2) * s * c * ata.data[0][1] + ata.data[1][1] * c * c);
  if (l1 > l0) {  // descending: v0 <- v1, v1 <- -v0 keeps det(V) = +1
    vec_t<2, T> t = v0;
    v0 = v1;
    v1 = neg(t);
  }
  v = mat_t<2, 2, T>(v0, v1);
  vec_t<2, T> a0 = mul(a, v0);
  T s0 = length(a0);
  vec_t<2, T> u0 = s0 > T(0) ? div(a0, s0) : vec_t<2, T>(T(1), T(0));
  vec_t<2, T> u1(T(-u0.c[1]), u0.c[0]);
  u = mat_t<2, 2, T>(u0, u1);
  sigma = vec_t<2, T>(s0, dot(u1, mul(a, v1)));
}

// Gram-Schmidt (twice, for orthogonality) on the columns; dependent columns get any unit vector
// orthogonal to the previous ones and a zero diagonal entry in R.
template <typename T>
WP_FUNC void qr3(const mat_t<3, 3, T>& a, mat_t<3, 3, T>& q, mat_t<3, 3, T>& r) {
  r = mat_t<3, 3, T>();
  vec_t<3, T> qs[3];
  T scale = T(0);
  for (int j = 0; j < 3; ++j) scale = max(scale, length(a.get_col(j)));
  for (int j = 0; j < 3; ++j) {
    vec_t<3, T> w = a.get_col(j);
    for (int pass = 0; pass < 2; ++pass)
      for (int i = 0; i < j; ++i) {
        T p = dot(qs[i], w);
        r.data[i][j] += p;
        w = sub(w, mul(qs[i], p));
      }
    T l = length(w);
    if (l > scale * T(is_same_t<T, float32>::value ? 1e-6 : 1e-14) && l > T(0)) {
      qs[j] = div(w, l);
      r.data[j][j] = l;
    } else {
      qs[j] = j == 0 ? vec_t<3, T>(T(1), T(0), T(0)) : (j == 1 ? any_orthogonal(qs[0]) : cross(qs[0], qs[1]));
      r.data[j][j] = T(0);
    }
  }
  q = mat_t<3, 3, T>(qs[0], qs[1], qs[2]);
}

// ---------------------------------------------------------------------------------------------
// Adjoints (square, distinct singular values / eigenvalues; coincident ones contribute no
// off-diagonal term instead of dividing by zero).
template <unsigned N, typename T>
WP_FUNC void adj_svd_n(const mat_t<N, N, T>& u, const vec_t<N, T>& s, const mat_t<N, N, T>& v, const mat_t<N, N, T>& adj_u,
                       const vec_t<N, T>& adj_s, const mat_t<N, N, T>& adj_v, mat_t<N, N, T>& adj_a) {
  mat_t<N, N, T> ut_au = mul(transpose(u), adj_u), vt_av = mul(transpose(v), adj_v);
  mat_t<N, N, T> inner;
  for (unsigned i = 0; i < N; ++i)
    for (unsigned j = 0; j < N; ++j) {
      if (i == j) {
        inner.data[i][j] = adj_s.c[i];
        continue;
      }
      T den = T(s.c[j] * s.c[j] - s.c[i] * s.c[i]);
      T f = abs(den) > T(1e-30) ? T(T(1) / den) : T(0);
      T ju = T(f * (ut_au.data[i][j] - ut_au.data[j][i]));
      T jv = T(f * (vt_av.data[i][j] - vt_av.data[j][i]));
      inner.data[i][j] = T(ju * s.c[j] + s.c[i] * jv);
    }
  adj_a += mul(mul(u, inner), transpose(v));
}
template <typename T>
WP_FUNC void adj_svd3(const mat_t<3, 3, T>&, const mat_t<3, 3, T>& u, const vec_t<3, T>& sigma, const mat_t<3, 3, T>& v, mat_t<3, 3, T>& adj_a,
                      const mat_t<3, 3, T>& adj_u, const vec_t<3, T>& adj_sigma, const mat_t<3, 3, T>& adj_v) {
  adj_svd_n(u, sigma, v, adj_u, adj_sigma, adj_v, adj_a);
}
template <typename T>
WP_FUNC void adj_svd2(const mat_t<2, 2, T>&, const mat_t<2, 2, T>& u, const vec_t<2, T>& sigma, const mat_t<2, 2, T>& v, mat_t<2, 2, T>& adj_a,
                      const mat_t<2, 2, T>& adj_u, const vec_t<2, T>& adj_sigma, const mat_t<2, 2, T>& adj_v) {
  adj_svd_n(u, sigma, v, adj_u, adj_sigma, adj_v, adj_a);
}
// Symmetric input: the gradient is symmetrized (perturbations of A stay symmetric).
template <typename T>
WP_FUNC void adj_eig3(const mat_t<3, 3, T>&, const mat_t<3, 3, T>& q, const vec_t<3, T>& d, mat_t<3, 3, T>& adj_a, const mat_t<3, 3, T>& adj_q,
                      const vec_t<3, T>& adj_d) {
  mat_t<3, 3, T> qt_aq = mul(transpose(q), adj_q);
  mat_t<3, 3, T> inner;
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) {
      if (i == j) {
        inner.data[i][j] = adj_d.c[i];
        continue;
      }
      T den = T(d.c[j] - d.c[i]);
      inner.data[i][j] = abs(den) > T(1e-30) ? T(qt_aq.data[i][j] / den) : T(0);
    }
  // Warp's convention: the gradient as a function of a symmetric A, Q (D_bar + F o Q^T adj_Q) Q^T
  // (for eigenvalue-only losses Q D_bar Q^T, symmetric), not folded onto the triangle eig3 reads.
  adj_a += mul(mul(q, inner), transpose(q));
}
// A = QR: adj_A = (adj_Q + Q copyltu(M)) R^-T, M = R adj_R^T - adj_Q^T Q (full-rank A).
template <typename T>
WP_FUNC void adj_qr3(const mat_t<3, 3, T>&, const mat_t<3, 3, T>& q, const mat_t<3, 3, T>& r, mat_t<3, 3, T>& adj_a, const mat_t<3, 3, T>& adj_q,
                     const mat_t<3, 3, T>& adj_r) {
  mat_t<3, 3, T> m = sub(mul(r, transpose(adj_r)), mul(transpose(adj_q), q));
  mat_t<3, 3, T> c;
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) c.data[i][j] = i >= j ? m.data[i][j] : m.data[j][i];
  mat_t<3, 3, T> lhs = add(adj_q, mul(q, c));
  adj_a += mul(lhs, transpose(inverse(r)));
}

}  // namespace wp
