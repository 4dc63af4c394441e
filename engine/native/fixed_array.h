// Native library: fixed-size arrays (Warp's wp.zeros(shape=..., dtype=...) inside a kernel or
// func, its `fixedarray`). Owns fixedarray_t (a value holding its elements, row-major, extents
// D0..D3 known at compile time, 0 past ndim) and the access forms generated code calls on it,
// each through as_array: an array_t view of the value's own elements (valid while the value
// lives), so indexing, views, bounds checks and atomics are those of arrays.
#pragma once

// Included at the end of codegen_support.h.
#include "codegen_support.h"

namespace wp {

template <typename T, int D0, int D1, int D2, int D3>
struct fixedarray_t {
  static constexpr int NDIM = D1 == 0 ? 1 : (D2 == 0 ? 2 : (D3 == 0 ? 3 : 4));
  static constexpr int SIZE = D0 * (D1 ? D1 : 1) * (D2 ? D2 : 1) * (D3 ? D3 : 1);
  T data[SIZE];
};

// A contiguous row-major array_t of n0 x n1 x n2 x n3 elements of U at `data` (trailing zero
// extents: fewer dimensions); no gradient.
template <typename U>
WP_FUNC array_t<U> contiguous_array(U* data, int64 n0, int64 n1, int64 n2, int64 n3) {
  array_t<U> r;
  r.data = data;
  r.grad = nullptr;
  const int64 ext[ARRAY_MAX_DIMS] = {n0, n1, n2, n3};
  r.ndim = n1 == 0 ? 1 : (n2 == 0 ? 2 : (n3 == 0 ? 3 : 4));
  r.flags = 0;
  int64 stride = (int64)sizeof(U);
  for (int d = ARRAY_MAX_DIMS - 1; d >= 0; --d) {
    r.shape[d] = d < r.ndim ? ext[d] : 0;
    r.strides[d] = d < r.ndim ? stride : 0;
    if (d < r.ndim) stride *= ext[d];
  }
  return r;
}

template <typename T, int D0, int D1, int D2, int D3>
WP_FUNC array_t<T> as_array(const fixedarray_t<T, D0, D1, D2, D3>& a) {
  return contiguous_array((T*)a.data, D0, D1, D2, D3);
}

// wp.array(ptr=f.ptr, shape=..., dtype=U) over a fixed-size array's elements (the compiler checks
// that the view fits and that U's alignment is at most the elements'): contiguous, row-major.
template <typename U, typename T>
WP_FUNC array_t<U> cg_reinterpret(const array_t<T>& a, int64 n0, int64 n1 = 0, int64 n2 = 0, int64 n3 = 0) {
  return contiguous_array((U*)a.data, n0, n1, n2, n3);
}

#define WP_FIXED_TEMPLATE template <typename T, int D0, int D1, int D2, int D3, typename... A>
#define WP_FIXED fixedarray_t<T, D0, D1, D2, D3>
WP_FIXED_TEMPLATE WP_FUNC T* address(const WP_FIXED& a, A... i) { return address(as_array(a), i...); }
WP_FIXED_TEMPLATE WP_FUNC T load(const WP_FIXED& a, A... i) { return load(as_array(a), i...); }
WP_FIXED_TEMPLATE WP_FUNC void store(const WP_FIXED& a, const A&... i) { store(as_array(a), i...); }
WP_FIXED_TEMPLATE WP_FUNC array_t<T> view(const WP_FIXED& a, A... i) { return view(as_array(a), i...); }
WP_FIXED_TEMPLATE WP_FUNC bool cg_check(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param,
                                        const char* name, const WP_FIXED& a, A... i) {
  return cg_check(ctx, function_id, line, array_param, name, as_array(a), i...);
}
WP_FIXED_TEMPLATE WP_FUNC bool cg_check_adj(const launch_context_t* ctx, int32 function_id, int32 line, int32 array_param,
                                            const char* name, const WP_FIXED& a, A... i) {
  return cg_check_adj(ctx, function_id, line, array_param, name, as_array(a), i...);
}
WP_FIXED_TEMPLATE WP_FUNC void adj_load(const WP_FIXED& a, const A&... i) { adj_load(as_array(a), i...); }
WP_FIXED_TEMPLATE WP_FUNC void adj_store(const WP_FIXED& a, A&... i) { adj_store(as_array(a), i...); }
WP_FIXED_TEMPLATE WP_FUNC T* cg_slot_grad(const WP_FIXED& a, A... i) { return cg_slot_grad(as_array(a), i...); }
// Atomics on a fixed-size array: its elements are the thread's own (a local value), so each is a
// plain read-modify-write returning the old value. Hardware atomics would be wrong on CUDA: they
// are undefined on local memory (the launch faults with CUDA_ERROR_LAUNCH_FAILED).
#define WP_FIXED_RMW(op, expr)                                                                       \
  template <typename T> WP_FUNC T fixed_rmw_##op(T* p, const T& v) { T old = *p; *p = (expr); return old; } \
  template <typename T, int D0, int D1, int D2, int D3>                                              \
  WP_FUNC T atomic_##op(const WP_FIXED& a, int64 i, typename type_identity_t<T>::type v) {           \
    return fixed_rmw_##op(address(as_array(a), i), v);                                               \
  }                                                                                                  \
  template <typename T, int D0, int D1, int D2, int D3>                                              \
  WP_FUNC T atomic_##op(const WP_FIXED& a, int64 i, int64 j, typename type_identity_t<T>::type v) {  \
    return fixed_rmw_##op(address(as_array(a), i, j), v);                                            \
  }                                                                                                  \
  template <typename T, int D0, int D1, int D2, int D3>                                              \
  WP_FUNC T atomic_##op(const WP_FIXED& a, int64 i, int64 j, int64 k, typename type_identity_t<T>::type v) { \
    return fixed_rmw_##op(address(as_array(a), i, j, k), v);                                         \
  }                                                                                                  \
  template <typename T, int D0, int D1, int D2, int D3>                                              \
  WP_FUNC T atomic_##op(const WP_FIXED& a, int64 i, int64 j, int64 k, int64 l, typename type_identity_t<T>::type v) { \
    return fixed_rmw_##op(address(as_array(a), i, j, k, l), v);                                      \
  }
WP_FIXED_RMW(add, add(old, v))
WP_FIXED_RMW(sub, sub(old, v))
WP_FIXED_RMW(min, min(old, v))
WP_FIXED_RMW(max, max(old, v))
WP_FIXED_RMW(exch, v)
WP_FIXED_RMW(and, bit_and(old, v))
WP_FIXED_RMW(or, bit_or(old, v))
WP_FIXED_RMW(xor, bit_xor(old, v))
#undef WP_FIXED_RMW
template <typename T> WP_FUNC T fixed_rmw_cas(T* p, const T& c, const T& v) {
  T old = *p;
  if (old == c) *p = v;
  return old;
}
template <typename T, int D0, int D1, int D2, int D3>
WP_FUNC T atomic_cas(const WP_FIXED& a, int64 i, typename type_identity_t<T>::type c, typename type_identity_t<T>::type v) {
  return fixed_rmw_cas(address(as_array(a), i), c, v);
}
template <typename T, int D0, int D1, int D2, int D3>
WP_FUNC T atomic_cas(const WP_FIXED& a, int64 i, int64 j, typename type_identity_t<T>::type c, typename type_identity_t<T>::type v) {
  return fixed_rmw_cas(address(as_array(a), i, j), c, v);
}
template <typename T, int D0, int D1, int D2, int D3>
WP_FUNC T atomic_cas(const WP_FIXED& a, int64 i, int64 j, int64 k, typename type_identity_t<T>::type c, typename type_identity_t<T>::type v) {
  return fixed_rmw_cas(address(as_array(a), i, j, k), c, v);
}
template <typename T, int D0, int D1, int D2, int D3>
WP_FUNC T atomic_cas(const WP_FIXED& a, int64 i, int64 j, int64 k, int64 l, typename type_identity_t<T>::type c,
                     typename type_identity_t<T>::type v) {
  return fixed_rmw_cas(address(as_array(a), i, j, k, l), c, v);
}
template <typename T, int D0, int D1, int D2, int D3> WP_FUNC int32 len(const WP_FIXED&) { return D0; }
template <typename T, int D0, int D1, int D2, int D3> WP_FUNC void cg_accum(WP_FIXED&, const WP_FIXED&) {}
#undef WP_FIXED
#undef WP_FIXED_TEMPLATE

}  // namespace wp
