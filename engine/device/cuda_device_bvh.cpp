// CudaDevice::BuildBvh: a wp.Bvh or wp.Mesh tree built on its GPU, queued on the session's stream
// with no download or upload (bvh_build.h BvhBuildJob: a linear BVH, leaves of one item).
// The centroid bounds of all items (one reduction), each item's 30-bit Morton code in them, a
// stable radix sort of (code, item id) (CudaDevice::SortPairs), Karras' binary radix tree over
// the sorted codes (ties broken by position, so every key is distinct and the tree depth stays
// below 30 + 32 levels, inside the traversal stack), then the node bounds bottom-up: each leaf's
// thread climbs while it is the second to arrive at a node (CudaDevice::BvhBoundsUp, which also
// refits such a tree). Bounds use the host build's arithmetic (empty bounds +-3e38, a NaN never
// wins a min/max, a NaN centroid counts as 0). CudaDevice::CheckMeshIndices copies a mesh's
// indices into the mesh's own memory and finds the first one out of range, on the device.
#include <algorithm>
#include <cstring>

#include "engine/device/cuda_device.h"
#include "engine/runtime/session.h"

namespace weft {

const char* kCudaBvhSource = R"CUDA(
// Floats as ints that compare in the same order (atomicMin/atomicMax on bounds).
__device__ __forceinline__ int weft_float_order(float f) {
  const int b = __float_as_int(f);
  return b >= 0 ? b : b ^ 0x7fffffff;
}
__device__ __forceinline__ float weft_order_float(int b) { return __int_as_float(b >= 0 ? b : b ^ 0x7fffffff); }
__device__ __forceinline__ void weft_item_centroid(i64 item, const float* lowers, const float* uppers,
                                                   const float* points, const int* indices, float* c) {
  float lo[3], hi[3];
  weft_item_bounds(item, lowers, uppers, points, indices, lo, hi);
  for (int a = 0; a < 3; ++a) {
    const float x = 0.5f * (lo[a] + hi[a]);
    c[a] = x == x ? x : 0.0f;
  }
}
// box[0..2] = min, box[3..5] = max of the centroids (ordered ints, preset to +-3e38).
extern "C" __global__ void weft_bvh_centroid_bounds(i64 n, const float* lowers, const float* uppers,
                                                    const float* points, const int* indices, int* box) {
  float lo[3] = {3.0e38f, 3.0e38f, 3.0e38f}, hi[3] = {-3.0e38f, -3.0e38f, -3.0e38f};
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) {
    float c[3];
    weft_item_centroid(k, lowers, uppers, points, indices, c);
    for (int a = 0; a < 3; ++a) {
      lo[a] = fminf(lo[a], c[a]);
      hi[a] = fmaxf(hi[a], c[a]);
    }
  }
  for (int off = 16; off > 0; off >>= 1)
    for (int a = 0; a < 3; ++a) {
      lo[a] = fminf(lo[a], __shfl_down_sync(0xffffffffu, lo[a], off));
      hi[a] = fmaxf(hi[a], __shfl_down_sync(0xffffffffu, hi[a], off));
    }
  if ((threadIdx.x & 31) == 0)
    for (int a = 0; a < 3; ++a) {
      atomicMin(box + a, weft_float_order(lo[a]));
      atomicMax(box + 3 + a, weft_float_order(hi[a]));
    }
}
// 10 bits of v spread to every third bit.
__device__ __forceinline__ unsigned weft_spread3(unsigned v) {
  v = (v * 0x00010001u) & 0xFF0000FFu;
  v = (v * 0x00000101u) & 0x0F00F00Fu;
  v = (v * 0x00000011u) & 0xC30C30C3u;
  v = (v * 0x00000005u) & 0x49249249u;
  return v;
}
// keys[k] = the Morton code of item k's centroid in the centroid bounds, ids[k] = k.
extern "C" __global__ void weft_bvh_morton(i64 n, const float* lowers, const float* uppers, const float* points,
                                           const int* indices, const int* box, int* keys, int* ids) {
  float lo[3], extent[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = weft_order_float(box[a]);
    extent[a] = weft_order_float(box[3 + a]) - lo[a];
  }
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) {
    float c[3];
    weft_item_centroid(k, lowers, uppers, points, indices, c);
    unsigned q[3];
    for (int a = 0; a < 3; ++a) {
      const float t = extent[a] > 0.0f ? (c[a] - lo[a]) / extent[a] * 1024.0f : 0.0f;
      q[a] = t >= 1023.0f ? 1023u : t > 0.0f ? (unsigned)t : 0u;   // NaN and below 0: 0
    }
    keys[k] = (int)(weft_spread3(q[0]) << 2 | weft_spread3(q[1]) << 1 | weft_spread3(q[2]));
    ids[k] = (int)k;
  }
}
// The length of the common prefix of sorted keys i and j (j outside [0, n): -1); equal keys
// compare their positions instead, so the 62-bit keys (code, position) are distinct.
__device__ __forceinline__ int weft_bvh_delta(const int* codes, i64 n, i64 i, i64 j) {
  if (j < 0 || j >= n) return -1;
  const unsigned a = (unsigned)codes[i], b = (unsigned)codes[j];
  return a != b ? __clz(a ^ b) : 32 + __clz((unsigned)(i ^ j));
}
// Inner node i covers the sorted range it finds from its neighbours' prefixes (Karras 2012) and
// splits it where the prefix changes; leaves are nodes n-1 .. 2n-2.
extern "C" __global__ void weft_bvh_hierarchy(const int* codes, i64 n, weft_bvh_node* nodes, int* parents) {
  for (i64 i = (i64)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += (i64)blockDim.x * gridDim.x) {
    nodes[n - 1 + i].left = (int)i;
    nodes[n - 1 + i].right = -1;
    if (i == 0) parents[0] = -1;
    if (i >= n - 1) continue;
    const i64 d = weft_bvh_delta(codes, n, i, i + 1) >= weft_bvh_delta(codes, n, i, i - 1) ? 1 : -1;
    const int dmin = weft_bvh_delta(codes, n, i, i - d);
    i64 lmax = 2;
    while (weft_bvh_delta(codes, n, i, i + lmax * d) > dmin) lmax <<= 1;
    i64 l = 0;
    for (i64 t = lmax >> 1; t >= 1; t >>= 1)
      if (weft_bvh_delta(codes, n, i, i + (l + t) * d) > dmin) l += t;
    const i64 j = i + l * d;
    const int dnode = weft_bvh_delta(codes, n, i, j);
    i64 s = 0, t = l;
    do {
      t = (t + 1) >> 1;
      if (weft_bvh_delta(codes, n, i, i + (s + t) * d) > dnode) s += t;
    } while (t > 1);
    const i64 split = i + s * d + (d < 0 ? -1 : 0);
    const i64 first = i < j ? i : j, last = i < j ? j : i;
    const int left = (int)(first == split ? n - 1 + split : split);
    const int right = (int)(last == split + 1 ? n - 1 + split + 1 : split + 1);
    nodes[i].left = left;
    nodes[i].right = right;
    parents[left] = (int)i;
    parents[right] = (int)i;
  }
}
// Node bounds from the leaves up: leaf n-1+k from item prim_ids[k]; a thread then climbs to the
// parent when it is the second to arrive there (arrivals zeroed before), reading the sibling's
// bounds through L2 (volatile) after the sibling's writes were fenced.
extern "C" __global__ void weft_bvh_bounds_up(weft_bvh_node* nodes, const int* parents, int* arrivals, i64 n,
                                              const int* prim_ids, const float* lowers, const float* uppers,
                                              const float* points, const int* indices) {
  volatile weft_bvh_node* vnodes = nodes;
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) {
    const i64 leaf = n - 1 + k;
    float lo[3], hi[3];
    weft_item_bounds(prim_ids[k], lowers, uppers, points, indices, lo, hi);
    for (int a = 0; a < 3; ++a) {
      vnodes[leaf].lower[a] = lo[a];
      vnodes[leaf].upper[a] = hi[a];
    }
    __threadfence();
    int p = parents[leaf];
    while (p >= 0) {
      if (atomicAdd(arrivals + p, 1) == 0) break;   // the sibling is not done: it climbs on
      __threadfence();
      const int l = nodes[p].left, r = nodes[p].right;
      float plo[3] = {3.0e38f, 3.0e38f, 3.0e38f}, phi[3] = {-3.0e38f, -3.0e38f, -3.0e38f};
      float cl[3], ch[3];
      for (int a = 0; a < 3; ++a) {
        cl[a] = vnodes[l].lower[a];
        ch[a] = vnodes[l].upper[a];
      }
      weft_grow(plo, phi, cl, ch);
      for (int a = 0; a < 3; ++a) {
        cl[a] = vnodes[r].lower[a];
        ch[a] = vnodes[r].upper[a];
      }
      weft_grow(plo, phi, cl, ch);
      for (int a = 0; a < 3; ++a) {
        vnodes[p].lower[a] = plo[a];
        vnodes[p].upper[a] = phi[a];
      }
      __threadfence();
      p = parents[p];
    }
  }
}
// A mesh's indices copied and checked: result[0] = the first position out of [0, limit) (preset
// to ~0), then result[1] = the value there (a second launch).
extern "C" __global__ void weft_mesh_indices_check(const int* src, i64 count, int limit, int* dst,
                                                   unsigned long long* result) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < count; k += (i64)blockDim.x * gridDim.x) {
    const int v = src[k];
    dst[k] = v;
    if (v < 0 || v >= limit) atomicMin(result, (unsigned long long)k);
  }
}
extern "C" __global__ void weft_mesh_indices_value(const int* dst, unsigned long long* result) {
  if (result[0] != ~0ull) result[1] = (unsigned long long)(unsigned)dst[result[0]];
}
)CUDA";

namespace {

int32_t FloatOrder(float f) {
  int32_t b;
  std::memcpy(&b, &f, 4);
  return b >= 0 ? b : b ^ 0x7fffffff;
}

}  // namespace

Status CudaDevice::BvhBoundsUp(Stream& st, const geometry::BvhRefitJob& job) {
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction fn, Builtin("weft_bvh_bounds_up"));
  int64_t n = job.num_items;
  if (n <= 0) return Status::Ok();
  jit::CuDevicePtr nodes = job.nodes, parents = job.parents, arrivals = job.arrivals, prim_ids = job.prim_ids,
                   lowers = job.lowers, uppers = job.uppers, points = job.points, indices = job.indices;
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemsetD32Async(arrivals, 0, static_cast<size_t>(n), st.stream),
                                      "cuMemsetD32Async (BVH bounds)"));
  void* params[] = {&nodes, &parents, &arrivals, &n, &prim_ids, &lowers, &uppers, &points, &indices};
  return driver_->Check(driver_->LaunchKernel(fn, GridFor(static_cast<uint64_t>(n), 256, 65536), 1, 1, 256, 1, 1, 0, st.stream,
                                              params, nullptr),
                        "cuLaunchKernel (BVH bounds)");
}

Status CudaDevice::CheckMeshIndices(Session& s, const geometry::MeshIndicesJob& job) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (lost_.load()) return Unavailable(name_ + " was lost");
  if (job.count < 1) return Internal("mesh indices job out of range");
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction check_fn, Builtin("weft_mesh_indices_check"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction value_fn, Builtin("weft_mesh_indices_value"));
  jit::CuDevicePtr src = job.src, dst = job.dst, result = job.result;
  int64_t count = job.count;
  int32_t limit = job.limit;
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemsetD32Async(result, 0xffffffffu, 4, st->stream),
                                      "cuMemsetD32Async (mesh indices)"));
  void* check_params[] = {&src, &count, &limit, &dst, &result};
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->LaunchKernel(check_fn, GridFor(static_cast<uint64_t>(count), 256, 65536), 1, 1, 256,
                                                            1, 1, 0, st->stream, check_params, nullptr),
                                      "cuLaunchKernel (mesh indices)"));
  void* value_params[] = {&dst, &result};
  return driver_->Check(driver_->LaunchKernel(value_fn, 1, 1, 1, 1, 1, 1, 0, st->stream, value_params, nullptr),
                        "cuLaunchKernel (mesh indices)");
}

Status CudaDevice::BuildBvh(Session& s, const geometry::BvhBuildJob& job) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (lost_.load()) return Unavailable(name_ + " was lost");
  if (job.n < 1 || job.n > INT32_MAX) return Internal("BVH build job out of range");
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction bounds_fn, Builtin("weft_bvh_centroid_bounds"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction morton_fn, Builtin("weft_bvh_morton"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction hierarchy_fn, Builtin("weft_bvh_hierarchy"));
  auto launch = [&](jit::CuFunction fn, unsigned grid, void** params, const char* what) {
    return driver_->Check(driver_->LaunchKernel(fn, grid, 1, 1, 256, 1, 1, 0, st->stream, params, nullptr), what);
  };
  int64_t n = job.n;
  const uint64_t words = geometry::RoundTo256(static_cast<uint64_t>(n) * 4);
  jit::CuDevicePtr arrivals = job.scratch;
  SortBuffers b{{job.scratch + words, job.scratch + 2 * words}, {job.prim_ids, job.scratch + 3 * words},
                job.scratch + 4 * words};
  jit::CuDevicePtr box = b.hist + geometry::SortHistogramBytes(n);
  jit::CuDevicePtr lowers = job.lowers, uppers = job.uppers, points = job.points, indices = job.indices;
  const unsigned item_blocks = GridFor(static_cast<uint64_t>(n), 256, 65536);

  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemsetD32Async(box, static_cast<unsigned>(FloatOrder(3.0e38f)), 3, st->stream),
                                      "cuMemsetD32Async (BVH build)"));
  WEFT_RETURN_IF_ERROR(driver_->Check(
      driver_->MemsetD32Async(box + 12, static_cast<unsigned>(FloatOrder(-3.0e38f)), 3, st->stream), "cuMemsetD32Async (BVH build)"));
  void* bounds_params[] = {&n, &lowers, &uppers, &points, &indices, &box};
  WEFT_RETURN_IF_ERROR(launch(bounds_fn, std::min(item_blocks, 1024u), bounds_params, "cuLaunchKernel (BVH centroid bounds)"));
  void* morton_params[] = {&n, &lowers, &uppers, &points, &indices, &box, &b.keys[0], &b.ids[0]};
  WEFT_RETURN_IF_ERROR(launch(morton_fn, item_blocks, morton_params, "cuLaunchKernel (BVH Morton codes)"));
  int cur = 0;
  WEFT_RETURN_IF_ERROR(SortPairs(*st, b, n, 30, &cur));   // 4 passes: the pairs end in buffers 0
  if (cur != 0) return Internal("BVH build: the sorted ids are not in the prim ids");
  jit::CuDevicePtr codes = b.keys[0], nodes = job.nodes, parents = job.parents;
  void* hierarchy_params[] = {&codes, &n, &nodes, &parents};
  WEFT_RETURN_IF_ERROR(launch(hierarchy_fn, item_blocks, hierarchy_params, "cuLaunchKernel (BVH hierarchy)"));
  geometry::BvhRefitJob up;
  up.nodes = job.nodes;
  up.prim_ids = job.prim_ids;
  up.lowers = job.lowers;
  up.uppers = job.uppers;
  up.points = job.points;
  up.indices = job.indices;
  up.parents = job.parents;
  up.arrivals = arrivals;
  up.num_items = n;
  return BvhBoundsUp(*st, up);
}

}  // namespace weft
