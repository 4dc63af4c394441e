// Warp's tiled geometry queries (tile_bvh_query_aabb / _ray, tile_mesh_query_aabb and their
// _next and tile_query_valid; the deprecated *_tiled names are aliases in the registry). weft
// runs one thread per block (docs/tiles.md), so a tiled query is the thread query with a
// `valid` flag: each _next gives a tile of shape (1,) holding the next item (-1 once the walk is
// done, which clears `valid`). Every item is reported once, as Warp's block-wide walk does.
#pragma once

namespace wp {

struct weft_struct_BvhQueryTiled {
  weft_struct_BvhQuery query;
  bool valid;
};
WP_FUNC void cg_accum(weft_struct_BvhQueryTiled&, const weft_struct_BvhQueryTiled&) {}
WP_FUNC void cg_link(weft_struct_BvhQueryTiled&, const weft_struct_BvhQueryTiled&) {}

struct weft_struct_MeshQueryAABBTiled {
  weft_struct_MeshQueryAABB query;
  bool valid;
};
WP_FUNC void cg_accum(weft_struct_MeshQueryAABBTiled&, const weft_struct_MeshQueryAABBTiled&) {}
WP_FUNC void cg_link(weft_struct_MeshQueryAABBTiled&, const weft_struct_MeshQueryAABBTiled&) {}

WP_FUNC weft_struct_BvhQueryTiled tile_bvh_query_aabb(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                      const vec3& lower, const vec3& upper) {
  weft_struct_BvhQueryTiled q;
  q.query = bvh_query_aabb(ctx, fid, line, id, lower, upper);
  q.valid = true;
  return q;
}
WP_FUNC weft_struct_BvhQueryTiled tile_bvh_query_ray(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                     const vec3& start, const vec3& dir) {
  weft_struct_BvhQueryTiled q;
  q.query = bvh_query_ray(ctx, fid, line, id, start, dir);
  q.valid = true;
  return q;
}
// The result of one _next of a tiled query whose thread query gave `found` / `index`: the
// item as a (1,) tile, -1 (and `valid` cleared) once the walk is done.
WP_FUNC tile_t<int32, 1, 0, 0, 0> tile_query_result(bool& valid, bool found, int32 index) {
  tile_t<int32, 1, 0, 0, 0> r;
  valid = found;
  r.data[0] = found ? index : -1;
  return r;
}
// With cooperative CPU blocks of B lanes (docs/tiles.md) a _next gives the next B items, -1 past
// the last; the query stays valid while a _next found any. Every lane walks the same query.
template <typename Q, typename Next, int B>
WP_FUNC tile_t<int32, B, 0, 0, 0> tile_query_next_lanes(Q& q, Next next) {
  tile_t<int32, B, 0, 0, 0> r;
  int found = 0;
  for (int k = 0; k < B; ++k) {
    int32 index = -1;
    const bool f = q.valid && found == k && next(q.query, index);
    r.data[k] = f ? index : -1;
    found += f;
  }
  q.valid = found > 0;
  return r;
}
struct tile_bvh_next_op {
  WP_FUNC bool operator()(weft_struct_BvhQuery& q, int32& index) const { return bvh_query_next(q, index); }
};
struct tile_mesh_aabb_next_op {
  WP_FUNC bool operator()(weft_struct_MeshQueryAABB& q, int32& index) const { return mesh_query_aabb_next(q, index); }
};
template <int B>
WP_FUNC tile_t<int32, B, 0, 0, 0> tile_bvh_query_next_lanes(const tile_t<int32, B, 0, 0, 0>&, weft_struct_BvhQueryTiled& q) {
  return tile_query_next_lanes<weft_struct_BvhQueryTiled, tile_bvh_next_op, B>(q, tile_bvh_next_op());
}
template <int B>
WP_FUNC tile_t<int32, B, 0, 0, 0> tile_mesh_query_aabb_next_lanes(const tile_t<int32, B, 0, 0, 0>&,
                                                                    weft_struct_MeshQueryAABBTiled& q) {
  return tile_query_next_lanes<weft_struct_MeshQueryAABBTiled, tile_mesh_aabb_next_op, B>(q, tile_mesh_aabb_next_op());
}

WP_FUNC tile_t<int32, 1, 0, 0, 0> tile_bvh_query_next(weft_struct_BvhQueryTiled& q) {
  int32 index = -1;
  return tile_query_result(q.valid, q.valid && bvh_query_next(q.query, index), index);
}
WP_FUNC bool tile_query_valid(const weft_struct_BvhQueryTiled& q) { return q.valid; }

WP_FUNC weft_struct_MeshQueryAABBTiled tile_mesh_query_aabb(const launch_context_t* ctx, int32 fid, int32 line,
                                                            uint64 id, const vec3& lower, const vec3& upper) {
  weft_struct_MeshQueryAABBTiled q;
  q.query = mesh_query_aabb(ctx, fid, line, id, lower, upper);
  q.valid = true;
  return q;
}
WP_FUNC tile_t<int32, 1, 0, 0, 0> tile_mesh_query_aabb_next(weft_struct_MeshQueryAABBTiled& q) {
  int32 index = -1;
  return tile_query_result(q.valid, q.valid && mesh_query_aabb_next(q.query, index), index);
}
WP_FUNC bool tile_query_valid(const weft_struct_MeshQueryAABBTiled& q) { return q.valid; }

}  // namespace wp
