// Kernel-side wp.HashGrid queries: hash_grid_query (the cells a sphere of radius max_dist around
// a point touches; with a group id, only that group's points), hash_grid_query_next (the next point
// index in those cells; the caller filters by distance, as in Warp) and hash_grid_point_id (points
// in cell order). A grouped query finds its group's run in each cell by binary search (a grouped
// build orders each cell by group id), so it never walks other groups' points; on a grid built
// without groups every point is in group 0. The cells are the
// daemon's build of the grid (geometry_abi.h: cell_starts/cell_ends/sorted_ids, index values
// checked by the build). vec3h / vec3d points are converted to float32. Not differentiable.
// No standard library headers.
#pragma once

#include "bvh.h"

namespace wp {

struct weft_struct_HashGridQuery {
  const geometry_desc_t* g;
  int32 lo[3];
  int32 hi[3];
  int32 cell[3];    // the current cell coordinates (x fastest)
  int32 cur;        // next entry of sorted_ids in the current cell
  int32 end;
  int32 group;      // with `grouped`: the only group visited
  bool grouped;
  bool started;
  bool done;
};
WP_FUNC void cg_accum(weft_struct_HashGridQuery&, const weft_struct_HashGridQuery&) {}
WP_FUNC void cg_link(weft_struct_HashGridQuery&, const weft_struct_HashGridQuery&) {}

template <typename T>
WP_FUNC weft_struct_HashGridQuery hash_grid_query(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                  const vec_t<3, T>& point, T max_dist) {
  weft_struct_HashGridQuery q;
  q.g = geometry_resolve(ctx, fid, line, "hash_grid_query", id, GEOMETRY_HASH_GRID);
  q.cur = q.end = 0;
  q.group = 0;
  q.grouped = false;
  q.started = false;
  q.done = true;
  for (int k = 0; k < 3; ++k) q.lo[k] = q.hi[k] = q.cell[k] = 0;
  if (!q.g || q.g->num_sorted == 0 || !(q.g->cell_width > 0.0f)) return q;
  float32 r = (float32)max_dist;
  if (!(r >= 0.0f)) r = 0.0f;
  for (int k = 0; k < 3; ++k) {
    float32 p = (float32)point[k];
    int32 a = hash_grid_coord(p - r, q.g->cell_width);
    int32 b = hash_grid_coord(p + r, q.g->cell_width);
    if ((int64)b - (int64)a + 1 > (int64)q.g->dim[k]) b = a + q.g->dim[k] - 1;   // every cell once
    q.lo[k] = a;
    q.hi[k] = b;
    q.cell[k] = a;
  }
  q.done = false;
  return q;
}

template <typename T>
WP_FUNC weft_struct_HashGridQuery hash_grid_query(const launch_context_t* ctx, int32 fid, int32 line, uint64 id,
                                                  const vec_t<3, T>& point, T max_dist, int32 group) {
  weft_struct_HashGridQuery q = hash_grid_query(ctx, fid, line, id, point, max_dist);
  q.group = group;
  q.grouped = true;
  return q;
}

// The run of `group` in [begin, end) of a grouped build's cell (ordered by group id).
WP_FUNC void hash_grid_group_run(const int32* groups, int32 group, int32& begin, int32& end) {
  int32 lo = begin, hi = end;
  while (lo < hi) {   // first entry >= group
    int32 mid = lo + (hi - lo) / 2;
    if (groups[mid] < group) lo = mid + 1;
    else hi = mid;
  }
  int32 first = lo;
  hi = end;
  while (lo < hi) {   // first entry > group
    int32 mid = lo + (hi - lo) / 2;
    if (groups[mid] <= group) lo = mid + 1;
    else hi = mid;
  }
  begin = first;
  end = lo;
}

WP_FUNC bool hash_grid_query_next(weft_struct_HashGridQuery& q, int32& index) {
  if (!q.g) return false;
  for (;;) {
    if (q.cur < q.end) {
      index = q.g->sorted_ids[q.cur++];
      return true;
    }
    if (q.done) return false;
    if (q.started) {   // advance to the next cell of the box
      if (++q.cell[0] > q.hi[0]) {
        q.cell[0] = q.lo[0];
        if (++q.cell[1] > q.hi[1]) {
          q.cell[1] = q.lo[1];
          if (++q.cell[2] > q.hi[2]) {
            q.done = true;
            return false;
          }
        }
      }
    }
    q.started = true;
    int64 c = hash_grid_cell(q.g->dim, q.cell[0], q.cell[1], q.cell[2]);
    q.cur = q.g->cell_starts[c];
    q.end = q.g->cell_ends[c];
    if (q.grouped) {
      if (q.g->sorted_groups) hash_grid_group_run(q.g->sorted_groups, q.group, q.cur, q.end);
      else if (q.group != 0) q.end = q.cur;
    }
  }
}

// The index of the point at position `index` of the grid's cell order; -1 outside [0, points).
WP_FUNC int32 hash_grid_point_id(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 index) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, "hash_grid_point_id", id, GEOMETRY_HASH_GRID);
  if (!g || index < 0 || (int64)index >= g->num_sorted) return -1;
  return g->sorted_ids[index];
}

}  // namespace wp
