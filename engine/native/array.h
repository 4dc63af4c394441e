// Native library: array access for kernels. Owns: element addresses from byte strides
// (address/index/load/store, 1-4 indices), sub-array views (a[i] on a 2-D array), bounds tests
// (bounds_ok), and the launch error reporters that fill launch_error_t with an atomic CAS on
// `kind` (first error of a launch wins, launch_abi.h).
#pragma once

#include "scalar.h"

namespace wp {

// Non-deduced context: lets `value` arguments convert to the array's element type.
template <typename T> struct type_identity_t { typedef T type; };

template <typename T>
WP_FUNC T* address(const array_t<T>& a, int64 i) {
  return (T*)((char*)a.data + i * a.strides[0]);
}
template <typename T>
WP_FUNC T* address(const array_t<T>& a, int64 i, int64 j) {
  return (T*)((char*)a.data + i * a.strides[0] + j * a.strides[1]);
}
template <typename T>
WP_FUNC T* address(const array_t<T>& a, int64 i, int64 j, int64 k) {
  return (T*)((char*)a.data + i * a.strides[0] + j * a.strides[1] + k * a.strides[2]);
}
template <typename T>
WP_FUNC T* address(const array_t<T>& a, int64 i, int64 j, int64 k, int64 l) {
  return (T*)((char*)a.data + i * a.strides[0] + j * a.strides[1] + k * a.strides[2] + l * a.strides[3]);
}
template <typename T> WP_FUNC T& index(const array_t<T>& a, int64 i) { return *address(a, i); }
template <typename T> WP_FUNC T& index(const array_t<T>& a, int64 i, int64 j) { return *address(a, i, j); }
template <typename T> WP_FUNC T& index(const array_t<T>& a, int64 i, int64 j, int64 k) { return *address(a, i, j, k); }
template <typename T> WP_FUNC T& index(const array_t<T>& a, int64 i, int64 j, int64 k, int64 l) { return *address(a, i, j, k, l); }
template <typename T> WP_FUNC T load(const array_t<T>& a, int64 i) { return *address(a, i); }
template <typename T> WP_FUNC T load(const array_t<T>& a, int64 i, int64 j) { return *address(a, i, j); }
template <typename T> WP_FUNC T load(const array_t<T>& a, int64 i, int64 j, int64 k) { return *address(a, i, j, k); }
template <typename T> WP_FUNC T load(const array_t<T>& a, int64 i, int64 j, int64 k, int64 l) { return *address(a, i, j, k, l); }
template <typename T> WP_FUNC void store(const array_t<T>& a, int64 i, const typename type_identity_t<T>::type& v) { *address(a, i) = v; }
template <typename T> WP_FUNC void store(const array_t<T>& a, int64 i, int64 j, const typename type_identity_t<T>::type& v) { *address(a, i, j) = v; }
template <typename T> WP_FUNC void store(const array_t<T>& a, int64 i, int64 j, int64 k, const typename type_identity_t<T>::type& v) { *address(a, i, j, k) = v; }
template <typename T> WP_FUNC void store(const array_t<T>& a, int64 i, int64 j, int64 k, int64 l, const typename type_identity_t<T>::type& v) {
  *address(a, i, j, k, l) = v;
}

// The gradient array seen as an array (same shape and strides as the data).
template <typename T>
WP_FUNC array_t<T> grad_of(const array_t<T>& a) {
  array_t<T> g = a;
  g.data = a.grad;
  g.grad = nullptr;
  return g;
}

// a[i] on an array of ndim >= 2: the sub-array with the first index fixed.
template <typename T>
WP_FUNC array_t<T> view(const array_t<T>& a, int64 i) {
  array_t<T> r;
  r.data = a.data ? (T*)((char*)a.data + i * a.strides[0]) : nullptr;
  r.grad = a.grad ? (T*)((char*)a.grad + i * a.strides[0]) : nullptr;
  for (int d = 0; d < ARRAY_MAX_DIMS - 1; ++d) {
    r.shape[d] = a.shape[d + 1];
    r.strides[d] = a.strides[d + 1];
  }
  r.shape[ARRAY_MAX_DIMS - 1] = 0;
  r.strides[ARRAY_MAX_DIMS - 1] = 0;
  r.ndim = a.ndim - 1;
  r.flags = a.flags;
  return r;
}
template <typename T> WP_FUNC array_t<T> view(const array_t<T>& a, int64 i, int64 j) { return view(view(a, i), j); }
template <typename T> WP_FUNC array_t<T> view(const array_t<T>& a, int64 i, int64 j, int64 k) { return view(view(view(a, i), j), k); }

template <typename T> WP_FUNC int32 len(const array_t<T>& a) { return (int32)a.shape[0]; }
template <typename T> WP_FUNC bool is_null(const array_t<T>& a) { return a.data == nullptr; }
// where/select/unot on an array test whether it is non-empty (not None).
template <typename T, typename V> WP_FUNC V where(const array_t<T>& a, const V& x, const V& y) { return a.data ? x : y; }
template <typename T, typename V> WP_FUNC V select(const array_t<T>& a, const V& f, const V& t) { return a.data ? t : f; }
template <typename T> WP_FUNC bool unot(const array_t<T>& a) { return a.data == nullptr; }
template <typename T, typename V>
WP_FUNC void adj_where(const array_t<T>& a, const V&, const V&, array_t<T>&, V& adj_x, V& adj_y, const V& adj_ret) {
  if (a.data) adj_x += adj_ret; else adj_y += adj_ret;
}
template <typename T, typename V>
WP_FUNC void adj_select(const array_t<T>& a, const V&, const V&, array_t<T>&, V& adj_f, V& adj_t, const V& adj_ret) {
  if (a.data) adj_t += adj_ret; else adj_f += adj_ret;
}

// ---------------------------------------------------------------------------------------------
// Bounds: true when the array is not None and every index is inside its dimension.
WP_FUNC bool in_range(int64 i, int64 n) { return (uint64)i < (uint64)n; }
template <typename T> WP_FUNC bool bounds_ok(const array_t<T>& a, int64 i) { return a.data && in_range(i, a.shape[0]); }
template <typename T> WP_FUNC bool bounds_ok(const array_t<T>& a, int64 i, int64 j) {
  return a.data && in_range(i, a.shape[0]) && in_range(j, a.shape[1]);
}
template <typename T> WP_FUNC bool bounds_ok(const array_t<T>& a, int64 i, int64 j, int64 k) {
  return a.data && in_range(i, a.shape[0]) && in_range(j, a.shape[1]) && in_range(k, a.shape[2]);
}
template <typename T> WP_FUNC bool bounds_ok(const array_t<T>& a, int64 i, int64 j, int64 k, int64 l) {
  return a.data && in_range(i, a.shape[0]) && in_range(j, a.shape[1]) && in_range(k, a.shape[2]) && in_range(l, a.shape[3]);
}

// ---------------------------------------------------------------------------------------------
// Error reports. The writer that moves error->kind from LAUNCH_OK wins and fills the rest; later
// errors of the same launch are dropped. Returns true when this call recorded the error.
WP_FUNC bool claim_error(launch_error_t* e, int32 kind) {
#if WP_DEVICE_CODE
  return atomicCAS((int*)&e->kind, 0, (int)kind) == 0;
#else
  int32 expected = 0;
  return __atomic_compare_exchange_n(&e->kind, &expected, kind, false, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE);
#endif
}
// Threads per block of this launch: blockDim.x on CUDA; on the CPU the block's lanes, or the
// launch's block_dim for a kernel without tiles (wp.config.enable_cpu_blocks, 2..1024), else 1.
WP_FUNC int32 block_dim(const launch_context_t* ctx) {
#if WP_DEVICE_CODE
  (void)ctx;
  return (int32)blockDim.x;
#else
  if (!ctx) return 1;
  if (ctx->lanes) return ctx->lanes->dim;
  return ctx->block_dim > 1 && ctx->block_dim <= 1024 ? (int32)ctx->block_dim : 1;
#endif
}
// True once some thread of this launch reported an error (kernels may stop early).
WP_FUNC bool launch_failed(const launch_context_t* ctx) {
  if (!ctx || !ctx->error) return false;
#if WP_DEVICE_CODE
  return *(volatile int32*)&ctx->error->kind != 0;
#else
  return __atomic_load_n(&ctx->error->kind, __ATOMIC_RELAXED) != 0;
#endif
}
WP_FUNC bool report_error(const launch_context_t* ctx, int32 kind, int32 function_id, int32 line, int32 array_param, int32 ndim,
                          const int64* idx, const int64* shape, const char* message) {
  if (!ctx || !ctx->error) return false;
  if (ctx->report_flag) *(volatile int32*)ctx->report_flag = 1;   // read back at the synchronize
  launch_error_t* e = ctx->error;
  if (!claim_error(e, kind)) return false;
  e->line = line;
  e->array_param = array_param;
  e->function_id = function_id;
  e->ndim = ndim;
  for (int d = 0; d < ARRAY_MAX_DIMS; ++d) {
    e->index[d] = (idx && d < ndim) ? idx[d] : 0;
    e->shape[d] = (shape && d < ndim) ? shape[d] : 0;
  }
  int n = 0;
  if (message)
    for (; n < (int)sizeof(e->message) - 1 && message[n]; ++n) e->message[n] = message[n];
  e->message[n] = '\0';
  return true;
}
// Out-of-bounds (or None-array) access of kernel parameter `array_param` at `line`.
template <typename T>
WP_FUNC void report_out_of_bounds(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const array_t<T>& a,
                                  int32 ndim, int64 i, int64 j = 0, int64 k = 0, int64 l = 0) {
  const int64 idx[ARRAY_MAX_DIMS] = {i, j, k, l};
  report_error(ctx, a.data ? LAUNCH_OUT_OF_BOUNDS : LAUNCH_NULL_ARRAY, function_id, line, array_param, ndim, idx, a.shape, nullptr);
}
// Checked address: nullptr after reporting when the access is invalid. Bounds checks are skipped
// when the launch carries LAUNCH_FLAG_NO_BOUNDS_CHECK (the session's `fast` policy).
template <typename T>
WP_FUNC T* checked_address(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const array_t<T>& a, int64 i) {
  if ((ctx && (ctx->flags & LAUNCH_FLAG_NO_BOUNDS_CHECK)) || bounds_ok(a, i)) return address(a, i);
  report_out_of_bounds(ctx, function_id, line, array_param, a, 1, i);
  return nullptr;
}
template <typename T>
WP_FUNC T* checked_address(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const array_t<T>& a, int64 i, int64 j) {
  if ((ctx && (ctx->flags & LAUNCH_FLAG_NO_BOUNDS_CHECK)) || bounds_ok(a, i, j)) return address(a, i, j);
  report_out_of_bounds(ctx, function_id, line, array_param, a, 2, i, j);
  return nullptr;
}
template <typename T>
WP_FUNC T* checked_address(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const array_t<T>& a, int64 i, int64 j,
                           int64 k) {
  if ((ctx && (ctx->flags & LAUNCH_FLAG_NO_BOUNDS_CHECK)) || bounds_ok(a, i, j, k)) return address(a, i, j, k);
  report_out_of_bounds(ctx, function_id, line, array_param, a, 3, i, j, k);
  return nullptr;
}
template <typename T>
WP_FUNC T* checked_address(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const array_t<T>& a, int64 i, int64 j,
                           int64 k, int64 l) {
  if ((ctx && (ctx->flags & LAUNCH_FLAG_NO_BOUNDS_CHECK)) || bounds_ok(a, i, j, k, l)) return address(a, i, j, k, l);
  report_out_of_bounds(ctx, function_id, line, array_param, a, 4, i, j, k, l);
  return nullptr;
}

// ---------------------------------------------------------------------------------------------
// Slices (a[1:3], a[:2, 1:], a[i, ::2]): a view with Python's slice rules. kinds[d]: 1 a slice
// (bounds[d] = start, stop, step; cg_slice_none for a missing bound), 0 an integer index
// (bounds[d][0]; negative counts from the end). An index outside its dimension gives a None view
// (its accesses report a None array); a step of 0 is a launch error at the slice's line ("slice
// step cannot be zero", Warp's words) and gives a None view; bounds clamp to the extent. A negative
// step walks backward from start (default: the last element) down to stop, exclusive
// (default: before the first element), with a negative stride.
constexpr int64 cg_slice_none = (int64)(-9223372036854775807LL - 1);
struct cg_slice_kinds_t {
  int32 k[ARRAY_MAX_DIMS];
};
struct cg_slice_bounds_t {
  int64 b[ARRAY_MAX_DIMS][3];
};
template <typename T> WP_FUNC array_t<T> as_array(const array_t<T>& a) { return a; }
WP_FUNC int64 cg_slice_bound(int64 v, int64 ext, int64 dflt) {
  if (v == cg_slice_none) return dflt;
  if (v < 0) v += ext;
  return v < 0 ? 0 : (v > ext ? ext : v);
}
// A bound of a negative-step slice: clamped to [-1, ext - 1] (-1: before the first element).
WP_FUNC int64 cg_slice_bound_back(int64 v, int64 ext, int64 dflt) {
  if (v == cg_slice_none) return dflt;
  if (v < 0) v += ext;
  return v < 0 ? -1 : (v > ext - 1 ? ext - 1 : v);
}
template <typename T>
WP_FUNC array_t<T> cg_slice(const launch_context_t* ctx, int32 function_id, int32 line, const array_t<T>& a, int32 n,
                            cg_slice_kinds_t kinds, cg_slice_bounds_t b) {
  array_t<T> r;
  int64 offset = 0;
  int out = 0;
  bool valid = a.data != nullptr && n <= a.ndim;
  for (int d = 0; d < n && d < ARRAY_MAX_DIMS; ++d) {
    const int64 ext = a.shape[d];
    if (kinds.k[d] == 0) {
      int64 i = b.b[d][0];
      if (i < 0) i += ext;
      if (!in_range(i, ext)) valid = false;
      else offset += i * a.strides[d];
      continue;
    }
    const int64 step = b.b[d][2];
    if (step == 0) {
      valid = false;
      report_error(ctx, LAUNCH_BAD_VALUE, function_id, line, -1, 0, nullptr, nullptr, "slice step cannot be zero");
    }
    int64 lo = 0, count = 0;
    if (step > 0) {
      lo = cg_slice_bound(b.b[d][0], ext, 0);
      const int64 hi = cg_slice_bound(b.b[d][1], ext, ext);
      count = hi > lo ? (hi - lo - 1) / step + 1 : 0;
    } else if (step < 0) {
      lo = cg_slice_bound_back(b.b[d][0], ext, ext - 1);
      const int64 hi = cg_slice_bound_back(b.b[d][1], ext, -1);
      count = lo > hi ? (lo - hi - 1) / (-step) + 1 : 0;
    }
    if (count > 0) offset += lo * a.strides[d];
    r.shape[out] = count;
    r.strides[out] = valid ? a.strides[d] * step : 0;
    ++out;
  }
  for (int d = n; d < a.ndim && d < ARRAY_MAX_DIMS; ++d, ++out) {
    r.shape[out] = a.shape[d];
    r.strides[out] = a.strides[d];
  }
  r.ndim = out;
  for (; out < ARRAY_MAX_DIMS; ++out) r.shape[out] = r.strides[out] = 0;
  r.data = valid ? (T*)((char*)a.data + offset) : nullptr;
  r.grad = (valid && a.grad) ? (T*)((char*)a.grad + offset) : nullptr;
  r.flags = a.flags;
  return r;
}

}  // namespace wp
