// CudaDevice::BuildBvh: a wp.Bvh or wp.Mesh tree built on its GPU, queued on the session's stream
// with no download or upload (bvh_build.h BvhBuildJob: a linear BVH, leaves of one item).
// The centroid bounds of all items (one reduction), each item's 30-bit Morton code in them, a
// stable radix sort of (code, item id) (CudaDevice::SortPairs), Karras' binary radix tree over
// the sorted codes (ties broken by position, so every key is distinct and the tree depth stays
// below 30 + 32 levels, inside the traversal stack), then the node bounds bottom-up: each leaf's
// thread climbs while it is the second to arrive at a node (CudaDevice::BvhBoundsUp, which also
// refits such a tree). Bounds use the host build's arithmetic (empty bounds +-3e38, a NaN never
// wins a min/max, a NaN centroid counts as 0). Grouped builds (CudaDevice::GroupRanks) sort the
// items stably by group after the code sort and build over (dense group rank, code, position),
// so each group is one subtree; its root and id are found on the device.
// CudaDevice::CheckMeshIndices copies a mesh's indices into the mesh's own memory and finds the
// first one out of range, on the device.
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
// keys[k] = the Morton code of item k's centroid in the centroid bounds, ids[k] = k (and, for a
// grouped build, codes_by_item[k] = the code).
extern "C" __global__ void weft_bvh_morton(i64 n, const float* lowers, const float* uppers, const float* points,
                                           const int* indices, const int* box, int* keys, int* ids,
                                           int* codes_by_item) {
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
    if (codes_by_item) codes_by_item[k] = keys[k];
  }
}
// Grouped builds, after the sort by code: keys[k] = the group of item ids[k], in unsigned order of
// the signed ids (a stable sort by these then orders the items by group, then code).
extern "C" __global__ void weft_bvh_group_keys(const int* groups, const int* ids, i64 n, int* keys) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x)
    keys[k] = (int)((unsigned)groups[ids[k]] ^ 0x80000000u);
}
// flags[k] = 1 where a group's run starts in the sorted group keys.
extern "C" __global__ void weft_bvh_group_flags(const int* gkeys, i64 n, int* flags) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x)
    flags[k] = k == 0 || gkeys[k] != gkeys[k - 1];
}
// ranks[k] (in: the exclusive sum of the flags within its segment of `seg` values) becomes the
// dense rank of position k's group (0 .. groups-1); the first position of each group writes the
// group's id at its rank (group_ids ascending, as the host build's).
extern "C" __global__ void weft_bvh_group_ranks(const int* gkeys, i64 n, i64 seg, const int* seg_offsets, int* ranks,
                                                int* group_ids) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) {
    const int first = k == 0 || gkeys[k] != gkeys[k - 1];
    const int r = ranks[k] + seg_offsets[k / seg] + first - 1;
    ranks[k] = r;
    if (first) group_ids[r] = (int)((unsigned)gkeys[k] ^ 0x80000000u);
  }
}
// The length of the common prefix of sorted keys i and j (j outside [0, n): -1). A key is
// (group rank, code, position): the dense rank of the item's group (grouped builds; 32 bits, or
// none), its 32-bit code, then its position, so every key is distinct. The ranks are dense
// (below the item count), so the group levels of the tree are at most log2(groups) deep.
__device__ __forceinline__ int weft_bvh_delta(const int* codes, const int* ranks, i64 n, i64 i, i64 j) {
  if (j < 0 || j >= n) return -1;
  if (ranks && ranks[i] != ranks[j]) return __clz((unsigned)(ranks[i] ^ ranks[j]));
  const unsigned a = (unsigned)codes[i], b = (unsigned)codes[j];
  return a != b ? 32 + __clz(a ^ b) : 64 + __clz((unsigned)(i ^ j));
}
// Inner node i covers the sorted range it finds from its neighbours' prefixes (Karras 2012) and
// splits it where the prefix changes; leaves are nodes n-1 .. 2n-2. Grouped builds (ranks):
// each group's items are one subtree, and the node covering exactly one group under a node
// that covers several (or the root, for one group) is that group's root: group_roots[rank].
extern "C" __global__ void weft_bvh_hierarchy(const int* codes, const int* ranks, i64 n, weft_bvh_node* nodes,
                                              int* parents, int* group_roots) {
  for (i64 i = (i64)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += (i64)blockDim.x * gridDim.x) {
    nodes[n - 1 + i].left = (int)i;
    nodes[n - 1 + i].right = -1;
    if (i == 0) parents[0] = -1;
    if (i == 0 && ranks && ranks[0] == ranks[n - 1]) group_roots[ranks[0]] = 0;   // one group
    if (i >= n - 1) continue;
    const i64 d = weft_bvh_delta(codes, ranks, n, i, i + 1) >= weft_bvh_delta(codes, ranks, n, i, i - 1) ? 1 : -1;
    const int dmin = weft_bvh_delta(codes, ranks, n, i, i - d);
    i64 lmax = 2;
    while (weft_bvh_delta(codes, ranks, n, i, i + lmax * d) > dmin) lmax <<= 1;
    i64 l = 0;
    for (i64 t = lmax >> 1; t >= 1; t >>= 1)
      if (weft_bvh_delta(codes, ranks, n, i, i + (l + t) * d) > dmin) l += t;
    const i64 j = i + l * d;
    const int dnode = weft_bvh_delta(codes, ranks, n, i, j);
    i64 s = 0, t = l;
    do {
      t = (t + 1) >> 1;
      if (weft_bvh_delta(codes, ranks, n, i, i + (s + t) * d) > dnode) s += t;
    } while (t > 1);
    const i64 split = i + s * d + (d < 0 ? -1 : 0);
    const i64 first = i < j ? i : j, last = i < j ? j : i;
    const int left = (int)(first == split ? n - 1 + split : split);
    const int right = (int)(last == split + 1 ? n - 1 + split + 1 : split + 1);
    nodes[i].left = left;
    nodes[i].right = right;
    parents[left] = (int)i;
    parents[right] = (int)i;
    if (ranks && ranks[first] != ranks[last]) {
      if (ranks[first] == ranks[split]) group_roots[ranks[first]] = left;
      if (ranks[split + 1] == ranks[last]) group_roots[ranks[last]] = right;
    }
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
  TimedSpan timed(*this, *st, kTimingKernelBuiltin, "builtin kernel mesh_check_indices");
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

Status CudaDevice::GroupRanks(Stream& st, const geometry::BvhBuildJob& job, const SortBuffers& b,
                              jit::CuDevicePtr codes_by_item) {
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction keys_fn, Builtin("weft_bvh_group_keys"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction gather_fn, Builtin("weft_gather_int"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction flags_fn, Builtin("weft_bvh_group_flags"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction scan_fn, Builtin("weft_scan_exclusive"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction ranks_fn, Builtin("weft_bvh_group_ranks"));
  auto launch = [&](jit::CuFunction fn, unsigned grid, unsigned block, void** params, const char* what) {
    return driver_->Check(driver_->LaunchKernel(fn, grid, 1, 1, block, 1, 1, 0, st.stream, params, nullptr), what);
  };
  int64_t n = job.n;
  const unsigned item_blocks = GridFor(static_cast<uint64_t>(n), 256, 65536);
  jit::CuDevicePtr groups = job.item_groups, group_ids = job.group_ids;
  // The object's copy of the groups (creation: from the user's array; a rebuild reads the copy).
  if (job.groups_src != 0 && job.groups_src != job.item_groups)
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemcpyDtoDAsync(groups, job.groups_src, static_cast<size_t>(n) * 4, st.stream),
                                        "cuMemcpyDtoDAsync (BVH groups)"));
  // Absent ranks read as the largest id with no root (the kernel-side search finds -1 there).
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemsetD32Async(group_ids, 0x7fffffffu, static_cast<size_t>(n), st.stream),
                                      "cuMemsetD32Async (BVH groups)"));
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemsetD32Async(job.group_roots, 0xffffffffu, static_cast<size_t>(n), st.stream),
                                      "cuMemsetD32Async (BVH groups)"));
  // A stable sort by group of the items in code order: (group, code) order, in buffers 0.
  jit::CuDevicePtr gkeys = b.keys[0], ids = b.ids[0];
  void* keys_params[] = {&groups, &ids, &n, &gkeys};
  WEFT_RETURN_IF_ERROR(launch(keys_fn, item_blocks, 256, keys_params, "cuLaunchKernel (BVH group keys)"));
  int cur = 0;
  WEFT_RETURN_IF_ERROR(SortPairs(st, b, n, 32, &cur));
  if (cur != 0) return Internal("BVH build: the group-sorted ids are not in the prim ids");
  jit::CuDevicePtr codes = b.keys[1], ranks = b.ids[1];
  void* gather_params[] = {&codes_by_item, &ids, &n, &codes};
  WEFT_RETURN_IF_ERROR(launch(gather_fn, item_blocks, 256, gather_params, "cuLaunchKernel (BVH group codes)"));
  // Dense ranks: run starts flagged, scanned per segment of kSortTile, the segment sums scanned
  // (one block), then each position's rank (the sort's digit counts are free for the sums).
  void* flags_params[] = {&gkeys, &n, &ranks};
  WEFT_RETURN_IF_ERROR(launch(flags_fn, item_blocks, 256, flags_params, "cuLaunchKernel (BVH group flags)"));
  int64_t seg = geometry::kSortTile;
  int64_t segments = (n + seg - 1) / seg;
  jit::CuDevicePtr sums = b.hist, total = b.hist + geometry::RoundTo256(static_cast<uint64_t>(segments) * 4);
  void* scan_params[] = {&ranks, &seg, &n, &sums};   // the last segment holds the rest of n
  WEFT_RETURN_IF_ERROR(launch(scan_fn, static_cast<unsigned>(segments), 1024, scan_params, "cuLaunchKernel (BVH group scan)"));
  void* sums_params[] = {&sums, &segments, &segments, &total};
  WEFT_RETURN_IF_ERROR(launch(scan_fn, 1, 1024, sums_params, "cuLaunchKernel (BVH group scan)"));
  void* ranks_params[] = {&gkeys, &n, &seg, &sums, &ranks, &group_ids};
  return launch(ranks_fn, item_blocks, 256, ranks_params, "cuLaunchKernel (BVH group ranks)");
}

Status CudaDevice::BuildBvh(Session& s, const geometry::BvhBuildJob& job) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (lost_.load()) return Unavailable(name_ + " was lost");
  if (job.n < 1 || job.n > INT32_MAX) return Internal("BVH build job out of range");
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  TimedSpan timed(*this, *st, kTimingKernelBuiltin, "builtin kernel bvh_build");
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
  const bool grouped = job.item_groups != 0;
  // Grouped: the codes by item wait in the arrival counters (free until the bounds pass).
  jit::CuDevicePtr codes_by_item = grouped ? arrivals : 0;
  void* morton_params[] = {&n, &lowers, &uppers, &points, &indices, &box, &b.keys[0], &b.ids[0], &codes_by_item};
  WEFT_RETURN_IF_ERROR(launch(morton_fn, item_blocks, morton_params, "cuLaunchKernel (BVH Morton codes)"));
  int cur = 0;
  WEFT_RETURN_IF_ERROR(SortPairs(*st, b, n, 30, &cur));   // 4 passes: the pairs end in buffers 0
  if (cur != 0) return Internal("BVH build: the sorted ids are not in the prim ids");
  jit::CuDevicePtr codes = b.keys[0], ranks = 0, group_roots = job.group_roots, nodes = job.nodes,
                   parents = job.parents;
  if (grouped) {
    WEFT_RETURN_IF_ERROR(GroupRanks(*st, job, b, codes_by_item));
    codes = b.keys[1];   // the codes in (group, code) order
    ranks = b.ids[1];
  }
  void* hierarchy_params[] = {&codes, &ranks, &n, &nodes, &parents, &group_roots};
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
