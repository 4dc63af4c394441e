// CudaDevice::BuildHashGrid: a wp.HashGrid built on its GPU, queued on the session's stream with
// no download or upload. Each point's cell (the host build's arithmetic: floor of x / width in
// float32, periodic in each dim), a stable radix sort of (cell, point id) (CudaDevice::SortPairs),
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
// Cell bounds from the sorted keys (starts and ends zeroed before).
extern "C" __global__ void weft_hash_grid_bounds(const int* keys, i64 n, int* starts, int* ends) {
  for (i64 k = (i64)blockIdx.x * blockDim.x + threadIdx.x; k < n; k += (i64)blockDim.x * gridDim.x) {
    const int c = keys[k];
    if (k == 0 || keys[k - 1] != c) starts[c] = (int)k;
    if (k == n - 1 || keys[k + 1] != c) ends[c] = (int)(k + 1);
  }
}
)CUDA";

Status CudaDevice::BuildHashGrid(Session& s, const geometry::HashGridBuildJob& job) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (lost_.load()) return Unavailable(name_ + " was lost");
  if (job.n < 0 || job.n > INT32_MAX || job.cells < 1 || job.cells > geometry::kMaxHashGridCells)
    return Internal("hash grid build job out of range");
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  TimedSpan timed(*this, *st, kTimingKernelBuiltin, "builtin kernel hash_grid_build");
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction keys_fn, Builtin("weft_hash_grid_keys"));
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

  const uint64_t words = geometry::RoundTo256(static_cast<uint64_t>(n) * 4);
  jit::CuDevicePtr keys[2] = {job.scratch, job.scratch + words};
  jit::CuDevicePtr ids[2] = {job.sorted_ids, job.scratch + 2 * words};
  jit::CuDevicePtr hist = job.scratch + 3 * words;
  SortBuffers sort_buffers{{keys[0], keys[1]}, {ids[0], ids[1]}, hist};
  const unsigned item_blocks = GridFor(static_cast<uint64_t>(n), 256, 65536);
  int bits = 0;
  while ((uint64_t{1} << bits) < cells) ++bits;
  // Each radix pass moves the pairs to the other buffer: start in the buffer from which the
  // passes (the group sort's, then the cell sort's) end in ids[0], the grid's sorted ids, so
  // that no copy is needed after.
  auto passes = [](int b) { return (b + geometry::kSortDigitBits - 1) / geometry::kSortDigitBits; };
  int cur = (passes(bits) + (job.groups ? passes(32) : 0)) % 2;
  auto sort = [&](int b) { return SortPairs(*st, sort_buffers, n, b, &cur); };

  jit::CuDevicePtr points = job.points, groups = job.groups, no_order = 0;
  int32_t scalar_size = job.scalar_size, dx = job.dim[0], dy = job.dim[1], dz = job.dim[2];
  float width = job.cell_width;
  if (groups) {
    WEFT_ASSIGN_OR_RETURN(jit::CuFunction group_keys_fn, Builtin("weft_hash_grid_group_keys"));
    void* params[] = {&groups, &n, &keys[cur], &ids[cur]};
    WEFT_RETURN_IF_ERROR(launch(group_keys_fn, item_blocks, 256, params, "cuLaunchKernel (hash grid groups)"));
    WEFT_RETURN_IF_ERROR(sort(32));
    void* cell_params[] = {&points, &scalar_size, &n, &width, &dx, &dy, &dz, &ids[cur], &keys[cur], &ids[cur]};
    WEFT_RETURN_IF_ERROR(launch(keys_fn, item_blocks, 256, cell_params, "cuLaunchKernel (hash grid keys)"));
  } else {
    void* params[] = {&points, &scalar_size, &n, &width, &dx, &dy, &dz, &no_order, &keys[cur], &ids[cur]};
    WEFT_RETURN_IF_ERROR(launch(keys_fn, item_blocks, 256, params, "cuLaunchKernel (hash grid keys)"));
  }
  WEFT_RETURN_IF_ERROR(sort(bits));
  if (cur != 0) return Internal("hash grid build: the sorted ids ended in the scratch buffer (weft bug)");
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
