// Native library: spatial (6D) algebra as in Warp: spatial_vector = vec_t<6,T> with the angular
// part w on top (0..2) and the linear part v at the bottom (3..5), spatial_matrix = mat_t<6,6,T>;
// spatial_top/bottom, spatial_dot, spatial_cross, spatial_cross_dual, spatial_adjoint and their
// adjoints.
#pragma once

#include "transform.h"

namespace wp {

template <typename T> using spatial_vector_t = vec_t<6, T>;
template <typename T> using spatial_matrix_t = mat_t<6, 6, T>;
typedef vec_t<6, float32> spatial_vector;
typedef vec_t<6, float32> spatial_vectorf;
typedef vec_t<6, float64> spatial_vectord;
typedef mat_t<6, 6, float32> spatial_matrix;
typedef mat_t<6, 6, float32> spatial_matrixf;
typedef mat_t<6, 6, float64> spatial_matrixd;

template <typename T> WP_FUNC vec_t<3, T> spatial_top(const vec_t<6, T>& a) { return vec_t<3, T>(a.c[0], a.c[1], a.c[2]); }
template <typename T> WP_FUNC vec_t<3, T> spatial_bottom(const vec_t<6, T>& a) { return vec_t<3, T>(a.c[3], a.c[4], a.c[5]); }
template <typename T> WP_FUNC T spatial_dot(const vec_t<6, T>& a, const vec_t<6, T>& b) { return dot(a, b); }
// Motion cross product: (wa x wb, va x wb + wa x vb).
template <typename T> WP_FUNC vec_t<6, T> spatial_cross(const vec_t<6, T>& a, const vec_t<6, T>& b) {
  vec_t<3, T> wa = spatial_top(a), va = spatial_bottom(a), wb = spatial_top(b), vb = spatial_bottom(b);
  return vec_t<6, T>(cross(wa, wb), add(cross(va, wb), cross(wa, vb)));
}
// Force cross product: (wa x wb + va x vb, wa x vb).
template <typename T> WP_FUNC vec_t<6, T> spatial_cross_dual(const vec_t<6, T>& a, const vec_t<6, T>& b) {
  vec_t<3, T> wa = spatial_top(a), va = spatial_bottom(a), wb = spatial_top(b), vb = spatial_bottom(b);
  return vec_t<6, T>(add(cross(wa, wb), cross(va, vb)), cross(wa, vb));
}
// [[R, 0], [S, R]].
template <typename T> WP_FUNC mat_t<6, 6, T> spatial_adjoint(const mat_t<3, 3, T>& r, const mat_t<3, 3, T>& s) {
  mat_t<6, 6, T> m;
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) {
      m.data[i][j] = r.data[i][j];
      m.data[i + 3][j + 3] = r.data[i][j];
      m.data[i + 3][j] = s.data[i][j];
    }
  return m;
}

template <typename T> WP_FUNC void adj_spatial_top(const vec_t<6, T>&, vec_t<6, T>& adj_a, const vec_t<3, T>& adj_ret) {
  for (unsigned i = 0; i < 3; ++i) adj_a.c[i] += adj_ret.c[i];
}
template <typename T> WP_FUNC void adj_spatial_bottom(const vec_t<6, T>&, vec_t<6, T>& adj_a, const vec_t<3, T>& adj_ret) {
  for (unsigned i = 0; i < 3; ++i) adj_a.c[i + 3] += adj_ret.c[i];
}
template <typename T> WP_FUNC void adj_spatial_dot(const vec_t<6, T>& a, const vec_t<6, T>& b, vec_t<6, T>& adj_a, vec_t<6, T>& adj_b, T adj_ret) {
  adj_dot(a, b, adj_a, adj_b, adj_ret);
}
template <typename T> WP_FUNC void adj_spatial_cross(const vec_t<6, T>& a, const vec_t<6, T>& b, vec_t<6, T>& adj_a, vec_t<6, T>& adj_b, const vec_t<6, T>& adj_ret) {
  vec_t<3, T> wa = spatial_top(a), va = spatial_bottom(a), wb = spatial_top(b), vb = spatial_bottom(b);
  vec_t<3, T> aw = spatial_top(adj_ret), av = spatial_bottom(adj_ret);
  vec_t<3, T> adj_wa, adj_va, adj_wb, adj_vb;
  adj_cross(wa, wb, adj_wa, adj_wb, aw);
  adj_cross(va, wb, adj_va, adj_wb, av);
  adj_cross(wa, vb, adj_wa, adj_vb, av);
  adj_a += vec_t<6, T>(adj_wa, adj_va);
  adj_b += vec_t<6, T>(adj_wb, adj_vb);
}
template <typename T> WP_FUNC void adj_spatial_cross_dual(const vec_t<6, T>& a, const vec_t<6, T>& b, vec_t<6, T>& adj_a, vec_t<6, T>& adj_b, const vec_t<6, T>& adj_ret) {
  vec_t<3, T> wa = spatial_top(a), va = spatial_bottom(a), wb = spatial_top(b), vb = spatial_bottom(b);
  vec_t<3, T> aw = spatial_top(adj_ret), av = spatial_bottom(adj_ret);
  vec_t<3, T> adj_wa, adj_va, adj_wb, adj_vb;
  adj_cross(wa, wb, adj_wa, adj_wb, aw);
  adj_cross(va, vb, adj_va, adj_vb, aw);
  adj_cross(wa, vb, adj_wa, adj_vb, av);
  adj_a += vec_t<6, T>(adj_wa, adj_va);
  adj_b += vec_t<6, T>(adj_wb, adj_vb);
}
template <typename T> WP_FUNC void adj_spatial_adjoint(const mat_t<3, 3, T>&, const mat_t<3, 3, T>&, mat_t<3, 3, T>& adj_r, mat_t<3, 3, T>& adj_s,
                                                       const mat_t<6, 6, T>& adj_ret) {
  for (unsigned i = 0; i < 3; ++i)
    for (unsigned j = 0; j < 3; ++j) {
      adj_r.data[i][j] += adj_ret.data[i][j] + adj_ret.data[i + 3][j + 3];
      adj_s.data[i][j] += adj_ret.data[i + 3][j];
    }
}
// spatial_vector(w, v) constructor adjoint.
template <typename T> WP_FUNC void adj_spatial_vector(const vec_t<3, T>&, const vec_t<3, T>&, vec_t<3, T>& adj_w, vec_t<3, T>& adj_v, const vec_t<6, T>& adj_ret) {
  adj_w += spatial_top(adj_ret);
  adj_v += spatial_bottom(adj_ret);
}

}  // namespace wp
