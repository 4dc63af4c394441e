// Kernel-side wp.Mesh queries: closest point (no sign, parity sign, pseudo-normal sign, winding
// number sign), ray cast, AABB iteration, and evaluation helpers (mesh_eval_position/velocity,
// mesh_eval_face_normal, mesh_get_point/index/velocity). Barycentrics follow Warp: a point of face
// f is u * p0 + v * p1 + (1 - u - v) * p2. Points are the user's array (bounds from the last
// build or refit); indices are the daemon's checked copy. Forward only (no adjoints).
// No standard library headers.
#pragma once

#include "bvh.h"

namespace wp {

struct weft_struct_MeshQueryPoint {
  bool f_result;
  float32 f_sign;
  int32 f_face;
  float32 f_u;
  float32 f_v;
};
struct weft_struct_MeshQueryRay {
  bool f_result;
  float32 f_sign;
  int32 f_face;
  float32 f_t;
  float32 f_u;
  float32 f_v;
  vec3 f_normal;
};
struct weft_struct_MeshQueryAABB {
  bvh_walk_t walk;
};
WP_FUNC void cg_accum(weft_struct_MeshQueryPoint&, const weft_struct_MeshQueryPoint&) {}
WP_FUNC void cg_link(weft_struct_MeshQueryPoint&, const weft_struct_MeshQueryPoint&) {}
WP_FUNC void cg_accum(weft_struct_MeshQueryRay&, const weft_struct_MeshQueryRay&) {}
WP_FUNC void cg_link(weft_struct_MeshQueryRay&, const weft_struct_MeshQueryRay&) {}
WP_FUNC void cg_accum(weft_struct_MeshQueryAABB&, const weft_struct_MeshQueryAABB&) {}
WP_FUNC void cg_link(weft_struct_MeshQueryAABB&, const weft_struct_MeshQueryAABB&) {}

WP_FUNC void mesh_face(const geometry_desc_t* g, int64 f, vec3& a, vec3& b, vec3& c) {
  a = geometry_load3(g->points, g->indices[3 * f]);
  b = geometry_load3(g->points, g->indices[3 * f + 1]);
  c = geometry_load3(g->points, g->indices[3 * f + 2]);
}

// Closest point of segment xy to p, with t its weight of y.
WP_FUNC vec3 mesh_closest_on_segment(const vec3& p, const vec3& x, const vec3& y, float32& t) {
  vec3 xy = y - x;
  float32 len_sq = dot(xy, xy);
  t = len_sq > 0.0f ? dot(p - x, xy) / len_sq : 0.0f;
  t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
  return x + xy * t;
}

// Closest point of triangle abc to p (Ericson 5.1.5): returns it, with u, v the weights of a, b.
// A zero-area triangle (a repeated vertex, collinear corners) is its three edges: Ericson's
// regions assume a nonzero area and would stop at a corner of the degenerate edge.
WP_FUNC vec3 mesh_closest_on_triangle(const vec3& p, const vec3& a, const vec3& b, const vec3& c, float32& u, float32& v) {
  vec3 ab = b - a, ac = c - a, ap = p - a;
  if (length_sq(cross(ab, ac)) == 0.0f) {
    float32 t_ab, t_ac, t_bc;
    vec3 q_ab = mesh_closest_on_segment(p, a, b, t_ab), q_ac = mesh_closest_on_segment(p, a, c, t_ac),
         q_bc = mesh_closest_on_segment(p, b, c, t_bc);
    float32 d_ab = length_sq(q_ab - p), d_ac = length_sq(q_ac - p), d_bc = length_sq(q_bc - p);
    if (d_ab <= d_ac && d_ab <= d_bc) { u = 1.0f - t_ab; v = t_ab; return q_ab; }
    if (d_ac <= d_bc) { u = 1.0f - t_ac; v = 0.0f; return q_ac; }
    u = 0.0f; v = 1.0f - t_bc;
    return q_bc;
  }
  float32 d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0.0f && d2 <= 0.0f) { u = 1.0f; v = 0.0f; return a; }
  vec3 bp = p - b;
  float32 d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0.0f && d4 <= d3) { u = 0.0f; v = 1.0f; return b; }
  float32 vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0f && d1 >= 0.0f && d3 <= 0.0f) {
    float32 t = (d1 - d3) != 0.0f ? d1 / (d1 - d3) : 0.0f;
    u = 1.0f - t; v = t;
    return a + ab * t;
  }
  vec3 cp = p - c;
  float32 d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0.0f && d5 <= d6) { u = 0.0f; v = 0.0f; return c; }
  float32 vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0f && d2 >= 0.0f && d6 <= 0.0f) {
    float32 t = (d2 - d6) != 0.0f ? d2 / (d2 - d6) : 0.0f;
    u = 1.0f - t; v = 0.0f;
    return a + ac * t;
  }
  float32 va = d3 * d6 - d5 * d4;
  if (va <= 0.0f && (d4 - d3) >= 0.0f && (d5 - d6) >= 0.0f) {
    float32 den = (d4 - d3) + (d5 - d6);
    float32 t = den != 0.0f ? (d4 - d3) / den : 0.0f;
    u = 0.0f; v = 1.0f - t;
    return b + (c - b) * t;
  }
  float32 sum = va + vb + vc;
  if (!(sum != 0.0f)) { u = 1.0f; v = 0.0f; return a; }   // degenerate: handled by the edges above
  float32 denom = 1.0f / sum;
  float32 vv = vb * denom, ww = vc * denom;
  u = 1.0f - vv - ww; v = vv;
  return a + ab * vv + ac * ww;
}

WP_FUNC float32 mesh_box_dist_sq(const float32* lo, const float32* hi, const vec3& p) {
  float32 d = 0.0f;
  for (int k = 0; k < 3; ++k) {
    float32 e = p[k] < lo[k] ? lo[k] - p[k] : (p[k] > hi[k] ? p[k] - hi[k] : 0.0f);
    d += e * e;
  }
  return d;
}

// Closest face within max_dist (squared distance in `best`); face -1 when none.
WP_FUNC void mesh_closest(const geometry_desc_t* g, const vec3& p, float32 max_dist, int32& face, float32& u, float32& v,
                          float32& best) {
  face = -1;
  u = v = 0.0f;
  best = max_dist * max_dist;
  if (!g || g->num_nodes == 0) return;
  // Each entry keeps its box distance (computed when its parent was opened): an entry farther
  // than the best found since is dropped without loading the node again.
  int32 stack[BVH_STACK];
  float32 dist[BVH_STACK];
  int32 count = 0;
  {
    float32 lo[3], hi[3];
    int32 l, r;
    bvh_load_node(g, 0, lo, hi, l, r);
    stack[0] = 0;
    dist[0] = mesh_box_dist_sq(lo, hi, p);
    count = 1;
  }
  while (count > 0) {
    --count;
    if (dist[count] > best) continue;
    float32 lo[3], hi[3];
    int32 left, right;
    bvh_load_node(g, stack[count], lo, hi, left, right);
    if (right < 0) {
      for (int32 i = left; i < left - right; ++i) {
        int32 f = g->prim_ids[i];
        vec3 a, b, c;
        mesh_face(g, f, a, b, c);
        float32 fu, fv;
        vec3 q = mesh_closest_on_triangle(p, a, b, c, fu, fv);
        float32 d = length_sq(q - p);
        if (d <= best && (face < 0 || d < best)) {
          best = d;
          face = f;
          u = fu;
          v = fv;
        }
      }
    } else if (count + 2 <= BVH_STACK) {
      float32 llo[3], lhi[3], rlo[3], rhi[3];
      int32 a, b;
      bvh_load_node(g, left, llo, lhi, a, b);
      bvh_load_node(g, right, rlo, rhi, a, b);
      const float32 dl = mesh_box_dist_sq(llo, lhi, p), dr = mesh_box_dist_sq(rlo, rhi, p);
      // the nearer child is searched first (pushed last)
      const bool left_first = dl <= dr;
      const int32 far_node = left_first ? right : left, near_node = left_first ? left : right;
      const float32 far_dist = left_first ? dr : dl, near_dist = left_first ? dl : dr;
      if (far_dist <= best) { stack[count] = far_node; dist[count++] = far_dist; }
      if (near_dist <= best) { stack[count] = near_node; dist[count++] = near_dist; }
    }
  }
}

// Ray-triangle (Moller-Trumbore); t in [0, max_t]; u, v as mesh_eval_position's.
WP_FUNC bool mesh_ray_triangle(const vec3& s, const vec3& d, const vec3& a, const vec3& b, const vec3& c, float32 max_t,
                               float32& t, float32& u, float32& v) {
  vec3 e1 = b - a, e2 = c - a;
  vec3 pv = cross(d, e2);
  float32 det = dot(e1, pv);
  if (det == 0.0f || !(det == det)) return false;   // parallel (or degenerate) triangle
  float32 inv = 1.0f / det;
  vec3 tv = s - a;
  float32 b1 = dot(tv, pv) * inv;
  if (b1 < 0.0f || b1 > 1.0f) return false;
  vec3 qv = cross(tv, e1);
  float32 b2 = dot(d, qv) * inv;
  if (b2 < 0.0f || b1 + b2 > 1.0f) return false;
  float32 tt = dot(e2, qv) * inv;
  if (!(tt >= 0.0f && tt <= max_t)) return false;
  t = tt;
  u = 1.0f - b1 - b2;
  v = b1;
  return true;
}

// Closest hit along the ray; face -1 when none.
WP_FUNC void mesh_raycast(const geometry_desc_t* g, const vec3& s, const vec3& d, float32 max_t, int32& face, float32& t,
                          float32& u, float32& v, int32 root = -1) {
  face = -1;
  t = max_t;
  u = v = 0.0f;
  if (!g || g->num_nodes == 0) return;
  bvh_walk_t w;
  bvh_walk_begin(w, g, 1, s, d, max_t, root);
  int32 f;
  while (bvh_walk_next(w, f)) {
    vec3 a, b, c;
    mesh_face(g, f, a, b, c);
    float32 ft, fu, fv;
    if (mesh_ray_triangle(s, d, a, b, c, t, ft, fu, fv) && (face < 0 || ft < t)) {
      face = f;
      t = ft;
      u = fu;
      v = fv;
      w.max_t = ft;
    }
  }
}

// Number of faces a ray crosses (every hit, t >= 0).
WP_FUNC int32 mesh_ray_count(const geometry_desc_t* g, const vec3& s, const vec3& d, int32 root = -1) {
  int32 hits = 0;
  if (!g || g->num_nodes == 0) return 0;
  bvh_walk_t w;
  bvh_walk_begin(w, g, 1, s, d, 3.0e38f, root);
  int32 f;
  while (bvh_walk_next(w, f)) {
    vec3 a, b, c;
    mesh_face(g, f, a, b, c);
    float32 ft, fu, fv;
    if (mesh_ray_triangle(s, d, a, b, c, 3.0e38f, ft, fu, fv)) ++hits;
  }
  return hits;
}

// Inside by majority vote of the parity of `n` rays (fixed, slightly skewed directions, so rays
// rarely graze edges): -1 inside, 1 outside.
WP_FUNC float32 mesh_parity_sign(const geometry_desc_t* g, const vec3& p, int32 n, float32 perturbation) {
  const float32 dirs[6][3] = {{1.0f, 0.0137f, 0.0071f},  {0.0093f, 1.0f, 0.0117f},  {0.0131f, 0.0057f, 1.0f},
                              {-1.0f, 0.0113f, -0.0049f}, {-0.0077f, -1.0f, 0.0101f}, {0.0067f, -0.0123f, -1.0f}};
  if (n < 1) n = 1;
  if (n > 6) n = 6;
  int32 inside = 0;
  for (int32 i = 0; i < n; ++i) {
    float32 s = 1.0f + perturbation;
    vec3 d(dirs[i][0] * s, dirs[i][1] * s, dirs[i][2] * s);
    if (mesh_ray_count(g, p, d) & 1) ++inside;
  }
  return 2 * inside > n ? -1.0f : 1.0f;
}

// Warp 1.19's mesh_query_point sign: three rays along +x, +y, +z; each votes by the orientation
// of its closest hit (leaving through a face whose normal points along the ray: inside; a miss:
// outside); -1 when at least two vote inside, else 1. It relies on outward-facing winding.
WP_FUNC float32 mesh_orientation_sign(const geometry_desc_t* g, const vec3& p) {
  if (!g || g->num_nodes == 0) return 1.0f;
  int32 inside = 0;
  for (int32 axis = 0; axis < 3; ++axis) {
    vec3 d(axis == 0 ? 1.0f : 0.0f, axis == 1 ? 1.0f : 0.0f, axis == 2 ? 1.0f : 0.0f);
    bvh_walk_t w;
    bvh_walk_begin(w, g, 1, p, d, 3.0e38f, 0);
    int32 f;
    float32 best_t = 3.0e38f;
    float32 best_dot = 0.0f;
    while (bvh_walk_next(w, f)) {
      vec3 a, b, c;
      mesh_face(g, f, a, b, c);
      float32 ft, fu, fv;
      if (mesh_ray_triangle(p, d, a, b, c, best_t, ft, fu, fv) && ft < best_t) {
        best_t = ft;
        best_dot = dot(d, cross(b - a, c - a));
      }
    }
    if (best_dot > 0.0f) ++inside;
  }
  return inside >= 2 ? -1.0f : 1.0f;
}

// Solid angle of triangle abc seen from p (Van Oosterom and Strackee), over 4 pi.
WP_FUNC float32 mesh_solid_angle(const vec3& p, const vec3& a0, const vec3& b0, const vec3& c0) {
  vec3 a = a0 - p, b = b0 - p, c = c0 - p;
  float32 la = length(a), lb = length(b), lc = length(c);
  float32 num = dot(a, cross(b, c));
  float32 den = la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la;
  return atan2(num, den) * (2.0f / 3.14159265358979f) * 0.5f;
}

// Exact generalized winding number (sum over every face).
WP_FUNC float32 mesh_winding_number(const geometry_desc_t* g, const vec3& p) {
  float32 w = 0.0f;
  for (int64 f = 0; f < g->num_prims; ++f) {
    vec3 a, b, c;
    mesh_face(g, f, a, b, c);
    w += mesh_solid_angle(p, a, b, c);
  }
  return w;
}

WP_FUNC vec3 mesh_face_normal(const geometry_desc_t* g, int64 f) {
  vec3 a, b, c;
  mesh_face(g, f, a, b, c);
  vec3 n = cross(b - a, c - a);
  float32 l = length(n);
  return l > 0.0f ? n / l : vec3();
}

// Sign from the angle-weighted pseudo-normal of the closest feature: the faces whose distance
// ties the closest one's (within epsilon of the distance) each add their normal, weighted by
// their angle at the closest vertex when the closest point is a vertex.
WP_FUNC float32 mesh_normal_sign(const geometry_desc_t* g, const vec3& p, float32 best_sq, int32 face, float32 u, float32 v,
                                 float32 epsilon) {
  vec3 a, b, c;
  mesh_face(g, face, a, b, c);
  vec3 q = a * u + b * v + c * (1.0f - u - v);
  float32 dist = sqrt(best_sq);
  float32 tol = dist + epsilon * (dist > 1.0f ? dist : 1.0f);
  vec3 n;
  bvh_walk_t w;
  vec3 lo(q[0] - epsilon, q[1] - epsilon, q[2] - epsilon), hi(q[0] + epsilon, q[1] + epsilon, q[2] + epsilon);
  bvh_walk_begin(w, g, 0, lo, hi, 0.0f, 0);
  int32 f;
  while (bvh_walk_next(w, f)) {
    vec3 fa, fb, fc;
    mesh_face(g, f, fa, fb, fc);
    float32 fu, fv;
    vec3 fq = mesh_closest_on_triangle(p, fa, fb, fc, fu, fv);
    if (length(fq - p) > tol) continue;
    vec3 fn = cross(fb - fa, fc - fa);
    float32 l = length(fn);
    if (!(l > 0.0f)) continue;
    fn = fn / l;
    float32 weight = 1.0f;
    float32 fw = 1.0f - fu - fv;
    const float32 one = 1.0f - 1.0e-5f;
    vec3 at, e1, e2;
    bool vertex = true;
    if (fu >= one) { at = fa; e1 = fb - fa; e2 = fc - fa; }
    else if (fv >= one) { at = fb; e1 = fa - fb; e2 = fc - fb; }
    else if (fw >= one) { at = fc; e1 = fa - fc; e2 = fb - fc; }
    else vertex = false;
    if (vertex) {
      float32 l1 = length(e1), l2 = length(e2);
      float32 cs = (l1 > 0.0f && l2 > 0.0f) ? dot(e1, e2) / (l1 * l2) : 1.0f;
      cs = cs > 1.0f ? 1.0f : (cs < -1.0f ? -1.0f : cs);
      weight = acos(cs);
    }
    n += fn * weight;
  }
  return dot(p - q, n) < 0.0f ? -1.0f : 1.0f;
}

WP_FUNC weft_struct_MeshQueryPoint mesh_point_result(int32 face, float32 u, float32 v, float32 sign) {
  weft_struct_MeshQueryPoint r;
  r.f_result = face >= 0;
  r.f_sign = face >= 0 ? sign : 0.0f;
  r.f_face = face >= 0 ? face : 0;
  r.f_u = u;
  r.f_v = v;
  return r;
}

WP_FUNC weft_struct_MeshQueryPoint mesh_query_point_no_sign(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                            const vec3& point, float32 max_dist) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_point_no_sign", id, GEOMETRY_MESH);
  int32 face;
  float32 u, v, best;
  mesh_closest(g, point, max_dist, face, u, v, best);
  return mesh_point_result(face, u, v, 0.0f);
}

WP_FUNC weft_struct_MeshQueryPoint mesh_query_point(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                    const vec3& point, float32 max_dist) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_point", id, GEOMETRY_MESH);
  int32 face;
  float32 u, v, best;
  mesh_closest(g, point, max_dist, face, u, v, best);
  return mesh_point_result(face, u, v, face >= 0 ? mesh_orientation_sign(g, point) : 0.0f);
}

WP_FUNC weft_struct_MeshQueryPoint mesh_query_point_sign_parity(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                                const vec3& point, float32 max_dist, int32 n_sample,
                                                                float32 perturbation_scale) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_point_sign_parity", id, GEOMETRY_MESH);
  int32 face;
  float32 u, v, best;
  mesh_closest(g, point, max_dist, face, u, v, best);
  return mesh_point_result(face, u, v, face >= 0 ? mesh_parity_sign(g, point, n_sample, 0.0f * perturbation_scale) : 0.0f);
}

WP_FUNC weft_struct_MeshQueryPoint mesh_query_point_sign_normal(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                                const vec3& point, float32 max_dist, float32 epsilon = 1.0e-3f) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_point_sign_normal", id, GEOMETRY_MESH);
  int32 face;
  float32 u, v, best;
  mesh_closest(g, point, max_dist, face, u, v, best);
  return mesh_point_result(face, u, v, face >= 0 ? mesh_normal_sign(g, point, best, face, u, v, epsilon) : 0.0f);
}

WP_FUNC weft_struct_MeshQueryPoint mesh_query_point_sign_winding_number(const launch_context_t* ctx, int32 fid, int32 line,
                                                                        uint64 id, const vec3& point, float32 max_dist,
                                                                        float32 accuracy = 2.0f, float32 threshold = 0.5f) {
  (void)accuracy;
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_point_sign_winding_number", id, GEOMETRY_MESH);
  int32 face;
  float32 u, v, best;
  mesh_closest(g, point, max_dist, face, u, v, best);
  return mesh_point_result(face, u, v, face >= 0 ? (mesh_winding_number(g, point) > threshold ? -1.0f : 1.0f) : 0.0f);
}

WP_FUNC weft_struct_MeshQueryRay mesh_query_ray(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                const vec3& start, const vec3& dir, float32 max_t, int32 root = -1) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_ray", id, GEOMETRY_MESH);
  weft_struct_MeshQueryRay r;
  int32 face;
  float32 t, u, v;
  mesh_raycast(g, start, dir, max_t, face, t, u, v, root);
  r.f_result = face >= 0;
  r.f_face = face >= 0 ? face : 0;
  r.f_t = face >= 0 ? t : 0.0f;
  r.f_u = u;
  r.f_v = v;
  r.f_normal = face >= 0 ? mesh_face_normal(g, face) : vec3();
  r.f_sign = face >= 0 ? (dot(dir, r.f_normal) < 0.0f ? 1.0f : -1.0f) : 0.0f;
  return r;
}

WP_FUNC weft_struct_MeshQueryAABB mesh_query_aabb(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                  const vec3& lower, const vec3& upper) {
  weft_struct_MeshQueryAABB q;
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_aabb", id, GEOMETRY_MESH);
  bvh_walk_begin(q.walk, g, 0, lower, upper, 0.0f, -1);
  return q;
}
WP_FUNC bool mesh_face_in_sphere(const geometry_desc_t* g, int32 face, const float32* center, float32 radius) {
  vec3 a, b, c, p(center[0], center[1], center[2]);
  mesh_face(g, face, a, b, c);
  float32 u, v;
  return length_sq(mesh_closest_on_triangle(p, a, b, c, u, v) - p) <= radius * radius;
}

// Faces within `radius` of center (exact distance), iterated like mesh_query_aabb.
WP_FUNC weft_struct_MeshQueryAABB mesh_query_sphere(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                    const vec3& center, float32 radius) {
  weft_struct_MeshQueryAABB q;
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_sphere", id, GEOMETRY_MESH);
  bvh_walk_begin(q.walk, g, 2, center, vec3(radius, 1.0f, 0.0f), 0.0f, -1);   // faces tested exactly
  return q;
}

WP_FUNC bool mesh_query_aabb_next(weft_struct_MeshQueryAABB& q, int32& index) { return bvh_walk_next(q.walk, index); }
WP_FUNC bool mesh_query_next(weft_struct_MeshQueryAABB& q, int32& index) { return bvh_walk_next(q.walk, index); }

// Checked face / index access: a value outside the mesh is a launch error (and a zero result).
WP_FUNC const geometry_desc_t* mesh_checked(const launch_context_t* ctx, int32 fid, int32 line, const char* fn, uint64 id,
                                            int64 i, int64 n_mul) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, fn, id, GEOMETRY_MESH);
  if (!g) return nullptr;
  int64 n = g->num_prims * n_mul;
  if (i < 0 || i >= n) {
    geometry_msg_t m;
    m.str(fn).str(": ").str(n_mul == 1 ? "face " : "index ").num(i).str(" is out of range [0, ").num(n).str(")");
    geometry_report(ctx, fid, line, m);
    return nullptr;
  }
  return g;
}

WP_FUNC vec3 mesh_eval_position(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 face, float32 u,
                                float32 v) {
  const geometry_desc_t* g = mesh_checked(ctx, fid, line, "mesh_eval_position", id, face, 1);
  if (!g) return vec3();
  vec3 a, b, c;
  mesh_face(g, face, a, b, c);
  return a * u + b * v + c * (1.0f - u - v);
}

WP_FUNC vec3 mesh_eval_velocity(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 face, float32 u,
                                float32 v) {
  const geometry_desc_t* g = mesh_checked(ctx, fid, line, "mesh_eval_velocity", id, face, 1);
  if (!g) return vec3();
  if (!g->velocities) {
    geometry_msg_t m;
    m.str("mesh_eval_velocity: the mesh was built without velocities");
    geometry_report(ctx, fid, line, m);
    return vec3();
  }
  vec3 a = geometry_load3(g->velocities, g->indices[3 * (int64)face]);
  vec3 b = geometry_load3(g->velocities, g->indices[3 * (int64)face + 1]);
  vec3 c = geometry_load3(g->velocities, g->indices[3 * (int64)face + 2]);
  return a * u + b * v + c * (1.0f - u - v);
}

WP_FUNC vec3 mesh_eval_face_normal(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 face) {
  const geometry_desc_t* g = mesh_checked(ctx, fid, line, "mesh_eval_face_normal", id, face, 1);
  return g ? mesh_face_normal(g, face) : vec3();
}

// wp.mesh_get: the mesh's arrays as kernel arrays. points and velocities are the caller's arrays
// (velocities a None array when the mesh has none), indices the caller's indices array, not the
// daemon's checked copy the queries read (writes through it cannot reach a query). No gradients.
struct weft_struct_Mesh {   // fields named as codegen names struct fields (f_<name>)
  array_t<vec3> f_points;
  array_t<vec3> f_velocities;
  array_t<int32> f_indices;
};
WP_FUNC void cg_accum(weft_struct_Mesh&, const weft_struct_Mesh&) {}
WP_FUNC void cg_link(weft_struct_Mesh&, const weft_struct_Mesh&) {}
// The adjoint of mesh_get's result (codegen_support.h cg_link_grads): a load from m.points
// accumulates into the points array's gradient, as in Warp; velocities and indices carry none.
WP_FUNC void cg_link_grads(weft_struct_Mesh& adj, const weft_struct_Mesh& m) { adj.f_points = grad_of(m.f_points); }

template <typename T>
WP_FUNC array_t<T> mesh_array_1d(const T* data, int64 n) {
  array_t<T> a;
  a.data = (T*)data;
  a.grad = nullptr;
  for (int d = 0; d < ARRAY_MAX_DIMS; ++d) a.shape[d] = a.strides[d] = 0;
  a.shape[0] = data ? n : 0;
  a.strides[0] = (int64)sizeof(T);
  a.ndim = 1;
  a.flags = 0;
  return a;
}

WP_FUNC weft_struct_Mesh mesh_get(const launch_context_t* ctx, int32 fid, int32 line, uint64 id) {
  weft_struct_Mesh m;
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_get", id, GEOMETRY_MESH);
  m.f_points = mesh_array_1d((const vec3*)(g ? g->points : nullptr), g ? g->num_points : 0);
  m.f_points.grad = (vec3*)(g ? g->points_grad : nullptr);
  m.f_velocities = mesh_array_1d((const vec3*)(g ? g->velocities : nullptr), g ? g->num_points : 0);
  m.f_indices = mesh_array_1d(g ? g->user_indices : (const int32*)nullptr, g ? 3 * g->num_prims : 0);
  return m;
}

WP_FUNC vec3 mesh_get_point(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 index) {
  const geometry_desc_t* g = mesh_checked(ctx, fid, line, "mesh_get_point", id, index, 3);
  return g ? geometry_load3(g->points, g->indices[index]) : vec3();
}

WP_FUNC vec3 mesh_get_velocity(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 index) {
  const geometry_desc_t* g = mesh_checked(ctx, fid, line, "mesh_get_velocity", id, index, 3);
  if (!g) return vec3();
  if (!g->velocities) {
    geometry_msg_t m;
    m.str("mesh_get_velocity: the mesh was built without velocities");
    geometry_report(ctx, fid, line, m);
    return vec3();
  }
  return geometry_load3(g->velocities, g->indices[index]);
}

WP_FUNC int32 mesh_get_index(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 index) {
  const geometry_desc_t* g = mesh_checked(ctx, fid, line, "mesh_get_index", id, index, 3);
  return g ? g->indices[index] : -1;
}

// ---------------------------------------------------------------------------------------------
// Further queries and Warp's older out-parameter forms.

WP_FUNC bool mesh_query_ray_anyhit(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& start,
                                   const vec3& dir, float32 max_t, int32 root = -1) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_ray_anyhit", id, GEOMETRY_MESH);
  if (!g || g->num_nodes == 0) return false;
  bvh_walk_t w;
  bvh_walk_begin(w, g, 1, start, dir, max_t, root);
  int32 f;
  while (bvh_walk_next(w, f)) {
    vec3 a, b, c;
    mesh_face(g, f, a, b, c);
    float32 t, u, v;
    if (mesh_ray_triangle(start, dir, a, b, c, max_t, t, u, v)) return true;
  }
  return false;
}

WP_FUNC int32 mesh_query_ray_count_intersections(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                 const vec3& start, const vec3& dir, int32 root = -1) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_ray_count_intersections", id, GEOMETRY_MESH);
  return mesh_ray_count(g, start, dir, root);
}

// The furthest point of the mesh from `point` at distance >= min_dist (a vertex: the furthest
// point of a triangle is one of its corners). O(faces).
WP_FUNC weft_struct_MeshQueryPoint mesh_query_furthest_point_no_sign(const launch_context_t* ctx, int32 fid, int32 line,
                                                                     uint64 id, const vec3& point, float32 min_dist) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "mesh_query_furthest_point_no_sign", id, GEOMETRY_MESH);
  int32 face = -1;
  float32 best = min_dist * min_dist, u = 0.0f, v = 0.0f;
  if (g) {
    for (int64 f = 0; f < g->num_prims; ++f) {
      vec3 p[3];
      mesh_face(g, f, p[0], p[1], p[2]);
      for (int c = 0; c < 3; ++c) {
        float32 d = length_sq(p[c] - point);
        if (d >= best && (face < 0 || d > best)) {
          best = d;
          face = (int32)f;
          u = c == 0 ? 1.0f : 0.0f;
          v = c == 1 ? 1.0f : 0.0f;
        }
      }
    }
  }
  return mesh_point_result(face, u, v, 0.0f);
}

WP_FUNC bool mesh_point_out(const weft_struct_MeshQueryPoint& r, float32* inside, int32& face, float32& u, float32& v) {
  if (inside) *inside = r.f_sign;
  face = r.f_face;
  u = r.f_u;
  v = r.f_v;
  return r.f_result;
}

WP_FUNC bool mesh_query_point(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& point,
                              float32 max_dist, float32& inside, int32& face, float32& u, float32& v) {
  return mesh_point_out(mesh_query_point(ctx, fid, line, id, point, max_dist), &inside, face, u, v);
}
WP_FUNC bool mesh_query_point_no_sign(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& point,
                                      float32 max_dist, int32& face, float32& u, float32& v) {
  return mesh_point_out(mesh_query_point_no_sign(ctx, fid, line, id, point, max_dist), nullptr, face, u, v);
}
WP_FUNC bool mesh_query_point_sign_normal(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& point,
                                          float32 max_dist, float32& inside, int32& face, float32& u, float32& v,
                                          float32 epsilon = 1.0e-3f) {
  return mesh_point_out(mesh_query_point_sign_normal(ctx, fid, line, id, point, max_dist, epsilon), &inside, face, u, v);
}
WP_FUNC bool mesh_query_point_sign_winding_number(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                  const vec3& point, float32 max_dist, float32& inside, int32& face,
                                                  float32& u, float32& v, float32 accuracy = 2.0f, float32 threshold = 0.5f) {
  return mesh_point_out(mesh_query_point_sign_winding_number(ctx, fid, line, id, point, max_dist, accuracy, threshold),
                        &inside, face, u, v);
}
WP_FUNC bool mesh_query_ray(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& start,
                            const vec3& dir, float32 max_t, float32& t, float32& u, float32& v, float32& sign, vec3& normal,
                            int32& face, int32 root = -1) {
  weft_struct_MeshQueryRay r = mesh_query_ray(ctx, fid, line, id, start, dir, max_t, root);
  t = r.f_t;
  u = r.f_u;
  v = r.f_v;
  sign = r.f_sign;
  normal = r.f_normal;
  face = r.f_face;
  return r.f_result;
}

}  // namespace wp
