// CudaDevice: context, slabs, streams, modules, built-in copy/fill kernels, asynchronous launch
// errors, bounded waits with cancellation, reset after a sticky fault.
#include "engine/device/cuda_device.h"

#include <sched.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <optional>
#include <string_view>
#include <thread>

#include <spdlog/spdlog.h>

#include "engine/core/frame_trace.h"
#include "engine/device/cuda_print.h"
#include "engine/native/launch_abi.h"
#include "engine/runtime/cpu_launch.h"
#include "engine/runtime/session.h"

namespace weft {

struct wp_launch_error : wp::launch_error_t {};

namespace {

constexpr uint64_t kAlignment = 256;

uint64_t RoundUp(uint64_t v, uint64_t a) { return (v + a - 1) / a * a; }

// A failed expectation of a GPU kernel keeps its values as a print record in the error's
// message (engine/native/expect.h): the error as FormatLaunchError reads it, with that record
// formatted as text (checked as any print record: the slot is device memory a kernel can write).
wp::launch_error_t WithExpectText(const wp::launch_error_t& e) {
  if (e.kind != wp::LAUNCH_EXPECT_FAILED) return e;
  wp::launch_error_t out = e;
  std::string text;
  if (e.message[0] == wp::EXPECT_RECORD) {
    const uint64_t capacity = sizeof(e.message) - 1;
    uint32_t size = 0;
    std::memcpy(&size, e.message + 1, sizeof(size));
    text = FormatPrintRecords(e.message + 1, std::min<uint64_t>(size, capacity), capacity);
    while (!text.empty() && text.back() == '\n') text.pop_back();
  } else if (e.message[0] == wp::EXPECT_IN_OUTPUT) {
    text = "the values are in the kernel's print output";
  } else {
    return e;
  }
  const size_t n = std::min(text.size(), sizeof(out.message) - 1);
  std::memcpy(out.message, text.data(), n);
  out.message[n] = '\0';
  return out;
}

// Strided copy and fill over views of up to 4 dimensions; elements move in words of `word`
// bytes (the largest of 8/4/2/1 that divides the element size, every stride and both bases).
const char* kBuiltinSource = R"CUDA(
typedef long long i64;
struct weft_view { i64 shape[4]; i64 strides[4]; int ndim; int pad; };
struct weft_value { unsigned char b[512]; };
__device__ __forceinline__ i64 weft_offset(const weft_view& v, i64 flat) {
  i64 off = 0;
  for (int d = v.ndim - 1; d >= 0; --d) {
    i64 n = v.shape[d];
    i64 idx = d == 0 ? flat : flat % n;
    flat = d == 0 ? 0 : flat / n;
    off += idx * v.strides[d];
  }
  return off;
}
template <typename W> __device__ __forceinline__ void weft_move(char* d, const char* s, int esize) {
  for (int k = 0; k < esize; k += (int)sizeof(W)) *(W*)(d + k) = *(const W*)(s + k);
}
extern "C" __global__ void weft_copy_strided(char* dst, weft_view dv, const char* src, weft_view sv, i64 n,
                                             int esize, int word) {
  for (i64 i = (i64)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += (i64)blockDim.x * gridDim.x) {
    char* d = dst + weft_offset(dv, i);
    const char* s = src + weft_offset(sv, i);
    if (word == 8) weft_move<unsigned long long>(d, s, esize);
    else if (word == 4) weft_move<unsigned int>(d, s, esize);
    else if (word == 2) weft_move<unsigned short>(d, s, esize);
    else weft_move<unsigned char>(d, s, esize);
  }
}
extern "C" __global__ void weft_fill_strided(char* dst, weft_view dv, weft_value v, i64 n, int esize, int word) {
  for (i64 i = (i64)blockIdx.x * blockDim.x + threadIdx.x; i < n; i += (i64)blockDim.x * gridDim.x) {
    char* d = dst + weft_offset(dv, i);
    const char* s = (const char*)v.b;
    if (word == 8) weft_move<unsigned long long>(d, s, esize);
    else if (word == 4) weft_move<unsigned int>(d, s, esize);
    else if (word == 2) weft_move<unsigned short>(d, s, esize);
    else weft_move<unsigned char>(d, s, esize);
  }
}
// BVH refit (wp::bvh_node_t): the nodes of one level, each from its items (a leaf: wp.Bvh boxes,
// or the triangles of a wp.Mesh) or its two children (refitted by the launch before), with the
// host refit's arithmetic (bounds start at +-3e38; a NaN coordinate never wins a min/max).
struct weft_bvh_node { float lower[3]; int left; float upper[3]; int right; };
__device__ __forceinline__ void weft_grow(float* lo, float* hi, const float* l, const float* h) {
  for (int k = 0; k < 3; ++k) {
    lo[k] = l[k] < lo[k] ? l[k] : lo[k];
    hi[k] = hi[k] < h[k] ? h[k] : hi[k];
  }
}
// Item `item`'s bounds: a wp.Bvh box, or the triangle of a wp.Mesh (`indices` set).
__device__ __forceinline__ void weft_item_bounds(i64 item, const float* lowers, const float* uppers,
                                                 const float* points, const int* indices, float* lo, float* hi) {
  for (int a = 0; a < 3; ++a) {
    lo[a] = 3.0e38f;
    hi[a] = -3.0e38f;
  }
  if (indices) {
    for (int c = 0; c < 3; ++c) {
      const float* v = points + 3 * (i64)indices[3 * item + c];
      for (int a = 0; a < 3; ++a) {
        if (v[a] < lo[a]) lo[a] = v[a];
        if (v[a] > hi[a]) hi[a] = v[a];
      }
    }
  } else {
    weft_grow(lo, hi, lowers + 3 * item, uppers + 3 * item);
  }
}
extern "C" __global__ void weft_bvh_refit_level(weft_bvh_node* nodes, const int* levels, i64 begin, i64 end,
                                                const int* prim_ids, const float* lowers, const float* uppers,
                                                const float* points, const int* indices) {
  for (i64 k = begin + (i64)blockIdx.x * blockDim.x + threadIdx.x; k < end; k += (i64)blockDim.x * gridDim.x) {
    weft_bvh_node n = nodes[levels[k]];
    float lo[3] = {3.0e38f, 3.0e38f, 3.0e38f}, hi[3] = {-3.0e38f, -3.0e38f, -3.0e38f};
    if (n.right < 0) {
      for (int i = n.left; i < n.left - n.right; ++i) {
        float l[3], h[3];
        weft_item_bounds(prim_ids[i], lowers, uppers, points, indices, l, h);
        weft_grow(lo, hi, l, h);
      }
    } else {
      weft_grow(lo, hi, nodes[n.left].lower, nodes[n.left].upper);
      weft_grow(lo, hi, nodes[n.right].lower, nodes[n.right].upper);
    }
    for (int a = 0; a < 3; ++a) {
      nodes[levels[k]].lower[a] = lo[a];
      nodes[levels[k]].upper[a] = hi[a];
    }
  }
}
)CUDA";

}  // namespace

extern const char* kCudaSortSource;       // cuda_device_sort.cpp
extern const char* kCudaHashGridSource;   // cuda_device_hash_grid.cpp
extern const char* kCudaBvhSource;        // cuda_device_bvh.cpp

std::string CudaBuiltinSource() {
  return std::string(kBuiltinSource) + kCudaSortSource + kCudaHashGridSource + kCudaBvhSource;
}

namespace {

struct ViewArg {
  int64_t shape[4] = {1, 1, 1, 1};
  int64_t strides[4] = {0, 0, 0, 0};
  int32_t ndim = 1;
  int32_t pad = 0;
};
struct ValueArg {
  unsigned char b[512];
};

ViewArg ViewArgOf(const ArrayView& v) {
  ViewArg a;
  a.ndim = static_cast<int32_t>(v.shape.size());
  for (size_t i = 0; i < v.shape.size() && i < 4; ++i) {
    a.shape[i] = v.shape[i];
    a.strides[i] = v.strides[i];
  }
  return a;
}

int WordOf(uint64_t esize, const std::vector<const ArrayView*>& views) {
  for (int w : {8, 4, 2}) {
    bool ok = esize % w == 0;
    for (const ArrayView* v : views) {
      ok = ok && reinterpret_cast<uintptr_t>(v->data()) % w == 0;
      for (int64_t s : v->strides) ok = ok && s % w == 0;
    }
    if (ok) return w;
  }
  return 1;
}


// A contiguous view over memory that belongs to no array (staging buffers).
ArrayView ScratchView(const DType& dtype, uint64_t count, void* data, const std::string& device) {
  auto a = std::make_shared<Allocation>();
  a->dtype = dtype;
  a->shape = {static_cast<int64_t>(count)};
  a->strides = ContiguousStrides(a->shape, dtype.ElementSize());
  a->byte_size = count * dtype.ElementSize();
  a->device = device;
  a->block.data = data;
  a->block.size = a->byte_size;
  ArrayView v;
  v.alloc = a;
  v.shape = a->shape;
  v.strides = a->strides;
  return v;
}

std::string Where(const SourceLocation& o) {
  return o.file.empty() ? std::string() : " (launched at " + o.file + ":" + std::to_string(o.line) + ")";
}

}  // namespace

CudaDevice::CudaDevice(CudaDeviceOptions options)
    : options_(std::move(options)), name_("cuda:" + std::to_string(options_.ordinal)) {}

Expected<std::unique_ptr<CudaDevice>> CudaDevice::Create(const CudaDeviceOptions& options) {
  std::unique_ptr<CudaDevice> d(new CudaDevice(options));
  WEFT_RETURN_IF_ERROR(d->Init());
  return d;
}

Status CudaDevice::Init() {
  WEFT_ASSIGN_OR_RETURN(driver_, jit::CudaDriver::Get());
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->DeviceGet(&device_, options_.ordinal), "cuDeviceGet"));
  WEFT_ASSIGN_OR_RETURN(sm_, driver_->ComputeCapability(options_.ordinal));
  {
    int mem_ops = 0;
    stream_mem_ops_ = driver_->DeviceGetAttribute(&mem_ops, jit::kCuAttributeCanUse64BitStreamMemOps, device_) == 0 &&
                      mem_ops != 0;
  }
  {
    int sms = 0, threads_per_sm = 0;
    if (driver_->DeviceGetAttribute(&sms, jit::kCuAttributeMultiprocessorCount, device_) == 0 &&
        driver_->DeviceGetAttribute(&threads_per_sm, jit::kCuAttributeMaxThreadsPerMultiprocessor, device_) == 0)
      coarsen_min_threads_ = CoarsenMinThreads(sms, threads_per_sm);
  }
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->DevicePrimaryCtxRetain(&ctx_, device_), "cuDevicePrimaryCtxRetain"));
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  // A first allocation proves the context works (a GPU that lists but cannot compute fails here).
  jit::CuDevicePtr probe = 0;
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemAlloc(&probe, 256), "cuMemAlloc"));
  driver_->MemFree(probe);
  return Status::Ok();
}

CudaDevice::~CudaDevice() {
  if (!driver_ || !ctx_) return;
  (void)MakeCurrent();
  std::lock_guard<std::mutex> lock(mu_);
  for (auto& [id, st] : streams_) DestroyStream(*st);
  streams_.clear();
  for (auto& [id, m] : modules_) driver_->ModuleUnload(m.module);
  if (builtins_) driver_->ModuleUnload(builtins_);
  for (auto& [id, slab] : slabs_) driver_->MemFree(slab->base);
  slabs_.clear();
}

Status CudaDevice::MakeCurrent() const {
  return driver_->Check(driver_->CtxSetCurrent(ctx_), "cuCtxSetCurrent");
}

CudaDeviceStats CudaDevice::stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  return {resets_, last_reset_ms_, coarsened_launches_.load(std::memory_order_relaxed)};
}

namespace {

// A decimal number from the environment variable `name`, digits only, at most `max`; nullopt
// when unset or anything else ("-5", "12abc", "", too large).
std::optional<uint64_t> EnvCount(const char* name, uint64_t max) {
  const char* v = std::getenv(name);
  if (!v || !*v) return std::nullopt;
  uint64_t n = 0;
  for (const char* p = v; *p; ++p) {
    if (*p < '0' || *p > '9') return std::nullopt;
    const uint64_t digit = static_cast<uint64_t>(*p - '0');
    if (n > (max - digit) / 10) return std::nullopt;
    n = n * 10 + digit;
  }
  return n;
}

}  // namespace

uint32_t CoarsenMaxLoadedBytes() {
  return static_cast<uint32_t>(EnvCount("WEFT_COARSEN_MAX_LOADED_BYTES", 1u << 20).value_or(12));
}

uint64_t CoarsenMinThreads(int sms, int threads_per_sm) {
  if (const char* off = std::getenv("WEFT_COARSEN"); off && std::string(off) == "0") return 0;
  if (auto n = EnvCount("WEFT_COARSEN_MIN_THREADS", UINT64_MAX); n && *n > 0) return *n;
  if (sms <= 0 || threads_per_sm <= 0) return 0;
  return 2ull * static_cast<uint64_t>(kCoarseFactor) * static_cast<uint64_t>(sms) *
         static_cast<uint64_t>(threads_per_sm);
}

// ---- memory ----

uint64_t CudaDevice::ReservedSize(uint64_t bytes) const {
  return RoundUp(bytes ? bytes : 1, kAlignment);
}

// Slab ids are unique across every GPU of the daemon (clients key their IPC mappings by them).
static std::atomic<uint64_t> next_slab_id{1};

Expected<CudaDevice::Slab*> CudaDevice::NewSlabLocked(uint64_t size, bool dedicated, const std::string& owner) {
  auto slab = std::make_unique<Slab>();
  slab->id = next_slab_id.fetch_add(1, std::memory_order_relaxed);
  slab->size = size;
  slab->dedicated = dedicated;
  slab->owner = owner;
  jit::CuResult r = driver_->MemAlloc(&slab->base, size);
  if (r == 2 /* CUDA_ERROR_OUT_OF_MEMORY */) {   // the cached slabs first, then the error
    DropCachedLocked();
    r = driver_->MemAlloc(&slab->base, size);
  }
  if (r == 2 /* CUDA_ERROR_OUT_OF_MEMORY */)
    return ResourceExhausted(name_ + " is out of memory (a slab of " + std::to_string(size) + " bytes)");
  WEFT_RETURN_IF_ERROR(driver_->Check(r, "cuMemAlloc"));
  jit::CuIpcMemHandle handle{};
  if (driver_->IpcGetMemHandle(&handle, slab->base) == 0) slab->ipc.assign(handle.reserved, sizeof(handle.reserved));
  slab->free_ranges[0] = size;
  Slab* out = slab.get();
  slabs_[slab->id] = std::move(slab);
  return out;
}

Expected<MemoryBlock> CudaDevice::Allocate(uint64_t bytes, const std::string& owner, bool dedicated) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  const uint64_t need = ReservedSize(bytes);
  if (!owner.empty()) WEFT_RETURN_IF_ERROR(StreamOf(owner).status());   // the owner's stream exists
  std::lock_guard<std::mutex> lock(mu_);
  Slab* slab = nullptr;
  uint64_t offset = 0;
  if (dedicated) {   // an export's slab: always a fresh one
    WEFT_ASSIGN_OR_RETURN(slab, NewSlabLocked(need, true, owner));
  } else if (need > options_.dedicated_threshold) {
    slab = TakeCachedLocked(need, owner);
    if (!slab) {
      WEFT_ASSIGN_OR_RETURN(slab, NewSlabLocked(need, true, owner));
    }
  } else {
    for (auto& [id, s] : slabs_) {
      if (s->dedicated || s->owner != owner) continue;
      for (auto& [off, size] : s->free_ranges) {
        if (size >= need) {
          slab = s.get();
          offset = off;
          break;
        }
      }
      if (slab) break;
    }
    if (!slab) {
      WEFT_ASSIGN_OR_RETURN(slab, NewSlabLocked(std::max(options_.slab_size, need), false, owner));
    }
  }
  if (!slab->dedicated || slab->used == 0) {
    auto it = slab->free_ranges.find(offset);
    uint64_t size = it->second;
    slab->free_ranges.erase(it);
    if (size > need) slab->free_ranges[offset + need] = size - need;
  }
  slab->used += need;
  MemoryBlock b;
  b.slab_id = slab->id;
  b.slab_size = slab->size;
  b.offset = offset;
  b.size = need;
  b.data = reinterpret_cast<void*>(static_cast<uintptr_t>(slab->base + offset));
  b.dedicated = slab->dedicated;
  b.owner = owner;
  b.ipc_handle = slab->ipc;
  b.generation = generation_.load();
  return b;
}

CudaDevice::Slab* CudaDevice::TakeCachedLocked(uint64_t need, const std::string& owner) {
  Slab* best = nullptr;
  for (auto& [id, s] : slabs_) {
    if (!s->cached || s->shared || s->owner != owner || s->size < need || s->size - need > need / 2) continue;
    if (!best || s->size < best->size) best = s.get();
  }
  if (best) best->cached = false;
  return best;
}

void CudaDevice::DropCachedLocked() {
  for (auto it = slabs_.begin(); it != slabs_.end();) {
    if (it->second->cached) {
      driver_->MemFree(it->second->base);
      it = slabs_.erase(it);
    } else {
      ++it;
    }
  }
}

void CudaDevice::MarkShared(const MemoryBlock& b) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = slabs_.find(b.slab_id);
  if (it != slabs_.end()) it->second->shared = true;
}

void CudaDevice::Free(const MemoryBlock& b) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (b.generation != generation_.load()) return;   // its memory went with the old context
  (void)MakeCurrent();
  std::lock_guard<std::mutex> lock(mu_);
  auto it = slabs_.find(b.slab_id);
  if (it == slabs_.end()) return;
  Slab& s = *it->second;
  s.used -= std::min(s.used, b.size);
  if (s.used == 0 && s.dedicated && !s.shared && streams_.count(s.owner)) {
    // Kept for the owner's next big array, within the owner's cache budget.
    uint64_t cached = 0;
    for (const auto& [id, o] : slabs_)
      if (o->cached && o->owner == s.owner) cached += o->size;
    if (cached + s.size <= options_.dedicated_cache_bytes) {
      s.cached = true;
      s.free_ranges.clear();
      s.free_ranges[0] = s.size;
      return;
    }
  }
  if (s.used == 0 && (s.dedicated || !streams_.count(s.owner))) {
    // An empty dedicated slab, or one whose owner has closed, goes back to the driver; the
    // regular slabs of a live session stay for its next arrays.
    driver_->MemFree(s.base);
    slabs_.erase(it);
    return;
  }
  uint64_t off = b.offset, size = b.size;
  auto next = s.free_ranges.lower_bound(off);
  if (next != s.free_ranges.end() && off + size == next->first) {
    size += next->second;
    next = s.free_ranges.erase(next);
  }
  if (next != s.free_ranges.begin()) {
    auto prev = std::prev(next);
    if (prev->first + prev->second == off) {
      prev->second += size;
      return;
    }
  }
  s.free_ranges[off] = size;
}

uint64_t CudaDevice::SlabBytes() const {
  std::lock_guard<std::mutex> lock(mu_);
  uint64_t n = 0;
  for (auto& [id, s] : slabs_) n += s->size;
  return n;
}

uint32_t CudaDevice::SlabCount() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<uint32_t>(slabs_.size());
}

Status CudaDevice::CheckUsable() const {
  if (lost_.load())
    return FailedPrecondition(name_ + " is unusable: " + lost_reason_ +
                              "; every array on it is lost (device was reset, these arrays are lost); using this GPU "
                              "again takes " + WhatBringsItBack() +
                              " (the CPU, and every GPU the driver still serves, keep working)");
  return Status::Ok();
}

bool CudaDevice::RegisterHost(void* p, uint64_t bytes) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (!CheckUsable().ok() || !MakeCurrent().ok()) return false;
  constexpr unsigned kPortable = 0x01;   // CU_MEMHOSTREGISTER_PORTABLE
  return driver_->MemHostRegister(p, bytes, kPortable) == 0;
}

void CudaDevice::UnregisterHost(void* p) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (lost_.load() || !MakeCurrent().ok()) return;
  (void)driver_->MemHostUnregister(p);
}

Status CudaDevice::CheckBlock(const MemoryBlock& b, const std::string& what) const {
  WEFT_RETURN_IF_ERROR(CheckUsable());
  if (b.generation != generation_.load())
    return FailedPrecondition(name_ + " was reset after a kernel fault: " + what +
                              " was lost with it (device was reset, these arrays are lost)");
  return Status::Ok();
}

// ---- streams ----

CudaDevice::Stream* CudaDevice::FindStream(const std::string& session_id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = streams_.find(session_id);
  return it == streams_.end() ? nullptr : it->second.get();
}

Expected<CudaDevice::Stream*> CudaDevice::StreamOf(const std::string& session_id) {
  if (Stream* st = FindStream(session_id)) return st;
  auto st = std::make_unique<Stream>();
  st->generation = generation_.load();
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->StreamCreate(&st->stream, jit::kCuStreamNonBlocking), "cuStreamCreate"));
  const uint64_t slots_bytes = kErrorSlots * sizeof(wp::launch_error_t);
  Status s = driver_->Check(driver_->MemAlloc(&st->errors_base, kPrintHeader + slots_bytes), "cuMemAlloc");
  if (s.ok()) st->errors = st->errors_base + kPrintHeader;
  if (s.ok()) s = driver_->Check(driver_->MemAlloc(&st->print_data, kPrintCapacity), "cuMemAlloc (print buffer)");
  void* pinned = nullptr;
  if (s.ok()) s = driver_->Check(driver_->MemHostAlloc(&pinned, kPrintHeader + slots_bytes, 0), "cuMemHostAlloc");
  if (s.ok()) {
    st->readback = static_cast<char*>(pinned);
    st->errors_host = reinterpret_cast<wp_launch_error*>(st->readback + kPrintHeader);
    std::memset(st->readback, 0, kPrintHeader + slots_bytes);
    wp::print_buffer_t header{};
    header.data = reinterpret_cast<char*>(static_cast<uintptr_t>(st->print_data));
    header.capacity = kPrintCapacity;
    std::memcpy(st->readback, &header, sizeof(header));
    // Zeroed slots and the header, from pinned memory; later read-backs into `readback` are
    // queued on the same stream, after this copy.
    s = driver_->Check(driver_->MemcpyHtoDAsync(st->errors_base, st->readback, kPrintHeader + slots_bytes, st->stream),
                       "cuMemcpyHtoDAsync (launch errors)");
  }
  void* host = nullptr;
  if (s.ok()) s = driver_->Check(driver_->MemHostAlloc(&host, 64, 0), "cuMemHostAlloc");
  if (s.ok()) {
    st->cancel_host = static_cast<int32_t*>(host);
    *st->cancel_host = 1;   // the value a cancel copies into the device word
    s = driver_->Check(driver_->StreamCreate(&st->cancel_stream, jit::kCuStreamNonBlocking), "cuStreamCreate (cancel)");
  }
  // The report flag (mapped pinned memory). Without it every synchronize reads the slots back.
  void* report = nullptr;
  if (s.ok() && driver_->MemHostAlloc(&report, 64, jit::kCuMemHostAllocMapped) == 0) {
    jit::CuDevicePtr device_word = 0;
    if (driver_->MemHostGetDevicePointer(&device_word, report, 0) == 0) {
      st->report_host = static_cast<volatile int32_t*>(report);
      *st->report_host = 0;
      st->report_device = device_word;
    } else {
      driver_->MemFreeHost(report);
    }
  }
  if (s.ok() && !st->report_host) spdlog::warn("{}: no mapped host memory for the launch report flag; errors are read back at every synchronize", name_);
  if (!s.ok()) {
    DestroyStream(*st);
    return s;
  }
  std::lock_guard<std::mutex> lock(mu_);
  auto timing = timing_filters_.find(session_id);
  if (timing != timing_filters_.end()) st->timing_filter.store(timing->second);
  auto [it, fresh] = streams_.emplace(session_id, std::move(st));
  if (!fresh) DestroyStream(*st);   // another thread made it meanwhile (not expected: one executor per session)
  return it->second.get();
}

void CudaDevice::DestroyStream(Stream& st) {
  ReleaseValueWaits(st);
  if (st.stream) driver_->StreamSynchronize(st.stream);
  ReleaseGeometry(st, true);
  if (st.stream) driver_->StreamDestroy(st.stream);
  {
    std::lock_guard<std::mutex> lock(st.timing_mu);
    for (const Stream::Timed& t : st.timed) {
      driver_->EventDestroy(t.start);
      driver_->EventDestroy(t.end);
    }
    for (jit::CuEvent e : st.spare_events) driver_->EventDestroy(e);
    st.timed.clear();
    st.spare_events.clear();
  }
  if (st.errors_base) driver_->MemFree(st.errors_base);
  if (st.print_data) driver_->MemFree(st.print_data);
  if (st.cancel_stream) driver_->StreamDestroy(st.cancel_stream);
  st.cancel_stream = nullptr;
  if (st.cancel_host) driver_->MemFreeHost(st.cancel_host);
  if (st.report_host) driver_->MemFreeHost(const_cast<int32_t*>(st.report_host));
  st.report_host = nullptr;
  st.report_device = 0;
  if (st.readback) driver_->MemFreeHost(st.readback);
  st.readback = nullptr;
  st.errors_host = nullptr;
  st.stream = nullptr;
  st.errors_base = 0;
  st.errors = 0;
  st.print_data = 0;
  st.cancel_host = nullptr;
}

void CudaDevice::CloseSession(Session& s) {
  ForgetImports(s.id());   // its arrays are gone already: this closes its imported mappings
  ForgetEvents(s.id());
  ForgetTimedEvents(s.id());
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  (void)MakeCurrent();
  std::unique_ptr<Stream> st;
  {
    std::lock_guard<std::mutex> lock(mu_);
    reset_sessions_.erase(s.id());
    timing_filters_.erase(s.id());
    auto it = streams_.find(s.id());
    if (it == streams_.end()) return;
    st = std::move(it->second);
    streams_.erase(it);
  }
  if (st->generation == generation_.load()) {
    ReleaseValueWaits(*st);
    driver_->StreamSynchronize(st->stream);
    DestroyStream(*st);
  }
  // The session's empty slabs go back to the driver (slabs still holding shared arrays follow
  // when those are freed).
  std::lock_guard<std::mutex> lock(mu_);
  for (auto it = slabs_.begin(); it != slabs_.end();) {
    if (it->second->owner == s.id() && it->second->used == 0) {
      driver_->MemFree(it->second->base);
      it = slabs_.erase(it);
    } else {
      ++it;
    }
  }
}

// A synchronize blocked on a stream waits for `fired` to change; the host function the
// stream runs when it gets there (SignalFromStream) changes it.
struct StreamSignal {
  std::mutex mu;
  std::condition_variable cv;
  uint64_t fired = 0;
};

namespace {

// cuLaunchHostFunc's function: `holder` is a heap std::shared_ptr<StreamSignal> of its own (the
// stream may be gone by the time the driver runs this). Makes no CUDA call, as the driver requires.
void SignalFromStream(void* holder) {
  auto* signal = static_cast<std::shared_ptr<StreamSignal>*>(holder);
  {
    std::lock_guard<std::mutex> lock((*signal)->mu);
    ++(*signal)->fired;
  }
  (*signal)->cv.notify_all();
  delete signal;
}

// WEFT_STREAM_WAIT=poll: the wait polls with 100 us sleeps after 4000 polls (the earlier way).
bool StreamWaitPolls() {
  static const bool polls = [] {
    const char* v = std::getenv("WEFT_STREAM_WAIT");
    return v && std::string_view(v) == "poll";
  }();
  return polls;
}

// How long a wait polls the stream before it blocks (WEFT_STREAM_SPIN_US, default 20 ms). Polling
// (yielding the core between polls) ends within microseconds of the work; blocking on the host
// function cost 190-230 us more per round on the lent H200 (bench/prof_stream_wait.py: saxpy
// 1e8, five launches then a synchronize, 405-407 us per launch polling 20 ms, 444-454 us
// blocking after 1 ms), so only waits longer than this, where that is about 1%, block. CUDA's
// own synchronize spins for the whole wait under its default scheduling.
constexpr long long kDefaultStreamSpinUs = 20'000;
std::chrono::nanoseconds StreamSpinTime() {
  static const std::chrono::nanoseconds spin = [] {
    const char* v = std::getenv("WEFT_STREAM_SPIN_US");
    char* end = nullptr;
    const long long us = v ? std::strtoll(v, &end, 10) : kDefaultStreamSpinUs;
    return std::chrono::microseconds(v && (end == v || us < 0 || us > 10'000'000) ? kDefaultStreamSpinUs : us);
  }();
  return spin;
}

}  // namespace

jit::CuResult CudaDevice::WaitStream(Session& s, Stream& st, int* cancel_reason) {
  *cancel_reason = 0;
  const auto start = std::chrono::steady_clock::now();
  const bool trace = frame_trace::Enabled();
  const int64_t trace_start = trace ? frame_trace::NowNs() : 0;
  // A host function may not be queued while the stream captures a graph (it would be captured).
  bool can_block = driver_->LaunchHostFunc != nullptr && !StreamWaitPolls() && !st.capture;
  bool queued = false;
  uint64_t seen = 0;   // signal->fired before the host function was queued
  for (int polls = 0;; ++polls) {
    jit::CuResult r = driver_->StreamQuery(st.stream);
    if (r != jit::kCuErrorNotReady) {
      if (trace) {
        frame_trace::Current().stream_wait_ns += frame_trace::NowNs() - trace_start;
        frame_trace::Current().stream_polls += polls + 1;
        if (queued) ++frame_trace::Current().stream_blocks;
      }
      return r;
    }
    const auto now = std::chrono::steady_clock::now();
    if (*cancel_reason == 0) {
      if (s.cancelled()) {
        *cancel_reason = 1;
      } else if (options_.launch_time_limit_s > 0 &&
                 std::chrono::duration<double>(now - start).count() > options_.launch_time_limit_s) {
        *cancel_reason = 2;
      }
      if (*cancel_reason && !st.cancel_set) {
        // The copy engine writes the word while the session's kernels run.
        st.cancel_set = driver_->MemcpyHtoDAsync(st.errors_base + kCancelOffset, st.cancel_host, sizeof(int32_t),
                                                 st.cancel_stream) == 0;
        // A stream-memory wait the client never satisfied would hold the stream for good.
        ReleaseValueWaits(st);
      }
    }
    if (!can_block) {
      // Spin briefly (short kernels), then sleep in small steps.
      if (polls < 4000) sched_yield();
      else std::this_thread::sleep_for(std::chrono::microseconds(100));
      continue;
    }
    // Short waits (a launch + synchronize) end while polling; a long one blocks until the
    // stream's host function signals, which wakes it within a thread wake-up of the work's end
    // where a sleep would overshoot by up to its length.
    if (now - start < StreamSpinTime()) {
      sched_yield();
      continue;
    }
    if (!queued) {
      if (!st.signal) st.signal = std::make_shared<StreamSignal>();
      {
        std::lock_guard<std::mutex> lock(st.signal->mu);
        seen = st.signal->fired;
      }
      auto* holder = new std::shared_ptr<StreamSignal>(st.signal);
      if (driver_->LaunchHostFunc(st.stream, SignalFromStream, holder) != 0) {
        delete holder;
        can_block = false;   // poll and sleep for the rest of this wait
        continue;
      }
      queued = true;
    }
    std::unique_lock<std::mutex> lock(st.signal->mu);
    if (st.signal->fired != seen) {
      // Signalled: the stream is about to report idle (or failed after the host function).
      lock.unlock();
      sched_yield();
      continue;
    }
    st.signal->cv.wait_for(lock, std::chrono::milliseconds(1));
  }
}

Status CudaDevice::ClearCancel(Stream& st) {
  if (!st.cancel_set) return Status::Ok();
  st.cancel_set = false;
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->StreamSynchronize(st.cancel_stream), "cuStreamSynchronize (cancel)"));
  return driver_->Check(driver_->MemsetD32Async(st.errors_base + kCancelOffset, 0, 1, st.stream), "cuMemsetD32Async (cancel)");
}

Status CudaDevice::QueueErrorReadback(Stream& st) {
  const size_t n = st.pending.size();
  if (n == 0) return Status::Ok();
  // The print buffer's header (its `used`) comes along with the slots.
  return driver_->Check(driver_->MemcpyDtoHAsync(st.readback, st.errors_base, kPrintHeader + n * sizeof(wp::launch_error_t),
                                                 st.stream),
                        "cuMemcpyDtoHAsync (launch errors)");
}

DeviceSyncResult CudaDevice::ReadBackAndDrain(Stream& st) {
  if (!st.pending.empty() && (!st.report_host || __atomic_load_n(st.report_host, __ATOMIC_ACQUIRE) != 0)) {
    Status read = QueueErrorReadback(st);
    if (read.ok()) read = driver_->Check(driver_->StreamSynchronize(st.stream), "cuStreamSynchronize (launch errors)");
    if (!read.ok()) {
      st.pending.clear();
      ReleaseGeometry(st, false);
      DeviceSyncResult out;
      out.error = read;
      return out;
    }
    if (st.report_host) *st.report_host = 0;   // the stream is idle: no kernel writes it now
  }
  // Not set: no launch since the last drain wrote a slot or a print record, so `readback`
  // (zeroed by the last drain) is what a read-back would bring.
  return Drain(st);
}

DeviceSyncResult CudaDevice::Drain(Stream& st) {
  const size_t n = st.pending.size();
  if (n == 0) return {};
  DeviceSyncResult out;
  for (size_t i = 0; i < n; ++i) {
    const wp::launch_error_t& e = st.errors_host[i];
    if (e.kind == 0) continue;
    const Pending& p = st.pending[i];
    out.error = FormatLaunchError(*p.module, *p.kernel, p.adjoint, WithExpectText(e));
    out.origin = p.origin;
    break;
  }
  // Only slots that hold an error need clearing (the next launches reuse them).
  if (!out.error.ok()) {
    Status cleared = driver_->Check(driver_->MemsetD8Async(st.errors, 0, n * sizeof(wp::launch_error_t), st.stream),
                                    "cuMemsetD8Async");
    if (!cleared.ok()) out.error = cleared;
    std::memset(static_cast<void*>(st.errors_host), 0, n * sizeof(wp::launch_error_t));
  }
  st.pending.clear();
  ReleaseGeometry(st, false);
  // Kernel print output: the records the launches appended (the stream is idle here).
  wp::print_buffer_t header;
  std::memcpy(&header, st.readback, sizeof(header));
  if (header.used > 0) {
    const uint64_t n_bytes = std::min<uint64_t>(header.used, kPrintCapacity);
    std::string records(n_bytes, '\0');
    Status copied = driver_->Check(driver_->MemcpyDtoHAsync(records.data(), st.print_data, n_bytes, st.stream),
                                   "cuMemcpyDtoHAsync (print output)");
    if (copied.ok()) copied = driver_->Check(driver_->StreamSynchronize(st.stream), "cuStreamSynchronize");
    if (copied.ok()) out.output = FormatPrintRecords(records.data(), header.used, kPrintCapacity);
    const uint64_t zero_used = st.errors_base + offsetof(wp::print_buffer_t, used);
    Status reset = driver_->Check(driver_->MemsetD8Async(zero_used, 0, sizeof(header.used), st.stream), "cuMemsetD8Async");
    header.used = 0;
    std::memcpy(st.readback, &header, sizeof(header));
    if (out.error.ok() && !copied.ok()) out.error = copied;
    if (out.error.ok() && !reset.ok()) out.error = reset;
  }
  return out;
}

DeviceSyncResult CudaDevice::Synchronize(Session& s) {
  struct Timed {   // WEFT_LANE_TRACE: the whole of this call
    int64_t start = frame_trace::Enabled() ? frame_trace::NowNs() : 0;
    ~Timed() {
      if (start) frame_trace::Current().device_sync_ns += frame_trace::NowNs() - start;
    }
  } timed;
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  DeviceSyncResult out;
  Stream* st = FindStream(s.id());
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto lost = reset_sessions_.find(s.id());
    if (lost != reset_sessions_.end()) {
      reset_sessions_.erase(lost);
      out.error = Status(StatusCode::kAborted,
                         name_ + (lost_.load() ? " was lost" : " was reset") +
                             " after a kernel fault of another session: the arrays this session had on it are lost "
                             "(device was reset, these arrays are lost)" +
                             (lost_.load() ? "; " + lost_reason_ + "; using it again takes " + WhatBringsItBack()
                                           : "; create them again"));
      return out;
    }
  }
  if (!st || lost_.load()) return out;
  (void)MakeCurrent();
  if (st->generation != generation_.load()) return out;
  int reason = 0;
  jit::CuResult r = WaitStream(s, *st, &reason);
  if (r == 0) ForgetValueWaits(*st);   // the stream is idle: every wait was satisfied
  if (r != 0) {
    const uint64_t gen = st->generation;
    std::string what = st->pending.empty() ? std::string("a copy or fill")
                                           : "one of the " + std::to_string(st->pending.size()) +
                                                 " launches since the last synchronize (the first: kernel '" +
                                                 st->pending.front().kernel->layout.name + "'" +
                                                 Where(st->pending.front().origin) + ")";
    out.origin = st->pending.empty() ? SourceLocation{} : st->pending.front().origin;
    if (!jit::IsStickyCudaError(r)) {
      st->pending.clear();
      out.error = Internal(name_ + ": " + what + " failed: " + driver_->ErrorName(r));
      return out;
    }
    reset.unlock();
    const double ms = [&] {
      auto t0 = std::chrono::steady_clock::now();
      Reset(gen);
      return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    }();
    {
      std::lock_guard<std::mutex> lock(mu_);
      reset_sessions_.erase(s.id());   // told here
    }
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.1f", ms);
    out.error = Status(StatusCode::kAborted,
                       name_ + ": a kernel faulted (" + driver_->ErrorName(r) + ") in " + what +
                           (lost_.load() ? "; the device could not be brought back in this process (" + std::string(buf) +
                                               " ms): using it again takes " + WhatBringsItBack() +
                                               "; every array on it is lost (device was reset, these arrays are lost)"
                                         : "; the device was reset in " + std::string(buf) +
                                               " ms and every array on it is lost (device was reset, these arrays "
                                               "are lost)"));
    return out;
  }
  out = ReadBackAndDrain(*st);
  if (reason != 0) {
    Status cleared = ClearCancel(*st);
    if (out.error.ok() && !cleared.ok()) out.error = cleared;
    if (out.error.ok()) {
      if (reason == 1) {
        out.error = Status(StatusCode::kCancelled, name_ + ": launches were stopped: the session was closed");
      } else {
        char limit[32];
        std::snprintf(limit, sizeof(limit), "%g", options_.launch_time_limit_s);
        out.error = Status(StatusCode::kDeadlineExceeded,
                           name_ + ": launches ran longer than the launch time limit of " + std::string(limit) +
                               " s (weftd --launch-time-limit) and were stopped");
      }
    }
  }
  return out;
}

void CudaDevice::ProbeAfterFaultOn(const std::string& faulted) {
  uint64_t gen = 0;
  jit::CuResult r = 0;
  {
    std::shared_lock<std::shared_mutex> reset(reset_mu_);
    if (lost_.load()) return;
    gen = generation_.load();
    r = driver_->CtxSetCurrent(ctx_);
    jit::CuDevicePtr probe = 0;
    if (r == 0) r = driver_->MemAlloc(&probe, 256);
    if (r == 0) r = driver_->MemsetD8Async(probe, 0, 256, nullptr);
    if (r == 0) r = driver_->CtxSynchronize();
    if (probe) driver_->MemFree(probe);
  }
  if (r == 0) return;
  spdlog::error("{}: after the kernel fault on {} this GPU fails too ({})", name_, faulted, driver_->ErrorName(r));
  Reset(gen, "a kernel fault on " + faulted + " (" + driver_->ErrorName(r) + " here too)");
}

void CudaDevice::Reset(uint64_t faulted_generation, const std::string& cause) {
  std::unique_lock<std::shared_mutex> reset(reset_mu_);
  if (generation_.load() != faulted_generation) return;   // another session reset it already
  const auto t0 = std::chrono::steady_clock::now();
  driver_->CtxSetCurrent(ctx_);
  {
    std::lock_guard<std::mutex> lock(mu_);
    // Every session with a stream or memory here is told at its next synchronize.
    for (auto& [id, st] : streams_) {
      reset_sessions_[id] = faulted_generation;
      DestroyStream(*st);
    }
    streams_.clear();
    for (auto& [id, slab] : slabs_) {
      if (!slab->owner.empty()) reset_sessions_[slab->owner] = faulted_generation;
      driver_->MemFree(slab->base);
    }
    slabs_.clear();
    for (auto& [id, m] : modules_) driver_->ModuleUnload(m.module);
    modules_.clear();
    if (builtins_) driver_->ModuleUnload(builtins_);
    builtins_ = nullptr;
    builtin_functions_.clear();
  }
  // Drop the daemon's reference, reset the primary context, take a fresh one and prove it
  // works (an allocation, a memset, a synchronize); the driver may need more than one try
  // before the sticky error is gone.
  std::string log;
  bool healthy = false;
  for (int attempt = 1; attempt <= 3 && !healthy; ++attempt) {
    driver_->CtxSetCurrent(nullptr);
    jit::CuResult released = driver_->DevicePrimaryCtxRelease(device_);
    jit::CuResult reset_r = driver_->DevicePrimaryCtxReset(device_);
    jit::CuContext fresh = nullptr;
    jit::CuResult retained = driver_->DevicePrimaryCtxRetain(&fresh, device_);
    if (retained == 0) ctx_ = fresh;
    jit::CuResult probe_r = driver_->CtxSetCurrent(ctx_);
    jit::CuDevicePtr probe = 0;
    if (probe_r == 0) probe_r = driver_->MemAlloc(&probe, 256);
    if (probe_r == 0) probe_r = driver_->MemsetD8Async(probe, 0, 256, nullptr);
    if (probe_r == 0) probe_r = driver_->CtxSynchronize();
    if (probe) driver_->MemFree(probe);
    healthy = retained == 0 && probe_r == 0;
    log += " [try " + std::to_string(attempt) + ": release " + driver_->ErrorName(released) + ", reset " +
           driver_->ErrorName(reset_r) + ", retain " + driver_->ErrorName(retained) + ", probe " +
           driver_->ErrorName(probe_r) + "]";
  }
  if (!healthy && !lost_.load()) {
    lost_reason_ = cause + " and the CUDA driver keeps the error for the life of the daemon process";
    lost_.store(true);
  }
  generation_++;
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (healthy) ++resets_;
    last_reset_ms_ = ms;
  }
  if (healthy)
    spdlog::warn("{}: reset after a kernel fault in {:.1f} ms:{}", name_, ms, log);
  else
    spdlog::error("{}: the device did not come back after a kernel fault ({:.1f} ms):{}", name_, ms, log);
  reset.unlock();
  if (!healthy)
    for (CudaDevice* p : peers_)
      if (p != this) p->ProbeAfterFaultOn(name_);
}

// ---- modules ----

Expected<jit::CuFunction> CudaDevice::Function(const LoadedModule& module, const std::string& symbol) {
  if (module.target != Target::kCuda || module.cuda_image.empty())
    return InvalidArgument("module '" + module.id + "' was compiled for the CPU; compile it for " + name_ +
                           " to launch there");
  if (module.cuda_sm != sm_)
    return InvalidArgument("module '" + module.id + "' was compiled for sm_" + std::to_string(module.cuda_sm) +
                           ", " + name_ + " is sm_" + std::to_string(sm_));
  // The key is built in a per-thread buffer: no allocation per launch once it has grown.
  thread_local std::string key;
  key.assign(module.id);
  key.append(module.has_backward ? "/b" : "/f");
  if (module.grid_stride) key.append("s");   // the grid-stride variant: same id and symbols
  if (module.trusts_tid_indices) key.append("t");   // the trusted-index variant: the same
  std::lock_guard<std::mutex> lock(mu_);
  auto it = modules_.find(key);
  if (it == modules_.end()) {
    CuModuleEntry e;
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->ModuleLoadData(&e.module, module.cuda_image.data()), "cuModuleLoadData"));
    it = modules_.emplace(key, std::move(e)).first;
  }
  auto f = it->second.functions.find(symbol);
  if (f != it->second.functions.end()) return f->second;
  jit::CuFunction fn = nullptr;
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->ModuleGetFunction(&fn, it->second.module, symbol.c_str()),
                                      ("cuModuleGetFunction " + symbol).c_str()));
  it->second.functions[symbol] = fn;
  return fn;
}

Expected<jit::CuFunction> CudaDevice::Builtin(const char* name) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!builtins_) {
    if (!options_.compile) return Unimplemented(name_ + ": no CUDA compiler in this daemon (strided copies and fills)");
    WEFT_ASSIGN_OR_RETURN(std::string image, options_.compile(CudaBuiltinSource(), "weft_builtin_copy_fill.cu", sm_));
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->ModuleLoadData(&builtins_, image.data()), "cuModuleLoadData"));
  }
  auto f = builtin_functions_.find(name);
  if (f != builtin_functions_.end()) return f->second;
  jit::CuFunction fn = nullptr;
  WEFT_RETURN_IF_ERROR(driver_->Check(driver_->ModuleGetFunction(&fn, builtins_, name), name));
  builtin_functions_[name] = fn;
  return fn;
}

Expected<CudaDevice::KernelProperties> CudaDevice::PropertiesOf(const LoadedModule& module,
                                                                const LoadedKernel& kernel) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  if (kernel.layout.forward_symbol.empty())
    return Internal("kernel '" + kernel.layout.name + "' has no CUDA entry point");
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction fn, Function(module, kernel.layout.forward_symbol));
  // CUfunction_attribute: 0 max threads per block, 1 static shared bytes, 3 local bytes, 4 registers
  KernelProperties p;
  const std::pair<int, int*> attributes[] = {{0, &p.max_threads_per_block}, {1, &p.shared_memory_size},
                                             {3, &p.local_memory_size}, {4, &p.register_count}};
  for (const auto& [attribute, out] : attributes)
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->FuncGetAttribute(out, attribute, fn), "cuFuncGetAttribute"));
  if (driver_->OccupancyMaxPotentialBlockSize)
    WEFT_RETURN_IF_ERROR(driver_->Check(
        driver_->OccupancyMaxPotentialBlockSize(&p.min_grid_size, &p.suggested_block_size, fn, nullptr, 0, 0),
        "cuOccupancyMaxPotentialBlockSize"));
  return p;
}

// ---- work ----

Status CudaDevice::Upload(Session& s, const MemoryBlock& dst, uint64_t offset, const void* src, uint64_t n) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckBlock(dst, "the array"));
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  if (n == 0) return Status::Ok();
  const jit::CuDevicePtr d = reinterpret_cast<uintptr_t>(dst.data) + offset;
  {
    TimedSpan timed(*this, *st, kTimingMemcpy, "memcpy HtoD");
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemcpyHtoDAsync(d, src, n, st->stream), "cuMemcpyHtoDAsync"));
  }
  return driver_->Check(driver_->StreamSynchronize(st->stream), "cuStreamSynchronize");
}

Status CudaDevice::Download(Session& s, const MemoryBlock& src, uint64_t offset, void* dst, uint64_t n) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckBlock(src, "the array"));
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  if (n == 0) return Status::Ok();
  const jit::CuDevicePtr p = reinterpret_cast<uintptr_t>(src.data) + offset;
  {
    TimedSpan timed(*this, *st, kTimingMemcpy, "memcpy DtoH");
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemcpyDtoHAsync(dst, p, n, st->stream), "cuMemcpyDtoHAsync"));
  }
  return driver_->Check(driver_->StreamSynchronize(st->stream), "cuStreamSynchronize");
}

Status CudaDevice::CopyBlock(Session& s, const MemoryBlock& dst, const MemoryBlock& src, uint64_t n) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckBlock(src, "the array"));
  WEFT_RETURN_IF_ERROR(CheckBlock(dst, "the array"));
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  if (n == 0) return Status::Ok();
  {
    TimedSpan timed(*this, *st, kTimingMemcpy, "memcpy DtoD");
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemcpyDtoDAsync(reinterpret_cast<uintptr_t>(dst.data),
                                                                 reinterpret_cast<uintptr_t>(src.data), n, st->stream),
                                        "cuMemcpyDtoDAsync"));
  }
  return driver_->Check(driver_->StreamSynchronize(st->stream), "cuStreamSynchronize");
}

Status CudaDevice::Fill(Session& s, const ArrayView& dst, const std::string& value) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckBlock(dst.alloc->block, "fill dst array " + std::to_string(dst.alloc->handle)));
  const uint64_t esize = dst.dtype().ElementSize();
  if (value.size() != esize)
    return InvalidArgument("fill value has " + std::to_string(value.size()) + " bytes; one element of " +
                           dst.dtype().Name() + " has " + std::to_string(esize));
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  const uint64_t n = dst.element_count();
  if (n == 0) return Status::Ok();
  const jit::CuDevicePtr d = reinterpret_cast<uintptr_t>(dst.data());
  if (dst.contiguous()) {
    // A value that repeats a 1-, 2- or 4-byte pattern is a memset.
    for (uint64_t w : {1, 2, 4}) {
      if (esize % w || d % w) continue;
      bool repeats = true;
      for (uint64_t i = w; i < esize && repeats; ++i) repeats = value[i] == value[i % w];
      if (!repeats) continue;
      const uint64_t count = n * esize / w;
      TimedSpan timed(*this, *st, kTimingMemset, "memset");
      if (w == 1) return driver_->Check(driver_->MemsetD8Async(d, static_cast<unsigned char>(value[0]), count, st->stream), "cuMemsetD8Async");
      if (w == 2) {
        uint16_t v;
        std::memcpy(&v, value.data(), 2);
        return driver_->Check(driver_->MemsetD16Async(d, v, count, st->stream), "cuMemsetD16Async");
      }
      uint32_t v;
      std::memcpy(&v, value.data(), 4);
      return driver_->Check(driver_->MemsetD32Async(d, v, count, st->stream), "cuMemsetD32Async");
    }
  }
  ValueArg v{};
  if (esize > sizeof(v.b))
    return Unimplemented("fill of " + std::to_string(esize) + "-byte elements on " + name_ + " (at most " +
                         std::to_string(sizeof(v.b)) + ")");
  std::memcpy(v.b, value.data(), esize);
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction fn, Builtin("weft_fill_strided"));
  ViewArg dv = ViewArgOf(dst);
  int64_t count = static_cast<int64_t>(n);
  int32_t es = static_cast<int32_t>(esize), word = WordOf(esize, {&dst});
  void* params[] = {const_cast<jit::CuDevicePtr*>(&d), &dv, &v, &count, &es, &word};
  TimedSpan timed(*this, *st, kTimingKernelBuiltin, "builtin kernel fill_strided");
  return driver_->Check(driver_->LaunchKernel(fn, GridFor(n, 256, 65536), 1, 1, 256, 1, 1, 0, st->stream, params, nullptr),
                        "cuLaunchKernel (fill)");
}

Status CudaDevice::RefitBvh(Session& s, const geometry::BvhRefitJob& job) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  if (lost_.load()) return Unavailable(name_ + " was lost");
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  TimedSpan timed(*this, *st, kTimingKernelBuiltin, "builtin kernel bvh_refit");
  if (job.parents) return BvhBoundsUp(*st, job);   // a tree built on the device
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction fn, Builtin("weft_bvh_refit_level"));
  jit::CuDevicePtr nodes = job.nodes, levels = job.levels, prim_ids = job.prim_ids, lowers = job.lowers,
                   uppers = job.uppers, points = job.points, indices = job.indices;
  for (size_t l = 0; l + 1 < job.level_starts.size(); ++l) {
    int64_t begin = job.level_starts[l], end = job.level_starts[l + 1];
    if (end <= begin) continue;
    void* params[] = {&nodes, &levels, &begin, &end, &prim_ids, &lowers, &uppers, &points, &indices};
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->LaunchKernel(fn, GridFor(static_cast<uint64_t>(end - begin), 128, 65536),
                                                              1, 1, 128, 1, 1, 0, st->stream, params, nullptr),
                                        "cuLaunchKernel (BVH refit)"));
  }
  return Status::Ok();
}

Status CudaDevice::StridedCopyOnDevice(Stream& st, const ArrayView& dst, const ArrayView& src) {
  const uint64_t n = dst.element_count();
  const uint64_t esize = dst.dtype().ElementSize();
  jit::CuDevicePtr d = reinterpret_cast<uintptr_t>(dst.data()), s = reinterpret_cast<uintptr_t>(src.data());
  if (dst.contiguous() && src.contiguous()) {
    TimedSpan timed(*this, st, kTimingMemcpy, "memcpy DtoD");
    return driver_->Check(driver_->MemcpyDtoDAsync(d, s, n * esize, st.stream), "cuMemcpyDtoDAsync");
  }
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction fn, Builtin("weft_copy_strided"));
  ViewArg dv = ViewArgOf(dst), sv = ViewArgOf(src);
  int64_t count = static_cast<int64_t>(n);
  int32_t es = static_cast<int32_t>(esize), word = WordOf(esize, {&dst, &src});
  void* params[] = {&d, &dv, &s, &sv, &count, &es, &word};
  TimedSpan timed(*this, st, kTimingKernelBuiltin, "builtin kernel copy_strided");
  return driver_->Check(driver_->LaunchKernel(fn, GridFor(n, 256, 65536), 1, 1, 256, 1, 1, 0, st.stream, params, nullptr),
                        "cuLaunchKernel (copy)");
}

Status CudaDevice::Copy(Session& s, const ArrayView& dst, const ArrayView& src) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  const uint64_t esize = dst.dtype().ElementSize();
  if (src.dtype().ElementSize() != esize)
    return InvalidArgument("copy: element sizes differ (" + dst.dtype().Name() + " vs " + src.dtype().Name() + ")");
  const uint64_t n = dst.element_count();
  if (src.element_count() != n)
    return InvalidArgument("copy: dst has " + std::to_string(n) + " elements, src has " +
                           std::to_string(src.element_count()));
  const bool dst_here = dst.alloc->device == name_, src_here = src.alloc->device == name_;
  if (dst_here) WEFT_RETURN_IF_ERROR(CheckBlock(dst.alloc->block, "copy dst array " + std::to_string(dst.alloc->handle)));
  if (src_here) WEFT_RETURN_IF_ERROR(CheckBlock(src.alloc->block, "copy src array " + std::to_string(src.alloc->handle)));
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  if (n == 0) return Status::Ok();
  const uint64_t bytes = n * esize;
  if (dst_here && src_here) return StridedCopyOnDevice(*st, dst, src);

  const bool src_cpu = src.alloc->device == "cpu", dst_cpu = dst.alloc->device == "cpu";
  if (src_cpu || dst_cpu) {
    // Host memory is touched by later CPU commands of the session: these copies complete
    // before Copy returns.
    const ArrayView& host = src_cpu ? src : dst;
    const ArrayView& dev = src_cpu ? dst : src;
    std::vector<char> staging;
    const char* host_src = nullptr;
    char* host_dst = nullptr;
    ArrayView host_contig;
    if (host.contiguous()) {
      host_contig = host;
    } else {
      staging.resize(bytes);
      host_contig = ScratchView(host.dtype(), n, staging.data(), "cpu");
      if (src_cpu) WEFT_RETURN_IF_ERROR(CopyView(host_contig, host, s.cancel_flag()));
    }
    host_src = host_contig.data();
    host_dst = host_contig.data();
    jit::CuDevicePtr scratch = 0;
    ArrayView dev_contig = dev;
    if (!dev.contiguous()) {
      WEFT_RETURN_IF_ERROR(driver_->Check(driver_->MemAlloc(&scratch, bytes), "cuMemAlloc (staging)"));
      dev_contig = ScratchView(dev.dtype(), n, reinterpret_cast<void*>(static_cast<uintptr_t>(scratch)), name_);
    }
    Status r = Status::Ok();
    const jit::CuDevicePtr dp = reinterpret_cast<uintptr_t>(dev_contig.data());
    if (src_cpu) {
      {
        TimedSpan timed(*this, *st, kTimingMemcpy, "memcpy HtoD");
        r = driver_->Check(driver_->MemcpyHtoDAsync(dp, host_src, bytes, st->stream), "cuMemcpyHtoDAsync");
      }
      if (r.ok() && scratch) r = StridedCopyOnDevice(*st, dev, dev_contig);
    } else {
      if (scratch) r = StridedCopyOnDevice(*st, dev_contig, dev);
      if (r.ok()) {
        TimedSpan timed(*this, *st, kTimingMemcpy, "memcpy DtoH");
        r = driver_->Check(driver_->MemcpyDtoHAsync(host_dst, dp, bytes, st->stream), "cuMemcpyDtoHAsync");
      }
    }
    if (r.ok()) r = driver_->Check(driver_->StreamSynchronize(st->stream), "cuStreamSynchronize");
    if (scratch) driver_->MemFree(scratch);
    if (r.ok() && !src_cpu && !staging.empty()) r = CopyView(host, host_contig, s.cancel_flag());
    return r;
  }
  // Between two GPUs: peer copy (the driver stages it when peer access is off).
  const ArrayView& other = dst_here ? src : dst;
  CudaDevice* peer = nullptr;
  for (CudaDevice* p : peers_)
    if (p->name() == other.alloc->device) peer = p;
  if (!peer) return InvalidArgument("copy between " + dst.alloc->device + " and " + src.alloc->device + ": unknown device");
  WEFT_RETURN_IF_ERROR(peer->CheckBlock(other.alloc->block, "copy array " + std::to_string(other.alloc->handle)));
  // The other GPU's queued work of this session comes first.
  if (Stream* ps = peer->FindStream(s.id())) {
    (void)peer->MakeCurrent();
    WEFT_RETURN_IF_ERROR(driver_->Check(driver_->StreamSynchronize(ps->stream), "cuStreamSynchronize (peer)"));
    WEFT_RETURN_IF_ERROR(MakeCurrent());
  }
  CudaDevice* const src_gpu = dst_here ? peer : this;
  CudaDevice* const dst_gpu = dst_here ? this : peer;
  // A strided view is gathered into (source) or scattered from (destination) contiguous scratch
  // memory on its own GPU, with that GPU's stream of the session; the peer copy itself always
  // moves one contiguous range.
  jit::CuDevicePtr src_scratch = 0, dst_scratch = 0;
  auto release = [&] {
    if (src_scratch && src_gpu->MakeCurrent().ok()) driver_->MemFree(src_scratch);
    if (dst_scratch && dst_gpu->MakeCurrent().ok()) driver_->MemFree(dst_scratch);
    (void)MakeCurrent();
  };
  Status r = Status::Ok();
  ArrayView src_contig = src, dst_contig = dst;
  if (!src.contiguous()) {
    r = src_gpu->MakeCurrent();
    if (r.ok()) r = driver_->Check(driver_->MemAlloc(&src_scratch, bytes), "cuMemAlloc (peer staging)");
    if (r.ok()) {
      src_contig = ScratchView(src.dtype(), n, reinterpret_cast<void*>(static_cast<uintptr_t>(src_scratch)),
                               src_gpu->name());
      auto sst = src_gpu->StreamOf(s.id());
      r = sst.ok() ? src_gpu->StridedCopyOnDevice(**sst, src_contig, src) : sst.status();
      if (r.ok()) r = driver_->Check(driver_->StreamSynchronize((*sst)->stream), "cuStreamSynchronize (gather)");
    }
  }
  if (r.ok() && !dst.contiguous()) {
    r = dst_gpu->MakeCurrent();
    if (r.ok()) r = driver_->Check(driver_->MemAlloc(&dst_scratch, bytes), "cuMemAlloc (peer staging)");
    if (r.ok())
      dst_contig = ScratchView(dst.dtype(), n, reinterpret_cast<void*>(static_cast<uintptr_t>(dst_scratch)),
                               dst_gpu->name());
  }
  if (r.ok()) r = MakeCurrent();
  if (r.ok()) {
    TimedSpan timed(*this, *st, kTimingMemcpy, "memcpy PtoP");
    r = driver_->Check(driver_->MemcpyPeerAsync(reinterpret_cast<uintptr_t>(dst_contig.data()), dst_gpu->context(),
                                                reinterpret_cast<uintptr_t>(src_contig.data()), src_gpu->context(),
                                                bytes, st->stream),
                       "cuMemcpyPeerAsync");
  }
  if (r.ok()) r = driver_->Check(driver_->StreamSynchronize(st->stream), "cuStreamSynchronize");
  if (r.ok() && dst_scratch) {
    r = dst_gpu->MakeCurrent();
    auto dst_stream = r.ok() ? dst_gpu->StreamOf(s.id()) : Expected<Stream*>(r);
    r = dst_stream.ok() ? dst_gpu->StridedCopyOnDevice(**dst_stream, dst, dst_contig) : dst_stream.status();
    if (r.ok()) r = driver_->Check(driver_->StreamSynchronize((*dst_stream)->stream), "cuStreamSynchronize (scatter)");
  }
  release();
  return r;
}

Status CudaDevice::MakeRoom(Session& s, Stream& st, size_t n) {
  if (st.pending.size() + n <= kErrorSlots) return Status::Ok();
  // Not enough free error slots: wait for the stream and read them back.
  int reason = 0;
  jit::CuResult r = WaitStream(s, st, &reason);
  if (r != 0) return driver_->Check(r, "cuStreamQuery");
  if (reason != 0) WEFT_RETURN_IF_ERROR(ClearCancel(st));
  DeviceSyncResult drained = ReadBackAndDrain(st);
  if (!drained.output.empty()) s.AppendOutput(drained.output);
  if (!drained.error.ok()) return Status(drained.error.code(), drained.error.message() + Where(drained.origin));
  return Status::Ok();
}

Status CudaDevice::Launch(Session& s, const KernelLaunch& l, std::string* out) {
  if (!frame_trace::Enabled()) return LaunchTraced(s, l, out, false);
  const int64_t start = frame_trace::NowNs();
  Status st = LaunchTraced(s, l, out, true);
  frame_trace::Current().gpu_launch_ns += frame_trace::NowNs() - start;
  return st;
}

Status CudaDevice::LaunchTraced(Session& s, const KernelLaunch& l, std::string*, bool trace) {
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  const uint64_t generation = generation_.load();
  for (const PackedArgs* block : {l.args, l.adj_args}) {
    if (!block) continue;
    for (const auto& a : block->keep_alive)
      if (a->block.generation != generation)   // the message is built only for a lost array
        WEFT_RETURN_IF_ERROR(CheckBlock(a->block, "kernel '" + l.kernel->layout.name + "' array " + std::to_string(a->handle)));
  }
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  const bool adjoint = l.adj_args != nullptr;
  if (l.block_dim > 1024) return InvalidArgument("block_dim " + std::to_string(l.block_dim) + " is more than 1024");
  wp::launch_context_t ctx{};
  WEFT_ASSIGN_OR_RETURN(ctx.bounds, LaunchBoundsOf(l.dim));
  if (ctx.bounds.size == 0) return Status::Ok();
  // A large 1-D forward launch of a module variant proven in range runs the coarsened entry:
  // kCoarseFactor logical threads per GPU thread (KernelLayout::coarse_symbol).
  const bool coarse = !adjoint && !l.kernel->layout.coarse_symbol.empty() && l.module->trusts_tid_indices &&
                      l.kernel->layout.coarse_loaded_bytes <= coarsen_max_loaded_bytes_ &&
                      ctx.bounds.ndim == 1 && l.max_blocks <= 0 && coarsen_min_threads_ > 0 &&
                      static_cast<uint64_t>(ctx.bounds.size) >= coarsen_min_threads_;
  const std::string& symbol = coarse    ? l.kernel->layout.coarse_symbol
                              : adjoint ? l.kernel->layout.backward_symbol
                                        : l.kernel->layout.forward_symbol;
  if (symbol.empty()) return Internal("kernel '" + l.kernel->layout.name + "' has no CUDA entry point");
  WEFT_ASSIGN_OR_RETURN(jit::CuFunction fn, Function(*l.module, symbol));
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  if (!st->capture) WEFT_RETURN_IF_ERROR(MakeRoom(s, *st, 1));
  jit::CuDevicePtr error_slot = st->errors + st->pending.size() * sizeof(wp::launch_error_t);
  if (st->capture) {   // recorded into a graph: the graph's own slots (cuda_device_graphs.cpp)
    if (st->capture->launches.size() >= kErrorSlots) {
      st->capture->refused = "more than " + std::to_string(kErrorSlots) + " launches";
      return FailedPrecondition("graph capture: " + st->capture->refused);
    }
    if (s.geometry().TableFor(name_)) {
      st->capture->refused = "a launch while the session holds geometry objects";
      return FailedPrecondition("graph capture: " + st->capture->refused);
    }
    error_slot = st->capture->slots + st->capture->launches.size() * sizeof(wp::launch_error_t);
  }
  ctx.error = reinterpret_cast<wp::launch_error_t*>(static_cast<uintptr_t>(error_slot));
  ctx.print = reinterpret_cast<wp::print_buffer_t*>(static_cast<uintptr_t>(st->errors_base));
  ctx.flags = 0;
  ctx.cancel = reinterpret_cast<const wp::int32*>(static_cast<uintptr_t>(st->errors_base + kCancelOffset));
  WEFT_ASSIGN_OR_RETURN(uint64_t geometry, GeometryTable(s, *st));
  ctx.geometry = reinterpret_cast<const wp::geometry_table_t*>(static_cast<uintptr_t>(geometry));
  ctx.report_flag = reinterpret_cast<wp::int32*>(static_cast<uintptr_t>(st->report_device));
  const unsigned block = l.block_dim ? l.block_dim : 256;
  if (!l.kernel->layout.grid_stride) {   // one index per thread: the grid must cover the launch
    if (l.max_blocks > 0)
      return InvalidArgument("kernel '" + l.kernel->layout.name + "' was launched with max_blocks=" +
                             std::to_string(l.max_blocks) +
                             ", but it was compiled without a grid-stride loop (grid_stride=False); capping the block "
                             "count requires @wp.kernel(grid_stride=True)");
    if ((static_cast<uint64_t>(ctx.bounds.size) + block - 1) / block > 0x7fffffffull)
      return InvalidArgument("kernel '" + l.kernel->layout.name + "': launch of " + std::to_string(ctx.bounds.size) +
                             " threads needs more blocks than one grid holds without a grid-stride loop; use "
                             "@wp.kernel(grid_stride=True)");
  }
  const uint64_t threads = coarse ? (static_cast<uint64_t>(ctx.bounds.size) + kCoarseFactor - 1) / kCoarseFactor
                                  : static_cast<uint64_t>(ctx.bounds.size);
  const unsigned grid = GridFor(threads, block, l.max_blocks);
  void* args = const_cast<char*>(l.args->block.data());
  void* adj = adjoint ? const_cast<char*>(l.adj_args->block.data()) : nullptr;
  void* params_fwd[] = {&ctx, args};
  void* params_adj[] = {&ctx, args, adj};
  const int64_t driver_start = trace ? frame_trace::NowNs() : 0;
  jit::CuResult launched = 0;
  {
    TimedSpan timed(*this, *st, kTimingKernel, adjoint ? "backward kernel " : "forward kernel ", l.kernel->layout.name);
    launched =
        driver_->LaunchKernel(fn, grid, 1, 1, block, 1, 1, 0, st->stream, adjoint ? params_adj : params_fwd, nullptr);
  }
  if (trace) frame_trace::Current().driver_launch_ns += frame_trace::NowNs() - driver_start;
  if (launched != 0) {
    // A kernel whose threads need more local memory than the GPU gives one (large tiles or
    // fixed-size arrays) is refused at launch: say so rather than pass on the driver's code.
    constexpr int kLocalSizeBytes = 3;   // CU_FUNC_ATTRIBUTE_LOCAL_SIZE_BYTES
    constexpr int kMaxLocalBytes = 512 * 1024;
    int local = 0;
    if (driver_->FuncGetAttribute && driver_->FuncGetAttribute(&local, kLocalSizeBytes, fn) == 0 && local > kMaxLocalBytes)
      return ResourceExhausted("kernel '" + l.kernel->layout.name + "' needs " + std::to_string(local) +
                               " bytes of local memory per GPU thread, more than a GPU thread holds (" +
                               std::to_string(kMaxLocalBytes) + "): its tiles or fixed-size arrays are too large "
                               "for the GPU (use smaller tiles)");
    return driver_->Check(launched, ("cuLaunchKernel " + symbol).c_str());
  }
  (st->capture ? st->capture->launches : st->pending).push_back(Pending{l.module, l.kernel, adjoint, l.origin});
  if (coarse) coarsened_launches_.fetch_add(1, std::memory_order_relaxed);
  return Status::Ok();
}

}  // namespace weft
