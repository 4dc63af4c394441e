// CudaDevice::SortPairs: a stable LSD radix sort of (int key, int id) pairs on a session's
// stream, shared by the device builds of hash grids (cells) and BVHs (Morton codes). One 4-bit
// digit per pass over tiles of kSortTile keys: per-tile digit counts, one exclusive scan of all
// counts, and a scatter that stages each tile in shared memory so that each digit's run is
// written to consecutive addresses. Keys are sorted as unsigned by their low `bits` bits.
#include <algorithm>

#include "engine/device/cuda_device.h"
#include "engine/geometry/device_sort.h"

namespace weft {

const char* kCudaSortSource = R"CUDA(
// One 4-bit digit per pass over tiles of 2048 keys (256 threads x 8 consecutive).
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
)CUDA";

Status CudaDevice::SortPairs(Stream& st, const SortBuffers& b, int64_t n, int bits, int* cur) {
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction counts_fn, Builtin("weft_radix_counts"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction scan_fn, Builtin("weft_scan_exclusive"));
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction scatter_fn, Builtin("weft_radix_scatter"));
  int64_t tiles = (n + geometry::kSortTile - 1) / geometry::kSortTile;
  const unsigned tile_blocks = static_cast<unsigned>(std::min<int64_t>(std::max<int64_t>(tiles, 1), 65536));
  jit::CuDevicePtr keys[2] = {b.keys[0], b.keys[1]}, ids[2] = {b.ids[0], b.ids[1]}, hist = b.hist;
  auto launch = [&](jit::CuFunction fn, unsigned grid, unsigned block, void** params) {
    return driver_->Check(driver_->LaunchKernel(fn, grid, 1, 1, block, 1, 1, 0, st.stream, params, nullptr),
                          "cuLaunchKernel (radix sort)");
  };
  for (int32_t shift = 0; shift < bits; shift += 4) {
    int64_t hist_len = 16 * tiles;
    void* count_params[] = {&keys[*cur], &n, &shift, &hist, &tiles};
    WEFT_RETURN_IF_ERROR(launch(counts_fn, tile_blocks, 256, count_params));
    void* scan_params[] = {&hist, &hist_len};
    WEFT_RETURN_IF_ERROR(launch(scan_fn, 1, 1024, scan_params));
    void* scatter_params[] = {&keys[*cur], &ids[*cur], &keys[1 - *cur], &ids[1 - *cur], &n, &shift, &hist, &tiles};
    WEFT_RETURN_IF_ERROR(launch(scatter_fn, tile_blocks, 256, scatter_params));
    *cur = 1 - *cur;
  }
  return Status::Ok();
}

}  // namespace weft
