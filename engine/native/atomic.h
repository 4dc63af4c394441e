// Native library: atomics on array elements. wp::atomic_{add,sub,min,max,cas,exch,and,or,xor}
// (arr, i[, j, k, l], value) return the element's old value. CPU: __atomic builtins (integers
// natively, floats and half through compare-exchange loops on their bits); CUDA: native atomics
// where they exist, else CAS loops (8/16-bit types on their containing 32-bit word). Vector and
// matrix elements are updated component-wise. Also the adjoints of atomics and of array
// loads/stores (Warp's semantics).
#pragma once

#include "array.h"
#include "mat.h"
#include "quat.h"
#include "transform.h"

namespace wp {

// Raw bits of a scalar, and back (same size).
template <typename T> struct bits_t;
template <> struct bits_t<int8> { typedef uint8 type; };
template <> struct bits_t<uint8> { typedef uint8 type; };
template <> struct bits_t<int16> { typedef uint16 type; };
template <> struct bits_t<uint16> { typedef uint16 type; };
template <> struct bits_t<half> { typedef uint16 type; };
template <> struct bits_t<bfloat16> { typedef uint16 type; };
template <> struct bits_t<int32> { typedef uint32 type; };
template <> struct bits_t<uint32> { typedef uint32 type; };
template <> struct bits_t<float32> { typedef uint32 type; };
template <> struct bits_t<int64> { typedef uint64 type; };
template <> struct bits_t<uint64> { typedef uint64 type; };
template <> struct bits_t<float64> { typedef uint64 type; };

template <typename T> WP_FUNC typename bits_t<T>::type to_bits(T v) { return (typename bits_t<T>::type)v; }
template <> WP_FUNC uint16 to_bits<half>(half v) { return v.u; }
template <> WP_FUNC uint16 to_bits<bfloat16>(bfloat16 v) { return v.u; }
template <> WP_FUNC uint32 to_bits<float32>(float32 v) { return float_to_bits(v); }
template <> WP_FUNC uint64 to_bits<float64>(float64 v) { return double_to_bits(v); }
template <typename T> WP_FUNC T from_bits(typename bits_t<T>::type b) { return (T)b; }
template <> WP_FUNC half from_bits<half>(uint16 b) { return half::from_bits(b); }
template <> WP_FUNC bfloat16 from_bits<bfloat16>(uint16 b) { return bfloat16::from_bits(b); }
template <> WP_FUNC float32 from_bits<float32>(uint32 b) { return bits_to_float(b); }
template <> WP_FUNC float64 from_bits<float64>(uint64 b) { return bits_to_double(b); }

// Read-modify-write operations for the CAS loops.
struct atomic_op_add { template <typename T> WP_CALLABLE static T apply(T a, T b) { return add(a, b); } };
struct atomic_op_sub { template <typename T> WP_CALLABLE static T apply(T a, T b) { return sub(a, b); } };
// min/max as the scalar min/max (fmin/fmax for floats): a NaN slot takes the value, a NaN value
// leaves the slot.
struct atomic_op_min { template <typename T> WP_CALLABLE static T apply(T a, T b) { return (isnan(a) || b < a) ? b : a; } };
struct atomic_op_max { template <typename T> WP_CALLABLE static T apply(T a, T b) { return (isnan(a) || b > a) ? b : a; } };
struct atomic_op_exch { template <typename T> WP_CALLABLE static T apply(T, T b) { return b; } };
struct atomic_op_and { template <typename T> WP_CALLABLE static T apply(T a, T b) { return bit_and(a, b); } };
struct atomic_op_or { template <typename T> WP_CALLABLE static T apply(T a, T b) { return bit_or(a, b); } };
struct atomic_op_xor { template <typename T> WP_CALLABLE static T apply(T a, T b) { return bit_xor(a, b); } };

// Compare-and-swap loop: *p = Op(*p, v) atomically; returns the old value.
template <typename Op, typename T>
WP_FUNC T atomic_rmw(T* p, T v) {
  typedef typename bits_t<T>::type B;
#if WP_DEVICE_CODE
  if constexpr (sizeof(T) == 4) {
    unsigned int* w = (unsigned int*)p;
    unsigned int old = *(volatile unsigned int*)w, assumed;
    do {
      assumed = old;
      T nv = Op::apply(from_bits<T>((B)assumed), v);
      old = atomicCAS(w, assumed, (unsigned int)to_bits(nv));
    } while (old != assumed);
    return from_bits<T>((B)old);
  } else if constexpr (sizeof(T) == 8) {
    unsigned long long* w = (unsigned long long*)p;
    unsigned long long old = *(volatile unsigned long long*)w, assumed;
    do {
      assumed = old;
      T nv = Op::apply(from_bits<T>((B)assumed), v);
      old = atomicCAS(w, assumed, (unsigned long long)to_bits(nv));
    } while (old != assumed);
    return from_bits<T>((B)old);
  } else {  // 1 or 2 bytes: CAS the aligned 32-bit word that contains the element
    unsigned long long addr = (unsigned long long)p;
    unsigned int* w = (unsigned int*)(addr & ~3ull);
    unsigned int shift = (unsigned int)(addr & 3ull) * 8u;
    unsigned int mask = (sizeof(T) == 1 ? 0xffu : 0xffffu) << shift;
    unsigned int old = *(volatile unsigned int*)w, assumed;
    do {
      assumed = old;
      T cur = from_bits<T>((B)((assumed & mask) >> shift));
      T nv = Op::apply(cur, v);
      unsigned int nw = (assumed & ~mask) | (((unsigned int)to_bits(nv) << shift) & mask);
      old = atomicCAS(w, assumed, nw);
    } while (old != assumed);
    return from_bits<T>((B)((old & mask) >> shift));
  }
#else
  B* w = (B*)p;
  B old = __atomic_load_n(w, __ATOMIC_RELAXED);
  for (;;) {
    T nv = Op::apply(from_bits<T>(old), v);
    if (__atomic_compare_exchange_n(w, &old, to_bits(nv), true, __ATOMIC_ACQ_REL, __ATOMIC_RELAXED)) return from_bits<T>(old);
  }
#endif
}

// Scalar atomics on one address. Native paths where the hardware has them.
template <typename T>
WP_FUNC T atomic_add_ptr(T* p, T v) {
#if WP_DEVICE_CODE
  if constexpr (is_same_t<T, float32>::value) return atomicAdd(p, v);
  else if constexpr (is_same_t<T, float64>::value) return atomicAdd(p, v);
  else if constexpr (is_same_t<T, int32>::value) return atomicAdd(p, v);
  else if constexpr (is_same_t<T, uint32>::value) return atomicAdd(p, v);
  else if constexpr (sizeof(T) == 8) return (T)atomicAdd((unsigned long long*)p, (unsigned long long)v);
  else return atomic_rmw<atomic_op_add>(p, v);
#else
  if constexpr (is_float_t<T>::value) return atomic_rmw<atomic_op_add>(p, v);
  else return (T)__atomic_fetch_add(p, v, __ATOMIC_RELAXED);
#endif
}
template <typename T>
WP_FUNC T atomic_sub_ptr(T* p, T v) {
#if WP_DEVICE_CODE
  if constexpr (is_same_t<T, float32>::value || is_same_t<T, float64>::value) return atomicAdd(p, T(-v));
  else if constexpr (is_same_t<T, int32>::value || is_same_t<T, uint32>::value || sizeof(T) == 8) return atomic_add_ptr(p, neg(v));
  else return atomic_rmw<atomic_op_sub>(p, v);
#else
  if constexpr (is_float_t<T>::value) return atomic_rmw<atomic_op_sub>(p, v);
  else return (T)__atomic_fetch_sub(p, v, __ATOMIC_RELAXED);
#endif
}
// min/max: a NaN value never replaces a number; a NaN slot is replaced (atomic_op_min/max).
template <typename T>
WP_FUNC T atomic_min_ptr(T* p, T v) {
#if WP_DEVICE_CODE
  if constexpr (is_same_t<T, int32>::value || is_same_t<T, uint32>::value) return atomicMin(p, v);
  else if constexpr (is_same_t<T, int64>::value) return (T)atomicMin((long long*)p, (long long)v);
  else if constexpr (is_same_t<T, uint64>::value) return (T)atomicMin((unsigned long long*)p, (unsigned long long)v);
  else return atomic_rmw<atomic_op_min>(p, v);
#else
  if constexpr (is_float_t<T>::value) return atomic_rmw<atomic_op_min>(p, v);
  else {
    T old = __atomic_load_n(p, __ATOMIC_RELAXED);
    while (v < old && !__atomic_compare_exchange_n(p, &old, v, true, __ATOMIC_ACQ_REL, __ATOMIC_RELAXED)) {
    }
    return old;
  }
#endif
}
template <typename T>
WP_FUNC T atomic_max_ptr(T* p, T v) {
#if WP_DEVICE_CODE
  if constexpr (is_same_t<T, int32>::value || is_same_t<T, uint32>::value) return atomicMax(p, v);
  else if constexpr (is_same_t<T, int64>::value) return (T)atomicMax((long long*)p, (long long)v);
  else if constexpr (is_same_t<T, uint64>::value) return (T)atomicMax((unsigned long long*)p, (unsigned long long)v);
  else return atomic_rmw<atomic_op_max>(p, v);
#else
  if constexpr (is_float_t<T>::value) return atomic_rmw<atomic_op_max>(p, v);
  else {
    T old = __atomic_load_n(p, __ATOMIC_RELAXED);
    while (v > old && !__atomic_compare_exchange_n(p, &old, v, true, __ATOMIC_ACQ_REL, __ATOMIC_RELAXED)) {
    }
    return old;
  }
#endif
}
template <typename T>
WP_FUNC T atomic_exch_ptr(T* p, T v) {
#if WP_DEVICE_CODE
  if constexpr (sizeof(T) == 4) return from_bits<T>((typename bits_t<T>::type)atomicExch((unsigned int*)p, (unsigned int)to_bits(v)));
  else if constexpr (sizeof(T) == 8) return from_bits<T>((typename bits_t<T>::type)atomicExch((unsigned long long*)p, (unsigned long long)to_bits(v)));
  else return atomic_rmw<atomic_op_exch>(p, v);
#else
  typedef typename bits_t<T>::type B;
  return from_bits<T>(__atomic_exchange_n((B*)p, to_bits(v), __ATOMIC_ACQ_REL));
#endif
}
// Compares bit patterns (so a NaN can be matched, and -0.0 differs from +0.0).
template <typename T>
WP_FUNC T atomic_cas_ptr(T* p, T compare, T v) {
  typedef typename bits_t<T>::type B;
#if WP_DEVICE_CODE
  if constexpr (sizeof(T) == 4) return from_bits<T>((B)atomicCAS((unsigned int*)p, (unsigned int)to_bits(compare), (unsigned int)to_bits(v)));
  else if constexpr (sizeof(T) == 8)
    return from_bits<T>((B)atomicCAS((unsigned long long*)p, (unsigned long long)to_bits(compare), (unsigned long long)to_bits(v)));
  else {
    unsigned long long addr = (unsigned long long)p;
    unsigned int* w = (unsigned int*)(addr & ~3ull);
    unsigned int shift = (unsigned int)(addr & 3ull) * 8u;
    unsigned int mask = (sizeof(T) == 1 ? 0xffu : 0xffffu) << shift;
    unsigned int cmp = ((unsigned int)to_bits(compare) << shift) & mask;
    unsigned int old = *(volatile unsigned int*)w;
    for (;;) {
      if ((old & mask) != cmp) return from_bits<T>((B)((old & mask) >> shift));
      unsigned int nw = (old & ~mask) | (((unsigned int)to_bits(v) << shift) & mask);
      unsigned int prev = atomicCAS(w, old, nw);
      if (prev == old) return compare;
      old = prev;
    }
  }
#else
  B expected = to_bits(compare);
  __atomic_compare_exchange_n((B*)p, &expected, to_bits(v), false, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE);
  return from_bits<T>(expected);
#endif
}
template <typename T> WP_FUNC T atomic_and_ptr(T* p, T v) {
#if WP_DEVICE_CODE
  return atomic_rmw<atomic_op_and>(p, v);
#else
  return __atomic_fetch_and(p, v, __ATOMIC_ACQ_REL);
#endif
}
template <typename T> WP_FUNC T atomic_or_ptr(T* p, T v) {
#if WP_DEVICE_CODE
  return atomic_rmw<atomic_op_or>(p, v);
#else
  return __atomic_fetch_or(p, v, __ATOMIC_ACQ_REL);
#endif
}
template <typename T> WP_FUNC T atomic_xor_ptr(T* p, T v) {
#if WP_DEVICE_CODE
  return atomic_rmw<atomic_op_xor>(p, v);
#else
  return __atomic_fetch_xor(p, v, __ATOMIC_ACQ_REL);
#endif
}

// Composite element types: component-wise (each component is atomic, the whole is not).
#define WP_ATOMIC_COMPOSITE(op) \
  template <unsigned N, typename T> \
  WP_FUNC vec_t<N, T> atomic_##op##_ptr(vec_t<N, T>* p, vec_t<N, T> v) { \
    vec_t<N, T> old; \
    for (unsigned i = 0; i < N; ++i) old.c[i] = atomic_##op##_ptr(&p->c[i], v.c[i]); \
    return old; \
  } \
  template <unsigned R, unsigned C, typename T> \
  WP_FUNC mat_t<R, C, T> atomic_##op##_ptr(mat_t<R, C, T>* p, mat_t<R, C, T> v) { \
    mat_t<R, C, T> old; \
    for (unsigned i = 0; i < R; ++i) \
      for (unsigned j = 0; j < C; ++j) old.data[i][j] = atomic_##op##_ptr(&p->data[i][j], v.data[i][j]); \
    return old; \
  } \
  template <typename T> \
  WP_FUNC quat_t<T> atomic_##op##_ptr(quat_t<T>* p, quat_t<T> v) { \
    quat_t<T> old; \
    for (int i = 0; i < 4; ++i) old[i] = atomic_##op##_ptr(&(*p)[i], v[i]); \
    return old; \
  } \
  template <typename T> \
  WP_FUNC transform_t<T> atomic_##op##_ptr(transform_t<T>* p, transform_t<T> v) { \
    transform_t<T> old; \
    old.p = atomic_##op##_ptr(&p->p, v.p); \
    old.q = atomic_##op##_ptr(&p->q, v.q); \
    return old; \
  }
WP_ATOMIC_COMPOSITE(add)
WP_ATOMIC_COMPOSITE(sub)
WP_ATOMIC_COMPOSITE(min)
WP_ATOMIC_COMPOSITE(max)
WP_ATOMIC_COMPOSITE(and)
WP_ATOMIC_COMPOSITE(or)
WP_ATOMIC_COMPOSITE(xor)
#undef WP_ATOMIC_COMPOSITE

// Array forms: wp::atomic_add(arr, i[, j, k, l], value) -> old value.
#define WP_ATOMIC_ARRAY(op) \
  template <typename T> WP_FUNC T atomic_##op(const array_t<T>& a, int64 i, typename type_identity_t<T>::type v) { \
    return atomic_##op##_ptr(address(a, i), v); \
  } \
  template <typename T> WP_FUNC T atomic_##op(const array_t<T>& a, int64 i, int64 j, typename type_identity_t<T>::type v) { \
    return atomic_##op##_ptr(address(a, i, j), v); \
  } \
  template <typename T> WP_FUNC T atomic_##op(const array_t<T>& a, int64 i, int64 j, int64 k, typename type_identity_t<T>::type v) { \
    return atomic_##op##_ptr(address(a, i, j, k), v); \
  } \
  template <typename T> \
  WP_FUNC T atomic_##op(const array_t<T>& a, int64 i, int64 j, int64 k, int64 l, typename type_identity_t<T>::type v) { \
    return atomic_##op##_ptr(address(a, i, j, k, l), v); \
  }
WP_ATOMIC_ARRAY(add)
WP_ATOMIC_ARRAY(sub)
WP_ATOMIC_ARRAY(min)
WP_ATOMIC_ARRAY(max)
WP_ATOMIC_ARRAY(exch)
WP_ATOMIC_ARRAY(and)
WP_ATOMIC_ARRAY(or)
WP_ATOMIC_ARRAY(xor)
#undef WP_ATOMIC_ARRAY
template <typename T> WP_FUNC T atomic_cas(const array_t<T>& a, int64 i, typename type_identity_t<T>::type c, typename type_identity_t<T>::type v) {
  return atomic_cas_ptr(address(a, i), c, v);
}
template <typename T>
WP_FUNC T atomic_cas(const array_t<T>& a, int64 i, int64 j, typename type_identity_t<T>::type c, typename type_identity_t<T>::type v) {
  return atomic_cas_ptr(address(a, i, j), c, v);
}
template <typename T>
WP_FUNC T atomic_cas(const array_t<T>& a, int64 i, int64 j, int64 k, typename type_identity_t<T>::type c, typename type_identity_t<T>::type v) {
  return atomic_cas_ptr(address(a, i, j, k), c, v);
}
template <typename T>
WP_FUNC T atomic_cas(const array_t<T>& a, int64 i, int64 j, int64 k, int64 l, typename type_identity_t<T>::type c,
                     typename type_identity_t<T>::type v) {
  return atomic_cas_ptr(address(a, i, j, k, l), c, v);
}

// ---------------------------------------------------------------------------------------------
// Adjoints (Warp): `adj_a` is the gradient array of `a` (data == nullptr: no gradient wanted).
// Reading a[i] accumulates the read's adjoint into adj_a[i] (atomically: many threads may read
// the same element). Writing a[i] = v moves adj_a[i] into adj_v (adj_store). atomic_add/sub: adj_v +=/-=
// adj_a[i]. atomic_min/max: adj_v += adj_a[i] when v is the value the element holds (it won).
template <typename T> WP_FUNC void adj_load(const array_t<T>& adj_a, int64 i, const T& adj_ret) {
  if (adj_a.data) atomic_add_ptr(address(adj_a, i), adj_ret);
}
template <typename T> WP_FUNC void adj_load(const array_t<T>& adj_a, int64 i, int64 j, const T& adj_ret) {
  if (adj_a.data) atomic_add_ptr(address(adj_a, i, j), adj_ret);
}
template <typename T> WP_FUNC void adj_load(const array_t<T>& adj_a, int64 i, int64 j, int64 k, const T& adj_ret) {
  if (adj_a.data) atomic_add_ptr(address(adj_a, i, j, k), adj_ret);
}
template <typename T> WP_FUNC void adj_load(const array_t<T>& adj_a, int64 i, int64 j, int64 k, int64 l, const T& adj_ret) {
  if (adj_a.data) atomic_add_ptr(address(adj_a, i, j, k, l), adj_ret);
}
// A store's adjoint: adj_v += adj_a[i], which is then cleared when adj_a is the gradient of
// the stored array (ARRAY_FLAG_CONSUME_ADJOINT): the overwritten value receives no gradient.
template <typename T> WP_FUNC void adj_store_at(const array_t<T>& adj_a, T* g, T& adj_v) {
  adj_v += *g;
  if (adj_a.flags & ARRAY_FLAG_CONSUME_ADJOINT) *g = T{};
}
template <typename T> WP_FUNC void adj_store(const array_t<T>& adj_a, int64 i, T& adj_v) {
  if (adj_a.data) adj_store_at(adj_a, address(adj_a, i), adj_v);
}
template <typename T> WP_FUNC void adj_store(const array_t<T>& adj_a, int64 i, int64 j, T& adj_v) {
  if (adj_a.data) adj_store_at(adj_a, address(adj_a, i, j), adj_v);
}
template <typename T> WP_FUNC void adj_store(const array_t<T>& adj_a, int64 i, int64 j, int64 k, T& adj_v) {
  if (adj_a.data) adj_store_at(adj_a, address(adj_a, i, j, k), adj_v);
}
template <typename T> WP_FUNC void adj_store(const array_t<T>& adj_a, int64 i, int64 j, int64 k, int64 l, T& adj_v) {
  if (adj_a.data) adj_store_at(adj_a, address(adj_a, i, j, k, l), adj_v);
}
// Atomic adjoints in the generic convention adj_f(args..., adj_args&..., adj_ret):
//   adj_atomic_add(a, i[, j, k, l], v, adj_a, adj_i[, adj_j, ...], adj_v, adj_ret)
// where adj_a is the gradient array of `a`; index adjoints are ignored.
template <typename T> WP_FUNC void adj_atomic_minmax_ptr(const T* p, const T& v, const T* g, T& adj_v) {
  if (g && (*p == v || (isnan(*p) && isnan(v)))) adj_v += *g;   // v won (also NaN over NaN)
}
template <unsigned N, typename T> WP_FUNC void adj_atomic_minmax_ptr(const vec_t<N, T>* p, const vec_t<N, T>& v, const vec_t<N, T>* g, vec_t<N, T>& adj_v) {
  if (g)
    for (unsigned c = 0; c < N; ++c)
      if (p->c[c] == v.c[c]) adj_v.c[c] += g->c[c];
}
template <unsigned R, unsigned C, typename T>
WP_FUNC void adj_atomic_minmax_ptr(const mat_t<R, C, T>* p, const mat_t<R, C, T>& v, const mat_t<R, C, T>* g, mat_t<R, C, T>& adj_v) {
  if (g)
    for (unsigned i = 0; i < R; ++i)
      for (unsigned j = 0; j < C; ++j)
        if (p->data[i][j] == v.data[i][j]) adj_v.data[i][j] += g->data[i][j];
}
template <typename T> WP_FUNC void adj_atomic_minmax_ptr(const quat_t<T>* p, const quat_t<T>& v, const quat_t<T>* g, quat_t<T>& adj_v) {
  if (g)
    for (int c = 0; c < 4; ++c)
      if ((*p)[c] == v[c]) adj_v[c] += (*g)[c];
}
template <typename T>
WP_FUNC void adj_atomic_minmax_ptr(const transform_t<T>* p, const transform_t<T>& v, const transform_t<T>* g, transform_t<T>& adj_v) {
  if (!g) return;
  adj_atomic_minmax_ptr(&p->p, v.p, &g->p, adj_v.p);
  adj_atomic_minmax_ptr(&p->q, v.q, &g->q, adj_v.q);
}
#define WP_ADJ_ATOMIC(op, BODY) \
  template <typename T, typename I0, typename J0> \
  WP_FUNC void adj_atomic_##op(const array_t<T>& a, I0 i, const T& v, const array_t<T>& adj_a, J0&, T& adj_v, const T&) { \
    T* g = adj_a.data ? address(adj_a, i) : (T*)nullptr; \
    T* p = address(a, i); \
    BODY; \
  } \
  template <typename T, typename I0, typename I1, typename J0, typename J1> \
  WP_FUNC void adj_atomic_##op(const array_t<T>& a, I0 i, I1 j, const T& v, const array_t<T>& adj_a, J0&, J1&, T& adj_v, const T&) { \
    T* g = adj_a.data ? address(adj_a, i, j) : (T*)nullptr; \
    T* p = address(a, i, j); \
    BODY; \
  } \
  template <typename T, typename I0, typename I1, typename I2, typename J0, typename J1, typename J2> \
  WP_FUNC void adj_atomic_##op(const array_t<T>& a, I0 i, I1 j, I2 k, const T& v, const array_t<T>& adj_a, J0&, J1&, J2&, T& adj_v, \
                               const T&) { \
    T* g = adj_a.data ? address(adj_a, i, j, k) : (T*)nullptr; \
    T* p = address(a, i, j, k); \
    BODY; \
  } \
  template <typename T, typename I0, typename I1, typename I2, typename I3, typename J0, typename J1, typename J2, typename J3> \
  WP_FUNC void adj_atomic_##op(const array_t<T>& a, I0 i, I1 j, I2 k, I3 l, const T& v, const array_t<T>& adj_a, J0&, J1&, J2&, J3&, \
                               T& adj_v, const T&) { \
    T* g = adj_a.data ? address(adj_a, i, j, k, l) : (T*)nullptr; \
    T* p = address(a, i, j, k, l); \
    BODY; \
  }
WP_ADJ_ATOMIC(add, (void)p; (void)v; if (g) adj_v += *g)
WP_ADJ_ATOMIC(sub, (void)p; (void)v; if (g) adj_v -= *g)
WP_ADJ_ATOMIC(min, adj_atomic_minmax_ptr(p, v, g, adj_v))
WP_ADJ_ATOMIC(max, adj_atomic_minmax_ptr(p, v, g, adj_v))
#undef WP_ADJ_ATOMIC

}  // namespace wp
