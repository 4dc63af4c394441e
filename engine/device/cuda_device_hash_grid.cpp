// CudaDevice::BuildHashGrid: a wp.HashGrid built on its GPU, queued on the session's stream with
// no download or upload. Each point's cell (the host build's arithmetic: floor of x / width in
// float32, periodic in each dim), a stable LSD radix sort of (cell, point id) in 4-bit digits,
// so that every cell lists its points by ascending id exactly as the host build does, then each
// cell's [start, end) from the sorted keys (empty cells 0, 0). A grouped build sorts by group id
// first and then, stably, by cell (each cell's points by group, then id, as on the host) and
// gathers each sorted point's group.
#include <algorithm>

#include "engine/device/cuda_device.h"
#include "engine/geometry/geometry_object.h"
#include "engine/runtime/session.h"

namespace weft {

const char* kCudaHashGridSource = R"CUDA(
__device__ __forceinline__ float weft_half_to_float(unsigned short h) {
  const unsigned int sign = (unsigned int)(h & 0x8000u) << 16, e = (h >> 10) & 31u, m = h & 1023u;
  if (e == 31) return __uint_as_float(sign | 0x7f800000u | (m << 13));
  if (e == 0) {
    const float f = (float)m * 5.9604644775390625e-8f;   // m * 2^-24, exact
    return sign ? -f : f;
  }
  return __uint_as_float(sign | ((e + 112u) << 23) | (m << 13));
}
__device__ __forceinline__ float weft_point_coord(const char* p, int scalar_size, i64 i, int k) {
  if (scalar_size == 4) return ((const float*)p)[3 * i + k];
  if (scalar_size == 8) return (float)((const double*)p)[3 * i + k];
  return weft_half_to_float(((const unsigned short*)p)[3 * i + k]);
}
// engine/native/geometry_abi.h hash_grid_coord / hash_grid_cell.
__device__ __forceinline__ int weft_grid_coord(float x, float w) {
  const float q = x / w;
  if (!(q == q)) return 0;
  if (q > 1.0e9f) return 1000000000;
  if (q < -1.0e9f) return -1000000000;
  int i = (int)q;
  if ((float)i > q) --i;
  return i;
}
// keys[k] = the cell of point order[k] (of point k without `order`, and then ids[k] = k).
extern "C" __global__ void weft_hash_grid_keys(const char* points, int scalar_size, i64 n, float width, int dx, int dy,
                                               int dz, const int* order, int* keys, int* ids) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) {
    const i64 i = order ? (i64)order[k] : k;
    int cx = weft_grid_coord(weft_point_coord(points, scalar_size, i, 0), width) % dx;
    int cy = weft_grid_coord(weft_point_coord(points, scalar_size, i, 1), width) % dy;
    int cz = weft_grid_coord(weft_point_coord(points, scalar_size, i, 2), width) % dz;
    if (cx < 0) cx += dx;
    if (cy < 0) cy += dy;
    if (cz < 0) cz += dz;
    keys[k] = (int)(((i64)cz * dy + cy) * dx + cx);
    if (!order) ids[k] = (int)k;
  }
}
// Grouped builds sort by group first: keys in unsigned order of the signed ids.
extern "C" __global__ void weft_hash_grid_group_keys(const int* groups, i64 n, int* keys, int* ids) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) {
    keys[k] = (int)((unsigned)groups[k] ^ 0x80000000u);
    ids[k] = (int)k;
  }
}
// dst[k] = src[index[k]].
extern "C" __global__ void weft_gather_int(const int* src, const int* index, i64 n, int* dst) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) dst[k] = src[index[k]];
}
// Radix sort, one 4-bit digit per pass over tiles of 2048 keys (256 threads x 8 consecutive).
// Pass = per-tile digit counts (hist[digit * tiles + tile]), one exclusive scan of all counts
// (digit-major: every key of digit d lands after every key of a smaller digit, and after the
// keys of digit d of earlier tiles), and a scatter that ranks each tile's keys stably.
// A thread's 16 digit counts are packed 16 bits each into 4 words (digit d: word d / 4, bits
// 16 * (d % 4)); a tile's counts stay below 2^16, so sums of packed words never carry over.
#define WEFT_RS_THREADS 256
#define WEFT_RS_ITEMS 8
#define WEFT_RS_TILE 2048
typedef unsigned long long u64;
struct weft_digits { u64 w[4]; };
__device__ __forceinline__ void weft_digit_add(weft_digits& c, int d, u64 v) {
  const u64 x = v << (16 * (d & 3));
  const int q = d >> 2;
  c.w[0] += q == 0 ? x : 0;
  c.w[1] += q == 1 ? x : 0;
  c.w[2] += q == 2 ? x : 0;
  c.w[3] += q == 3 ? x : 0;
}
__device__ __forceinline__ int weft_digit_get(const weft_digits& c, int d) {
  const int q = d >> 2;
  const u64 w = q == 0 ? c.w[0] : q == 1 ? c.w[1] : q == 2 ? c.w[2] : c.w[3];
  return (int)((w >> (16 * (d & 3))) & 0xffffu);
}
__device__ __forceinline__ weft_digits weft_thread_digits(const int* keys, i64 base, i64 n, int shift) {
  weft_digits c = {{0, 0, 0, 0}};
  for (int j = 0; j < WEFT_RS_ITEMS; ++j)
    if (base + j < n) weft_digit_add(c, (keys[base + j] >> shift) & 15, 1);
  return c;
}
extern "C" __global__ void weft_radix_counts(const int* keys, i64 n, int shift, int* hist, i64 tiles) {
  __shared__ u64 warp_sums[WEFT_RS_THREADS / 32][4];
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
  for (i64 t = blockIdx.x; t < tiles; t += gridDim.x) {
    weft_digits c = weft_thread_digits(keys, t * WEFT_RS_TILE + (i64)threadIdx.x * WEFT_RS_ITEMS, n, shift);
    for (int off = 16; off > 0; off >>= 1)
      for (int k = 0; k < 4; ++k) c.w[k] += __shfl_down_sync(0xffffffffu, c.w[k], off);
    if (lane == 0)
      for (int k = 0; k < 4; ++k) warp_sums[warp][k] = c.w[k];
    __syncthreads();
    if (threadIdx.x < 16) {
      const int d = threadIdx.x;
      int total = 0;
      for (int w = 0; w < WEFT_RS_THREADS / 32; ++w) total += (int)((warp_sums[w][d >> 2] >> (16 * (d & 3))) & 0xffffu);
      hist[d * tiles + t] = total;
    }
    __syncthreads();
  }
}
// Exclusive prefix sums of v[0, m) in place; one block of 1024 threads, in rounds of 4096
// (4 consecutive values a thread, warp scans, then a scan of the 32 warp totals).
extern "C" __global__ void weft_scan_exclusive(int* v, i64 m) {
  __shared__ int warp_totals[32];
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, warps = blockDim.x >> 5;
  int carry = 0;
  for (i64 round = 0; round < m; round += 4 * (i64)blockDim.x) {
    const i64 b = round + 4 * (i64)threadIdx.x;
    int x[4];
    for (int k = 0; k < 4; ++k) x[k] = b + k < m ? v[b + k] : 0;
    const int s = x[0] + x[1] + x[2] + x[3];
    int inc = s;
    for (int off = 1; off < 32; off <<= 1) {
      const int y = __shfl_up_sync(0xffffffffu, inc, off);
      if (lane >= off) inc += y;
    }
    if (lane == 31) warp_totals[warp] = inc;
    __syncthreads();
    if (warp == 0) {
      int w = lane < warps ? warp_totals[lane] : 0;
      for (int off = 1; off < 32; off <<= 1) {
        const int y = __shfl_up_sync(0xffffffffu, w, off);
        if (lane >= off) w += y;
      }
      if (lane < warps) warp_totals[lane] = w;
    }
    __syncthreads();
    int before = carry + (warp ? warp_totals[warp - 1] : 0) + inc - s;
    for (int k = 0; k < 4; ++k) {
      if (b + k < m) v[b + k] = before;
      before += x[k];
    }
    carry += warp_totals[warps - 1];
    __syncthreads();
  }
}
// The scatter ranks each key within its tile (digit start in the tile + rank among the keys of
// its digit before it), places the tile in shared memory in that order, then writes each
// digit's run to its global place in consecutive addresses.
extern "C" __global__ void weft_radix_scatter(const int* keys_in, const int* ids_in, int* keys_out, int* ids_out, i64 n,
                                              int shift, const int* offsets, i64 tiles) {
  __shared__ u64 warp_sums[WEFT_RS_THREADS / 32][4];
  __shared__ int tile_offsets[16], tile_starts[16];
  __shared__ int tile_keys[WEFT_RS_TILE], tile_ids[WEFT_RS_TILE];
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
  for (i64 t = blockIdx.x; t < tiles; t += gridDim.x) {
    const i64 base = t * WEFT_RS_TILE + (i64)threadIdx.x * WEFT_RS_ITEMS;
    const weft_digits mine = weft_thread_digits(keys_in, base, n, shift);
    weft_digits inc = mine;   // inclusive scan over the warp's lanes
    for (int off = 1; off < 32; off <<= 1)
      for (int k = 0; k < 4; ++k) {
        const u64 x = __shfl_up_sync(0xffffffffu, inc.w[k], off);
        if (lane >= off) inc.w[k] += x;
      }
    if (lane == 31)
      for (int k = 0; k < 4; ++k) warp_sums[warp][k] = inc.w[k];
    if (threadIdx.x < 16) tile_offsets[threadIdx.x] = offsets[threadIdx.x * tiles + t];
    __syncthreads();
    if (threadIdx.x == 0) {   // where each digit's keys start within the tile
      weft_digits total = {{0, 0, 0, 0}};
      for (int w = 0; w < WEFT_RS_THREADS / 32; ++w)
        for (int k = 0; k < 4; ++k) total.w[k] += warp_sums[w][k];
      int run = 0;
      for (int d = 0; d < 16; ++d) {
        tile_starts[d] = run;
        run += weft_digit_get(total, d);
      }
    }
    weft_digits next;   // the rank of this thread's next key of each digit among the tile's
    for (int k = 0; k < 4; ++k) {
      u64 before = inc.w[k] - mine.w[k];
      for (int w = 0; w < warp; ++w) before += warp_sums[w][k];
      next.w[k] = before;
    }
    __syncthreads();
    for (int j = 0; j < WEFT_RS_ITEMS; ++j) {
      if (base + j >= n) break;
      const int k = keys_in[base + j];
      const int d = (k >> shift) & 15;
      const int local = tile_starts[d] + weft_digit_get(next, d);
      weft_digit_add(next, d, 1);
      tile_keys[local] = k;
      tile_ids[local] = ids_in[base + j];
    }
    __syncthreads();
    const i64 left = n - t * WEFT_RS_TILE;
    const int count = left < WEFT_RS_TILE ? (int)left : WEFT_RS_TILE;
    for (int j = threadIdx.x; j < count; j += blockDim.x) {
      const int k = tile_keys[j];
      const int d = (k >> shift) & 15;
      const int pos = tile_offsets[d] + j - tile_starts[d];
      keys_out[pos] = k;
      ids_out[pos] = tile_ids[j];
    }
    __syncthreads();
  }
}
// Cell bounds from the sorted keys (starts and ends zeroed before).
extern "C" __global__ void weft_hash_grid_bounds(const int* keys, i64 n, int* starts, int* ends) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) {
    const int c = keys[k];
    if (k == 0 || keys[k - 1] != c) starts[c] = (int)k;
    if (k == n - 1 || keys[k + 1] != c) ends[c] = (int)(k + 1);
  }
}
)CUDA";

namespace {

unsigned Blocks(uint64_t n, unsigned block) {
  uint64_t g = (n + block - 1) / block;
  g = std::min<uint64_t>(g, 65536);
  return static_cast<unsigned>(g ? g : 1);
}

uint64_t Round256(uint64_t v) { return (v + 255) / 256 * 256; }

}  // namespace

Status CudaDevice::BuildHashGrid(Session& s, const geometry::HashGridBuildJob& job) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (lost_.load()) return Unavailable(name_ + " was lost");
  if (job.n < 0 || job.n > INT32_MAX || job.cells < 1 || job.cells > geometry::kMaxHashGridCells)
    return Internal("hash grid build job out of range");
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction keys_fn, Builtin("weft_hash_grid_keys"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction counts_fn, Builtin("weft_radix_counts"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction scan_fn, Builtin("weft_scan_exclusive"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction scatter_fn, Builtin("weft_radix_scatter"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction bounds_fn, Builtin("weft_hash_grid_bounds"));
  auto launch = [&](jit::CuFunction fn, unsigned grid, unsigned block, void** params, const char* what) {
    return driver_->Check(driver_->LaunchKernel(fn, grid, 1, 1, block, 1, 1, 0, st->stream, params, nullptr), what);
  };
  const uint64_t cells = static_cast<uint64_t>(job.cells);
  jit::CuDevicePtr starts = job.cell_starts, ends = job.cell_ends;
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemsetD32Async(starts, 0, cells, st->stream), "cuMemsetD32Async (cells)"));
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemsetD32Async(ends, 0, cells, st->stream), "cuMemsetD32Async (cells)"));
  int64_t n = job.n;
  if (n == 0) return Status::Ok();

  const uint64_t words = Round256(static_cast<uint64_t>(n) * 4);
  jit::CuDevicePtr keys[2] = {job.scratch, job.scratch + words};
  jit::CuDevicePtr ids[2] = {job.sorted_ids, job.scratch + 2 * words};
  jit::CuDevicePtr hist = job.scratch + 3 * words;
  int64_t tiles = (n + geometry::kHashGridSortTile - 1) / geometry::kHashGridSortTile;
  const unsigned item_blocks = Blocks(static_cast<uint64_t>(n), 256), tile_blocks = Blocks(static_cast<uint64_t>(tiles), 1);
  int cur = 0;
  // Sorts (keys[cur], ids[cur]) by the low `bits` bits of the keys; the result lands in [cur].
  auto sort = [&](int bits) -> Status {
    for (int32_t shift = 0; shift < bits; shift += 4) {
      int64_t hist_len = 16 * tiles;
      void* count_params[] = {&keys[cur], &n, &shift, &hist, &tiles};
      WEFT_RETURN_IF_ERROR(launch(counts_fn, tile_blocks, 256, count_params, "cuLaunchKernel (hash grid sort)"));
      void* scan_params[] = {&hist, &hist_len};
      WEFT_RETURN_IF_ERROR(launch(scan_fn, 1, 1024, scan_params, "cuLaunchKernel (hash grid sort)"));
      void* scatter_params[] = {&keys[cur], &ids[cur], &keys[1 - cur], &ids[1 - cur], &n, &shift, &hist, &tiles};
      WEFT_RETURN_IF_ERROR(launch(scatter_fn, tile_blocks, 256, scatter_params, "cuLaunchKernel (hash grid sort)"));
      cur = 1 - cur;
    }
    return Status::Ok();
  };

  jit::CuDevicePtr points = job.points, groups = job.groups, no_order = 0;
  int32_t scalar_size = job.scalar_size, dx = job.dim[0], dy = job.dim[1], dz = job.dim[2];
  float width = job.cell_width;
  if (groups) {
    WEFT_ASSIGN_OR_RETURN(jit::CuFunction group_keys_fn, Builtin("weft_hash_grid_group_keys"));
    void* params[] = {&groups, &n, &keys[0], &ids[0]};
    WEFT_RETURN_IF_ERROR(launch(group_keys_fn, item_blocks, 256, params, "cuLaunchKernel (hash grid groups)"));
    WEFT_RETURN_IF_ERROR(sort(32));
    void* cell_params[] = {&points, &scalar_size, &n, &width, &dx, &dy, &dz, &ids[cur], &keys[cur], &ids[cur]};
    WEFT_RETURN_IF_ERROR(launch(keys_fn, item_blocks, 256, cell_params, "cuLaunchKernel (hash grid keys)"));
  } else {
    void* params[] = {&points, &scalar_size, &n, &width, &dx, &dy, &dz, &no_order, &keys[0], &ids[0]};
    WEFT_RETURN_IF_ERROR(launch(keys_fn, item_blocks, 256, params, "cuLaunchKernel (hash grid keys)"));
  }
  int bits = 0;
  while ((uint64_t{1} << bits) < cells) ++bits;
  WEFT_RETURN_IF_ERROR(sort(bits));
  if (cur == 1)
    WEFT_RETURN_IF_ERROR(driver_->Check(
        driver_->MemcpyDtoDAsync(ids[0], ids[1], static_cast<size_t>(n) * 4, st->stream), "cuMemcpyDtoDAsync (hash grid)"));
  if (groups) {
    WEFT_ASSIGN_OR_RETURN(jit::CuFunction gather_fn, Builtin("weft_gather_int"));
    jit::CuDevicePtr sorted_groups = job.sorted_groups;
    void* params[] = {&groups, &ids[0], &n, &sorted_groups};
    WEFT_RETURN_IF_ERROR(launch(gather_fn, item_blocks, 256, params, "cuLaunchKernel (hash grid groups)"));
  }
  void* bounds_params[] = {&keys[cur], &n, &starts, &ends};
  return launch(bounds_fn, item_blocks, 256, bounds_params, "cuLaunchKernel (hash grid bounds)");
}

}  // namespace weft
