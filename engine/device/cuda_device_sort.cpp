// CudaDevice::SortPairs: a stable LSD radix sort of (int key, int id) pairs on a session's
// stream, shared by the device builds of hash grids (cells) and BVHs (Morton codes). One 8-bit
// digit per pass over tiles of kSortTile keys: per-tile digit counts, a scan of each digit's
// counts over the tiles, and a scatter that stages each tile in shared memory so that each
// digit's run is written to consecutive addresses. Keys are sorted as unsigned by their low
// `bits` bits, rounded up to whole digits.
#include <algorithm>

#include "engine/device/cuda_device.h"
#include "engine/geometry/device_sort.h"

namespace weft {

const char* kCudaSortSource = R"CUDA(
// One 8-bit digit per pass over tiles of 4096 keys: 256 threads, each warp 16 rounds of 32
// consecutive keys. A pass is three launches: per-tile digit counts (hist[digit * tiles +
// tile]), an exclusive scan of each digit's counts over the tiles (one block per digit, its
// total into totals[digit]), and a scatter that ranks each tile's keys stably (warp by warp,
// round by round: the lanes holding the same digit found with __match_any_sync), stages the
// tile in shared memory in digit order and writes each digit's run to consecutive addresses
// from digit base (the keys of smaller digits) + the tile's offset in its digit.
#define WEFT_RS_THREADS 256
#define WEFT_RS_WARPS 8
#define WEFT_RS_ROUNDS 16
#define WEFT_RS_TILE 4096
#define WEFT_RS_BINS 256
__device__ __forceinline__ int weft_digit(int key, int shift) { return (int)(((unsigned)key >> shift) & 255u); }
// Inclusive scan of one value per lane over a full warp.
__device__ __forceinline__ int weft_warp_scan(int x) {
  const int lane = threadIdx.x & 31;
  for (int off = 1; off < 32; off <<= 1) {
    const int y = __shfl_up_sync(0xffffffffu, x, off);
    if (lane >= off) x += y;
  }
  return x;
}
// Exclusive scan of one value per thread over a block of 256 threads; `tmp` holds 8 ints.
__device__ __forceinline__ int weft_block_scan256(int x, int* tmp) {
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
  const int inc = weft_warp_scan(x);
  if (lane == 31) tmp[warp] = inc;
  __syncthreads();
  int before = 0;
  for (int w = 0; w < warp; ++w) before += tmp[w];
  __syncthreads();
  return before + inc - x;
}
extern "C" __global__ void weft_radix_counts(const int* keys, i64 n, int shift, int* hist, i64 tiles) {
  __shared__ int bins[WEFT_RS_BINS];
  const unsigned lanes_below = (1u << (threadIdx.x & 31)) - 1u;
  for (i64 t = blockIdx.x; t < tiles; t += gridDim.x) {
    bins[threadIdx.x] = 0;
    __syncthreads();
    const i64 base = t * WEFT_RS_TILE;
    for (int j = threadIdx.x; j < WEFT_RS_TILE; j += WEFT_RS_THREADS) {   // every lane takes each trip
      const bool valid = base + j < n;
      const int d = valid ? weft_digit(keys[base + j], shift) : WEFT_RS_BINS;
      const unsigned peers = __match_any_sync(0xffffffffu, d);
      if (valid && (peers & lanes_below) == 0) atomicAdd(&bins[d], __popc(peers));
    }
    __syncthreads();
    hist[(i64)threadIdx.x * tiles + t] = bins[threadIdx.x];
    __syncthreads();
  }
}
// Exclusive prefix sums of each segment v[s * m, (s + 1) * m) in place, one block of 1024
// threads per segment (s = blockIdx.x), in rounds of 4096 (4 consecutive values a thread, warp
// scans, then a scan of the 32 warp totals); totals[s] = the segment's sum. v holds `count`
// values: the last segment may be shorter than m.
extern "C" __global__ void weft_scan_exclusive(int* v, i64 m, i64 count, int* totals) {
  __shared__ int warp_totals[32];
  v += (i64)blockIdx.x * m;
  const i64 left = count - (i64)blockIdx.x * m;
  if (left < m) m = left > 0 ? left : 0;
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5, warps = blockDim.x >> 5;
  int carry = 0;
  for (i64 round = 0; round < m; round += 4 * (i64)blockDim.x) {
    const i64 b = round + 4 * (i64)threadIdx.x;
    int x[4];
    for (int k = 0; k < 4; ++k) x[k] = b + k < m ? v[b + k] : 0;
    const int s = x[0] + x[1] + x[2] + x[3];
    const int inc = weft_warp_scan(s);
    if (lane == 31) warp_totals[warp] = inc;
    __syncthreads();
    if (warp == 0) {
      const int w = weft_warp_scan(lane < warps ? warp_totals[lane] : 0);
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
  if (threadIdx.x == 0) totals[blockIdx.x] = carry;
}
extern "C" __global__ void weft_radix_scatter(const int* keys_in, const int* ids_in, int* keys_out, int* ids_out, i64 n,
                                              int shift, const int* offsets, const int* totals, i64 tiles) {
  __shared__ int digit_base[WEFT_RS_BINS];   // keys of smaller digits, over all tiles
  __shared__ int warp_counts[WEFT_RS_WARPS][WEFT_RS_BINS];
  __shared__ int tile_starts[WEFT_RS_BINS], tile_offsets[WEFT_RS_BINS], tmp[WEFT_RS_WARPS];
  __shared__ int tile_keys[WEFT_RS_TILE], tile_ids[WEFT_RS_TILE];
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
  const unsigned lanes_below = (1u << lane) - 1u;
  digit_base[threadIdx.x] = weft_block_scan256(totals[threadIdx.x], tmp);
  for (i64 t = blockIdx.x; t < tiles; t += gridDim.x) {
    for (int d = lane; d < WEFT_RS_BINS; d += 32) warp_counts[warp][d] = 0;
    __syncwarp();
    const i64 base = t * WEFT_RS_TILE + (i64)warp * (32 * WEFT_RS_ROUNDS);
    int key[WEFT_RS_ROUNDS], id[WEFT_RS_ROUNDS], local[WEFT_RS_ROUNDS];
    for (int r = 0; r < WEFT_RS_ROUNDS; ++r) {   // rank among the warp's earlier keys of its digit
      const i64 k = base + r * 32 + lane;
      const bool valid = k < n;
      key[r] = valid ? keys_in[k] : 0;
      id[r] = valid ? ids_in[k] : 0;
      const int d = valid ? weft_digit(key[r], shift) : WEFT_RS_BINS;
      const unsigned peers = __match_any_sync(0xffffffffu, d);
      local[r] = valid ? warp_counts[warp][d] + __popc(peers & lanes_below) : 0;
      __syncwarp();
      if (valid && (peers & lanes_below) == 0) warp_counts[warp][d] += __popc(peers);
      __syncwarp();
    }
    __syncthreads();
    {   // per digit: each warp's start in the tile's run of the digit, and where each run starts
      const int d = threadIdx.x;
      int run = 0;
      for (int w = 0; w < WEFT_RS_WARPS; ++w) {
        const int c = warp_counts[w][d];
        warp_counts[w][d] = run;
        run += c;
      }
      tile_offsets[d] = digit_base[d] + offsets[(i64)d * tiles + t];
      tile_starts[d] = weft_block_scan256(run, tmp);
    }
    __syncthreads();
    for (int r = 0; r < WEFT_RS_ROUNDS; ++r) {
      if (base + r * 32 + lane >= n) break;
      const int d = weft_digit(key[r], shift);
      const int at = tile_starts[d] + warp_counts[warp][d] + local[r];
      tile_keys[at] = key[r];
      tile_ids[at] = id[r];
    }
    __syncthreads();
    const i64 left = n - t * WEFT_RS_TILE;
    const int count = left < WEFT_RS_TILE ? (int)left : WEFT_RS_TILE;
    for (int j = threadIdx.x; j < count; j += WEFT_RS_THREADS) {
      const int k = tile_keys[j];
      const int d = weft_digit(k, shift);
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
  jit::CuDevicePtr totals = hist + geometry::SortCountsBytes(n);
  auto launch = [&](jit::CuFunction fn, unsigned grid, unsigned block, void** params) {
    return driver_->Check(driver_->LaunchKernel(fn, grid, 1, 1, block, 1, 1, 0, st.stream, params, nullptr),
                          "cuLaunchKernel (radix sort)");
  };
  for (int32_t shift = 0; shift < bits; shift += geometry::kSortDigitBits) {
    void* count_params[] = {&keys[*cur], &n, &shift, &hist, &tiles};
    WEFT_RETURN_IF_ERROR(launch(counts_fn, tile_blocks, 256, count_params));
    int64_t counts = tiles * geometry::kSortBins;
    void* scan_params[] = {&hist, &tiles, &counts, &totals};
    WEFT_RETURN_IF_ERROR(launch(scan_fn, geometry::kSortBins, 1024, scan_params));
    void* scatter_params[] = {&keys[*cur], &ids[*cur], &keys[1 - *cur], &ids[1 - *cur], &n, &shift, &hist, &totals, &tiles};
    WEFT_RETURN_IF_ERROR(launch(scatter_fn, tile_blocks, 256, scatter_params));
    *cur = 1 - *cur;
  }
  return Status::Ok();
}

}  // namespace weft
