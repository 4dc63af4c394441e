// Native library: tiles (Warp's tile programming). Owns tile_t (a value holding its elements,
// row-major, extents D0..D3 known at compile time, 0 past ndim) and the tile builtins with
// their adjoints: construction, loads and stores between tiles and arrays, element-wise
// arithmetic, element access, reductions, transpose, broadcast and matrix products.
//
// A tile belongs to the thread that computes it, on every device: a tiled launch runs each
// block as one thread (block_dim 1, Warp's rule on the CPU), so a tile op is a loop over the
// tile's elements and no op waits for other threads.
//
// Every access of an array element from a tile op goes through tile_slot, the one check:
// an element outside the array (or an array without data) is not touched; loads read it as
// zero, stores and atomics skip it (Warp's bounds-checked tile loads and stores).
#pragma once

// Included at the end of codegen_support.h.
#include "codegen_support.h"

namespace wp {

template <typename T, int D0, int D1, int D2, int D3>
struct tile_t {
  static constexpr int NDIM = D1 == 0 ? 1 : (D2 == 0 ? 2 : (D3 == 0 ? 3 : 4));
  static constexpr int E0 = D0, E1 = D1 ? D1 : 1, E2 = D2 ? D2 : 1, E3 = D3 ? D3 : 1;
  static constexpr int SIZE = E0 * E1 * E2 * E3;
  using value_type = T;
  T data[SIZE];
  // Extent of dimension d (1 past ndim).
  static WP_FUNC constexpr int extent(int d) { return d == 0 ? E0 : d == 1 ? E1 : d == 2 ? E2 : E3; }
  // The coordinates of flat element k (row-major).
  static WP_FUNC void coord(int k, int64 (&c)[4]) {
    c[3] = k % E3; k /= E3;
    c[2] = k % E2; k /= E2;
    c[1] = k % E1; k /= E1;
    c[0] = k;
  }
};

#define WP_TILE_TEMPLATE template <typename T, int D0, int D1, int D2, int D3>
#define WP_TILE tile_t<T, D0, D1, D2, D3>

// Atomic accumulation of a gradient element: fieldwise for structs (their cg_atomic_accum is
// generated with each struct and found at instantiation), atomic_add_ptr otherwise.
template <typename T> WP_FUNC void cg_atomic_accum(T* p, const T& v) { atomic_add_ptr(p, v); }
// tile_atomic_add of one element: the old value. Structs (no atomic add of their own) add the
// fields Warp accumulates ([u]int32, [u]int64 and float scalars and composites, nested structs:
// the generated struct_atomic_add) atomically one by one and give the value read before.
template <typename T>
WP_FUNC auto tile_atomic_add_elem(T* p, const T& v, int) -> decltype(add(*p, v), atomic_add_ptr(p, v)) {
  return atomic_add_ptr(p, v);
}
template <typename T> WP_FUNC T tile_atomic_add_elem(T* p, const T& v, long) {
  const T old = *p;
  struct_atomic_add(p, v);
  return old;
}

// a + b of two tile elements: numbers add, structs field by field (the generated struct_add).
template <typename T> WP_FUNC auto tile_value_add(const T& a, const T& b, int) -> decltype(struct_add(a, b)) {
  return struct_add(a, b);
}
template <typename T> WP_FUNC T tile_value_add(const T& a, const T& b, long) { return add(a, b); }

// A subscript's integer index as NumPy reads it: a negative one counts from the end (what is
// still outside the extent stays so, and the op using it reports it).
WP_FUNC int64 tile_wrap_index(int64 i, int64 extent) { return i < 0 ? i + extent : i; }

// The one check of a tile op's array access: the element of `a` at at[0..ndim), or nullptr
// when `a` has no data, another number of dimensions, or the element lies outside its shape.
template <typename T>
WP_FUNC T* tile_slot(const array_t<T>& a, int ndim, const int64 (&at)[4]) {
  if (!a.data || a.ndim != ndim) return nullptr;
  char* p = (char*)a.data;
  for (int d = 0; d < ndim; ++d) {
    if (!in_range(at[d], a.shape[d])) return nullptr;
    p += at[d] * a.strides[d];
  }
  return (T*)p;
}

// The array position of tile element k placed at `off`.
// (Sums wrap in uint64: an offset near the int64 limit lands outside the array, never UB.)
WP_TILE_TEMPLATE WP_FUNC void tile_position(int k, const int64 (&off)[4], int64 (&at)[4]) {
  WP_TILE::coord(k, at);
  for (int d = 0; d < 4; ++d) at[d] = (int64)((uint64)at[d] + (uint64)off[d]);
}

// ---- loads, stores and atomic adds: forms for 1 to 4 offsets -------------------------------

WP_TILE_TEMPLATE WP_FUNC WP_TILE tile_load_at(const array_t<T>& a, const int64 (&off)[4]) {
  WP_TILE r;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_position<T, D0, D1, D2, D3>(k, off, at);
    const T* p = tile_slot(a, WP_TILE::NDIM, at);
    r.data[k] = p ? *p : cg_zeros<T>();
  }
  return r;
}
// adj_a[off + c] += adj_ret[c] (the gradient array; nothing without one).
WP_TILE_TEMPLATE WP_FUNC void tile_scatter_add_at(const array_t<T>& adj_a, const int64 (&off)[4], const WP_TILE& t) {
  if (!adj_a.data) return;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_position<T, D0, D1, D2, D3>(k, off, at);
    if (T* p = tile_slot(adj_a, WP_TILE::NDIM, at)) cg_atomic_accum(p, t.data[k]);
  }
}
WP_TILE_TEMPLATE WP_FUNC void tile_store_at(const array_t<T>& a, const int64 (&off)[4], const WP_TILE& t) {
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_position<T, D0, D1, D2, D3>(k, off, at);
    if (T* p = tile_slot(a, WP_TILE::NDIM, at)) *p = t.data[k];
  }
}
WP_TILE_TEMPLATE WP_FUNC WP_TILE tile_atomic_add_at(const array_t<T>& a, const int64 (&off)[4], const WP_TILE& t) {
  WP_TILE old;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_position<T, D0, D1, D2, D3>(k, off, at);
    T* p = tile_slot(a, WP_TILE::NDIM, at);
    old.data[k] = p ? tile_atomic_add_elem(p, t.data[k], 0) : cg_zeros<T>();
  }
  return old;
}
// adj_t[c] += adj_a[off + c] (the adjoint of a store or an atomic add of t).
WP_TILE_TEMPLATE WP_FUNC void tile_gather_add_at(const array_t<T>& adj_a, const int64 (&off)[4], WP_TILE& adj_t) {
  if (!adj_a.data) return;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_position<T, D0, D1, D2, D3>(k, off, at);
    if (const T* p = tile_slot(adj_a, WP_TILE::NDIM, at)) cg_accum(adj_t.data[k], *p);
  }
}

// The rows' forms: `like` (a tile of the result's type, never read) comes first, then the
// array and its offsets (as many as the tile has dimensions).
#define WP_TILE_IO_FORMS(OFFSET_PARAMS, ADJ_OFFSET_PARAMS, OFFSETS)                                                  \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC WP_TILE tile_load(const WP_TILE&, const array_t<T>& a, OFFSET_PARAMS) {                                   \
    const int64 off[4] = OFFSETS;                                                                                   \
    return tile_load_at<T, D0, D1, D2, D3>(a, off);                                                                 \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC void adj_tile_load(const WP_TILE&, const array_t<T>&, OFFSET_PARAMS, WP_TILE&, const array_t<T>& adj_a,  \
                             ADJ_OFFSET_PARAMS, const WP_TILE& adj_ret) {                                           \
    const int64 off[4] = OFFSETS;                                                                                   \
    tile_scatter_add_at(adj_a, off, adj_ret);                                                                       \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC void tile_store(const array_t<T>& a, OFFSET_PARAMS, const WP_TILE& t) {                                   \
    const int64 off[4] = OFFSETS;                                                                                   \
    tile_store_at(a, off, t);                                                                                       \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC void adj_tile_store(const array_t<T>&, OFFSET_PARAMS, const WP_TILE&, const array_t<T>& adj_a,           \
                              ADJ_OFFSET_PARAMS, WP_TILE& adj_t) {                                                  \
    const int64 off[4] = OFFSETS;                                                                                   \
    tile_gather_add_at(adj_a, off, adj_t);                                                                          \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC WP_TILE tile_atomic_add(const array_t<T>& a, OFFSET_PARAMS, const WP_TILE& t) {                           \
    const int64 off[4] = OFFSETS;                                                                                   \
    return tile_atomic_add_at(a, off, t);                                                                           \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC void adj_tile_atomic_add(const array_t<T>&, OFFSET_PARAMS, const WP_TILE&, const array_t<T>& adj_a,      \
                                   ADJ_OFFSET_PARAMS, WP_TILE& adj_t, const WP_TILE&) {                             \
    const int64 off[4] = OFFSETS;                                                                                   \
    tile_gather_add_at(adj_a, off, adj_t);                                                                          \
  }

#define WP_COMMA ,
WP_TILE_IO_FORMS(I i0, I&, {int64(i0) WP_COMMA 0 WP_COMMA 0 WP_COMMA 0})
WP_TILE_IO_FORMS(I i0 WP_COMMA I i1, I& WP_COMMA I&, {int64(i0) WP_COMMA int64(i1) WP_COMMA 0 WP_COMMA 0})
WP_TILE_IO_FORMS(I i0 WP_COMMA I i1 WP_COMMA I i2, I& WP_COMMA I& WP_COMMA I&,
                 {int64(i0) WP_COMMA int64(i1) WP_COMMA int64(i2) WP_COMMA 0})
WP_TILE_IO_FORMS(I i0 WP_COMMA I i1 WP_COMMA I i2 WP_COMMA I i3, I& WP_COMMA I& WP_COMMA I& WP_COMMA I&,
                 {int64(i0) WP_COMMA int64(i1) WP_COMMA int64(i2) WP_COMMA int64(i3)})
#undef WP_COMMA
#undef WP_TILE_IO_FORMS

// ---- construction -------------------------------------------------------------------------

template <typename R, typename V> WP_FUNC R tile_full(V value) {
  R r;
  for (int k = 0; k < R::SIZE; ++k) r.data[k] = value;
  return r;
}
// start, start + step, ... (R's element type), as many as R has elements.
template <typename R, typename V> WP_FUNC R tile_arange(V start, V step) {
  R r;
  for (int k = 0; k < R::SIZE; ++k) r.data[k] = start + V(k) * step;
  return r;
}
// wp.tile(x) of one thread: a tile of shape (1,) holding x; untile: its element.
template <typename T> WP_FUNC tile_t<T, 1, 0, 0, 0> tile(T x) {
  tile_t<T, 1, 0, 0, 0> r;
  r.data[0] = x;
  return r;
}
template <typename T> WP_FUNC void adj_tile(T, T& adj_x, const tile_t<T, 1, 0, 0, 0>& adj_ret) { cg_accum(adj_x, adj_ret.data[0]); }
template <typename T> WP_FUNC T untile(const tile_t<T, 1, 0, 0, 0>& t) { return t.data[0]; }
template <typename T> WP_FUNC void adj_untile(const tile_t<T, 1, 0, 0, 0>&, tile_t<T, 1, 0, 0, 0>& adj_t, T adj_ret) {
  cg_accum(adj_t.data[0], adj_ret);
}

// With lanes (engine/native/lanes.h) wp.tile(x) is a tile of the block's lanes, lane l's x at
// element l (zero for lanes that do not run); untile gives each lane its element, and its
// adjoint gathers every lane's. `like` carries the shape (B,) (or (n, B), (rows, cols, B)).
template <typename T, int B>
WP_FUNC tile_t<T, B, 0, 0, 0> tile_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, B, 0, 0, 0>&, T x) {
  tile_t<T, B, 0, 0, 0> r = cg_zeros<tile_t<T, B, 0, 0, 0>>();
  lane_block_t* b = lanes_of(ctx);
  if (!b) {
    r.data[0] = x;
    return r;
  }
  const T* all = lane_share(b, x);
  for (int l = 0; all && l < B; ++l)
    if (lane_running(b, l)) r.data[l] = all[l];
  b->sync(b);
  return r;
}
template <typename T, int B>
WP_FUNC void adj_tile_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, B, 0, 0, 0>&, T,
                            tile_t<T, B, 0, 0, 0>&, T& adj_x, const tile_t<T, B, 0, 0, 0>& adj_ret) {
  const int l = lane_index(ctx);
  if (l < B) cg_accum(adj_x, adj_ret.data[l]);
}
// The components of a vector or matrix, in row-major order.
template <unsigned N, typename T> WP_FUNC const T* lane_components(const vec_t<N, T>& v) { return v.c; }
template <unsigned R, unsigned C, typename T> WP_FUNC const T* lane_components(const mat_t<R, C, T>& m) { return &m.data[0][0]; }
// Component c of lane l's value at (c, l): vectors (n, B), matrices (rows, cols, B).
template <typename T, int N, int B, typename V>
WP_FUNC tile_t<T, N, B, 0, 0> tile_split_lanes_of(const launch_context_t* ctx, const V& v) {
  tile_t<T, N, B, 0, 0> r = cg_zeros<tile_t<T, N, B, 0, 0>>();
  lane_block_t* b = lanes_of(ctx);
  if (!b) {
    for (int c = 0; c < N; ++c) r.data[c * B] = lane_components(v)[c];
    return r;
  }
  const V* all = lane_share(b, v);
  for (int l = 0; all && l < B; ++l)
    if (lane_running(b, l))
      for (int c = 0; c < N; ++c) r.data[c * B + l] = lane_components(all[l])[c];
  b->sync(b);
  return r;
}
template <unsigned N, typename T, int B>
WP_FUNC tile_t<T, (int)N, B, 0, 0> tile_split_lanes(const launch_context_t* ctx, int32, int32,
                                                    const tile_t<T, (int)N, B, 0, 0>&, const vec_t<N, T>& v) {
  return tile_split_lanes_of<T, (int)N, B>(ctx, v);
}
template <unsigned R, unsigned C, typename T, int B>
WP_FUNC tile_t<T, (int)R, (int)C, B, 0> tile_split_lanes(const launch_context_t* ctx, int32, int32,
                                                         const tile_t<T, (int)R, (int)C, B, 0>&, const mat_t<R, C, T>& m) {
  const tile_t<T, (int)(R * C), B, 0, 0> flat = tile_split_lanes_of<T, (int)(R * C), B>(ctx, m);
  tile_t<T, (int)R, (int)C, B, 0> r;
  for (int k = 0; k < (int)(R * C) * B; ++k) r.data[k] = flat.data[k];
  return r;
}
template <unsigned N, typename T, int B>
WP_FUNC void adj_tile_split_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, (int)N, B, 0, 0>&,
                                  const vec_t<N, T>&, tile_t<T, (int)N, B, 0, 0>&, vec_t<N, T>& adj_v,
                                  const tile_t<T, (int)N, B, 0, 0>& adj_ret) {
  const int l = lane_index(ctx);
  for (unsigned c = 0; l < B && c < N; ++c) cg_accum(adj_v.c[c], adj_ret.data[c * B + l]);
}
template <unsigned R, unsigned C, typename T, int B>
WP_FUNC void adj_tile_split_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, (int)R, (int)C, B, 0>&,
                                  const mat_t<R, C, T>&, tile_t<T, (int)R, (int)C, B, 0>&, mat_t<R, C, T>& adj_m,
                                  const tile_t<T, (int)R, (int)C, B, 0>& adj_ret) {
  const int l = lane_index(ctx);
  for (unsigned i = 0; l < B && i < R; ++i)
    for (unsigned j = 0; j < C; ++j) cg_accum(adj_m.data[i][j], adj_ret.data[(i * C + j) * B + l]);
}
// untile with lanes: lane l's element (column l of a vector's or matrix's tile).
template <typename T, int B> WP_FUNC T untile_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, B, 0, 0, 0>& t) {
  const int l = lane_index(ctx);
  return l < B ? t.data[l] : cg_zeros<T>();
}
template <typename T, int B>
WP_FUNC void adj_untile_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, B, 0, 0, 0>&,
                              tile_t<T, B, 0, 0, 0>& adj_t, const T& adj_ret) {
  lane_block_t* b = lanes_of(ctx);
  if (!b) {
    cg_accum(adj_t.data[0], adj_ret);
    return;
  }
  const T* all = lane_share(b, adj_ret);
  for (int l = 0; all && l < B; ++l)
    if (lane_running(b, l)) cg_accum(adj_t.data[l], all[l]);
  b->sync(b);
}
template <typename T, int N, int B>
WP_FUNC vec_t<(unsigned)N, T> untile_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, N, B, 0, 0>& t) {
  const int l = lane_index(ctx);
  vec_t<(unsigned)N, T> v;
  for (int c = 0; c < N; ++c) v.c[c] = l < B ? t.data[c * B + l] : T(0);
  return v;
}
template <typename T, int N, int B>
WP_FUNC void adj_untile_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, N, B, 0, 0>&,
                              tile_t<T, N, B, 0, 0>& adj_t, const vec_t<(unsigned)N, T>& adj_ret) {
  lane_block_t* b = lanes_of(ctx);
  if (!b) {
    for (int c = 0; c < N; ++c) cg_accum(adj_t.data[c * B], adj_ret.c[c]);
    return;
  }
  const vec_t<(unsigned)N, T>* all = lane_share(b, adj_ret);
  for (int l = 0; all && l < B; ++l)
    if (lane_running(b, l))
      for (int c = 0; c < N; ++c) cg_accum(adj_t.data[c * B + l], all[l].c[c]);
  b->sync(b);
}
template <typename T, int R, int C, int B>
WP_FUNC mat_t<(unsigned)R, (unsigned)C, T> untile_lanes(const launch_context_t* ctx, int32, int32,
                                                        const tile_t<T, R, C, B, 0>& t) {
  const int l = lane_index(ctx);
  mat_t<(unsigned)R, (unsigned)C, T> m;
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) m.data[i][j] = l < B ? t.data[(i * C + j) * B + l] : T(0);
  return m;
}
template <typename T, int R, int C, int B>
WP_FUNC void adj_untile_lanes(const launch_context_t* ctx, int32, int32, const tile_t<T, R, C, B, 0>&,
                              tile_t<T, R, C, B, 0>& adj_t, const mat_t<(unsigned)R, (unsigned)C, T>& adj_ret) {
  lane_block_t* b = lanes_of(ctx);
  if (!b) {
    for (int i = 0; i < R; ++i)
      for (int j = 0; j < C; ++j) cg_accum(adj_t.data[(i * C + j) * B], adj_ret.data[i][j]);
    return;
  }
  const mat_t<(unsigned)R, (unsigned)C, T>* all = lane_share(b, adj_ret);
  for (int l = 0; all && l < B; ++l)
    if (lane_running(b, l))
      for (int i = 0; i < R; ++i)
        for (int j = 0; j < C; ++j) cg_accum(adj_t.data[(i * C + j) * B + l], all[l].data[i][j]);
  b->sync(b);
}

// wp.tile_from_thread(shape, value, thread_idx) with lanes: every element lane thread_idx's value
// (zero when that lane does not run).
template <typename R, typename T>
WP_FUNC R tile_from_lane(const launch_context_t* ctx, int32, int32, const T& v, int32 from) {
  T x = v;
  if (lane_block_t* b = lanes_of(ctx)) {
    const T* all = lane_share(b, v);
    x = all && lane_running(b, from) ? all[from] : cg_zeros<T>();
    b->sync(b);
  }
  return tile_full<R>(x);
}

// wp.tile(v) of a vector or matrix on one thread: its components as a tile of shape (n, 1) or
// (rows, cols, 1) (the last extent is the block's one thread); untile reverses it.
template <unsigned N, typename T> WP_FUNC tile_t<T, (int)N, 1, 0, 0> tile_split(const vec_t<N, T>& v) {
  tile_t<T, (int)N, 1, 0, 0> r;
  for (unsigned i = 0; i < N; ++i) r.data[i] = v.c[i];
  return r;
}
template <unsigned N, typename T>
WP_FUNC void adj_tile_split(const vec_t<N, T>&, vec_t<N, T>& adj_v, const tile_t<T, (int)N, 1, 0, 0>& adj_ret) {
  for (unsigned i = 0; i < N; ++i) cg_accum(adj_v.c[i], adj_ret.data[i]);
}
template <unsigned R, unsigned C, typename T> WP_FUNC tile_t<T, (int)R, (int)C, 1, 0> tile_split(const mat_t<R, C, T>& m) {
  tile_t<T, (int)R, (int)C, 1, 0> r;
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) r.data[i * C + j] = m.data[i][j];
  return r;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_tile_split(const mat_t<R, C, T>&, mat_t<R, C, T>& adj_m, const tile_t<T, (int)R, (int)C, 1, 0>& adj_ret) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) cg_accum(adj_m.data[i][j], adj_ret.data[i * C + j]);
}
template <typename T, int N> WP_FUNC vec_t<(unsigned)N, T> untile(const tile_t<T, N, 1, 0, 0>& t) {
  vec_t<(unsigned)N, T> v;
  for (int i = 0; i < N; ++i) v.c[i] = t.data[i];
  return v;
}
template <typename T, int N>
WP_FUNC void adj_untile(const tile_t<T, N, 1, 0, 0>&, tile_t<T, N, 1, 0, 0>& adj_t, const vec_t<(unsigned)N, T>& adj_ret) {
  for (int i = 0; i < N; ++i) cg_accum(adj_t.data[i], adj_ret.c[i]);
}
template <typename T, int R, int C> WP_FUNC mat_t<(unsigned)R, (unsigned)C, T> untile(const tile_t<T, R, C, 1, 0>& t) {
  mat_t<(unsigned)R, (unsigned)C, T> m;
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) m.data[i][j] = t.data[i * C + j];
  return m;
}
template <typename T, int R, int C>
WP_FUNC void adj_untile(const tile_t<T, R, C, 1, 0>&, tile_t<T, R, C, 1, 0>& adj_t,
                        const mat_t<(unsigned)R, (unsigned)C, T>& adj_ret) {
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < C; ++j) cg_accum(adj_t.data[i * C + j], adj_ret.data[i][j]);
}

// tile_randi / tile_randf, Warp's draws: lane t of a block of B lanes advances its rng + t once,
// then draws the elements t, t + B, t + 2B, ... in turn. One thread per block (lane 0 of 1):
// the state is rng advanced once and each element the next draw, in row-major order. With lanes
// every lane computes every lane's draws from their rng (shared); elements of lanes that do not
// run are zero. `rng` itself is not changed. `bounds`: none, or (min, max).
template <bool Ints, typename R, typename... B> WP_FUNC R tile_rand_lanes(const launch_context_t* ctx, uint32 rng, B... bounds) {
  R r = cg_zeros<R>();
  lane_block_t* b = lanes_of(ctx);
  const uint32* all = b ? lane_share(b, rng) : nullptr;
  const int lanes = b ? b->dim : 1;
  for (int t = 0; t < lanes; ++t) {
    if (b && (!all || !lane_running(b, t))) continue;
    uint32 s = rand_pcg((b ? all[t] : rng) + uint32(t));
    for (int k = t; k < R::SIZE; k += lanes) {
      if constexpr (Ints) r.data[k] = randi(s, bounds...);
      else r.data[k] = randf(s, bounds...);
    }
  }
  if (b) b->sync(b);
  return r;
}
template <typename R, typename... B> WP_FUNC R tile_randi(const launch_context_t* ctx, int32, int32, uint32 rng, B... bounds) {
  return tile_rand_lanes<true, R>(ctx, rng, bounds...);
}
template <typename R, typename... B> WP_FUNC R tile_randf(const launch_context_t* ctx, int32, int32, uint32 rng, B... bounds) {
  return tile_rand_lanes<false, R>(ctx, rng, bounds...);
}

// ---- element access -------------------------------------------------------------------------

// Flat position of (i, j, k, l) in t, or -1 (and a launch error at the call's line) outside it.
WP_TILE_TEMPLATE WP_FUNC int tile_flat(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE&, int n,
                                       int64 i, int64 j, int64 k, int64 l) {
  const int64 c[4] = {i, j, k, l};
  int64 flat = 0;
  for (int d = 0; d < 4; ++d) {
    const int64 e = WP_TILE::extent(d);
    const int64 v = d < n ? c[d] : 0;
    if (!in_range(v, e) || (d >= n && d < WP_TILE::NDIM)) {
      int64 shape[4] = {WP_TILE::extent(0), WP_TILE::extent(1), WP_TILE::extent(2), WP_TILE::extent(3)};
      report_error(ctx, LAUNCH_BAD_VALUE, fid, line, -1, n, c, shape, "tile index out of range");
      return -1;
    }
    flat = flat * e + v;
  }
  return (int)flat;
}
// With lanes: every running lane's (element f, value v) applied to r in lane order as op(r[f], v)
// (f < 0: none); returns false without lanes. t[i] = v, t[i] op= v and scatters of the lanes
// of a block so update every lane's tile alike.
template <typename R, typename T, typename Op> WP_FUNC bool tile_lanes_apply(const launch_context_t* ctx, R& r, int f, const T& v, Op op) {
  lane_block_t* b = lanes_of(ctx);
  if (!b) return false;
  struct update_t {
    int32 f;
    T v;
  };
  const update_t* all = lane_share(b, update_t{f, v});
  for (int32 l = 0; all && l < b->count; ++l)
    if (lane_running(b, l) && all[l].f >= 0 && all[l].f < R::SIZE) op(r.data[all[l].f], all[l].v);
  b->sync(b);
  return true;
}
template <typename T> struct tile_assign_op {
  WP_FUNC void operator()(T& a, const T& v) const { a = v; }
};
template <typename T> struct tile_accum_op {
  WP_FUNC void operator()(T& a, const T& v) const { cg_accum(a, v); }
};
template <typename T> struct tile_add_op {
  WP_FUNC void operator()(T& a, const T& v) const { a = tile_value_add(a, v, 0); }
};
template <typename T> struct tile_bit_and_op {
  WP_FUNC void operator()(T& a, const T& v) const { a = bit_and(a, v); }
};
template <typename T> struct tile_bit_or_op {
  WP_FUNC void operator()(T& a, const T& v) const { a = bit_or(a, v); }
};
template <typename T> struct tile_bit_xor_op {
  WP_FUNC void operator()(T& a, const T& v) const { a = bit_xor(a, v); }
};

#define WP_TILE_EXTRACT_FORMS(PARAMS, ADJ_PARAMS, N, IDX)                                                             \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC T tile_extract(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t, PARAMS) {            \
    const int f = tile_flat(ctx, fid, line, t, N, IDX);                                                              \
    return f < 0 ? cg_zeros<T>() : t.data[f];                                                                        \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC void adj_tile_extract(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t, PARAMS,       \
                                WP_TILE& adj_t, ADJ_PARAMS, const T& adj_ret) {                                     \
    const int f = tile_flat(ctx, fid, line, t, N, IDX); /* lanes: every lane's read adds its adjoint */             \
    if (!tile_lanes_apply(ctx, adj_t, f, adj_ret, tile_accum_op<T>()) && f >= 0) cg_accum(adj_t.data[f], adj_ret);  \
  }
// Expands FORMS(params, adjoint params, count, the 4 indices) for 1 to 4 element indices.
#define WP_COMMA ,
#define WP_TILE_FOR_EACH_INDEX_COUNT(FORMS)                                                                            \
  FORMS(I i, I&, 1, i WP_COMMA 0 WP_COMMA 0 WP_COMMA 0)                                                              \
  FORMS(I i WP_COMMA I j, I& WP_COMMA I&, 2, i WP_COMMA j WP_COMMA 0 WP_COMMA 0)                                     \
  FORMS(I i WP_COMMA I j WP_COMMA I k, I& WP_COMMA I& WP_COMMA I&, 3, i WP_COMMA j WP_COMMA k WP_COMMA 0)            \
  FORMS(I i WP_COMMA I j WP_COMMA I k WP_COMMA I l, I& WP_COMMA I& WP_COMMA I& WP_COMMA I&, 4,                      \
        i WP_COMMA j WP_COMMA k WP_COMMA l)
WP_TILE_FOR_EACH_INDEX_COUNT(WP_TILE_EXTRACT_FORMS)
#undef WP_TILE_EXTRACT_FORMS

// ---- reductions -----------------------------------------------------------------------------

// Struct arithmetic (the struct_add / struct_sub / struct_neg generated with each @wp.struct,
// found at instantiation): the adjoints pass the result's gradient to both operands.
template <typename S> WP_FUNC void adj_struct_add(const S&, const S&, S& adj_a, S& adj_b, const S& adj_ret) {
  cg_accum(adj_a, adj_ret);
  cg_accum(adj_b, adj_ret);
}
template <typename S> WP_FUNC void adj_struct_sub(const S&, const S&, S& adj_a, S& adj_b, const S& adj_ret) {
  cg_accum(adj_a, adj_ret);
  cg_accum(adj_b, struct_neg(adj_ret));
}
template <typename S> WP_FUNC void adj_struct_neg(const S&, S& adj_a, const S& adj_ret) {
  cg_accum(adj_a, struct_neg(adj_ret));
}
// The sum of a tile's elements: of numbers from zero; of structs field by field from the first
// element (Warp: the fields that do not accumulate keep a value of the tile).
template <typename T> WP_FUNC auto tile_sum_elements(const T* data, int n, int) -> decltype(struct_add(*data, *data)) {
  T s = data[0];
  for (int k = 1; k < n; ++k) s = tile_value_add(s, data[k], 0);
  return s;
}
template <typename T> WP_FUNC T tile_sum_elements(const T* data, int n, long) {
  T s = cg_zeros<T>();
  for (int k = 0; k < n; ++k) cg_accum(s, data[k]);
  return s;
}
WP_TILE_TEMPLATE WP_FUNC tile_t<T, 1, 0, 0, 0> tile_sum(const WP_TILE& a) {
  tile_t<T, 1, 0, 0, 0> r;
  r.data[0] = tile_sum_elements(a.data, WP_TILE::SIZE, 0);
  return r;
}
WP_TILE_TEMPLATE WP_FUNC void adj_tile_sum(const WP_TILE&, WP_TILE& adj_a, const tile_t<T, 1, 0, 0, 0>& adj_ret) {
  for (int k = 0; k < WP_TILE::SIZE; ++k) cg_accum(adj_a.data[k], adj_ret.data[0]);
}
// Position of the largest (smallest) element, the first one among equals.
WP_TILE_TEMPLATE WP_FUNC int tile_arg_extreme(const WP_TILE& a, bool largest) {
  int best = 0;
  for (int k = 1; k < WP_TILE::SIZE; ++k)
    if (largest ? a.data[k] > a.data[best] : a.data[k] < a.data[best]) best = k;
  return best;
}
WP_TILE_TEMPLATE WP_FUNC tile_t<T, 1, 0, 0, 0> tile_max(const WP_TILE& a) {
  tile_t<T, 1, 0, 0, 0> r;
  r.data[0] = a.data[tile_arg_extreme(a, true)];
  return r;
}
WP_TILE_TEMPLATE WP_FUNC tile_t<T, 1, 0, 0, 0> tile_min(const WP_TILE& a) {
  tile_t<T, 1, 0, 0, 0> r;
  r.data[0] = a.data[tile_arg_extreme(a, false)];
  return r;
}
WP_TILE_TEMPLATE WP_FUNC void adj_tile_max(const WP_TILE& a, WP_TILE& adj_a, const tile_t<T, 1, 0, 0, 0>& adj_ret) {
  const int k = tile_arg_extreme(a, true);
  cg_accum(adj_a.data[k], adj_ret.data[0]);
}
WP_TILE_TEMPLATE WP_FUNC void adj_tile_min(const WP_TILE& a, WP_TILE& adj_a, const tile_t<T, 1, 0, 0, 0>& adj_ret) {
  const int k = tile_arg_extreme(a, false);
  cg_accum(adj_a.data[k], adj_ret.data[0]);
}
WP_TILE_TEMPLATE WP_FUNC tile_t<int32, 1, 0, 0, 0> tile_argmax(const WP_TILE& a) {
  tile_t<int32, 1, 0, 0, 0> r;
  r.data[0] = tile_arg_extreme(a, true);
  return r;
}
WP_TILE_TEMPLATE WP_FUNC tile_t<int32, 1, 0, 0, 0> tile_argmin(const WP_TILE& a) {
  tile_t<int32, 1, 0, 0, 0> r;
  r.data[0] = tile_arg_extreme(a, false);
  return r;
}

// ---- shape ----------------------------------------------------------------------------------

template <typename T, int M, int N> WP_FUNC tile_t<T, N, M, 0, 0> tile_transpose(const tile_t<T, M, N, 0, 0>& a) {
  tile_t<T, N, M, 0, 0> r;
  for (int i = 0; i < M; ++i)
    for (int j = 0; j < N; ++j) r.data[j * M + i] = a.data[i * N + j];
  return r;
}
template <typename T, int M, int N>
WP_FUNC void adj_tile_transpose(const tile_t<T, M, N, 0, 0>&, tile_t<T, M, N, 0, 0>& adj_a, const tile_t<T, N, M, 0, 0>& adj_ret) {
  for (int i = 0; i < M; ++i)
    for (int j = 0; j < N; ++j) cg_accum(adj_a.data[i * N + j], adj_ret.data[j * M + i]);
}

// Broadcast a to R's shape (numpy rules, trailing dimensions aligned; the compiler checked
// that every extent of a is 1 or R's).
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC int tile_broadcast_source(int k) {
  int64 c[4];
  R::coord(k, c);
  const int shift = R::NDIM - WP_TILE::NDIM;
  int64 flat = 0;
  for (int d = 0; d < WP_TILE::NDIM; ++d) {
    const int e = WP_TILE::extent(d);
    flat = flat * e + (e == 1 ? 0 : c[d + shift]);
  }
  return (int)flat;
}
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC R tile_broadcast(const R&, const WP_TILE& a) {
  R r;
  for (int k = 0; k < R::SIZE; ++k) r.data[k] = a.data[tile_broadcast_source<R, T, D0, D1, D2, D3>(k)];
  return r;
}
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_broadcast(const R&, const WP_TILE&, R&, WP_TILE& adj_a, const R& adj_ret) {
  for (int k = 0; k < R::SIZE; ++k) {
    const int s = tile_broadcast_source<R, T, D0, D1, D2, D3>(k);
    cg_accum(adj_a.data[s], adj_ret.data[k]);
  }
}

// Element type conversion (R: the same shape, another scalar type).
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC R tile_astype(const R&, const WP_TILE& a) {
  R r;
  for (int k = 0; k < R::SIZE; ++k) r.data[k] = typename R::value_type(a.data[k]);
  return r;
}
// The gradient converted back to a's element type (float elements only; integers carry none).
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_astype(const R&, const WP_TILE&, R&, WP_TILE& adj_a, const R& adj_ret) {
  if constexpr (is_float_t<T>::value)
    for (int k = 0; k < R::SIZE; ++k) cg_accum(adj_a.data[k], T(adj_ret.data[k]));
}

// ---- matrix products ------------------------------------------------------------------------

// alpha * a @ b + beta * c (c: a tile of the result's shape). With beta == 0, c is not read
// (Warp: a reused output tile may hold NaN or infinities, which 0 * c would carry).
template <typename T, int M, int K, int N>
WP_FUNC tile_t<T, M, N, 0, 0> tile_matmul_acc(const tile_t<T, M, K, 0, 0>& a, const tile_t<T, K, N, 0, 0>& b,
                                              const tile_t<T, M, N, 0, 0>& c, T alpha, T beta) {
  tile_t<T, M, N, 0, 0> r;
  const bool read_c = !(beta == T(0));
  for (int i = 0; i < M; ++i)
    for (int j = 0; j < N; ++j) {
      T s = T(0);
      for (int k = 0; k < K; ++k) s += a.data[i * K + k] * b.data[k * N + j];
      r.data[i * N + j] = read_c ? T(alpha * s + beta * c.data[i * N + j]) : T(alpha * s);
    }
  return r;
}
template <typename T, int M, int K, int N>
WP_FUNC void adj_tile_matmul_acc(const tile_t<T, M, K, 0, 0>& a, const tile_t<T, K, N, 0, 0>& b,
                                 const tile_t<T, M, N, 0, 0>& c, T alpha, T beta, tile_t<T, M, K, 0, 0>& adj_a,
                                 tile_t<T, K, N, 0, 0>& adj_b, tile_t<T, M, N, 0, 0>& adj_c, T& adj_alpha, T& adj_beta,
                                 const tile_t<T, M, N, 0, 0>& adj_ret) {
  for (int i = 0; i < M; ++i)
    for (int k = 0; k < K; ++k) {
      T s = T(0);
      for (int j = 0; j < N; ++j) s += adj_ret.data[i * N + j] * b.data[k * N + j];
      adj_a.data[i * K + k] += alpha * s;
    }
  for (int k = 0; k < K; ++k)
    for (int j = 0; j < N; ++j) {
      T s = T(0);
      for (int i = 0; i < M; ++i) s += a.data[i * K + k] * adj_ret.data[i * N + j];
      adj_b.data[k * N + j] += alpha * s;
    }
  for (int i = 0; i < M; ++i)
    for (int j = 0; j < N; ++j) {
      T s = T(0);
      for (int k = 0; k < K; ++k) s += a.data[i * K + k] * b.data[k * N + j];
      adj_alpha += s * adj_ret.data[i * N + j];
      adj_beta += c.data[i * N + j] * adj_ret.data[i * N + j];
      adj_c.data[i * N + j] += beta * adj_ret.data[i * N + j];
    }
}

// ---- print ------------------------------------------------------------------------------------

// wp.print(t) as Warp prints a tile: the elements in nested brackets (a 2-D tile's rows one per
// line, higher dimensions separated by a blank line), then " = tile(shape=(...), storage=...)";
// weft's tiles are the thread's values, so storage reads "register". The line is bounded like
// every print line (print.h): a large tile's text is cut there.
WP_TILE_TEMPLATE WP_FUNC void tile_print_level(print_line& l, const WP_TILE& t, int level, int index) {
  constexpr int N = WP_TILE::NDIM;
  int stride = 1;
  for (int d = level + 1; d < N; ++d) stride *= WP_TILE::extent(d);
  l.add("[");
  for (int i = 0; i < WP_TILE::extent(level); ++i) {
    if (level == N - 1) {
      if (i) l.add(" ");
      print_value(l, t.data[index + i]);
      continue;
    }
    if (i) {
      l.add(level == N - 2 ? "\n" : "\n\n");
      for (int k = 0; k <= level; ++k) l.add(" ");
    }
    tile_print_level(l, t, level + 1, index + i * stride);
  }
  l.add("]");
}
WP_TILE_TEMPLATE WP_FUNC void print_value(print_line& l, const WP_TILE& t) {
  tile_print_level(l, t, 0, 0);
  l.add(" = tile(shape=(");
  for (int d = 0; d < WP_TILE::NDIM; ++d) {
    if (d) l.add(",");
    l.add("%d", WP_TILE::extent(d));
  }
  l.add("), storage=register)");
}
WP_TILE_TEMPLATE WP_FUNC void print_spaced(print_line& l, const WP_TILE& t) { print_value(l, t); }

#undef WP_TILE
#undef WP_TILE_TEMPLATE

}  // namespace wp

namespace wp {

#define WP_TILE_TEMPLATE template <typename T, int D0, int D1, int D2, int D3>
#define WP_TILE tile_t<T, D0, D1, D2, D3>

// Adjoint accumulation (copies and assignments of tiles in reverse code).
WP_TILE_TEMPLATE WP_FUNC void cg_accum(WP_TILE& a, const WP_TILE& b) {
  for (int k = 0; k < WP_TILE::SIZE; ++k) cg_accum(a.data[k], b.data[k]);
}

// The same elements in row-major order under another shape (tile_reshape, tile_squeeze; the
// compiler checked that the sizes agree).
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC R tile_reshape(const R&, const WP_TILE& a) {
  static_assert(R::SIZE == WP_TILE::SIZE, "tile_reshape keeps the size");
  R r;
  for (int k = 0; k < R::SIZE; ++k) r.data[k] = a.data[k];
  return r;
}
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_reshape(const R&, const WP_TILE&, R&, WP_TILE& adj_a, const R& adj_ret) {
  for (int k = 0; k < R::SIZE; ++k) cg_accum(adj_a.data[k], adj_ret.data[k]);
}

// The sum of a[k] * b[k] as a tile of shape (1,).
WP_TILE_TEMPLATE WP_FUNC tile_t<T, 1, 0, 0, 0> tile_dot(const WP_TILE& a, const WP_TILE& b) {
  T s = cg_zeros<T>();
  for (int k = 0; k < WP_TILE::SIZE; ++k) cg_accum(s, mul(a.data[k], b.data[k]));
  tile_t<T, 1, 0, 0, 0> r;
  r.data[0] = s;
  return r;
}
WP_TILE_TEMPLATE WP_FUNC void adj_tile_dot(const WP_TILE& a, const WP_TILE& b, WP_TILE& adj_a, WP_TILE& adj_b,
                                           const tile_t<T, 1, 0, 0, 0>& adj_ret) {
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    cg_accum(adj_a.data[k], mul(b.data[k], adj_ret.data[0]));
    cg_accum(adj_b.data[k], mul(a.data[k], adj_ret.data[0]));
  }
}

// Tiles of vectors or matrices: the full contraction, sum over k of dot(a[k], b[k]) (ddot for
// matrices), a scalar tile of shape (1,).
template <unsigned N, typename S> WP_FUNC S tile_inner(const vec_t<N, S>& a, const vec_t<N, S>& b) { return dot(a, b); }
template <unsigned R, unsigned C, typename S> WP_FUNC S tile_inner(const mat_t<R, C, S>& a, const mat_t<R, C, S>& b) {
  return ddot(a, b);
}
template <unsigned N, typename S, int D0, int D1, int D2, int D3>
WP_FUNC tile_t<S, 1, 0, 0, 0> tile_dot(const tile_t<vec_t<N, S>, D0, D1, D2, D3>& a,
                                       const tile_t<vec_t<N, S>, D0, D1, D2, D3>& b) {
  tile_t<S, 1, 0, 0, 0> r;
  r.data[0] = S(0);
  for (int k = 0; k < tile_t<vec_t<N, S>, D0, D1, D2, D3>::SIZE; ++k) r.data[0] += tile_inner(a.data[k], b.data[k]);
  return r;
}
template <unsigned R, unsigned C, typename S, int D0, int D1, int D2, int D3>
WP_FUNC tile_t<S, 1, 0, 0, 0> tile_dot(const tile_t<mat_t<R, C, S>, D0, D1, D2, D3>& a,
                                       const tile_t<mat_t<R, C, S>, D0, D1, D2, D3>& b) {
  tile_t<S, 1, 0, 0, 0> r;
  r.data[0] = S(0);
  for (int k = 0; k < tile_t<mat_t<R, C, S>, D0, D1, D2, D3>::SIZE; ++k) r.data[0] += tile_inner(a.data[k], b.data[k]);
  return r;
}
template <typename E, typename S, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_dot_composite(const tile_t<E, D0, D1, D2, D3>& a, const tile_t<E, D0, D1, D2, D3>& b,
                                    tile_t<E, D0, D1, D2, D3>& adj_a, tile_t<E, D0, D1, D2, D3>& adj_b,
                                    const tile_t<S, 1, 0, 0, 0>& adj_ret) {
  for (int k = 0; k < tile_t<E, D0, D1, D2, D3>::SIZE; ++k) {
    cg_accum(adj_a.data[k], mul(b.data[k], adj_ret.data[0]));
    cg_accum(adj_b.data[k], mul(a.data[k], adj_ret.data[0]));
  }
}
template <unsigned N, typename S, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_dot(const tile_t<vec_t<N, S>, D0, D1, D2, D3>& a, const tile_t<vec_t<N, S>, D0, D1, D2, D3>& b,
                          tile_t<vec_t<N, S>, D0, D1, D2, D3>& adj_a, tile_t<vec_t<N, S>, D0, D1, D2, D3>& adj_b,
                          const tile_t<S, 1, 0, 0, 0>& adj_ret) {
  adj_tile_dot_composite(a, b, adj_a, adj_b, adj_ret);
}
template <unsigned R, unsigned C, typename S, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_dot(const tile_t<mat_t<R, C, S>, D0, D1, D2, D3>& a, const tile_t<mat_t<R, C, S>, D0, D1, D2, D3>& b,
                          tile_t<mat_t<R, C, S>, D0, D1, D2, D3>& adj_a, tile_t<mat_t<R, C, S>, D0, D1, D2, D3>& adj_b,
                          const tile_t<S, 1, 0, 0, 0>& adj_ret) {
  adj_tile_dot_composite(a, b, adj_a, adj_b, adj_ret);
}

// dest + alpha * src (wp.tile_axpy assigns it to dest); the elements may be vectors or matrices
// with a scalar alpha.
template <typename S> WP_FUNC S tile_inner(const S& a, const S& b) { return mul(a, b); }
template <typename A, typename T, int D0, int D1, int D2, int D3>
WP_FUNC WP_TILE tile_axpy(A alpha, const WP_TILE& src, const WP_TILE& dest) {
  WP_TILE r;
  for (int k = 0; k < WP_TILE::SIZE; ++k) r.data[k] = add(dest.data[k], mul(alpha, src.data[k]));
  return r;
}
template <typename A, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_axpy(A alpha, const WP_TILE& src, const WP_TILE&, A& adj_alpha, WP_TILE& adj_src,
                           WP_TILE& adj_dest, const WP_TILE& adj_ret) {
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    cg_accum(adj_alpha, tile_inner(src.data[k], adj_ret.data[k]));
    cg_accum(adj_src.data[k], mul(alpha, adj_ret.data[k]));
    cg_accum(adj_dest.data[k], adj_ret.data[k]);
  }
}

// Scans over the elements in row-major order.
enum tile_scan_kind { TILE_SCAN_SUM_INCLUSIVE, TILE_SCAN_SUM_EXCLUSIVE, TILE_SCAN_MAX, TILE_SCAN_MIN };
template <int KIND, typename T, int D0, int D1, int D2, int D3>
WP_FUNC WP_TILE tile_scan(const WP_TILE& a) {
  WP_TILE r;
  T acc = a.data[0];
  if (KIND == TILE_SCAN_SUM_EXCLUSIVE) acc = cg_zeros<T>();
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    if (KIND == TILE_SCAN_SUM_EXCLUSIVE) {
      r.data[k] = acc;
      cg_accum(acc, a.data[k]);
      continue;
    }
    if (k > 0) {
      if (KIND == TILE_SCAN_SUM_INCLUSIVE) cg_accum(acc, a.data[k]);
      // max / min skip NaN elements (fmax / fmin, Warp's rule): NaN only while every element so far is
      else if (KIND == TILE_SCAN_MAX) acc = (a.data[k] > acc || acc != acc) ? a.data[k] : acc;
      else acc = (a.data[k] < acc || acc != acc) ? a.data[k] : acc;
    }
    r.data[k] = acc;
  }
  return r;
}
WP_TILE_TEMPLATE WP_FUNC WP_TILE tile_scan_inclusive(const WP_TILE& a) { return tile_scan<TILE_SCAN_SUM_INCLUSIVE>(a); }
WP_TILE_TEMPLATE WP_FUNC WP_TILE tile_scan_exclusive(const WP_TILE& a) { return tile_scan<TILE_SCAN_SUM_EXCLUSIVE>(a); }
WP_TILE_TEMPLATE WP_FUNC WP_TILE tile_scan_max_inclusive(const WP_TILE& a) { return tile_scan<TILE_SCAN_MAX>(a); }
WP_TILE_TEMPLATE WP_FUNC WP_TILE tile_scan_min_inclusive(const WP_TILE& a) { return tile_scan<TILE_SCAN_MIN>(a); }
// adj_a[k] += the sum of adj_ret over the outputs element k reaches.
WP_TILE_TEMPLATE WP_FUNC void adj_tile_scan_inclusive(const WP_TILE&, WP_TILE& adj_a, const WP_TILE& adj_ret) {
  T acc = cg_zeros<T>();
  for (int k = WP_TILE::SIZE - 1; k >= 0; --k) {
    cg_accum(acc, adj_ret.data[k]);
    cg_accum(adj_a.data[k], acc);
  }
}
WP_TILE_TEMPLATE WP_FUNC void adj_tile_scan_exclusive(const WP_TILE&, WP_TILE& adj_a, const WP_TILE& adj_ret) {
  T acc = cg_zeros<T>();
  for (int k = WP_TILE::SIZE - 1; k >= 0; --k) {
    cg_accum(adj_a.data[k], acc);
    cg_accum(acc, adj_ret.data[k]);
  }
}

// A sub-tile: R's extents starting at o0..o3 and stepping s0..s3 (by a's dimension; tile_view,
// t[i], t[a:b, :], t[::2], t[::-1]). `dims` maps R's dimension d to a's dimension
// (dims >> 4d) & 0xf; a's other dimensions stay at their offset (an integer index drops a
// dimension).
struct tile_region_t {
  int64 o[4];
  int64 s[4];
  int32 dims;
};
// The region's parameters as builtins take them (offsets, steps, dims), and their adjoints.
#define WP_TILE_REGION_PARAMS int64 o0, int64 o1, int64 o2, int64 o3, int64 s0, int64 s1, int64 s2, int64 s3, int32 dims
#define WP_TILE_REGION_ADJ_PARAMS int64&, int64&, int64&, int64&, int64&, int64&, int64&, int64&, int32&
#define WP_TILE_REGION (tile_region_t{{o0, o1, o2, o3}, {s0, s1, s2, s3}, dims})
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC int tile_view_source(int k, const tile_region_t& g) {
  int64 c[4];
  R::coord(k, c);
  int64 src[4] = {g.o[0], g.o[1], g.o[2], g.o[3]};
  for (int d = 0; d < R::NDIM; ++d) {
    const int a = (g.dims >> (4 * d)) & 0xf;
    src[a] += c[d] * g.s[a];
  }
  int64 flat = 0;
  for (int d = 0; d < WP_TILE::NDIM; ++d) flat = flat * WP_TILE::extent(d) + src[d];
  return (int)flat;
}
// Does R placed by g lie inside a? If not, a launch error at the call's line.
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC bool tile_view_fits(const launch_context_t* ctx, int32 fid, int32 line, const tile_region_t& g) {
  int64 last[4] = {g.o[0], g.o[1], g.o[2], g.o[3]};
  bool ok = true;
  for (int d = 0; d < R::NDIM; ++d) {
    const int a = (g.dims >> (4 * d)) & 0xf;
    ok = ok && a < WP_TILE::NDIM;
    if (a < 4) last[a] += (R::extent(d) - 1) * g.s[a];
  }
  for (int d = 0; ok && d < WP_TILE::NDIM; ++d) ok = in_range(g.o[d], WP_TILE::extent(d)) && in_range(last[d], WP_TILE::extent(d));
  if (!ok) {
    const int64 shape[4] = {WP_TILE::extent(0), WP_TILE::extent(1), WP_TILE::extent(2), WP_TILE::extent(3)};
    report_error(ctx, LAUNCH_BAD_VALUE, fid, line, -1, WP_TILE::NDIM, g.o, shape, "tile view or assignment out of bounds");
  }
  return ok;
}
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC R tile_view(const launch_context_t* ctx, int32 fid, int32 line, const R&, const WP_TILE& a, WP_TILE_REGION_PARAMS) {
  const tile_region_t g = WP_TILE_REGION;
  R r;
  if (!tile_view_fits<R, T, D0, D1, D2, D3>(ctx, fid, line, g)) return cg_zeros<R>();
  for (int k = 0; k < R::SIZE; ++k) r.data[k] = a.data[tile_view_source<R, T, D0, D1, D2, D3>(k, g)];
  return r;
}
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_view(const launch_context_t* ctx, int32 fid, int32 line, const R&, const WP_TILE&, WP_TILE_REGION_PARAMS,
                           R&, WP_TILE& adj_a, WP_TILE_REGION_ADJ_PARAMS, const R& adj_ret) {
  const tile_region_t g = WP_TILE_REGION;
  if (!tile_view_fits<R, T, D0, D1, D2, D3>(ctx, fid, line, g)) return;
  for (int k = 0; k < R::SIZE; ++k) {
    const int s = tile_view_source<R, T, D0, D1, D2, D3>(k, g);
    cg_accum(adj_a.data[s], adj_ret.data[k]);
  }
}
// dst with src written where g places it (as tile_view reads a sub-tile): wp.tile_assign,
// t[i] = row, t[a:b, :] = block; the result is assigned to dst.
template <typename S, typename T, int D0, int D1, int D2, int D3>
WP_FUNC WP_TILE tile_assign(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& dst, const S& src,
                            WP_TILE_REGION_PARAMS) {
  const tile_region_t g = WP_TILE_REGION;
  WP_TILE r = dst;
  if (!tile_view_fits<S, T, D0, D1, D2, D3>(ctx, fid, line, g)) return r;
  for (int k = 0; k < S::SIZE; ++k) r.data[tile_view_source<S, T, D0, D1, D2, D3>(k, g)] = src.data[k];
  return r;
}
template <typename S, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_assign(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE&, const S&, WP_TILE_REGION_PARAMS,
                             WP_TILE& adj_dst, S& adj_src, WP_TILE_REGION_ADJ_PARAMS, const WP_TILE& adj_ret) {
  const tile_region_t g = WP_TILE_REGION;
  WP_TILE pass = adj_ret;   // positions src did not overwrite pass their adjoint to dst
  if (tile_view_fits<S, T, D0, D1, D2, D3>(ctx, fid, line, g)) {
    for (int k = 0; k < S::SIZE; ++k) {
      const int s = tile_view_source<S, T, D0, D1, D2, D3>(k, g);
      cg_accum(adj_src.data[k], adj_ret.data[s]);
      pass.data[s] = cg_zeros<T>();
    }
  }
  cg_accum(adj_dst, pass);
}

// t with element (i, j, ...) replaced by v (t[i, j] = v); an index outside t is a launch error.
#define WP_TILE_INSERT_FORMS(PARAMS, ADJ_PARAMS, N, IDX)                                                              \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC WP_TILE tile_insert(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t, PARAMS, T v) {  \
    WP_TILE r = t;                                                                                                  \
    const int f = tile_flat(ctx, fid, line, t, N, IDX);                                                              \
    if (!tile_lanes_apply(ctx, r, f, v, tile_assign_op<T>()) && f >= 0) r.data[f] = v;                              \
    return r;                                                                                                       \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC void adj_tile_insert(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t, PARAMS, T,     \
                               WP_TILE& adj_t, ADJ_PARAMS, T& adj_v, const WP_TILE& adj_ret) {                      \
    const int f = tile_flat(ctx, fid, line, t, N, IDX);                                                              \
    if (lane_block_t* b = lanes_of(ctx)) { /* lanes: no gradient passes the elements any lane wrote */             \
      bool written[WP_TILE::SIZE] = {};                                                                             \
      const int32* all = lane_share(b, (int32)f);                                                                   \
      for (int32 l = 0; all && l < b->count; ++l)                                                                   \
        if (lane_running(b, l) && all[l] >= 0 && all[l] < WP_TILE::SIZE) written[all[l]] = true;                    \
      b->sync(b);                                                                                                   \
      for (int k = 0; k < WP_TILE::SIZE; ++k)                                                                       \
        if (!written[k] && k != f) cg_accum(adj_t.data[k], adj_ret.data[k]);                                        \
    } else {                                                                                                        \
      for (int k = 0; k < WP_TILE::SIZE; ++k)                                                                       \
        if (k != f) cg_accum(adj_t.data[k], adj_ret.data[k]);                                                       \
    }                                                                                                               \
    if (f >= 0) cg_accum(adj_v, adj_ret.data[f]);                                                                 \
  }
WP_TILE_FOR_EACH_INDEX_COUNT(WP_TILE_INSERT_FORMS)
#undef WP_TILE_INSERT_FORMS

// wp.tile_scatter_add(t, i, ..., v, has_value) and wp.tile_scatter_masked(t, i, ..., v, has_value):
// the block's one thread adds v into (writes v at) element (i, ...) when has_value; the index
// is checked only then (a launch error outside t).
#define WP_TILE_SCATTER_FORMS(PARAMS, ADJ_PARAMS, N, IDX)                                                             \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC WP_TILE tile_scatter_add(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t, PARAMS,    \
                                   T v, bool has) {                                                                 \
    WP_TILE r = t;                                                                                                  \
    const int f = has ? tile_flat(ctx, fid, line, t, N, IDX) : -1;                                                  \
    if (!tile_lanes_apply(ctx, r, f, v, tile_add_op<T>()) && f >= 0) r.data[f] = tile_value_add(r.data[f], v, 0);  \
    return r;                                                                                                       \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC void adj_tile_scatter_add(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t, PARAMS,   \
                                    T, bool has, WP_TILE& adj_t, ADJ_PARAMS, T& adj_v, bool&,                       \
                                    const WP_TILE& adj_ret) {                                                       \
    const int f = has ? tile_flat(ctx, fid, line, t, N, IDX) : -1;                                                  \
    cg_accum(adj_t, adj_ret);                                                                                       \
    if (f >= 0) cg_accum(adj_v, adj_ret.data[f]);                                                                   \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC WP_TILE tile_scatter_masked(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t, PARAMS, \
                                      T v, bool has) {                                                              \
    WP_TILE r = t;                                                                                                  \
    const int f = has ? tile_flat(ctx, fid, line, t, N, IDX) : -1;                                                  \
    if (!tile_lanes_apply(ctx, r, f, v, tile_assign_op<T>()) && f >= 0) r.data[f] = v;                              \
    return r;                                                                                                       \
  }                                                                                                                 \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC void adj_tile_scatter_masked(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t,       \
                                       PARAMS, T, bool has, WP_TILE& adj_t, ADJ_PARAMS, T& adj_v, bool&,            \
                                       const WP_TILE& adj_ret) {                                                    \
    const int f = has ? tile_flat(ctx, fid, line, t, N, IDX) : -1;                                                  \
    for (int k = 0; k < WP_TILE::SIZE; ++k)                                                                         \
      if (k != f) cg_accum(adj_t.data[k], adj_ret.data[k]);                                                         \
    if (f >= 0) cg_accum(adj_v, adj_ret.data[f]);                                                                   \
  }
WP_TILE_FOR_EACH_INDEX_COUNT(WP_TILE_SCATTER_FORMS)
#undef WP_TILE_SCATTER_FORMS

// t[i, ...] &= v, |= v, ^= v in a kernel compiled with lanes: every lane's v combined into the
// element (as Warp's block-shared tiles do); one thread alone without lanes.
template <typename Op, typename R, typename T> WP_FUNC R tile_lanes_update(const launch_context_t* ctx, const R& t, int f, const T& v) {
  R r = t;
  if (!tile_lanes_apply(ctx, r, f, v, Op()) && f >= 0) Op()(r.data[f], v);
  return r;
}
// One form per index count of the operator WP_TILE_LANE_OP named WP_TILE_LANE_NAME.
#define WP_TILE_LANE_BITWISE_FORMS(PARAMS, ADJ_PARAMS, N, IDX)                                                        \
  template <typename T, int D0, int D1, int D2, int D3, typename I>                                                \
  WP_FUNC WP_TILE WP_TILE_LANE_NAME(const launch_context_t* ctx, int32 fid, int32 line, const WP_TILE& t, PARAMS,   \
                                    T v) {                                                                          \
    return tile_lanes_update<WP_TILE_LANE_OP<T>>(ctx, t, tile_flat(ctx, fid, line, t, N, IDX), v);                 \
  }
#define WP_TILE_LANE_NAME tile_lanes_bit_and
#define WP_TILE_LANE_OP tile_bit_and_op
WP_TILE_FOR_EACH_INDEX_COUNT(WP_TILE_LANE_BITWISE_FORMS)
#undef WP_TILE_LANE_NAME
#undef WP_TILE_LANE_OP
#define WP_TILE_LANE_NAME tile_lanes_bit_or
#define WP_TILE_LANE_OP tile_bit_or_op
WP_TILE_FOR_EACH_INDEX_COUNT(WP_TILE_LANE_BITWISE_FORMS)
#undef WP_TILE_LANE_NAME
#undef WP_TILE_LANE_OP
#define WP_TILE_LANE_NAME tile_lanes_bit_xor
#define WP_TILE_LANE_OP tile_bit_xor_op
WP_TILE_FOR_EACH_INDEX_COUNT(WP_TILE_LANE_BITWISE_FORMS)
#undef WP_TILE_LANE_NAME
#undef WP_TILE_LANE_OP
#undef WP_TILE_LANE_BITWISE_FORMS
#undef WP_TILE_FOR_EACH_INDEX_COUNT
#undef WP_COMMA

// ---- tile_map and tile_reduce ---------------------------------------------------------------

// Element k of a tile argument; any other argument is the same value for every element.
template <typename V> WP_FUNC const V& tile_elem(const V& v, int) { return v; }
WP_TILE_TEMPLATE WP_FUNC const T& tile_elem(const WP_TILE& t, int k) { return t.data[k]; }
template <typename V> WP_FUNC V& tile_elem_adj(V& v, int) { return v; }
WP_TILE_TEMPLATE WP_FUNC T& tile_elem_adj(WP_TILE& t, int k) { return t.data[k]; }

// f over the elements of the tile arguments (all of R's shape; the compiler checked).
template <typename R, typename F, typename... A> WP_FUNC R tile_map(F f, const A&... a) {
  R r;
  for (int k = 0; k < R::SIZE; ++k) r.data[k] = f(tile_elem(a, k)...);
  return r;
}
// An argument of a tile map's adjoint: its value and its adjoint.
template <typename V> struct tile_ref_t {
  const V& v;
  V& adj;
};
template <typename V> WP_FUNC tile_ref_t<V> tile_ref(const V& v, V& adj) { return tile_ref_t<V>{v, adj}; }
template <typename F, typename R, typename... P> WP_FUNC void adj_tile_map(F adj_f, const R& adj_ret, P... p) {
  for (int k = 0; k < R::SIZE; ++k) adj_f(tile_elem(p.v, k)..., tile_elem_adj(p.adj, k)..., adj_ret.data[k]);
}

// f(...f(f(a[0], a[1]), a[2])..., a[n-1]) as a tile of shape (1,).
template <typename F, typename T, int D0, int D1, int D2, int D3>
WP_FUNC tile_t<T, 1, 0, 0, 0> tile_reduce(F f, const WP_TILE& a) {
  T acc = a.data[0];
  for (int k = 1; k < WP_TILE::SIZE; ++k) acc = f(acc, a.data[k]);
  tile_t<T, 1, 0, 0, 0> r;
  r.data[0] = acc;
  return r;
}
// Reverse of the fold: the partial results are computed again, then each step's adjoint runs
// from the last step back.
template <typename G, typename F, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_reduce(G adj_f, F f, const WP_TILE& a, WP_TILE& adj_a, const tile_t<T, 1, 0, 0, 0>& adj_ret) {
  T acc[WP_TILE::SIZE];
  acc[0] = a.data[0];
  for (int k = 1; k < WP_TILE::SIZE; ++k) acc[k] = f(acc[k - 1], a.data[k]);
  T adj_acc = adj_ret.data[0];
  for (int k = WP_TILE::SIZE - 1; k >= 1; --k) {
    T adj_prev = cg_zeros<T>();
    adj_f(acc[k - 1], a.data[k], adj_prev, adj_a.data[k], adj_acc);
    adj_acc = adj_prev;
  }
  cg_accum(adj_a.data[0], adj_acc);
}

// Position in R (a without `axis`) of a's element k, and k's coordinate along the axis.
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC int tile_axis_target(int k, int axis, int* along) {
  int64 c[4];
  WP_TILE::coord(k, c);
  int64 flat = 0;
  for (int d = 0, o = 0; d < WP_TILE::NDIM; ++d) {
    if (d == axis) continue;
    flat = flat * R::extent(o++) + c[d];
  }
  *along = (int)c[axis];
  return (int)flat;
}
// Sum along `axis` (a constant the compiler checked): R is the tile without that dimension;
// each sum starts at the axis's first element (structs: its fields that do not accumulate stay).
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC R tile_sum_axis(const R&, const WP_TILE& a, int32 axis) {
  R r;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int j;
    const int o = tile_axis_target<R, T, D0, D1, D2, D3>(k, axis, &j);
    r.data[o] = j == 0 ? a.data[k] : tile_value_add(r.data[o], a.data[k], 0);
  }
  return r;
}
template <typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_sum_axis(const R&, const WP_TILE&, int32 axis, R&, WP_TILE& adj_a, int32&, const R& adj_ret) {
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int j;
    cg_accum(adj_a.data[k], adj_ret.data[tile_axis_target<R, T, D0, D1, D2, D3>(k, axis, &j)]);
  }
}

// tile_reduce(f, a, axis): a fold along the axis for each position of the others.
template <typename F, typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC R tile_reduce(F f, const R&, const WP_TILE& a, int32 axis) {
  R r;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int j;
    const int o = tile_axis_target<R, T, D0, D1, D2, D3>(k, axis, &j);
    r.data[o] = j == 0 ? a.data[k] : f(r.data[o], a.data[k]);
  }
  return r;
}
template <typename G, typename F, typename R, typename T, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_reduce(G adj_f, F f, const R&, const WP_TILE& a, int32 axis, R&, WP_TILE& adj_a, int32&, const R& adj_ret) {
  T before[WP_TILE::SIZE];   // the partial result each element is folded into
  R acc;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int j;
    const int o = tile_axis_target<R, T, D0, D1, D2, D3>(k, axis, &j);
    if (j == 0) {
      acc.data[o] = a.data[k];
    } else {
      before[k] = acc.data[o];
      acc.data[o] = f(acc.data[o], a.data[k]);
    }
  }
  R adj_acc = adj_ret;
  for (int k = WP_TILE::SIZE - 1; k >= 0; --k) {
    int j;
    const int o = tile_axis_target<R, T, D0, D1, D2, D3>(k, axis, &j);
    if (j == 0) {
      cg_accum(adj_a.data[k], adj_acc.data[o]);
      continue;
    }
    T adj_prev = cg_zeros<T>();
    adj_f(before[k], a.data[k], adj_prev, adj_a.data[k], adj_acc.data[o]);
    adj_acc.data[o] = adj_prev;
  }
}

// t[idx, :] with idx a 1-D tile of integers: the slices of a along `axis` that idx names, in
// its order (R: a's shape with idx's length on the axis). An index outside a is a launch error.
template <typename R, typename T, int D0, int D1, int D2, int D3, typename I, int N>
WP_FUNC int tile_gather_source(const launch_context_t* ctx, int32 fid, int32 line, int k, const tile_t<I, N, 0, 0, 0>& idx,
                               int32 axis) {
  int64 c[4];
  R::coord(k, c);
  const int64 pick = tile_wrap_index((int64)idx.data[c[axis]], WP_TILE::extent(axis));   // NumPy's negative indices
  if (!in_range(pick, WP_TILE::extent(axis))) {
    const int64 at[1] = {pick};
    const int64 shape[1] = {WP_TILE::extent(axis)};
    report_error(ctx, LAUNCH_BAD_VALUE, fid, line, -1, 1, at, shape, "tile index out of range");
    return -1;
  }
  c[axis] = pick;
  int64 flat = 0;
  for (int d = 0; d < WP_TILE::NDIM; ++d) flat = flat * WP_TILE::extent(d) + c[d];
  return (int)flat;
}
template <typename R, typename T, int D0, int D1, int D2, int D3, typename I, int N>
WP_FUNC R tile_gather(const launch_context_t* ctx, int32 fid, int32 line, const R&, const WP_TILE& a,
                      const tile_t<I, N, 0, 0, 0>& idx, int32 axis) {
  R r;
  for (int k = 0; k < R::SIZE; ++k) {
    const int s = tile_gather_source<R, T, D0, D1, D2, D3>(ctx, fid, line, k, idx, axis);
    r.data[k] = s < 0 ? cg_zeros<T>() : a.data[s];
  }
  return r;
}
template <typename R, typename T, int D0, int D1, int D2, int D3, typename I, int N>
WP_FUNC void adj_tile_gather(const launch_context_t* ctx, int32 fid, int32 line, const R&, const WP_TILE&,
                             const tile_t<I, N, 0, 0, 0>& idx, int32 axis, R&, WP_TILE& adj_a, tile_t<I, N, 0, 0, 0>&, int32&,
                             const R& adj_ret) {
  for (int k = 0; k < R::SIZE; ++k) {
    const int s = tile_gather_source<R, T, D0, D1, D2, D3>(ctx, fid, line, k, idx, axis);
    if (s >= 0) cg_accum(adj_a.data[s], adj_ret.data[k]);
  }
}

// ---- linear algebra: Cholesky factorization and triangular solves -----------------------------
// Right-hand sides are tiles of shape (n,) or (n, k) (k columns), read as n x k.
template <typename Y> struct tile_rhs {
  static constexpr int K = Y::NDIM == 1 ? 1 : Y::E1;
};
// Solves E x = b in place for each column of b (n x k), E = M or M^T (M n x n, row-major);
// `lower`: E is lower triangular (else upper).
template <typename T, int N, typename Y> WP_FUNC void tile_tri_solve(const T* m, Y& b, bool lower, bool transpose) {
  constexpr int K = tile_rhs<Y>::K;
  auto e = [&](int i, int j) { return transpose ? m[j * N + i] : m[i * N + j]; };
  for (int c = 0; c < K; ++c) {
    for (int s = 0; s < N; ++s) {
      const int i = lower ? s : N - 1 - s;
      T acc = b.data[i * K + c];
      if (lower) {
        for (int j = 0; j < i; ++j) acc -= e(i, j) * b.data[j * K + c];
      } else {
        for (int j = i + 1; j < N; ++j) acc -= e(i, j) * b.data[j * K + c];
      }
      b.data[i * K + c] = acc / e(i, i);
    }
  }
}
// A = L L^T (L lower) or, `upper`, A = U^T U (U = L^T); the other triangle zero. A matrix that
// is not positive definite gives NaN entries (a square root of a negative number).
template <typename T, int N> WP_FUNC tile_t<T, N, N, 0, 0> tile_cholesky(const tile_t<T, N, N, 0, 0>& a, bool upper) {
  tile_t<T, N, N, 0, 0> l = cg_zeros<tile_t<T, N, N, 0, 0>>();
  for (int j = 0; j < N; ++j) {
    T d = a.data[j * N + j];
    for (int k = 0; k < j; ++k) d -= l.data[j * N + k] * l.data[j * N + k];
    const T ljj = sqrt(d);
    l.data[j * N + j] = ljj;
    for (int i = j + 1; i < N; ++i) {
      T s = a.data[i * N + j];
      for (int k = 0; k < j; ++k) s -= l.data[i * N + k] * l.data[j * N + k];
      l.data[i * N + j] = s / ljj;
    }
  }
  return upper ? tile_transpose(l) : l;
}
// Warp's adjoint (lower): P = tril(L^T adj_L) with half its diagonal, S = P + P^T,
// adj_A += tril(L^-T S L^-1) with half its diagonal; upper mirrored.
template <typename T, int N>
WP_FUNC void adj_tile_cholesky(const tile_t<T, N, N, 0, 0>& a, bool upper, tile_t<T, N, N, 0, 0>& adj_a, bool&,
                               const tile_t<T, N, N, 0, 0>& adj_ret) {
  const tile_t<T, N, N, 0, 0> f = tile_cholesky(a, upper);
  // work with L (lower) and adj_L either way: U = L^T, adj_U = adj_L^T
  const tile_t<T, N, N, 0, 0> l = upper ? tile_transpose(f) : f;
  const tile_t<T, N, N, 0, 0> al = upper ? tile_transpose(adj_ret) : adj_ret;
  tile_t<T, N, N, 0, 0> s;
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      T p = T(0);
      const int r = i >= j ? i : j, c = i >= j ? j : i;   // P is lower: P(r, c)
      for (int k = 0; k < N; ++k) p += l.data[k * N + r] * al.data[k * N + c];
      if (r == c) p *= T(0.5);
      s.data[i * N + j] = (i == j) ? T(2) * p : p;
    }
  // B = L^-T S L^-1: solve L^T X = S, then L^T B = X^T
  tile_tri_solve<T, N>(l.data, s, false, true);
  tile_t<T, N, N, 0, 0> b = tile_transpose(s);
  tile_tri_solve<T, N>(l.data, b, false, true);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j <= i; ++j) {
      const T g = i == j ? T(0.5) * b.data[i * N + j] : b.data[i * N + j];
      if (upper) adj_a.data[j * N + i] += g;
      else adj_a.data[i * N + j] += g;
    }
}
// z with L z = y (L lower), and its adjoint: adj_y += L^-T adj_z, adj_L -= tril(adj_y z^T).
template <typename T, int N, typename Y> WP_FUNC Y tile_lower_solve(const tile_t<T, N, N, 0, 0>& l, const Y& y) {
  Y z = y;
  tile_tri_solve<T, N>(l.data, z, true, false);
  return z;
}
template <typename T, int N, typename Y> WP_FUNC Y tile_upper_solve(const tile_t<T, N, N, 0, 0>& u, const Y& y) {
  Y x = y;
  tile_tri_solve<T, N>(u.data, x, false, false);
  return x;
}
template <typename T, int N, typename Y>
WP_FUNC void tile_tri_solve_adjoint(const tile_t<T, N, N, 0, 0>& m, const Y& x, bool lower, tile_t<T, N, N, 0, 0>& adj_m,
                                    Y& adj_y, const Y& adj_x) {
  constexpr int K = tile_rhs<Y>::K;
  Y w = adj_x;
  tile_tri_solve<T, N>(m.data, w, !lower, true);   // M^T w = adj_x
  for (int k = 0; k < Y::SIZE; ++k) adj_y.data[k] += w.data[k];
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      if (lower ? j > i : j < i) continue;
      T g = T(0);
      for (int c = 0; c < K; ++c) g += w.data[i * K + c] * x.data[j * K + c];
      adj_m.data[i * N + j] -= g;
    }
}
template <typename T, int N, typename Y>
WP_FUNC void adj_tile_lower_solve(const tile_t<T, N, N, 0, 0>& l, const Y& y, tile_t<T, N, N, 0, 0>& adj_l, Y& adj_y,
                                  const Y& adj_z) {
  tile_tri_solve_adjoint(l, tile_lower_solve(l, y), true, adj_l, adj_y, adj_z);
}
template <typename T, int N, typename Y>
WP_FUNC void adj_tile_upper_solve(const tile_t<T, N, N, 0, 0>& u, const Y& y, tile_t<T, N, N, 0, 0>& adj_u, Y& adj_y,
                                  const Y& adj_x) {
  tile_tri_solve_adjoint(u, tile_upper_solve(u, y), false, adj_u, adj_y, adj_x);
}
// x with A x = y, A = L L^T (or U^T U): two triangular solves.
template <typename T, int N, typename Y>
WP_FUNC Y tile_cholesky_solve(const tile_t<T, N, N, 0, 0>& f, const Y& y, bool upper) {
  Y x = y;
  tile_tri_solve<T, N>(f.data, x, !upper, upper);    // L w = y (or U^T w = y)
  tile_tri_solve<T, N>(f.data, x, upper, !upper);    // L^T x = w (or U x = w)
  return x;
}
// adj_y += A^-1 adj_x; with A_bar = -adj_y x^T: adj_L += tril((A_bar + A_bar^T) L), or
// adj_U += triu(U (A_bar + A_bar^T)).
template <typename T, int N, typename Y>
WP_FUNC void adj_tile_cholesky_solve(const tile_t<T, N, N, 0, 0>& f, const Y& y, bool upper, tile_t<T, N, N, 0, 0>& adj_f,
                                     Y& adj_y, bool&, const Y& adj_x) {
  constexpr int K = tile_rhs<Y>::K;
  const Y x = tile_cholesky_solve(f, y, upper);
  const Y w = tile_cholesky_solve(f, adj_x, upper);
  for (int k = 0; k < Y::SIZE; ++k) adj_y.data[k] += w.data[k];
  tile_t<T, N, N, 0, 0> sym;   // A_bar + A_bar^T = -(w x^T + x w^T)
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      T s = T(0);
      for (int c = 0; c < K; ++c) s += w.data[i * K + c] * x.data[j * K + c] + x.data[i * K + c] * w.data[j * K + c];
      sym.data[i * N + j] = -s;
    }
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < N; ++j) {
      if (upper ? j < i : j > i) continue;
      T g = T(0);
      for (int k = 0; k < N; ++k)
        g += upper ? f.data[i * N + k] * sym.data[k * N + j] : sym.data[i * N + k] * f.data[k * N + j];
      adj_f.data[i * N + j] += g;
    }
}

// ---- FFT of complex tiles (vec2: real, imaginary) along the last dimension --------------------
// Unnormalized in both directions (cuFFT's convention, Warp's): ifft(fft(x)) = n x. A length
// that is a power of two takes the radix-2 algorithm in place, others the direct sum; twiddle
// factors are computed in float64.
template <bool INVERSE, typename S, int D0, int D1, int D2, int D3>
WP_FUNC tile_t<vec_t<2, S>, D0, D1, D2, D3> tile_dft(const tile_t<vec_t<2, S>, D0, D1, D2, D3>& a) {
  using TT = tile_t<vec_t<2, S>, D0, D1, D2, D3>;
  constexpr int N = TT::extent(TT::NDIM - 1);
  constexpr int ROWS = TT::SIZE / N;
  constexpr bool POW2 = (N & (N - 1)) == 0;
  const float64 sign = INVERSE ? 1.0 : -1.0;
  const float64 tau = 6.283185307179586476925286766559;
  TT r;
  for (int row = 0; row < ROWS; ++row) {
    const vec_t<2, S>* x = a.data + row * N;
    vec_t<2, S>* y = r.data + row * N;
    if (!POW2) {
      for (int k = 0; k < N; ++k) {
        float64 re = 0.0, im = 0.0;
        for (int j = 0; j < N; ++j) {
          const float64 ang = sign * tau * (float64)((int64)j * k % N) / N;
          const float64 c = cos(ang), s = sin(ang);
          re += (float64)x[j].c[0] * c - (float64)x[j].c[1] * s;
          im += (float64)x[j].c[0] * s + (float64)x[j].c[1] * c;
        }
        y[k].c[0] = S(re);
        y[k].c[1] = S(im);
      }
      continue;
    }
    for (int j = 0, rev = 0; j < N; ++j) {   // bit-reversed copy
      y[rev] = x[j];
      for (int bit = N >> 1; bit; bit >>= 1) {
        rev ^= bit;
        if (rev & bit) break;
      }
    }
    for (int len = 2; len <= N; len <<= 1) {
      for (int i = 0; i < N; i += len) {
        for (int j = 0; j < len / 2; ++j) {
          const float64 ang = sign * tau * j / len;
          const S c = S(cos(ang)), s = S(sin(ang));
          const vec_t<2, S> u = y[i + j], v = y[i + j + len / 2];
          const S vr = v.c[0] * c - v.c[1] * s, vi = v.c[0] * s + v.c[1] * c;
          y[i + j].c[0] = u.c[0] + vr;
          y[i + j].c[1] = u.c[1] + vi;
          y[i + j + len / 2].c[0] = u.c[0] - vr;
          y[i + j + len / 2].c[1] = u.c[1] - vi;
        }
      }
    }
  }
  return r;
}
template <typename S, int D0, int D1, int D2, int D3>
WP_FUNC tile_t<vec_t<2, S>, D0, D1, D2, D3> tile_fft(const tile_t<vec_t<2, S>, D0, D1, D2, D3>& a) {
  return tile_dft<false>(a);
}
template <typename S, int D0, int D1, int D2, int D3>
WP_FUNC tile_t<vec_t<2, S>, D0, D1, D2, D3> tile_ifft(const tile_t<vec_t<2, S>, D0, D1, D2, D3>& a) {
  return tile_dft<true>(a);
}
// The adjoint of the unnormalized transform is the unnormalized transform the other way.
template <typename S, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_fft(const tile_t<vec_t<2, S>, D0, D1, D2, D3>&, tile_t<vec_t<2, S>, D0, D1, D2, D3>& adj_a,
                          const tile_t<vec_t<2, S>, D0, D1, D2, D3>& adj_ret) {
  cg_accum(adj_a, tile_dft<true>(adj_ret));
}
template <typename S, int D0, int D1, int D2, int D3>
WP_FUNC void adj_tile_ifft(const tile_t<vec_t<2, S>, D0, D1, D2, D3>&, tile_t<vec_t<2, S>, D0, D1, D2, D3>& adj_a,
                           const tile_t<vec_t<2, S>, D0, D1, D2, D3>& adj_ret) {
  cg_accum(adj_a, tile_dft<false>(adj_ret));
}

// ---- indexed loads, stores and atomic adds ---------------------------------------------------
// Element c of the tile sits at off + c in the array, except along `axis`, where it sits at
// off[axis] + idx[c[axis]]. Elements outside the array (tile_slot) read as zero and are skipped.
template <typename T, int D0, int D1, int D2, int D3, int NI>
WP_FUNC void tile_indexed_position(int k, const tile_t<int32, NI, 0, 0, 0>& idx, int32 axis, const int64 (&off)[4],
                                   int64 (&at)[4]) {
  WP_TILE::coord(k, at);
  if (axis >= 0 && axis < 4 && at[axis] < NI) at[axis] = idx.data[at[axis]];
  for (int d = 0; d < 4; ++d) at[d] = (int64)((uint64)at[d] + (uint64)off[d]);
}
#define WP_TILE_OFF int64 o0, int64 o1, int64 o2, int64 o3
#define WP_TILE_ADJ_OFF int64&, int64&, int64&, int64&
template <typename T, int D0, int D1, int D2, int D3, int NI>
WP_FUNC WP_TILE tile_load_indexed(const WP_TILE&, const array_t<T>& a, const tile_t<int32, NI, 0, 0, 0>& idx, int32 axis,
                                  WP_TILE_OFF) {
  const int64 off[4] = {o0, o1, o2, o3};
  WP_TILE r;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_indexed_position<T, D0, D1, D2, D3>(k, idx, axis, off, at);
    const T* p = tile_slot(a, WP_TILE::NDIM, at);
    r.data[k] = p ? *p : cg_zeros<T>();
  }
  return r;
}
template <typename T, int D0, int D1, int D2, int D3, int NI>
WP_FUNC void adj_tile_load_indexed(const WP_TILE&, const array_t<T>&, const tile_t<int32, NI, 0, 0, 0>& idx, int32 axis,
                                   WP_TILE_OFF, WP_TILE&, const array_t<T>& adj_a, tile_t<int32, NI, 0, 0, 0>&, int32&,
                                   WP_TILE_ADJ_OFF, const WP_TILE& adj_ret) {
  if (!adj_a.data) return;
  const int64 off[4] = {o0, o1, o2, o3};
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_indexed_position<T, D0, D1, D2, D3>(k, idx, axis, off, at);
    if (T* p = tile_slot(adj_a, WP_TILE::NDIM, at)) cg_atomic_accum(p, adj_ret.data[k]);
  }
}
template <typename T, int D0, int D1, int D2, int D3, int NI>
WP_FUNC void tile_store_indexed(const array_t<T>& a, const tile_t<int32, NI, 0, 0, 0>& idx, const WP_TILE& t, int32 axis,
                                WP_TILE_OFF) {
  const int64 off[4] = {o0, o1, o2, o3};
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_indexed_position<T, D0, D1, D2, D3>(k, idx, axis, off, at);
    if (T* p = tile_slot(a, WP_TILE::NDIM, at)) *p = t.data[k];
  }
}
template <typename T, int D0, int D1, int D2, int D3, int NI>
WP_FUNC WP_TILE tile_atomic_add_indexed(const array_t<T>& a, const tile_t<int32, NI, 0, 0, 0>& idx, const WP_TILE& t,
                                        int32 axis, WP_TILE_OFF) {
  const int64 off[4] = {o0, o1, o2, o3};
  WP_TILE old;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_indexed_position<T, D0, D1, D2, D3>(k, idx, axis, off, at);
    T* p = tile_slot(a, WP_TILE::NDIM, at);
    old.data[k] = p ? tile_atomic_add_elem(p, t.data[k], 0) : cg_zeros<T>();
  }
  return old;
}
// Both adjoints: adj_t[c] += adj_a[position of c].
template <typename T, int D0, int D1, int D2, int D3, int NI>
WP_FUNC void tile_indexed_gather_add(const array_t<T>& adj_a, const tile_t<int32, NI, 0, 0, 0>& idx, int32 axis,
                                     const int64 (&off)[4], WP_TILE& adj_t) {
  if (!adj_a.data) return;
  for (int k = 0; k < WP_TILE::SIZE; ++k) {
    int64 at[4];
    tile_indexed_position<T, D0, D1, D2, D3>(k, idx, axis, off, at);
    if (const T* p = tile_slot(adj_a, WP_TILE::NDIM, at)) cg_accum(adj_t.data[k], *p);
  }
}
template <typename T, int D0, int D1, int D2, int D3, int NI>
WP_FUNC void adj_tile_store_indexed(const array_t<T>&, const tile_t<int32, NI, 0, 0, 0>& idx, const WP_TILE&, int32 axis,
                                    WP_TILE_OFF, const array_t<T>& adj_a, tile_t<int32, NI, 0, 0, 0>&, WP_TILE& adj_t,
                                    int32&, WP_TILE_ADJ_OFF) {
  const int64 off[4] = {o0, o1, o2, o3};
  tile_indexed_gather_add(adj_a, idx, axis, off, adj_t);
}
template <typename T, int D0, int D1, int D2, int D3, int NI>
WP_FUNC void adj_tile_atomic_add_indexed(const array_t<T>&, const tile_t<int32, NI, 0, 0, 0>& idx, const WP_TILE&,
                                         int32 axis, WP_TILE_OFF, const array_t<T>& adj_a, tile_t<int32, NI, 0, 0, 0>&,
                                         WP_TILE& adj_t, int32&, WP_TILE_ADJ_OFF, const WP_TILE&) {
  const int64 off[4] = {o0, o1, o2, o3};
  tile_indexed_gather_add(adj_a, idx, axis, off, adj_t);
}
#undef WP_TILE_OFF
#undef WP_TILE_ADJ_OFF

// tile_sort(keys, values): both sorted by key, ascending, stably (insertion into a run of
// sorted keys; tiles are small).
template <typename K, typename V, int N>
WP_FUNC void tile_sort_pairs(tile_t<K, N, 0, 0, 0>& keys, tile_t<V, N, 0, 0, 0>& values) {
  for (int i = 1; i < N; ++i) {
    const K k = keys.data[i];
    const V v = values.data[i];
    int j = i - 1;
    while (j >= 0 && k < keys.data[j]) {
      keys.data[j + 1] = keys.data[j];
      values.data[j + 1] = values.data[j];
      --j;
    }
    keys.data[j + 1] = k;
    values.data[j + 1] = v;
  }
}
// tile_sort(keys, values): both results at once (the compiler assigns them to the arguments).
template <typename K, typename V, int N>
WP_FUNC void tile_sort(const tile_t<K, N, 0, 0, 0>& keys, const tile_t<V, N, 0, 0, 0>& values, tile_t<K, N, 0, 0, 0>& sorted_keys,
                       tile_t<V, N, 0, 0, 0>& sorted_values) {
  sorted_keys = keys;
  sorted_values = values;
  tile_sort_pairs(sorted_keys, sorted_values);
}

// a with d added to its diagonal.
template <typename T, int N, int M>
WP_FUNC tile_t<T, N, M, 0, 0> tile_diag_add(const tile_t<T, N, M, 0, 0>& a, const tile_t<T, (N < M ? N : M), 0, 0, 0>& d) {
  tile_t<T, N, M, 0, 0> r = a;
  for (int i = 0; i < (N < M ? N : M); ++i) r.data[i * M + i] = add(r.data[i * M + i], d.data[i]);
  return r;
}
template <typename T, int N, int M>
WP_FUNC void adj_tile_diag_add(const tile_t<T, N, M, 0, 0>&, const tile_t<T, (N < M ? N : M), 0, 0, 0>&,
                               tile_t<T, N, M, 0, 0>& adj_a, tile_t<T, (N < M ? N : M), 0, 0, 0>& adj_d,
                               const tile_t<T, N, M, 0, 0>& adj_ret) {
  cg_accum(adj_a, adj_ret);
  for (int i = 0; i < (N < M ? N : M); ++i) cg_accum(adj_d.data[i], adj_ret.data[i * M + i]);
}

// ---- tile stacks (wp.tile_stack) -------------------------------------------------------------
// A stack of at most C values; with one thread per block a push or pop is the thread's own.
// With lanes every lane holds the block's stack: a push appends the values of the pushing
// lanes in lane order (a lane's slot: the count before the push plus its rank among them), a
// pop gives the running lanes the top values, the leader the topmost.
template <typename T, int C> struct tile_stack_t {
  T data[C];
  int32 count;
};
// The slot a push writes (-1: full, or nothing to push), and the stack after it.
template <typename T, int C>
WP_FUNC int32 tile_stack_push_slot(const launch_context_t* ctx, int32, int32, const tile_stack_t<T, C>& s, const T&,
                                   bool has_value) {
  int32 rank = 0;
  if (lane_block_t* b = lanes_of(ctx)) {
    const bool* all = lane_share(b, has_value);
    for (int32 l = 0; all && l < b->lane; ++l) rank += lane_running(b, l) && all[l];
    b->sync(b);
  }
  const int32 slot = s.count + rank;
  return has_value && s.count >= 0 && slot < C ? slot : -1;
}
template <typename T, int C>
WP_FUNC tile_stack_t<T, C> tile_stack_pushed(const launch_context_t* ctx, int32, int32, const tile_stack_t<T, C>& s,
                                             const T& v, bool has_value) {
  tile_stack_t<T, C> r = s;
  if (r.count < 0 || r.count > C) r.count = 0;
  if (lane_block_t* b = lanes_of(ctx)) {
    struct push_t {
      T value;
      bool has;
    };
    const push_t* all = lane_share(b, push_t{v, has_value});
    for (int32 l = 0; all && l < b->count; ++l)
      if (lane_running(b, l) && all[l].has && r.count < C) r.data[r.count++] = all[l].value;
    b->sync(b);
    return r;
  }
  if (has_value && r.count < C) r.data[r.count++] = v;
  return r;
}
// The top value and its slot (zero and -1 when empty), and the stack after the pop.
template <typename T, int C>
WP_FUNC void tile_stack_top(const launch_context_t* ctx, int32, int32, const tile_stack_t<T, C>& s, T& value,
                            int32& slot) {
  const lane_block_t* b = lanes_of(ctx);
  const int32 at = s.count - 1 - (b ? lane_rank(b, b->lane) : 0);
  const bool any = s.count <= C && at >= 0;
  value = any ? s.data[at] : cg_zeros<T>();
  slot = any ? at : -1;
}
template <typename T, int C>
WP_FUNC tile_stack_t<T, C> tile_stack_popped(const launch_context_t* ctx, int32, int32, const tile_stack_t<T, C>& s) {
  const lane_block_t* b = lanes_of(ctx);
  tile_stack_t<T, C> r = s;
  r.count -= b ? lane_rank(b, b->count) : 1;
  if (r.count < 0) r.count = 0;
  return r;
}
template <typename T, int C>
WP_FUNC tile_stack_t<T, C> tile_stack_cleared(const launch_context_t*, int32, int32, const tile_stack_t<T, C>& s) {
  tile_stack_t<T, C> r = s;
  r.count = 0;
  return r;
}
template <typename T, int C> WP_FUNC int32 tile_stack_count(const tile_stack_t<T, C>& s) { return s.count; }

#undef WP_TILE
#undef WP_TILE_TEMPLATE

}  // namespace wp
