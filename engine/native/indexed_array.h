// Native library: indexed arrays (Warp's wp.indexedarray) in kernels. Owns indexedarray_t (a data
// array plus one optional int32 index array per dimension), its shape, the index mapping, and the
// access forms generated code calls on it: address/load/store/view, the atomics, their adjoints
// and the bounds check (cg_check).
//
// Safety: the daemon validates the data array and every index array as arrays of the launching
// session (launch_args.cpp: an indexed array is packed as its fields). Index VALUES come from
// client memory and are checked at every access, here, whatever the launch's bounds-check policy:
// `indexed_address` returns nullptr when an index is outside the indexed shape or a mapped index
// outside the data array, and every access through a null address reads zero / writes nothing.
// cg_check reports the same conditions as a bounds error before the access.
#pragma once

// Included at the end of codegen_support.h (it uses cg_zeros and the array forms).
#include "codegen_support.h"

namespace wp {

template <typename T>
struct indexedarray_t {
  array_t<T> data;                        // the array the indices select from
  array_t<int32> indices[ARRAY_MAX_DIMS]; // indices[d].data == nullptr: dimension d not indexed
};

// Extent of dimension d as the kernel sees it: the index array's length where indexed.
template <typename T> WP_FUNC int64 indexed_dim(const indexedarray_t<T>& a, int d) {
  return a.indices[d].data ? a.indices[d].shape[0] : a.data.shape[d];
}
template <typename T> WP_FUNC int64 array_dim(const array_t<T>& a, int d) { return a.shape[d]; }
template <typename T> WP_FUNC int64 array_dim(const indexedarray_t<T>& a, int d) {
  return d < a.data.ndim ? indexed_dim(a, d) : 0;
}

// Maps index `i` of dimension d to an index of the data array; false when `i` is outside the
// indexed extent or the index array holds a value outside the data array's extent.
template <typename T> WP_FUNC bool indexed_map(const indexedarray_t<T>& a, int d, int64 i, int64* out) {
  if (!in_range(i, indexed_dim(a, d))) return false;
  int64 m = i;
  if (a.indices[d].data) m = (int64)*address(a.indices[d], i);
  if (!in_range(m, a.data.shape[d])) return false;
  *out = m;
  return true;
}

template <typename T> WP_FUNC T* indexed_address(const indexedarray_t<T>& a, int n, int64 i, int64 j, int64 k, int64 l) {
  if (!a.data.data || n != a.data.ndim) return nullptr;
  const int64 idx[ARRAY_MAX_DIMS] = {i, j, k, l};
  char* p = (char*)a.data.data;
  for (int d = 0; d < n; ++d) {
    int64 m = 0;
    if (!indexed_map(a, d, idx[d], &m)) return nullptr;
    p += m * a.data.strides[d];
  }
  return (T*)p;
}
template <typename T> WP_FUNC T* address(const indexedarray_t<T>& a, int64 i) { return indexed_address(a, 1, i, 0, 0, 0); }
template <typename T> WP_FUNC T* address(const indexedarray_t<T>& a, int64 i, int64 j) { return indexed_address(a, 2, i, j, 0, 0); }
template <typename T> WP_FUNC T* address(const indexedarray_t<T>& a, int64 i, int64 j, int64 k) {
  return indexed_address(a, 3, i, j, k, 0);
}
template <typename T> WP_FUNC T* address(const indexedarray_t<T>& a, int64 i, int64 j, int64 k, int64 l) {
  return indexed_address(a, 4, i, j, k, l);
}

template <typename T> WP_FUNC T indexed_load(const T* p) { return p ? *p : cg_zeros<T>(); }
template <typename T> WP_FUNC T load(const indexedarray_t<T>& a, int64 i) { return indexed_load(address(a, i)); }
template <typename T> WP_FUNC T load(const indexedarray_t<T>& a, int64 i, int64 j) { return indexed_load(address(a, i, j)); }
template <typename T> WP_FUNC T load(const indexedarray_t<T>& a, int64 i, int64 j, int64 k) { return indexed_load(address(a, i, j, k)); }
template <typename T> WP_FUNC T load(const indexedarray_t<T>& a, int64 i, int64 j, int64 k, int64 l) {
  return indexed_load(address(a, i, j, k, l));
}
template <typename T> WP_FUNC void indexed_store(T* p, const T& v) { if (p) *p = v; }
template <typename T> WP_FUNC void store(const indexedarray_t<T>& a, int64 i, const typename type_identity_t<T>::type& v) {
  indexed_store(address(a, i), v);
}
template <typename T> WP_FUNC void store(const indexedarray_t<T>& a, int64 i, int64 j, const typename type_identity_t<T>::type& v) {
  indexed_store(address(a, i, j), v);
}
template <typename T>
WP_FUNC void store(const indexedarray_t<T>& a, int64 i, int64 j, int64 k, const typename type_identity_t<T>::type& v) {
  indexed_store(address(a, i, j, k), v);
}
template <typename T>
WP_FUNC void store(const indexedarray_t<T>& a, int64 i, int64 j, int64 k, int64 l, const typename type_identity_t<T>::type& v) {
  indexed_store(address(a, i, j, k, l), v);
}

// a[i] on an indexed array of ndim >= 2: the indexed sub-array with the first index fixed (its
// data is null when `i` does not map into the data array, so later accesses see None).
template <typename T>
WP_FUNC indexedarray_t<T> view(const indexedarray_t<T>& a, int64 i) {
  indexedarray_t<T> r = cg_zeros<indexedarray_t<T>>();
  int64 m = 0;
  const bool ok = a.data.data && a.data.ndim >= 2 && indexed_map(a, 0, i, &m);
  r.data = view(a.data, ok ? m : 0);
  if (!ok) r.data.data = nullptr, r.data.grad = nullptr;
  for (int d = 0; d < ARRAY_MAX_DIMS - 1; ++d) r.indices[d] = a.indices[d + 1];
  return r;
}
template <typename T> WP_FUNC indexedarray_t<T> view(const indexedarray_t<T>& a, int64 i, int64 j) { return view(view(a, i), j); }
template <typename T> WP_FUNC indexedarray_t<T> view(const indexedarray_t<T>& a, int64 i, int64 j, int64 k) {
  return view(view(view(a, i), j), k);
}

template <typename T> WP_FUNC int32 len(const indexedarray_t<T>& a) { return (int32)indexed_dim(a, 0); }
template <typename T> WP_FUNC bool is_null(const indexedarray_t<T>& a) { return a.data.data == nullptr; }

// The bounds check generated code runs before an access (see cg_check for arrays): an index
// outside the indexed shape is reported against that shape; an index array value outside the
// data array is reported with the mapped indices against the data array's shape.
template <typename T>
WP_FUNC bool cg_check(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const char* name,
                      const indexedarray_t<T>& a, int64 i, int64 j = 0, int64 k = 0, int64 l = 0, int32 ndim = 1) {
  const int64 idx[ARRAY_MAX_DIMS] = {i, j, k, l};
  if (!a.data.data) {
    report_error(ctx, LAUNCH_NULL_ARRAY, function_id, line, array_param, ndim, idx, a.data.shape, name);
    return false;
  }
  int64 shape[ARRAY_MAX_DIMS] = {0, 0, 0, 0};
  for (int d = 0; d < ARRAY_MAX_DIMS; ++d) shape[d] = array_dim(a, d);
  for (int d = 0; d < ndim; ++d)
    if (!in_range(idx[d], shape[d])) {
      report_error(ctx, LAUNCH_OUT_OF_BOUNDS, function_id, line, array_param, ndim, idx, shape, name);
      return false;
    }
  int64 mapped[ARRAY_MAX_DIMS] = {0, 0, 0, 0};
  for (int d = 0; d < ndim && d < a.data.ndim; ++d) {
    mapped[d] = a.indices[d].data ? (int64)*address(a.indices[d], idx[d]) : idx[d];
    if (!in_range(mapped[d], a.data.shape[d])) {
      report_error(ctx, LAUNCH_OUT_OF_BOUNDS, function_id, line, array_param, ndim, mapped, a.data.shape, name);
      return false;
    }
  }
  return true;
}
template <typename T>
WP_FUNC bool cg_check_adj(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param, const char* name,
                          const indexedarray_t<T>& adj, int64 i, int64 j = 0, int64 k = 0, int64 l = 0, int32 ndim = 1) {
  if (adj.data.data == nullptr) return true;
  return cg_check(ctx, function_id, line, array_param, name, adj, i, j, k, l, ndim);
}

// Atomics: the element's address through the indices; an unmapped address does nothing.
#define WP_INDEXED_ATOMIC(op) \
  template <typename T> WP_FUNC T indexed_atomic_##op(T* p, const T& v) { return p ? atomic_##op##_ptr(p, v) : cg_zeros<T>(); } \
  template <typename T> WP_FUNC T atomic_##op(const indexedarray_t<T>& a, int64 i, typename type_identity_t<T>::type v) { \
    return indexed_atomic_##op(address(a, i), v); \
  } \
  template <typename T> WP_FUNC T atomic_##op(const indexedarray_t<T>& a, int64 i, int64 j, typename type_identity_t<T>::type v) { \
    return indexed_atomic_##op(address(a, i, j), v); \
  } \
  template <typename T> \
  WP_FUNC T atomic_##op(const indexedarray_t<T>& a, int64 i, int64 j, int64 k, typename type_identity_t<T>::type v) { \
    return indexed_atomic_##op(address(a, i, j, k), v); \
  } \
  template <typename T> \
  WP_FUNC T atomic_##op(const indexedarray_t<T>& a, int64 i, int64 j, int64 k, int64 l, typename type_identity_t<T>::type v) { \
    return indexed_atomic_##op(address(a, i, j, k, l), v); \
  }
WP_INDEXED_ATOMIC(add)
WP_INDEXED_ATOMIC(sub)
WP_INDEXED_ATOMIC(min)
WP_INDEXED_ATOMIC(max)
WP_INDEXED_ATOMIC(exch)
WP_INDEXED_ATOMIC(and)
WP_INDEXED_ATOMIC(or)
WP_INDEXED_ATOMIC(xor)
#undef WP_INDEXED_ATOMIC
template <typename T> WP_FUNC T indexed_atomic_cas(T* p, const T& c, const T& v) { return p ? atomic_cas_ptr(p, c, v) : cg_zeros<T>(); }
template <typename T>
WP_FUNC T atomic_cas(const indexedarray_t<T>& a, int64 i, typename type_identity_t<T>::type c, typename type_identity_t<T>::type v) {
  return indexed_atomic_cas(address(a, i), c, v);
}
template <typename T>
WP_FUNC T atomic_cas(const indexedarray_t<T>& a, int64 i, int64 j, typename type_identity_t<T>::type c, typename type_identity_t<T>::type v) {
  return indexed_atomic_cas(address(a, i, j), c, v);
}
template <typename T>
WP_FUNC T atomic_cas(const indexedarray_t<T>& a, int64 i, int64 j, int64 k, typename type_identity_t<T>::type c,
                     typename type_identity_t<T>::type v) {
  return indexed_atomic_cas(address(a, i, j, k), c, v);
}
template <typename T>
WP_FUNC T atomic_cas(const indexedarray_t<T>& a, int64 i, int64 j, int64 k, int64 l, typename type_identity_t<T>::type c,
                     typename type_identity_t<T>::type v) {
  return indexed_atomic_cas(address(a, i, j, k, l), c, v);
}

// ---- adjoints ----------------------------------------------------------------------------
// The adjoint of an indexed array is the indexed view of the data's gradient through the same
// indices (cg_indexed_adjoint gives the backward pass's parameter its primal's indices).
template <typename T> WP_FUNC void cg_indexed_adjoint(indexedarray_t<T>& adj, const indexedarray_t<T>& primal) {
  for (int d = 0; d < ARRAY_MAX_DIMS; ++d) adj.indices[d] = primal.indices[d];
}
template <typename T> WP_FUNC void cg_indexed_adjoint(T&, const T&) {}
template <typename T> WP_FUNC void cg_accum(indexedarray_t<T>&, const indexedarray_t<T>&) {}
template <typename T> WP_FUNC void cg_link(indexedarray_t<T>& d, const indexedarray_t<T>& s) { d = s; }

template <typename T, typename... I> WP_FUNC T* cg_slot_grad(const indexedarray_t<T>& adj_a, I... i) {
  return address(adj_a, int64(i)...);   // null without gradient data
}
template <typename T> WP_FUNC void indexed_adj_load(T* g, const T& adj_ret) { if (g) atomic_add_ptr(g, adj_ret); }
template <typename T> WP_FUNC void adj_load(const indexedarray_t<T>& adj_a, int64 i, const T& adj_ret) {
  indexed_adj_load(address(adj_a, i), adj_ret);
}
template <typename T> WP_FUNC void adj_load(const indexedarray_t<T>& adj_a, int64 i, int64 j, const T& adj_ret) {
  indexed_adj_load(address(adj_a, i, j), adj_ret);
}
template <typename T> WP_FUNC void adj_load(const indexedarray_t<T>& adj_a, int64 i, int64 j, int64 k, const T& adj_ret) {
  indexed_adj_load(address(adj_a, i, j, k), adj_ret);
}
template <typename T> WP_FUNC void adj_load(const indexedarray_t<T>& adj_a, int64 i, int64 j, int64 k, int64 l, const T& adj_ret) {
  indexed_adj_load(address(adj_a, i, j, k, l), adj_ret);
}
template <typename T> WP_FUNC void indexed_adj_store(const T* g, T& adj_v) { if (g) adj_v += *g; }
template <typename T> WP_FUNC void adj_store(const indexedarray_t<T>& adj_a, int64 i, T& adj_v) { indexed_adj_store(address(adj_a, i), adj_v); }
template <typename T> WP_FUNC void adj_store(const indexedarray_t<T>& adj_a, int64 i, int64 j, T& adj_v) {
  indexed_adj_store(address(adj_a, i, j), adj_v);
}
template <typename T> WP_FUNC void adj_store(const indexedarray_t<T>& adj_a, int64 i, int64 j, int64 k, T& adj_v) {
  indexed_adj_store(address(adj_a, i, j, k), adj_v);
}
template <typename T> WP_FUNC void adj_store(const indexedarray_t<T>& adj_a, int64 i, int64 j, int64 k, int64 l, T& adj_v) {
  indexed_adj_store(address(adj_a, i, j, k, l), adj_v);
}
#define WP_INDEXED_ADJ_ATOMIC(op, BODY) \
  template <typename T, typename I0, typename J0> \
  WP_FUNC void adj_atomic_##op(const indexedarray_t<T>& a, I0 i, const T& v, const indexedarray_t<T>& adj_a, J0&, T& adj_v, const T&) { \
    T* g = address(adj_a, i); \
    T* p = address(a, i); \
    if (p) { BODY; } \
  } \
  template <typename T, typename I0, typename I1, typename J0, typename J1> \
  WP_FUNC void adj_atomic_##op(const indexedarray_t<T>& a, I0 i, I1 j, const T& v, const indexedarray_t<T>& adj_a, J0&, J1&, T& adj_v, \
                               const T&) { \
    T* g = address(adj_a, i, j); \
    T* p = address(a, i, j); \
    if (p) { BODY; } \
  } \
  template <typename T, typename I0, typename I1, typename I2, typename J0, typename J1, typename J2> \
  WP_FUNC void adj_atomic_##op(const indexedarray_t<T>& a, I0 i, I1 j, I2 k, const T& v, const indexedarray_t<T>& adj_a, J0&, J1&, \
                               J2&, T& adj_v, const T&) { \
    T* g = address(adj_a, i, j, k); \
    T* p = address(a, i, j, k); \
    if (p) { BODY; } \
  } \
  template <typename T, typename I0, typename I1, typename I2, typename I3, typename J0, typename J1, typename J2, typename J3> \
  WP_FUNC void adj_atomic_##op(const indexedarray_t<T>& a, I0 i, I1 j, I2 k, I3 l, const T& v, const indexedarray_t<T>& adj_a, J0&, \
                               J1&, J2&, J3&, T& adj_v, const T&) { \
    T* g = address(adj_a, i, j, k, l); \
    T* p = address(a, i, j, k, l); \
    if (p) { BODY; } \
  }
WP_INDEXED_ADJ_ATOMIC(add, (void)v; if (g) adj_v += *g)
WP_INDEXED_ADJ_ATOMIC(sub, (void)v; if (g) adj_v -= *g)
WP_INDEXED_ADJ_ATOMIC(min, adj_atomic_minmax_ptr(p, v, g, adj_v))
WP_INDEXED_ADJ_ATOMIC(max, adj_atomic_minmax_ptr(p, v, g, adj_v))
#undef WP_INDEXED_ADJ_ATOMIC

}  // namespace wp
