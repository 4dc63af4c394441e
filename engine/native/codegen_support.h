// Helpers the code generator (engine/codegen) emits calls to, beside the builtins of weft.h:
// flat component access for vec/mat/quat/transform, constructors by mode (concat, fill,
// convert, columns) with their adjoints, component extract/insert and adjoints, adjoint
// accumulation and zeroing for every value type, phi adjoints, range loop tests, tid
// unravelling and bounds checks that record the array's name. Owner: codegen (C2).
// No standard library headers: compiles under clang (CPU JIT) and NVRTC.
#pragma once

#include "weft.h"

namespace wp {

// ---- flat scalar components --------------------------------------------------------------
template <typename T> struct cg_traits { typedef T scalar; static constexpr int n = 1; };
template <unsigned N, typename T> struct cg_traits<vec_t<N, T>> { typedef T scalar; static constexpr int n = N; };
template <unsigned R, unsigned C, typename T> struct cg_traits<mat_t<R, C, T>> { typedef T scalar; static constexpr int n = R * C; };
template <typename T> struct cg_traits<quat_t<T>> { typedef T scalar; static constexpr int n = 4; };
template <typename T> struct cg_traits<transform_t<T>> { typedef T scalar; static constexpr int n = 7; };

template <typename T> WP_FUNC typename cg_traits<T>::scalar* cg_comps(T& v) { return reinterpret_cast<typename cg_traits<T>::scalar*>(&v); }
template <typename T> WP_FUNC const typename cg_traits<T>::scalar* cg_comps(const T& v) {
  return reinterpret_cast<const typename cg_traits<T>::scalar*>(&v);
}

// ---- zero, accumulate ----------------------------------------------------------------------
// All bytes zero (quat/transform adjoints must be 0, not identity; arrays null).
template <typename T> WP_FUNC T cg_zeros() {
  T r;
  char* p = reinterpret_cast<char*>(&r);
  for (unsigned i = 0; i < sizeof(T); ++i) p[i] = 0;
  return r;
}

template <typename T> struct cg_is_array { static constexpr bool value = false; };
template <typename T> struct cg_is_array<array_t<T>> { static constexpr bool value = true; };

WP_FUNC void cg_accum(bool&, const bool&) {}
WP_FUNC void cg_accum(int8& a, const int8& b) { a = (int8)(a + b); }
WP_FUNC void cg_accum(uint8& a, const uint8& b) { a = (uint8)(a + b); }
WP_FUNC void cg_accum(int16& a, const int16& b) { a = (int16)(a + b); }
WP_FUNC void cg_accum(uint16& a, const uint16& b) { a = (uint16)(a + b); }
WP_FUNC void cg_accum(int32& a, const int32& b) { a += b; }
WP_FUNC void cg_accum(uint32& a, const uint32& b) { a += b; }
WP_FUNC void cg_accum(int64& a, const int64& b) { a += b; }
WP_FUNC void cg_accum(uint64& a, const uint64& b) { a += b; }
WP_FUNC void cg_accum(float32& a, const float32& b) { a += b; }
WP_FUNC void cg_accum(float64& a, const float64& b) { a += b; }
WP_FUNC void cg_accum(half& a, const half& b) { a = add(a, b); }
WP_FUNC void cg_accum(bfloat16& a, const bfloat16& b) { a = add(a, b); }
template <typename T> WP_FUNC void cg_accum(array_t<T>&, const array_t<T>&) {}
template <unsigned N, typename T> WP_FUNC void cg_accum(vec_t<N, T>& a, const vec_t<N, T>& b) {
  for (unsigned i = 0; i < N; ++i) cg_accum(a.c[i], b.c[i]);
}
template <unsigned R, unsigned C, typename T> WP_FUNC void cg_accum(mat_t<R, C, T>& a, const mat_t<R, C, T>& b) {
  for (unsigned i = 0; i < R; ++i)
    for (unsigned j = 0; j < C; ++j) cg_accum(a.data[i][j], b.data[i][j]);
}
template <typename T> WP_FUNC void cg_accum(quat_t<T>& a, const quat_t<T>& b) {
  for (int i = 0; i < 4; ++i) cg_accum(cg_comps(a)[i], cg_comps(b)[i]);
}
template <typename T> WP_FUNC void cg_accum(transform_t<T>& a, const transform_t<T>& b) {
  for (int i = 0; i < 7; ++i) cg_accum(cg_comps(a)[i], cg_comps(b)[i]);
}

// Adjoint arrays are the gradient arrays: values holding arrays (arrays, structs with array
// fields) get their adjoint's arrays linked during the backward pass's replay. Structs get
// generated overloads of cg_accum / cg_link (fieldwise).
template <typename T> WP_FUNC void cg_link(T&, const T&) {}
template <typename T> WP_FUNC void cg_link(array_t<T>& d, const array_t<T>& s) { d = s; }
// The adjoint of a builtin's result that holds arrays, from the result itself (their gradients):
// nothing for most types; mesh_get's Mesh overloads it (mesh.h).
template <typename T> WP_FUNC void cg_link_grads(T&, const T&) {}

// ---- constructors by mode ----------------------------------------------------------------
template <typename S, typename A> WP_FUNC void cg_put(S* out, int& k, const A& a) {
  if constexpr (is_same_t<A, typename cg_traits<A>::scalar>::value) {   // a scalar (not a 1-vector)
    out[k++] = S(a);
  } else {
    const typename cg_traits<A>::scalar* in = cg_comps(a);
    for (int i = 0; i < cg_traits<A>::n; ++i) out[k++] = S(in[i]);
  }
}
template <typename S, typename A> WP_FUNC void cg_take(const S* in, int& k, A& adj_a) {
  typedef typename cg_traits<A>::scalar SA;
  SA* out = cg_comps(adj_a);
  for (int i = 0; i < cg_traits<A>::n; ++i) cg_accum(out[i], SA(in[k++]));
}
template <typename R, typename... A> WP_FUNC R cg_concat(const A&... a) {
  R r = cg_zeros<R>();
  typename cg_traits<R>::scalar* out = cg_comps(r);
  int k = 0;
  (cg_put(out, k, a), ...);
  return r;
}
template <typename R, typename... A> WP_FUNC void cg_adj_concat(const R& adj_r, A&... adj_a) {
  const typename cg_traits<R>::scalar* in = cg_comps(adj_r);
  int k = 0;
  (cg_take(in, k, adj_a), ...);
}
template <typename R> WP_FUNC R cg_fill(typename cg_traits<R>::scalar s) {
  R r = cg_zeros<R>();
  for (int i = 0; i < cg_traits<R>::n; ++i) cg_comps(r)[i] = s;
  return r;
}
template <typename R> WP_FUNC void cg_adj_fill(const R& adj_r, typename cg_traits<R>::scalar& adj_s) {
  for (int i = 0; i < cg_traits<R>::n; ++i) cg_accum(adj_s, cg_comps(adj_r)[i]);
}
template <typename R, typename A> WP_FUNC R cg_convert(const A& a) {
  R r = cg_zeros<R>();
  typename cg_traits<R>::scalar* out = cg_comps(r);
  int k = 0;
  cg_put(out, k, a);
  return r;
}
template <typename R, typename A> WP_FUNC void cg_adj_convert(const R& adj_r, A& adj_a) {
  int k = 0;
  cg_take(cg_comps(adj_r), k, adj_a);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void cg_put_col(mat_t<R, C, T>& m, unsigned& j, const vec_t<R, T>& col) {
  for (unsigned i = 0; i < R; ++i) m.data[i][j] = col.c[i];
  ++j;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void cg_take_col(const mat_t<R, C, T>& adj_m, unsigned& j, vec_t<R, T>& adj_col) {
  for (unsigned i = 0; i < R; ++i) cg_accum(adj_col.c[i], adj_m.data[i][j]);
  ++j;
}
template <typename R, typename... V> WP_FUNC R cg_from_cols(const V&... cols) {
  R r = cg_zeros<R>();
  unsigned j = 0;
  (cg_put_col(r, j, cols), ...);
  return r;
}
template <typename R, typename... V> WP_FUNC void cg_adj_from_cols(const R& adj_r, V&... adj_cols) {
  unsigned j = 0;
  (cg_take_col(adj_r, j, adj_cols), ...);
}
// Adjoints of matrix_from_rows / matrix_from_cols (the forward functions are in mat.h).
template <unsigned R, unsigned C, typename T>
WP_FUNC void cg_take_row(const mat_t<R, C, T>& adj_m, unsigned& i, vec_t<C, T>& adj_row) {
  for (unsigned j = 0; j < C; ++j) cg_accum(adj_row.c[j], adj_m.data[i][j]);
  ++i;
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_matrix_from_rows(const vec_t<C, T>&, const vec_t<C, T>&, const vec_t<C, T>&, vec_t<C, T>& adj_a,
                                  vec_t<C, T>& adj_b, vec_t<C, T>& adj_c, const mat_t<R, C, T>& adj_ret) {
  unsigned i = 0;
  cg_take_row(adj_ret, i, adj_a);
  cg_take_row(adj_ret, i, adj_b);
  cg_take_row(adj_ret, i, adj_c);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_matrix_from_cols(const vec_t<R, T>&, const vec_t<R, T>&, const vec_t<R, T>&, vec_t<R, T>& adj_a,
                                  vec_t<R, T>& adj_b, vec_t<R, T>& adj_c, const mat_t<R, C, T>& adj_ret) {
  unsigned j = 0;
  cg_take_col(adj_ret, j, adj_a);
  cg_take_col(adj_ret, j, adj_b);
  cg_take_col(adj_ret, j, adj_c);
}

template <typename M> WP_FUNC M cg_identity();
template <typename T> struct cg_identity_impl;
template <unsigned N, typename T> struct cg_identity_impl<mat_t<N, N, T>> {
  WP_CALLABLE static mat_t<N, N, T> get() {
    mat_t<N, N, T> m = cg_zeros<mat_t<N, N, T>>();
    for (unsigned i = 0; i < N; ++i) m.data[i][i] = T(1);
    return m;
  }
};
template <typename T> struct cg_identity_impl<quat_t<T>> {
  WP_CALLABLE static quat_t<T> get() { return quat_t<T>(T(0), T(0), T(0), T(1)); }
};
template <typename T> struct cg_identity_impl<transform_t<T>> {
  WP_CALLABLE static transform_t<T> get() {
    transform_t<T> t = cg_zeros<transform_t<T>>();
    t.q.w = T(1);
    return t;
  }
};
template <typename M> WP_FUNC M cg_identity() { return cg_identity_impl<M>::get(); }

// ---- component extract / insert ----------------------------------------------------------
// Python's negative indices count from the end (v[-1] is the last component); an index still
// outside [0, n) reads 0 and writes nothing, so no memory outside the value is touched.
WP_FUNC bool cg_component(int64& i, int64 n) {
  if (i < 0) i += n;
  return i >= 0 && i < n;
}
template <typename V> WP_FUNC typename cg_traits<V>::scalar cg_extract(const V& v, int64 i) {
  typedef typename cg_traits<V>::scalar S;
  return cg_component(i, cg_traits<V>::n) ? cg_comps(v)[i] : S(0);
}
template <unsigned R, unsigned C, typename T> WP_FUNC vec_t<C, T> cg_extract(const mat_t<R, C, T>& m, int64 i) {
  vec_t<C, T> r = cg_zeros<vec_t<C, T>>();
  if (!cg_component(i, R)) return r;
  for (unsigned j = 0; j < C; ++j) r.c[j] = m.data[i][j];
  return r;
}
template <unsigned R, unsigned C, typename T> WP_FUNC T cg_extract(const mat_t<R, C, T>& m, int64 i, int64 j) {
  return cg_component(i, R) && cg_component(j, C) ? m.data[i][j] : T(0);
}
template <typename V> WP_FUNC void cg_adj_extract(V& adj_v, int64 i, const typename cg_traits<V>::scalar& adj_r) {
  if (cg_component(i, cg_traits<V>::n)) cg_accum(cg_comps(adj_v)[i], adj_r);
}
template <unsigned R, unsigned C, typename T> WP_FUNC void cg_adj_extract(mat_t<R, C, T>& adj_m, int64 i, const vec_t<C, T>& adj_r) {
  if (!cg_component(i, R)) return;
  for (unsigned j = 0; j < C; ++j) cg_accum(adj_m.data[i][j], adj_r.c[j]);
}
template <unsigned R, unsigned C, typename T> WP_FUNC void cg_adj_extract(mat_t<R, C, T>& adj_m, int64 i, int64 j, const T& adj_r) {
  if (cg_component(i, R) && cg_component(j, C)) cg_accum(adj_m.data[i][j], adj_r);
}
template <typename V> WP_FUNC V cg_insert(V v, int64 i, const typename cg_traits<V>::scalar& x) {
  if (cg_component(i, cg_traits<V>::n)) cg_comps(v)[i] = x;
  return v;
}
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T> cg_insert(mat_t<R, C, T> m, int64 i, const vec_t<C, T>& row) {
  if (!cg_component(i, R)) return m;
  for (unsigned j = 0; j < C; ++j) m.data[i][j] = row.c[j];
  return m;
}
template <unsigned R, unsigned C, typename T> WP_FUNC mat_t<R, C, T> cg_insert(mat_t<R, C, T> m, int64 i, int64 j, const T& x) {
  if (cg_component(i, R) && cg_component(j, C)) m.data[i][j] = x;
  return m;
}
template <typename V> WP_FUNC void cg_adj_insert(V& adj_v, int64 i, typename cg_traits<V>::scalar& adj_x, const V& adj_r) {
  V t = adj_r;
  if (cg_component(i, cg_traits<V>::n)) {
    cg_accum(adj_x, cg_comps(t)[i]);
    cg_comps(t)[i] = typename cg_traits<V>::scalar(0);
  }
  cg_accum(adj_v, t);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void cg_adj_insert(mat_t<R, C, T>& adj_m, int64 i, vec_t<C, T>& adj_row, const mat_t<R, C, T>& adj_r) {
  mat_t<R, C, T> t = adj_r;
  if (cg_component(i, R)) {
    for (unsigned j = 0; j < C; ++j) {
      cg_accum(adj_row.c[j], t.data[i][j]);
      t.data[i][j] = T(0);
    }
  }
  cg_accum(adj_m, t);
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void cg_adj_insert(mat_t<R, C, T>& adj_m, int64 i, int64 j, T& adj_x, const mat_t<R, C, T>& adj_r) {
  mat_t<R, C, T> t = adj_r;
  if (cg_component(i, R) && cg_component(j, C)) {
    cg_accum(adj_x, t.data[i][j]);
    t.data[i][j] = T(0);
  }
  cg_accum(adj_m, t);
}

// ---- composite slot writes (a[i].x = v, a[i].f = v) ----------------------------------------
// Sema lowers them as load a[i], replace the slot, store a[i] (ops marked `slot`). Reversed,
// the store passes the element's gradient g = adj_a[i] to the updated element (its slot goes to
// v, the rest back to the loaded element) and the load writes what comes back into adj_a[i]:
// g with the written slot cleared (Warp's adj_array_store_slot: an overwrite consumes its
// slot's gradient; the other slots keep theirs, the load is not a read).
// cg_slot_grad: the gradient element's address, null when no gradient is wanted.
template <typename T, typename... I> WP_FUNC T* cg_slot_grad(const array_t<T>& adj_a, I... i) {
  return adj_a.data ? address(adj_a, int64(i)...) : nullptr;
}
// (cg_adj_slot_store is also the adjoint of a plain store of a struct element: adj_v += g.)
template <typename A, typename T, typename... I> WP_FUNC void cg_adj_slot_store(const A& adj_a, T& adj_v, I... i) {
  if (T* g = cg_slot_grad(adj_a, i...)) cg_accum(adj_v, *g);
}
template <typename A, typename T, typename... I> WP_FUNC void cg_adj_slot_load(const A& adj_a, const T& adj_r, I... i) {
  if (T* g = cg_slot_grad(adj_a, i...)) *g = adj_r;
}
// The adjoint of a read of a struct element: its differentiable fields are added atomically
// (cg_atomic_accum is emitted with each struct).
template <typename A, typename T, typename... I>
WP_FUNC void cg_adj_load_struct(const A& adj_a, const T& adj_r, I... i) {
  if (T* g = cg_slot_grad(adj_a, i...)) cg_atomic_accum(g, adj_r);
}

// ---- control flow ------------------------------------------------------------------------
template <typename T> WP_FUNC void cg_adj_phi(bool c, T& adj_a, T& adj_b, const T& adj_r) {
  if (c) cg_accum(adj_a, adj_r);
  else cg_accum(adj_b, adj_r);
}
template <typename I> WP_FUNC bool cg_range_continue(I i, I end, I step) { return step > 0 ? i < end : i > end; }

// Loop cancellation poll, emitted at the top of every loop body: reads the launch's cancel
// word on the first iteration and then every 1024th (`counter` is the loop's own iteration
// count), so a loop of a cancelled launch ends within 1024 iterations and a nested loop
// entered after the cancellation ends at once.
WP_FUNC bool cg_loop_poll(const launch_context_t* ctx, uint32& counter) {
  if ((counter++ & 1023u) != 0u || !ctx || !ctx->cancel) return false;
#if WP_DEVICE_CODE
  return *(const volatile int32*)ctx->cancel != 0;
#else
  return __atomic_load_n(ctx->cancel, __ATOMIC_RELAXED) != 0;
#endif
}

// tid of flat launch index `flat`, unravelled by the launch shape (row-major). The outermost
// index is what is left of `flat`: a 1-D launch does no division at all.
// i = wp.tid() (one name): the first coordinate of the thread's launch index (Warp's rule: only
// the leading indices are returned); the flat index of a 1-D launch.
WP_FUNC int64 cg_tid_first(const launch_context_t* ctx, int64 flat) {
  const launch_bounds_t& b = ctx->bounds;
  if (b.ndim <= 1) return flat;
  const int64 inner = (b.shape[1] > 0 ? b.shape[1] : 1) * (b.shape[2] > 0 ? b.shape[2] : 1) * (b.shape[3] > 0 ? b.shape[3] : 1);
  return flat / inner;
}
// The coarsened CUDA entry (KernelLayout::coarse_symbol): asks the GPU to bring element i of a
// 1-D array (one the body loads at wp.tid()) into L2 ahead of the body that loads it, so the
// loads of a thread's later logical threads are in flight together. A hint: it never faults and
// changes no value; nothing on the CPU.
template <typename T>
WP_FUNC void cg_prefetch_l2(const array_t<T>& a, int64 i) {
#if defined(__CUDA_ARCH__)
  asm volatile("prefetch.global.L2 [%0];" ::"l"(reinterpret_cast<const char*>(a.data) + i * a.strides[0]));
#else
  (void)a;
  (void)i;
#endif
}
WP_FUNC void cg_unravel(const launch_bounds_t& b, int64 flat, int64* tid) {
  tid[1] = tid[2] = tid[3] = 0;
  for (int d = b.ndim - 1; d > 0; --d) {
    int64 n = b.shape[d] > 0 ? b.shape[d] : 1;
    tid[d] = flat % n;
    flat /= n;
  }
  tid[0] = b.ndim > 0 ? flat : 0;
}

// ---- bounds checks -----------------------------------------------------------------------
// Returns false (after recording the first error of the launch) when an index is outside
// the array or the array is None; the caller then stops the thread's work.
template <typename T>
WP_FUNC bool cg_check(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const char* name,
                      const array_t<T>& a, int64 i, int64 j = 0, int64 k = 0, int64 l = 0, int32 ndim = 1) {
  if (ctx && (ctx->flags & LAUNCH_FLAG_NO_BOUNDS_CHECK)) return true;
  const int64 idx[ARRAY_MAX_DIMS] = {i, j, k, l};
  bool ok = a.data != nullptr;
  for (int d = 0; d < ndim && ok; ++d) ok = in_range(idx[d], a.shape[d]);
  if (ok) return true;
  report_error(ctx, a.data ? LAUNCH_OUT_OF_BOUNDS : LAUNCH_NULL_ARRAY, function_id, line, array_param, ndim, idx, a.shape, name);
  return false;
}
// The adjoint twin of cg_check, run before every adjoint array access (adj_load, adj_store,
// atomic adjoints): an adjoint array without data (no gradient wanted) passes; otherwise every
// index must lie inside the adjoint array's own shape, whatever the primal check found.
template <typename T>
WP_FUNC bool cg_check_adj(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const char* name,
                          const array_t<T>& adj, int64 i, int64 j = 0, int64 k = 0, int64 l = 0, int32 ndim = 1) {
  if (adj.data == nullptr) return true;
  return cg_check(ctx, function_id, line, array_param, name, adj, i, j, k, l, ndim);
}

}  // namespace wp

#include "indexed_array.h"
#include "fixed_array.h"
#include "lanes.h"
#include "tile.h"
#include "geometry_tiled.h"
