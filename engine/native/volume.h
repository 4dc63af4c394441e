// Kernel-side wp.Volume: voxel lookups and stores, closest and trilinear sampling (with the
// sample's spatial gradient), sampling through an index grid into a user array, voxel indices,
// and the index/world transforms; the adjoints of the differentiable ones. A volume is the
// daemon's build of 8x8x8 leaves (geometry_abi.h): a voxel outside every leaf reads the
// background, a store there does nothing. Values are read and written in the caller's values
// array. Asking a volume for another value type than it holds is a launch error at the call's
// line (Warp silently returns zero). No standard library headers.
#pragma once

#include "bvh.h"
#include "mat.h"

namespace wp {

// The volume type code of a kernel value type, the scalar of its interpolation weights, and the
// type of its spatial gradient (vec3 for scalars, an N x 3 matrix for N-vectors).
template <typename T> struct volume_value_t;
#define WP_VOLUME_SCALAR(T, CODE)                 \
  template <> struct volume_value_t<T> {          \
    static constexpr uint32 code = CODE;          \
    typedef T scalar;                             \
    typedef vec_t<3, T> grad;                     \
  };
WP_VOLUME_SCALAR(float32, VOLUME_FLOAT)
WP_VOLUME_SCALAR(float64, VOLUME_DOUBLE)
WP_VOLUME_SCALAR(int32, VOLUME_INT32)
WP_VOLUME_SCALAR(int64, VOLUME_INT64)
WP_VOLUME_SCALAR(uint32, VOLUME_UINT32)
#undef WP_VOLUME_SCALAR
#define WP_VOLUME_VECTOR(N, T, CODE)              \
  template <> struct volume_value_t<vec_t<N, T>> { \
    static constexpr uint32 code = CODE;          \
    typedef T scalar;                             \
    typedef mat_t<N, 3, T> grad;                  \
  };
WP_VOLUME_VECTOR(3, float32, VOLUME_VEC3F)
WP_VOLUME_VECTOR(3, float64, VOLUME_VEC3D)
WP_VOLUME_VECTOR(4, float32, VOLUME_VEC4F)
WP_VOLUME_VECTOR(4, float64, VOLUME_VEC4D)
#undef WP_VOLUME_VECTOR

WP_FUNC const char* volume_type_name(uint32 t) {
  switch (t) {
    case VOLUME_FLOAT: return "float";
    case VOLUME_DOUBLE: return "double";
    case VOLUME_INT32: return "int32";
    case VOLUME_INT64: return "int64";
    case VOLUME_UINT32: return "uint32";
    case VOLUME_VEC3F: return "Vec3f";
    case VOLUME_VEC3D: return "Vec3d";
    case VOLUME_VEC4F: return "Vec4f";
    case VOLUME_VEC4D: return "Vec4d";
    case VOLUME_INDEX: return "Index";
    case VOLUME_ONINDEX: return "OnIndex";
    default: return "unknown";
  }
}

// The volume `id`, or null after reporting a launch error (not a live volume of this session,
// or, with want != 0, a volume of another value type).
WP_FUNC const geometry_desc_t* volume_resolve(const launch_context_t* ctx, int32 fid, int32 line, const char* fn,
                                              uint64 id, uint32 want) {
  const geometry_desc_t* g = geometry_resolve(ctx, fid, line, fn, id, GEOMETRY_VOLUME);
  if (g && want != 0 && g->vol_type != want) {
    geometry_msg_t m;
    m.str(fn).str(": the volume holds ").str(volume_type_name(g->vol_type)).str(" values, not ").str(volume_type_name(want));
    geometry_report(ctx, fid, line, m);
    return nullptr;
  }
  return g;
}

// The position of the leaf holding voxel (i, j, k), or -1.
WP_FUNC int32 volume_find_leaf(const geometry_desc_t* g, int32 i, int32 j, int32 k) {
  const int32 kx = i >> 3, ky = j >> 3, kz = k >> 3;
  int64 slot = volume_leaf_hash(kx, ky, kz, g->vol_table_mask);
  for (int32 p = 0; p < g->vol_max_probe; ++p) {
    const int32* e = g->vol_table + 4 * slot;   // one 16-byte entry: key and position
    if (e[3] < 0) return -1;
    if (e[0] == kx && e[1] == ky && e[2] == kz) return e[3];
    slot = (slot + 1) & g->vol_table_mask;
  }
  return -1;
}

WP_FUNC int32 volume_voxel_offset(int32 i, int32 j, int32 k) { return ((i & 7) << 6) | ((j & 7) << 3) | (k & 7); }

// The last leaf a sampler found: the 8 voxels of a trilinear stencil mostly share one leaf, so
// most reads skip the table search.
struct volume_leaf_cache_t {
  int32 key[3];
  int32 leaf;
  WP_FUNC volume_leaf_cache_t() : key{0x7fffffff, 0, 0}, leaf(-1) {}
  WP_FUNC int32 find(const geometry_desc_t* g, int32 i, int32 j, int32 k) {
    const int32 kx = i >> 3, ky = j >> 3, kz = k >> 3;
    if (kx != key[0] || ky != key[1] || kz != key[2]) {
      key[0] = kx;
      key[1] = ky;
      key[2] = kz;
      leaf = volume_find_leaf(g, i, j, k);
    }
    return leaf;
  }
};

WP_FUNC int32 volume_popcount(uint64 w) {
#if WP_DEVICE_CODE
  return __popcll(w);
#else
  return __builtin_popcountll(w);
#endif
}

// The voxel's index (Warp's volume_lookup_index): leaf * 512 + offset for value and Index grids,
// the rank among the active voxels for OnIndex grids; -1 outside the leaves (or inactive, OnIndex).
WP_FUNC int64 volume_voxel_index_in(const geometry_desc_t* g, int32 leaf, int32 i, int32 j, int32 k) {
  if (leaf < 0) return -1;
  const int32 off = volume_voxel_offset(i, j, k);
  if (g->vol_type != VOLUME_ONINDEX) return (int64)leaf * VOLUME_LEAF_VOXELS + off;
  const uint64* m = g->vol_masks + 8 * (int64)leaf;
  const int32 w = off >> 6, b = off & 63;
  if (!((m[w] >> b) & 1ull)) return -1;
  int64 idx = g->vol_prefix[leaf];
  for (int32 q = 0; q < w; ++q) idx += volume_popcount(m[q]);
  return idx + volume_popcount(m[w] & ((1ull << b) - 1ull));
}
WP_FUNC int64 volume_voxel_index(const geometry_desc_t* g, int32 i, int32 j, int32 k) {
  return volume_voxel_index_in(g, volume_find_leaf(g, i, j, k), i, j, k);
}

// Integer voxel coordinate of a float one, clamped so that far points stay outside every leaf.
WP_FUNC int32 volume_coord(float32 x) {
  if (!(x == x)) return 1 << 30 | 8;   // NaN: outside (leaves stay within +-2^30)
  if (x > 1.5e9f) return 1500000000;
  if (x < -1.5e9f) return -1500000000;
  return (int32)x;
}

// The background value (bytes copied: vol_background is float64 storage).
template <typename T>
WP_FUNC T volume_background(const geometry_desc_t* g) {
  T v;
  const char* src = (const char*)g->vol_background;
  char* dst = (char*)&v;
  for (unsigned b = 0; b < sizeof(T); ++b) dst[b] = src[b];
  return v;
}

// Readers: values stored in the volume, or an external array through the voxel index.
template <typename T>
struct volume_values_reader {
  const geometry_desc_t* g;
  mutable volume_leaf_cache_t cache;
  WP_FUNC explicit volume_values_reader(const geometry_desc_t* desc) : g(desc) {}
  WP_FUNC T read(int32 i, int32 j, int32 k) const {
    const int32 leaf = cache.find(g, i, j, k);
    if (leaf < 0) return volume_background<T>(g);
    return ((const T*)g->vol_values)[(int64)leaf * VOLUME_LEAF_VOXELS + volume_voxel_offset(i, j, k)];
  }
  WP_FUNC void adj_read(int32, int32, int32, const T&) const {}
};

template <typename T>
struct volume_index_reader {
  const launch_context_t* ctx;
  int32 fid, line;
  const geometry_desc_t* g;
  array_t<T> data;
  T background;
  array_t<T> adj_data;
  T* adj_background;
  mutable volume_leaf_cache_t cache;
  // The voxel's index into data, -1 for the background; -2 after reporting an index past data's end.
  WP_FUNC int64 slot(int32 i, int32 j, int32 k) const {
    const int64 idx = volume_voxel_index_in(g, cache.find(g, i, j, k), i, j, k);
    if (idx < 0) return -1;
    if (idx >= data.shape[0]) {
      geometry_msg_t m;
      m.str("volume_sample_index: voxel index ").num(idx).str(" is out of range for voxel_data of ").num(data.shape[0]).str(" values");
      geometry_report(ctx, fid, line, m);
      return -2;
    }
    return idx;
  }
  WP_FUNC T read(int32 i, int32 j, int32 k) const {
    const int64 s = slot(i, j, k);
    return s >= 0 ? load(data, s) : background;
  }
  WP_FUNC void adj_read(int32 i, int32 j, int32 k, const T& adj) const {
    const int64 s = slot(i, j, k);
    if (s >= 0) adj_load(adj_data, s, adj);
    else if (s == -1 && adj_background) *adj_background = add(*adj_background, adj);
  }
};

// Products of a value with the weights and their derivatives, for scalars and vectors alike.
template <typename S> WP_FUNC vec_t<3, S> volume_outer(S v, const vec_t<3, S>& w) { return mul(w, v); }
template <unsigned N, typename S> WP_FUNC mat_t<N, 3, S> volume_outer(const vec_t<N, S>& v, const vec_t<3, S>& w) {
  return outer(v, w);
}
template <typename S> WP_FUNC S volume_rmul(const vec_t<3, S>& grad, const vec_t<3, S>& w) { return dot(grad, w); }
template <unsigned N, typename S> WP_FUNC vec_t<N, S> volume_rmul(const mat_t<N, 3, S>& grad, const vec_t<3, S>& w) {
  return mul(grad, w);
}
template <typename S> WP_FUNC S volume_dot(S a, S b) { return a * b; }
template <unsigned N, typename S> WP_FUNC S volume_dot(const vec_t<N, S>& a, const vec_t<N, S>& b) { return dot(a, b); }
// v^T adj_grad for the Hessian term: a 3-vector.
template <typename S> WP_FUNC vec_t<3, S> volume_vgrad(S v, const vec_t<3, S>& adj_grad) { return mul(adj_grad, v); }
template <unsigned N, typename S> WP_FUNC vec_t<3, S> volume_vgrad(const vec_t<N, S>& v, const mat_t<N, 3, S>& adj_grad) {
  return mul(transpose(adj_grad), v);
}

// The 8 corners of the trilinear stencil at uvw, with their weights and weight gradients.
struct volume_stencil_t {
  int32 base[3];
  float32 w[3][2];
  WP_FUNC explicit volume_stencil_t(const vec3& uvw) {
    for (int d = 0; d < 3; ++d) {
      const float32 f = floor(uvw[d]);
      base[d] = volume_coord(f);
      const float32 t = uvw[d] - f;
      w[d][0] = 1.0f - t;
      w[d][1] = t;
    }
  }
  WP_FUNC float32 weight(int32 c) const { return w[0][(c >> 2) & 1] * w[1][(c >> 1) & 1] * w[2][c & 1]; }
  WP_FUNC vec3 weight_grad(int32 c) const {
    const int32 x = (c >> 2) & 1, y = (c >> 1) & 1, z = c & 1;
    return vec3((x ? 1.0f : -1.0f) * w[1][y] * w[2][z], (y ? 1.0f : -1.0f) * w[0][x] * w[2][z],
                (z ? 1.0f : -1.0f) * w[0][x] * w[1][y]);
  }
  // d(weight_grad)/d(uvw): symmetric, zero diagonal.
  WP_FUNC mat33 weight_hess(int32 c) const {
    const int32 x = (c >> 2) & 1, y = (c >> 1) & 1, z = c & 1;
    const float32 sx = x ? 1.0f : -1.0f, sy = y ? 1.0f : -1.0f, sz = z ? 1.0f : -1.0f;
    const float32 xy = sx * sy * w[2][z], xz = sx * sz * w[1][y], yz = sy * sz * w[0][x];
    return mat33(0.0f, xy, xz, xy, 0.0f, yz, xz, yz, 0.0f);
  }
  WP_FUNC int32 i(int32 c) const { return base[0] + ((c >> 2) & 1); }
  WP_FUNC int32 j(int32 c) const { return base[1] + ((c >> 1) & 1); }
  WP_FUNC int32 k(int32 c) const { return base[2] + (c & 1); }
};

WP_FUNC void volume_closest(const vec3& uvw, int32& i, int32& j, int32& k) {
  i = volume_coord(round(uvw[0]));
  j = volume_coord(round(uvw[1]));
  k = volume_coord(round(uvw[2]));
}

template <typename T, typename R>
WP_FUNC T volume_sample_with(const R& r, const vec3& uvw, int32 mode, typename volume_value_t<T>::grad* grad) {
  typedef typename volume_value_t<T>::scalar S;
  if (grad) *grad = typename volume_value_t<T>::grad();
  if (mode != 1) {   // CLOSEST (and any other mode, as Warp's samplers)
    if (mode != 0) return T();
    int32 i, j, k;
    volume_closest(uvw, i, j, k);
    return r.read(i, j, k);
  }
  const volume_stencil_t st(uvw);
  T val = T();
  for (int32 c = 0; c < 8; ++c) {
    const T v = r.read(st.i(c), st.j(c), st.k(c));
    val = add(val, mul(v, S(st.weight(c))));
    if (grad) *grad = add(*grad, volume_outer(v, vec_t<3, S>(st.weight_grad(c))));
  }
  return val;
}

template <typename T, typename R>
WP_FUNC void adj_volume_sample_with(const R& r, const vec3& uvw, int32 mode, vec3& adj_uvw,
                                    const typename volume_value_t<T>::grad* adj_grad, const T& adj_ret) {
  typedef typename volume_value_t<T>::scalar S;
  if (mode != 1) {
    if (mode != 0) return;
    int32 i, j, k;
    volume_closest(uvw, i, j, k);
    r.adj_read(i, j, k, adj_ret);
    return;
  }
  const volume_stencil_t st(uvw);
  for (int32 c = 0; c < 8; ++c) {
    const T v = r.read(st.i(c), st.j(c), st.k(c));
    const vec_t<3, S> wg(st.weight_grad(c));
    adj_uvw = add(adj_uvw, vec3(mul(wg, volume_dot(v, adj_ret))));
    T adj_v = mul(adj_ret, S(st.weight(c)));
    if (adj_grad) {
      adj_uvw = add(adj_uvw, vec3(mul(mat_t<3, 3, S>(st.weight_hess(c)), volume_vgrad(v, *adj_grad))));
      adj_v = add(adj_v, volume_rmul(*adj_grad, wg));
    }
    r.adj_read(st.i(c), st.j(c), st.k(c), adj_v);
  }
}

// ---------------------------------------------------------------------------------------------
// Builtins. Each takes (ctx, function id, line) first (kBuiltinNeedsLoc), adjoints too.

template <typename T>
WP_FUNC T volume_lookup_typed(const launch_context_t* ctx, int32 fid, int32 line, const char* fn, uint64 id, int32 i,
                              int32 j, int32 k) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, fn, id, volume_value_t<T>::code);
  if (!g) return T();
  return volume_values_reader<T>(g).read(i, j, k);
}
template <typename T>
WP_FUNC T volume_lookup(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k,
                        const T&) {
  return volume_lookup_typed<T>(ctx, fid, line, "volume_lookup", id, i, j, k);
}
WP_FUNC float32 volume_lookup_f(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k) {
  return volume_lookup_typed<float32>(ctx, fid, line, "volume_lookup_f", id, i, j, k);
}
WP_FUNC int32 volume_lookup_i(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k) {
  return volume_lookup_typed<int32>(ctx, fid, line, "volume_lookup_i", id, i, j, k);
}
WP_FUNC vec3 volume_lookup_v(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k) {
  return volume_lookup_typed<vec3>(ctx, fid, line, "volume_lookup_v", id, i, j, k);
}

template <typename T>
WP_FUNC void volume_store_typed(const launch_context_t* ctx, int32 fid, int32 line, const char* fn, uint64 id, int32 i,
                                int32 j, int32 k, const T& value) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, fn, id, volume_value_t<T>::code);
  if (!g) return;
  const int32 leaf = volume_find_leaf(g, i, j, k);
  if (leaf < 0) return;   // outside the leaves: the background stays
  ((T*)g->vol_values)[(int64)leaf * VOLUME_LEAF_VOXELS + volume_voxel_offset(i, j, k)] = value;
}
template <typename T>
WP_FUNC void volume_store(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k,
                          const T& value) {
  volume_store_typed<T>(ctx, fid, line, "volume_store", id, i, j, k, value);
}
WP_FUNC void volume_store_f(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k,
                            float32 value) {
  volume_store_typed<float32>(ctx, fid, line, "volume_store_f", id, i, j, k, value);
}
WP_FUNC void volume_store_i(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k,
                            int32 value) {
  volume_store_typed<int32>(ctx, fid, line, "volume_store_i", id, i, j, k, value);
}
WP_FUNC void volume_store_v(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k,
                            const vec3& value) {
  volume_store_typed<vec3>(ctx, fid, line, "volume_store_v", id, i, j, k, value);
}

// Sampling of stored values.
template <typename T>
WP_FUNC T volume_sample_typed(const launch_context_t* ctx, int32 fid, int32 line, const char* fn, uint64 id,
                              const vec3& uvw, int32 mode, typename volume_value_t<T>::grad* grad) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, fn, id, volume_value_t<T>::code);
  if (!g) {
    if (grad) *grad = typename volume_value_t<T>::grad();
    return T();
  }
  return volume_sample_with<T>(volume_values_reader<T>(g), uvw, mode, grad);
}
template <typename T>
WP_FUNC void adj_volume_sample_typed(const launch_context_t* ctx, int32 fid, int32 line, const char* fn, uint64 id,
                                     const vec3& uvw, int32 mode, vec3& adj_uvw,
                                     const typename volume_value_t<T>::grad* adj_grad, const T& adj_ret) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, fn, id, volume_value_t<T>::code);
  if (g) adj_volume_sample_with<T>(volume_values_reader<T>(g), uvw, mode, adj_uvw, adj_grad, adj_ret);
}

template <typename T>
WP_FUNC T volume_sample(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw, int32 mode,
                        const T&) {
  return volume_sample_typed<T>(ctx, fid, line, "volume_sample", id, uvw, mode, nullptr);
}
template <typename T, typename A0, typename A2, typename A3>
WP_FUNC void adj_volume_sample(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw, int32 mode,
                               const T&, A0&, vec3& adj_uvw, A2&, A3&, const T& adj_ret) {
  adj_volume_sample_typed<T>(ctx, fid, line, "volume_sample", id, uvw, mode, adj_uvw, nullptr, adj_ret);
}
WP_FUNC float32 volume_sample_f(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw, int32 mode) {
  return volume_sample_typed<float32>(ctx, fid, line, "volume_sample_f", id, uvw, mode, nullptr);
}
template <typename A0, typename A2>
WP_FUNC void adj_volume_sample_f(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                 int32 mode, A0&, vec3& adj_uvw, A2&, float32 adj_ret) {
  adj_volume_sample_typed<float32>(ctx, fid, line, "volume_sample_f", id, uvw, mode, adj_uvw, nullptr, adj_ret);
}
WP_FUNC vec3 volume_sample_v(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw, int32 mode) {
  return volume_sample_typed<vec3>(ctx, fid, line, "volume_sample_v", id, uvw, mode, nullptr);
}
template <typename A0, typename A2>
WP_FUNC void adj_volume_sample_v(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                 int32 mode, A0&, vec3& adj_uvw, A2&, const vec3& adj_ret) {
  adj_volume_sample_typed<vec3>(ctx, fid, line, "volume_sample_v", id, uvw, mode, adj_uvw, nullptr, adj_ret);
}
WP_FUNC int32 volume_sample_i(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw) {
  return volume_sample_typed<int32>(ctx, fid, line, "volume_sample_i", id, uvw, 0, nullptr);
}

// With the spatial gradient (Warp's out-parameter `grad`: the second result, which sema assigns
// to the argument).
template <typename T>
WP_FUNC void volume_sample_grad(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                int32 mode, const T&, T& val, typename volume_value_t<T>::grad& grad) {
  val = volume_sample_typed<T>(ctx, fid, line, "volume_sample_grad", id, uvw, mode, &grad);
}
template <typename T, typename A0, typename A2, typename A3>
WP_FUNC void adj_volume_sample_grad(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                    int32 mode, const T&, const T&, const typename volume_value_t<T>::grad&, A0&,
                                    vec3& adj_uvw, A2&, A3&, const T& adj_val,
                                    const typename volume_value_t<T>::grad& adj_grad) {
  adj_volume_sample_typed<T>(ctx, fid, line, "volume_sample_grad", id, uvw, mode, adj_uvw, &adj_grad, adj_val);
}
WP_FUNC void volume_sample_grad_f(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                  int32 mode, float32& val, vec3& grad) {
  val = volume_sample_typed<float32>(ctx, fid, line, "volume_sample_grad_f", id, uvw, mode, &grad);
}
template <typename A0, typename A2>
WP_FUNC void adj_volume_sample_grad_f(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                      int32 mode, float32, const vec3&, A0&, vec3& adj_uvw, A2&, float32 adj_val,
                                      const vec3& adj_grad) {
  adj_volume_sample_typed<float32>(ctx, fid, line, "volume_sample_grad_f", id, uvw, mode, adj_uvw, &adj_grad, adj_val);
}

// Sampling an external array through the voxel index (any volume; index grids mainly).
template <typename T>
WP_FUNC volume_index_reader<T> volume_index_reader_of(const launch_context_t* ctx, int32 fid, int32 line,
                                                      const geometry_desc_t* g, const array_t<T>& data,
                                                      const T& background, const array_t<T>* adj_data,
                                                      T* adj_background) {
  volume_index_reader<T> r;
  r.ctx = ctx;
  r.fid = fid;
  r.line = line;
  r.g = g;
  r.data = data;
  r.background = background;
  if (adj_data) r.adj_data = *adj_data;
  else r.adj_data.data = nullptr;
  r.adj_background = adj_background;
  return r;
}
template <typename T>
WP_FUNC T volume_sample_index(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw, int32 mode,
                              const array_t<T>& voxel_data, const T& background) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, "volume_sample_index", id, 0);
  if (!g) return T();
  return volume_sample_with<T>(volume_index_reader_of<T>(ctx, fid, line, g, voxel_data, background, nullptr, nullptr), uvw,
                               mode, nullptr);
}
template <typename T, typename A0, typename A2>
WP_FUNC void adj_volume_sample_index(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                     int32 mode, const array_t<T>& voxel_data, const T& background, A0&, vec3& adj_uvw,
                                     A2&, array_t<T>& adj_voxel_data, T& adj_background, const T& adj_ret) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, "volume_sample_index", id, 0);
  if (!g) return;
  adj_volume_sample_with<T>(volume_index_reader_of<T>(ctx, fid, line, g, voxel_data, background, &adj_voxel_data, &adj_background),
                            uvw, mode, adj_uvw, nullptr, adj_ret);
}
template <typename T>
WP_FUNC void volume_sample_grad_index(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                      int32 mode, const array_t<T>& voxel_data, const T& background, T& val,
                                      typename volume_value_t<T>::grad& grad) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, "volume_sample_grad_index", id, 0);
  if (!g) {
    grad = typename volume_value_t<T>::grad();
    val = T();
    return;
  }
  val = volume_sample_with<T>(volume_index_reader_of<T>(ctx, fid, line, g, voxel_data, background, nullptr, nullptr), uvw,
                              mode, &grad);
}
template <typename T, typename A0, typename A2>
WP_FUNC void adj_volume_sample_grad_index(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec3& uvw,
                                          int32 mode, const array_t<T>& voxel_data, const T& background, const T&,
                                          const typename volume_value_t<T>::grad&, A0&, vec3& adj_uvw, A2&,
                                          array_t<T>& adj_voxel_data, T& adj_background, const T& adj_val,
                                          const typename volume_value_t<T>::grad& adj_grad) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, "volume_sample_grad_index", id, 0);
  if (!g) return;
  adj_volume_sample_with<T>(volume_index_reader_of<T>(ctx, fid, line, g, voxel_data, background, &adj_voxel_data, &adj_background),
                            uvw, mode, adj_uvw, &adj_grad, adj_val);
}

WP_FUNC int32 volume_lookup_index(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, int32 i, int32 j, int32 k) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, "volume_lookup_index", id, 0);
  if (!g) return -1;
  return (int32)volume_voxel_index(g, i, j, k);
}
WP_FUNC int32 volume_voxel_count(const launch_context_t* ctx, int32 fid, int32 line, uint64 id) {
  const geometry_desc_t* g = volume_resolve(ctx, fid, line, "volume_voxel_count", id, 0);
  if (!g) return 0;
  const int64 n = g->vol_type == VOLUME_ONINDEX ? g->vol_active : g->num_prims * VOLUME_LEAF_VOXELS;
  return n > 2147483647 ? 2147483647 : (int32)n;
}

// Transforms: index to world x = M u + t, world to index u = M^-1 (x - t); the _dir forms leave
// out the translation. Computed in float64 and returned in the argument's precision.
template <typename S>
WP_FUNC vec_t<3, S> volume_apply(const float64* m, const vec_t<3, S>& v, const float64* t, bool transpose) {
  const float64 x = (float64)v[0], y = (float64)v[1], z = (float64)v[2];
  float64 r[3];
  for (int a = 0; a < 3; ++a) {
    r[a] = transpose ? m[a] * x + m[3 + a] * y + m[6 + a] * z : m[3 * a] * x + m[3 * a + 1] * y + m[3 * a + 2] * z;
    if (t) r[a] += t[a];
  }
  return vec_t<3, S>(S(r[0]), S(r[1]), S(r[2]));
}
template <typename S>
WP_FUNC vec_t<3, S> volume_untranslate(const geometry_desc_t* g, const vec_t<3, S>& p) {
  vec_t<3, S> q;
  for (int a = 0; a < 3; ++a) q[a] = S((float64)p[a] - g->vol_translation[a]);
  return q;
}
#define WP_VOLUME_TRANSFORM(NAME, BODY, ADJ)                                                                          \
  template <typename S>                                                                                               \
  WP_FUNC vec_t<3, S> NAME(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec_t<3, S>& p) {     \
    const geometry_desc_t* g = volume_resolve(ctx, fid, line, #NAME, id, 0);                                          \
    if (!g) return vec_t<3, S>();                                                                                     \
    BODY                                                                                                              \
  }                                                                                                                   \
  template <typename S, typename A0>                                                                                  \
  WP_FUNC void adj_##NAME(const launch_context_t* ctx, int32 fid, int32 line, uint64 id, const vec_t<3, S>&, A0&,     \
                          vec_t<3, S>& adj_p, const vec_t<3, S>& adj_ret) {                                           \
    const geometry_desc_t* g = volume_resolve(ctx, fid, line, #NAME, id, 0);                                          \
    if (g) adj_p = add(adj_p, ADJ);                                                                                   \
  }
WP_VOLUME_TRANSFORM(volume_index_to_world, return volume_apply(g->vol_xform, p, g->vol_translation, false);,
                    volume_apply<S>(g->vol_xform, adj_ret, nullptr, true))
WP_VOLUME_TRANSFORM(volume_index_to_world_dir, return volume_apply<S>(g->vol_xform, p, nullptr, false);,
                    volume_apply<S>(g->vol_xform, adj_ret, nullptr, true))
WP_VOLUME_TRANSFORM(volume_world_to_index, return volume_apply<S>(g->vol_inverse, volume_untranslate(g, p), nullptr, false);,
                    volume_apply<S>(g->vol_inverse, adj_ret, nullptr, true))
WP_VOLUME_TRANSFORM(volume_world_to_index_dir, return volume_apply<S>(g->vol_inverse, p, nullptr, false);,
                    volume_apply<S>(g->vol_inverse, adj_ret, nullptr, true))
#undef WP_VOLUME_TRANSFORM

}  // namespace wp
