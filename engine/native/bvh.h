// Kernel-side geometry lookup and the BVH queries: geometry_resolve (an id to the descriptor of
// a live object of the launching session, or a launch error naming the kernel line), and
// bvh_query_aabb / bvh_query_ray / bvh_query_next over wp.Bvh objects (the traversal is shared
// with mesh.h). Ids are never dereferenced: they index the per-launch table (geometry_abi.h).
// Not differentiable. No standard library headers.
#pragma once

#include "array.h"
#include "geometry_abi.h"
#include "vec.h"

namespace wp {

// ---------------------------------------------------------------------------------------------
// Error text without a C library: "<what> <decimal>" pieces appended to a 128-byte buffer.
// Out of line (WP_NOINLINE), as every error path.
struct geometry_msg_t {
  char text[128];
  int32 n;
  WP_CALLABLE geometry_msg_t() : text(), n(0) {}
  WP_NOINLINE WP_CALLABLE geometry_msg_t& str(const char* s) {
    for (; s && *s && n < 127; ++s) text[n++] = *s;
    text[n] = '\0';
    return *this;
  }
  WP_NOINLINE WP_CALLABLE geometry_msg_t& num(int64 v) {
    char buf[24];
    int32 k = 0;
    uint64 u = v < 0 ? (uint64)0 - (uint64)v : (uint64)v;
    do { buf[k++] = (char)('0' + (int32)(u % 10)); u /= 10; } while (u && k < 22);
    if (v < 0 && n < 127) text[n++] = '-';
    while (k > 0 && n < 127) text[n++] = buf[--k];
    text[n] = '\0';
    return *this;
  }
};

inline WP_NOINLINE WP_CALLABLE void geometry_report(const launch_context_t* ctx, int32 function_id, int32 line,
                                                    const geometry_msg_t& m) {
  report_error(ctx, LAUNCH_BAD_GEOMETRY, function_id, line, -1, 0, nullptr, nullptr, m.text);
}

WP_FUNC const char* geometry_kind_name(uint32 kind) {
  return kind == GEOMETRY_HASH_GRID ? "HashGrid"
         : kind == GEOMETRY_BVH     ? "Bvh"
         : kind == GEOMETRY_MESH    ? "Mesh"
                                    : "Volume";
}

// Reports why `id` names no live object of kind `kind` for `fn` (out of line: the cold path).
inline WP_NOINLINE WP_CALLABLE void geometry_resolve_failed(const launch_context_t* ctx, int32 function_id, int32 line,
                                                            const char* fn, uint64 id, uint32 kind,
                                                            const geometry_table_t* t, const geometry_desc_t* d) {
  geometry_msg_t m;
  m.str(fn).str(": ");
  if (id == 0) {
    m.str("id 0 (None) is not a ").str(geometry_kind_name(kind));
  } else if (!t) {
    m.str("id ").num((int64)id).str(" is not a live ").str(geometry_kind_name(kind)).str(" of this session (it has none on this device)");
  } else if (!d) {
    m.str("id ").num((int64)id).str(" is not a live ").str(geometry_kind_name(kind)).str(" of this session");
  } else {
    m.str("id ").num((int64)id).str(" is a ").str(geometry_kind_name(d->kind)).str(", not a ").str(geometry_kind_name(kind));
  }
  geometry_report(ctx, function_id, line, m);
}

// The live object `id` of kind `kind` (a Mesh also serves BVH queries when kind is GEOMETRY_BVH
// and `mesh_ok`), or null after reporting a launch error: id 0, a slot outside the table, a
// stale generation (freed object, another session's id, a forged value) or another kind.
WP_FUNC const geometry_desc_t* geometry_resolve(const launch_context_t* ctx, int32 function_id, int32 line,
                                                const char* fn, uint64 id, uint32 kind) {
  const geometry_table_t* t = ctx ? ctx->geometry : nullptr;
  uint64 slot = (id & 0xffffffffull);
  uint32 gen = (uint32)(id >> 32);
  const bool mesh_bvh = (slot & GEOMETRY_MESH_BVH_BIT) != 0;   // mesh_get_bvh's id
  slot &= ~GEOMETRY_MESH_BVH_BIT;
  const geometry_desc_t* d = nullptr;
  if (t && slot >= 1 && slot <= t->count) {
    d = &t->slots[slot - 1];
    if (d->kind == GEOMETRY_NONE || d->generation != gen) d = nullptr;
  }
  if (d && !mesh_bvh && d->kind == kind) return d;
  if (d && mesh_bvh && kind == GEOMETRY_BVH && d->kind == GEOMETRY_MESH) return d;
  if (d && mesh_bvh) d = nullptr;   // a mesh's BVH id names no object of another kind
  geometry_resolve_failed(ctx, function_id, line, fn, id, kind, t, d);
  return nullptr;
}

// The root node of `group`'s subtree in a grouped Bvh or Mesh (binary search of the ascending
// group ids); -1 when the object has no such group (or no groups): a query from root -1 walks
// the whole tree.
WP_FUNC int32 bvh_group_root(const geometry_desc_t* g, int32 group) {
  if (!g || g->num_groups <= 0) return -1;
  int64 lo = 0, hi = g->num_groups;
  while (lo < hi) {
    const int64 mid = lo + (hi - lo) / 2;
    if (g->group_ids[mid] < group) lo = mid + 1;
    else hi = mid;
  }
  return (lo < g->num_groups && g->group_ids[lo] == group) ? g->group_roots[lo] : -1;
}
WP_FUNC int32 bvh_get_group_root(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 group) {
  return bvh_group_root(geometry_resolve(ctx, fid, line, "bvh_get_group_root", id, GEOMETRY_BVH), group);
}
WP_FUNC uint64 mesh_get_bvh(const launch_context_t* ctx, int32 fid, int32 line, uint64 id) {
  return geometry_resolve(ctx, fid, line, "mesh_get_bvh", id, GEOMETRY_MESH) ? (id | GEOMETRY_MESH_BVH_BIT) : 0;
}
WP_FUNC int32 mesh_get_group_root(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 group) {
  return bvh_group_root(geometry_resolve(ctx, fid, line, "mesh_get_group_root", id, GEOMETRY_MESH), group);
}

WP_FUNC vec3 geometry_load3(const float32* p, int64 i) { return vec3(p[3 * i], p[3 * i + 1], p[3 * i + 2]); }

// ---------------------------------------------------------------------------------------------
// Traversal state shared by BVH and mesh AABB/ray queries.

struct bvh_walk_t {
  const geometry_desc_t* g;
  int32 mode;         // 0 aabb, 1 ray, 2 sphere, 3 capsule
  float32 a[3];       // aabb lower | ray/capsule start | sphere center
  float32 b[3];       // aabb upper | ray/capsule direction | sphere radius in b[0], and in b[1]
                      // 1 when the items are a mesh's faces tested exactly (mesh_query_sphere)
  float32 max_t;      // ray/capsule: items hit beyond it are skipped
  float32 radius;     // capsule: the ray's bounds are inflated by it
  int32 stack[BVH_STACK];
  int32 count;
  int32 leaf_cur;
  int32 leaf_end;
};

WP_FUNC bool bvh_box_overlap(const float32* lo, const float32* hi, const float32* qa, const float32* qb) {
  return !(lo[0] > qb[0] || hi[0] < qa[0] || lo[1] > qb[1] || hi[1] < qa[1] || lo[2] > qb[2] || hi[2] < qa[2]);
}

// Slab test: the ray start + t dir (t >= 0) meets [lo, hi] at some t <= max_t.
WP_FUNC bool bvh_ray_box(const float32* lo, const float32* hi, const float32* s, const float32* d, float32 max_t) {
  float32 t0 = 0.0f, t1 = max_t;
  for (int k = 0; k < 3; ++k) {
    if (d[k] == 0.0f) {
      if (s[k] < lo[k] || s[k] > hi[k]) return false;
      continue;
    }
    float32 inv = 1.0f / d[k];
    float32 ta = (lo[k] - s[k]) * inv, tb = (hi[k] - s[k]) * inv;
    if (ta > tb) { float32 x = ta; ta = tb; tb = x; }
    if (ta > t0) t0 = ta;
    if (tb < t1) t1 = tb;
    if (t0 > t1) return false;
  }
  return true;
}

// Node i's bounds and children: on a GPU two 16-byte loads through the read-only cache (nodes
// are never written while a kernel runs: builds and refits are launches of their own).
WP_FUNC void bvh_load_node(const geometry_desc_t* g, int32 i, float32* lo, float32* hi, int32& left, int32& right) {
#if defined(__CUDA_ARCH__)
  const float4* p = reinterpret_cast<const float4*>(g->nodes + i);
  const float4 a = __ldg(p), b = __ldg(p + 1);
  lo[0] = a.x; lo[1] = a.y; lo[2] = a.z; left = __float_as_int(a.w);
  hi[0] = b.x; hi[1] = b.y; hi[2] = b.z; right = __float_as_int(b.w);
#else
  const bvh_node_t& n = g->nodes[i];
  for (int k = 0; k < 3; ++k) { lo[k] = n.lower[k]; hi[k] = n.upper[k]; }
  left = n.left;
  right = n.right;
#endif
}

// Item bounds: a Bvh's lowers/uppers, a Mesh's triangle from the current points.
WP_FUNC void bvh_item_bounds(const geometry_desc_t* g, int32 item, float32* lo, float32* hi) {
  if (g->kind == GEOMETRY_BVH) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = g->lowers[3 * (int64)item + k];
      hi[k] = g->uppers[3 * (int64)item + k];
    }
    return;
  }
  for (int k = 0; k < 3; ++k) { lo[k] = 3.0e38f; hi[k] = -3.0e38f; }
  for (int c = 0; c < 3; ++c) {
    int64 v = g->indices[3 * (int64)item + c];
    for (int k = 0; k < 3; ++k) {
      float32 x = g->points[3 * v + k];
      if (x < lo[k]) lo[k] = x;
      if (x > hi[k]) hi[k] = x;
    }
  }
}

WP_FUNC void bvh_walk_begin(bvh_walk_t& w, const geometry_desc_t* g, int32 mode, const vec3& a, const vec3& b,
                            float32 max_t, int32 root) {
  w.g = g;
  w.mode = mode;
  for (int k = 0; k < 3; ++k) { w.a[k] = a[k]; w.b[k] = b[k]; }
  w.max_t = max_t;
  w.radius = 0.0f;
  w.count = 0;
  w.leaf_cur = 0;
  w.leaf_end = 0;
  if (g && g->num_nodes > 0) {
    int32 r = (root >= 0 && root < g->num_nodes) ? root : 0;
    w.stack[w.count++] = r;
  }
}

// Squared distance from point c to the box [lo, hi] (0 inside).
WP_FUNC float32 bvh_box_dist_sq(const float32* lo, const float32* hi, const float32* c) {
  float32 d = 0.0f;
  for (int k = 0; k < 3; ++k) {
    float32 e = c[k] < lo[k] ? lo[k] - c[k] : (c[k] > hi[k] ? c[k] - hi[k] : 0.0f);
    d += e * e;
  }
  return d;
}

// mode 0: box overlap; 1: ray; 2: sphere (a = center, b[0] = radius); 3: capsule (the ray
// against the box inflated by the radius: conservative near the box's edges, as Warp's).
WP_FUNC bool bvh_walk_test(const bvh_walk_t& w, const float32* lo, const float32* hi) {
  if (w.mode == 2) return bvh_box_dist_sq(lo, hi, w.a) <= w.b[0] * w.b[0];
  if (w.mode == 3) {
    float32 elo[3], ehi[3];
    for (int k = 0; k < 3; ++k) { elo[k] = lo[k] - w.radius; ehi[k] = hi[k] + w.radius; }
    return bvh_ray_box(elo, ehi, w.a, w.b, w.max_t);
  }
  return w.mode == 0 ? bvh_box_overlap(lo, hi, w.a, w.b) : bvh_ray_box(lo, hi, w.a, w.b, w.max_t);
}

// Sphere narrow phase of a mesh face (mesh.h): the face's closest point lies within the radius.
WP_FUNC bool mesh_face_in_sphere(const geometry_desc_t* g, int32 face, const float32* center, float32 radius);

inline WP_NOINLINE WP_CALLABLE bool bvh_walk_next(bvh_walk_t& w, int32& index) {
  const geometry_desc_t* g = w.g;
  if (!g) return false;
  for (;;) {
    if (w.leaf_cur < w.leaf_end) {
      int32 item = g->prim_ids[w.leaf_cur++];
      float32 lo[3], hi[3];
      bvh_item_bounds(g, item, lo, hi);
      if (bvh_walk_test(w, lo, hi) &&
          (w.mode != 2 || w.b[1] == 0.0f || mesh_face_in_sphere(g, item, w.a, w.b[0]))) {
        index = item;
        return true;
      }
      continue;
    }
    if (w.count == 0) return false;
    float32 lo[3], hi[3];
    int32 left, right;
    bvh_load_node(g, w.stack[--w.count], lo, hi, left, right);
    if (!bvh_walk_test(w, lo, hi)) continue;
    if (right == -1 && (w.mode != 2 || w.b[1] == 0.0f)) {
      // A leaf of one item (device builds): its bounds are the item's, already tested. (The
      // item test would also pass an item with a NaN bound, which no node bound holds.)
      index = g->prim_ids[left];
      return true;
    }
    if (right < 0) {
      w.leaf_cur = left;
      w.leaf_end = left - right;
    } else if (w.count + 2 <= BVH_STACK) {
      w.stack[w.count++] = right;
      w.stack[w.count++] = left;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// wp.BvhQuery (sema: struct BvhQuery).
struct weft_struct_BvhQuery {
  bvh_walk_t walk;
};
WP_FUNC void cg_accum(weft_struct_BvhQuery&, const weft_struct_BvhQuery&) {}
WP_FUNC void cg_link(weft_struct_BvhQuery&, const weft_struct_BvhQuery&) {}

WP_FUNC weft_struct_BvhQuery bvh_query_aabb(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                            const vec3& lower, const vec3& upper, int32 root = -1) {
  weft_struct_BvhQuery q;
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "bvh_query_aabb", id, GEOMETRY_BVH);
  bvh_walk_begin(q.walk, g, 0, lower, upper, 0.0f, root);
  return q;
}

WP_FUNC weft_struct_BvhQuery bvh_query_ray(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                           const vec3& start, const vec3& dir, int32 root = -1) {
  weft_struct_BvhQuery q;
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "bvh_query_ray", id, GEOMETRY_BVH);
  bvh_walk_begin(q.walk, g, 1, start, dir, 3.0e38f, root);
  return q;
}

WP_FUNC weft_struct_BvhQuery bvh_query_sphere(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                              const vec3& center, float32 radius, int32 root = -1) {
  weft_struct_BvhQuery q;
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "bvh_query_sphere", id, GEOMETRY_BVH);
  bvh_walk_begin(q.walk, g, 2, center, vec3(radius, 0.0f, 0.0f), 0.0f, root);
  return q;
}

// The capsule swept by start + t dir, t in [0, max_dist] (bvh_query_next's; unbounded without
// it), with the given radius.
WP_FUNC weft_struct_BvhQuery bvh_query_capsule(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                               const vec3& start, const vec3& dir, float32 radius,
                                               int32 root = -1) {
  weft_struct_BvhQuery q;
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "bvh_query_capsule", id, GEOMETRY_BVH);
  bvh_walk_begin(q.walk, g, 3, start, dir, 3.0e38f, root);
  q.walk.radius = radius > 0.0f ? radius : 0.0f;
  return q;
}

WP_FUNC bool bvh_query_next(weft_struct_BvhQuery& q, int32& index) { return bvh_walk_next(q.walk, index); }
WP_FUNC bool bvh_query_next(weft_struct_BvhQuery& q, int32& index, float32 max_dist) {
  q.walk.max_t = max_dist;
  return bvh_walk_next(q.walk, index);
}

}  // namespace wp
