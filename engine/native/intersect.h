// Geometric queries between primitives: closest points of two segments
// (closest_point_edge_edge, forward + adjoint) and the triangle-triangle overlap test
// (intersect_tri_tri, not differentiable). Owner: codegen (C2). No standard library headers.
#pragma once

#include "vec.h"

namespace wp {

// Closest points of segments p1-q1 and p2-q2 (Ericson, Real-Time Collision Detection 5.1.9,
// as Warp): returns (s, t, d) with c1 = p1 + (q1 - p1) s, c2 = p2 + (q2 - p2) t the closest
// points and d = |c1 - c2|. Segments with squared length <= epsilon are points.
template <typename T>
struct cpee_state_t {
  vec_t<3, T> d1, d2, r;
  T a, b, c, e, f, denom, s0, tt, s, t;
  int branch;  // 0 both points, 1 first a point, 2 second a point, 3 t<0, 4 t>1, 5 interior t
};

template <typename T>
WP_FUNC T cpee_clamp01(T x) { return x < T(0) ? T(0) : (x > T(1) ? T(1) : x); }
template <typename T>
WP_FUNC bool cpee_inside01(T x) { return x >= T(0) && x <= T(1); }

template <typename T>
WP_FUNC cpee_state_t<T> cpee_solve(const vec_t<3, T>& p1, const vec_t<3, T>& q1, const vec_t<3, T>& p2,
                                   const vec_t<3, T>& q2, T epsilon) {
  cpee_state_t<T> st;
  st.d1 = q1 - p1;
  st.d2 = q2 - p2;
  st.r = p1 - p2;
  st.a = dot(st.d1, st.d1);
  st.e = dot(st.d2, st.d2);
  st.f = dot(st.d2, st.r);
  st.b = st.c = st.denom = st.s0 = st.tt = T(0);
  st.s = st.t = T(0);
  if (st.a <= epsilon && st.e <= epsilon) {
    st.branch = 0;
  } else if (st.a <= epsilon) {
    st.branch = 1;
    st.t = cpee_clamp01(T(st.f / st.e));
  } else {
    st.c = dot(st.d1, st.r);
    if (st.e <= epsilon) {
      st.branch = 2;
      st.s = cpee_clamp01(T(-st.c / st.a));
    } else {
      st.b = dot(st.d1, st.d2);
      st.denom = st.a * st.e - st.b * st.b;
      st.s0 = st.denom != T(0) ? cpee_clamp01(T((st.b * st.f - st.c * st.e) / st.denom)) : T(0);
      st.tt = (st.b * st.s0 + st.f) / st.e;
      if (st.tt < T(0)) {
        st.branch = 3;
        st.t = T(0);
        st.s = cpee_clamp01(T(-st.c / st.a));
      } else if (st.tt > T(1)) {
        st.branch = 4;
        st.t = T(1);
        st.s = cpee_clamp01(T((st.b - st.c) / st.a));
      } else {
        st.branch = 5;
        st.t = st.tt;
        st.s = st.s0;
      }
    }
  }
  return st;
}

template <typename T>
WP_FUNC vec_t<3, T> closest_point_edge_edge(const vec_t<3, T>& p1, const vec_t<3, T>& q1, const vec_t<3, T>& p2,
                                            const vec_t<3, T>& q2, T epsilon) {
  cpee_state_t<T> st = cpee_solve(p1, q1, p2, q2, epsilon);
  vec_t<3, T> diff = (p1 + st.d1 * st.s) - (p2 + st.d2 * st.t);
  return vec_t<3, T>(st.s, st.t, length(diff));
}

template <typename T>
WP_FUNC void adj_closest_point_edge_edge(const vec_t<3, T>& p1, const vec_t<3, T>& q1, const vec_t<3, T>& p2,
                                         const vec_t<3, T>& q2, T epsilon, vec_t<3, T>& adj_p1, vec_t<3, T>& adj_q1,
                                         vec_t<3, T>& adj_p2, vec_t<3, T>& adj_q2, T& adj_epsilon,
                                         const vec_t<3, T>& adj_ret) {
  (void)adj_epsilon;
  cpee_state_t<T> st = cpee_solve(p1, q1, p2, q2, epsilon);
  vec_t<3, T> diff = (p1 + st.d1 * st.s) - (p2 + st.d2 * st.t);
  T len = length(diff);
  vec_t<3, T> adj_diff = len > T(0) ? diff * T(adj_ret[2] / len) : vec_t<3, T>(T(0), T(0), T(0));
  vec_t<3, T> adj_d1 = adj_diff * st.s, adj_d2 = adj_diff * T(-st.t), adj_r(T(0), T(0), T(0));
  adj_p1 += adj_diff;
  adj_p2 -= adj_diff;
  T adj_s = adj_ret[0] + dot(adj_diff, st.d1);
  T adj_t = adj_ret[1] - dot(adj_diff, st.d2);
  T adj_a = 0, adj_b = 0, adj_c = 0, adj_e = 0, adj_f = 0;
  switch (st.branch) {
    case 1: {
      T x = st.f / st.e;
      if (cpee_inside01(x)) {
        adj_f += adj_t / st.e;
        adj_e -= adj_t * x / st.e;
      }
      break;
    }
    case 2:
    case 3: {
      T x = -st.c / st.a;
      if (cpee_inside01(x)) {
        adj_c -= adj_s / st.a;
        adj_a -= adj_s * x / st.a;
      }
      break;
    }
    case 4: {
      T x = (st.b - st.c) / st.a;
      if (cpee_inside01(x)) {
        adj_b += adj_s / st.a;
        adj_c -= adj_s / st.a;
        adj_a -= adj_s * x / st.a;
      }
      break;
    }
    case 5: {
      T adj_s0 = adj_s + adj_t * st.b / st.e;
      adj_b += adj_t * st.s0 / st.e;
      adj_f += adj_t / st.e;
      adj_e -= adj_t * st.tt / st.e;
      if (st.denom != T(0)) {
        T x = (st.b * st.f - st.c * st.e) / st.denom;
        if (cpee_inside01(x)) {
          T adj_num = adj_s0 / st.denom, adj_den = -adj_s0 * x / st.denom;
          adj_b += adj_num * st.f;
          adj_f += adj_num * st.b;
          adj_c -= adj_num * st.e;
          adj_e -= adj_num * st.c;
          adj_a += adj_den * st.e;
          adj_e += adj_den * st.a;
          adj_b -= T(2) * st.b * adj_den;
        }
      }
      break;
    }
    default:
      break;
  }
  adj_d1 += st.d1 * T(2 * adj_a) + st.r * adj_c + st.d2 * adj_b;
  adj_d2 += st.d2 * T(2 * adj_e) + st.r * adj_f + st.d1 * adj_b;
  adj_r += st.d2 * adj_f + st.d1 * adj_c;
  adj_q1 += adj_d1;
  adj_p1 -= adj_d1;
  adj_q2 += adj_d2;
  adj_p2 -= adj_d2;
  adj_p1 += adj_r;
  adj_p2 -= adj_r;
}

// 1 when triangles (v0, v1, v2) and (u0, u1, u2) overlap (touching counts), else 0.
// Separating-axis test over both normals, the 9 edge-edge cross products and the 6 in-plane
// edge normals (coplanar triangles); an axis of (near) zero length is skipped.
template <typename T>
WP_FUNC bool tri_tri_separated_on(const vec_t<3, T>& axis, const vec_t<3, T>* a, const vec_t<3, T>* b, T scale) {
  T l2 = dot(axis, axis);
  if (!(l2 > scale)) return false;
  T amin = dot(axis, a[0]), amax = amin, bmin = dot(axis, b[0]), bmax = bmin;
  for (int i = 1; i < 3; ++i) {
    T pa = dot(axis, a[i]), pb = dot(axis, b[i]);
    amin = pa < amin ? pa : amin;
    amax = pa > amax ? pa : amax;
    bmin = pb < bmin ? pb : bmin;
    bmax = pb > bmax ? pb : bmax;
  }
  return amax < bmin || bmax < amin;
}

template <typename T>
WP_FUNC int32 intersect_tri_tri(const vec_t<3, T>& v0, const vec_t<3, T>& v1, const vec_t<3, T>& v2,
                                const vec_t<3, T>& u0, const vec_t<3, T>& u1, const vec_t<3, T>& u2) {
  vec_t<3, T> a[3] = {v0, v1, v2}, b[3] = {u0, u1, u2};
  vec_t<3, T> ea[3] = {v1 - v0, v2 - v1, v0 - v2}, eb[3] = {u1 - u0, u2 - u1, u0 - u2};
  T size2 = T(0);
  for (int i = 0; i < 3; ++i) {
    T la = dot(ea[i], ea[i]), lb = dot(eb[i], eb[i]);
    size2 = la > size2 ? la : size2;
    size2 = lb > size2 ? lb : size2;
  }
  // axes shorter than this (relative to the triangles' size) carry no direction
  T tiny = T(sizeof(T) == 4 ? 1e-12 : 1e-24) * size2 * size2;
  vec_t<3, T> na = cross(ea[0], ea[1]), nb = cross(eb[0], eb[1]);
  if (tri_tri_separated_on(na, a, b, tiny) || tri_tri_separated_on(nb, a, b, tiny)) return 0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (tri_tri_separated_on(cross(ea[i], eb[j]), a, b, tiny)) return 0;
  T tiny3 = tiny * size2;
  for (int i = 0; i < 3; ++i) {
    if (tri_tri_separated_on(cross(na, ea[i]), a, b, tiny3)) return 0;
    if (tri_tri_separated_on(cross(nb, eb[i]), a, b, tiny3)) return 0;
  }
  return 1;
}

}  // namespace wp
