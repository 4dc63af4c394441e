// Engine: sessions, arrays, command submission, compiles and statistics.
#include "engine/runtime/engine.h"

#include <sys/random.h>
#include <sys/statvfs.h>

#include <cstring>

#include <spdlog/spdlog.h>

#include "engine/codegen/emit_text.h"
#include "engine/core/checked_math.h"
#include "engine/runtime/array_validation.h"
#include "engine/runtime/array_view.h"
#include "engine/runtime/ipc_token.h"

namespace weft {

namespace {

// 256 bits from the kernel's CSPRNG, hex.
std::string NewSessionId() {
  unsigned char b[32];
  size_t got = 0;
  while (got < sizeof(b)) {
    ssize_t r = getrandom(b + got, sizeof(b) - got, 0);
    if (r > 0) got += static_cast<size_t>(r);
  }
  static const char* hex = "0123456789abcdef";
  std::string s = "s-";
  for (unsigned char c : b) {
    s += hex[c >> 4];
    s += hex[c & 15];
  }
  return s;
}

// The first array handle of a session host: a random number in [2^32, 2^47), so that a handle
// a client kept from an ended session (of another host, whose handles counted from the same
// start) names no array here instead of another one.
uint64_t SessionHostFirstHandle() {
  uint64_t r = 0;
  while (getrandom(&r, sizeof(r), 0) != static_cast<ssize_t>(sizeof(r))) {
  }
  return (uint64_t{1} << 32) + (r % ((uint64_t{1} << 47) - (uint64_t{1} << 32)));
}

// The default daemon-wide array limit: the size of /dev/shm (where CPU arrays live), at most
// physical memory + swap.
uint64_t DefaultDaemonMemoryLimit(uint64_t physical_and_swap) {
  struct statvfs vfs {};
  uint64_t limit = physical_and_swap;
  if (statvfs("/dev/shm", &vfs) == 0) {
    uint64_t shm = static_cast<uint64_t>(vfs.f_blocks) * vfs.f_frsize;
    if (shm > 0 && shm < limit) limit = shm;
  }
  return limit;
}

}  // namespace

Expected<std::unique_ptr<Engine>> Engine::Create(const EngineOptions& options,
                                                 std::unique_ptr<ModuleStore> store) {
  if (!store) {
    auto created = ModuleStore::Create(options.modules);
    if (!created.ok()) return created.status();
    store = std::move(created).value();
  }
  if (options.remove_stale_slabs) ShmSlabPool::RemoveStaleSlabs();
  return std::unique_ptr<Engine>(new Engine(options, std::move(store)));
}

Engine::Engine(const EngineOptions& options, std::unique_ptr<ModuleStore> store)
    : options_(options),
      store_(std::move(store)),
      pool_(std::make_unique<ThreadPool>(options.cpu_threads)) {
  watchdog_ = std::make_unique<LaunchWatchdog>();
  if (options.session_host) next_handle_ = SessionHostFirstHandle();
  CpuDeviceOptions cpu;
  cpu.slabs = options.slabs;
  cpu.print_capacity = options.print_capacity;
  cpu.launch_time_limit_s = options.launch_time_limit_s;
  std::vector<std::unique_ptr<CudaDevice>> gpus;
  if (options.use_gpus) {
    ModuleStore* st = store_.get();
    for (const DeviceInfo& info : QueryCudaDevices()) {
      CudaDeviceOptions o;
      o.ordinal = std::stoi(info.name.substr(5));
      if (options.only_gpu >= 0 && o.ordinal != options.only_gpu) continue;
      o.launch_time_limit_s = options.launch_time_limit_s;
      o.process_ends_with_session = options.session_host;
      o.process_of_device = options.device_host;
      if (st) o.compile = [st](const std::string& source, const std::string& name, int sm) {
        return st->CompileCudaSource(source, name, sm);
      };
      auto gpu = CudaDevice::Create(o);
      if (!gpu.ok()) {
        spdlog::warn("{} ({}) cannot compute here: {}", info.name, info.description, gpu.status().ToString());
        continue;
      }
      spdlog::info("{}: {} (sm_{}) ready", info.name, info.description, (*gpu)->sm());
      gpus.push_back(std::move(*gpu));
    }
  }
  devices_ = std::make_unique<DeviceSet>(std::make_unique<CpuDevice>(*pool_, watchdog_.get(), cpu), std::move(gpus));
  executor_ = std::make_unique<CommandExecutor>(
      *devices_, store_.get(),
      [this](Session& s, const geometry::GeometryRequest& r) { return RunGeometryHere(s, r).status(); });
  memory_limit_ = PhysicalMemoryAndSwap();
  MemoryLimits limits = options.memory;
  if (limits.daemon == 0) limits.daemon = DefaultDaemonMemoryLimit(memory_limit_);
  quota_ = std::make_unique<MemoryQuota>(limits);
  spdlog::info("array memory limits: daemon {}, per principal {}, per session {}", ByteCountString(limits.daemon),
               limits.per_principal ? ByteCountString(limits.per_principal) : std::string("none"),
               limits.per_session ? ByteCountString(limits.per_session) : std::string("none"));
}

Engine::~Engine() {
  CancelAllSessions();
  CloseAllSessions();
  executor_.reset();
  watchdog_.reset();
  pool_.reset();
  store_.reset();
  devices_.reset();
}

// ---- sessions ----

std::shared_ptr<Session> Engine::OpenSession(const SessionOptions& options) {
  const uint64_t serial = ++sessions_opened_;
  auto s = std::make_shared<Session>(NewSessionId(), "#" + std::to_string(serial), options);
  s->unchecked_allowed = options_.allow_unchecked;
  {
    std::lock_guard<std::mutex> lock(mu_);
    sessions_[s->id()] = s;
  }
  spdlog::info("session {} opened: {} (pid {}, {}, {})", s->label(), options.client_name, options.client_pid,
               options.local ? "local" : "remote", options.principal);
  return s;
}

Expected<std::shared_ptr<Session>> Engine::OpenClientSession(const SessionOptions& options) {
  if (stopping_) return Unavailable("the daemon is shutting down");
  {
    std::lock_guard<std::mutex> lock(mu_);
    uint32_t same = 0;
    for (const auto& [id, s] : sessions_) same += s->options().principal == options.principal ? 1 : 0;
    if (same >= options_.max_sessions_per_principal)
      return ResourceExhausted("too many sessions: " + options.principal + " already has " + std::to_string(same) +
                               " open, the limit is " + std::to_string(options_.max_sessions_per_principal) +
                               " (weftd --max-sessions-per-principal)");
  }
  return OpenSession(options);
}

std::shared_ptr<Session> Engine::FindSession(const std::string& id) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = sessions_.find(id);
  return it == sessions_.end() ? nullptr : it->second;
}

Status Engine::CloseSession(const std::string& id, bool reaped) {
  std::shared_ptr<Session> s;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = sessions_.find(id);
    if (it == sessions_.end()) return NotFound("unknown session '" + id + "'");
    s = std::move(it->second);
    sessions_.erase(it);
  }
  s->Cancel();   // queued batches are skipped, running launches/fills/copies stop
  s->queue().WaitIdle();
  for (auto& g : devices_->gpus()) (void)g->Synchronize(*s);   // GPU loops see the cancel word
  size_t n = s->array_count();
  if (reaped) ++sessions_reaped_;   // counted before the arrays go: Stats never shows them freed but the reap uncounted
  s->ReleaseAll();   // tapes hold weak references only; they go with the Session object
  for (auto& g : devices_->gpus()) g->CloseSession(*s);
  devices_->Forget(s->id());
  spdlog::info("session {} {}: {} array handle(s) released", s->label(),
               reaped ? "reaped (client went away)" : "closed", n);
  return Status::Ok();
}

size_t Engine::ReapUnattachedSessions(std::chrono::steady_clock::duration timeout) {
  const auto now = std::chrono::steady_clock::now();
  std::vector<std::shared_ptr<Session>> stale;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (const auto& [id, s] : sessions_)
      if (!s->attached() && now - s->opened_at() >= timeout) stale.push_back(s);
  }
  size_t n = 0;
  for (const auto& s : stale) {
    // Claiming the session for the reap makes a racing Attach fail instead of attaching to
    // a session that is about to close.
    if (!s->ClaimAttach()) continue;   // an Attach claimed it meanwhile
    spdlog::info("session {}: no Attach stream within the attach timeout", s->label());
    if (CloseSession(s->id(), /*reaped=*/true).ok()) ++n;
  }
  return n;
}

void Engine::CancelAllSessions() {
  stopping_ = true;
  std::lock_guard<std::mutex> lock(mu_);
  for (auto& [id, s] : sessions_) s->Cancel();
}

void Engine::CloseAllSessions() {
  std::vector<std::string> ids;
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (auto& [id, s] : sessions_) ids.push_back(id);
  }
  for (auto& id : ids) (void)CloseSession(id);
}

std::vector<DeviceInfo> Engine::ListDevices() const {
  std::vector<DeviceInfo> out;
  out.push_back(QueryCpuDevice(pool_->size()));
  for (auto& d : QueryCudaDevices()) {
    Device* dev = devices_->Find(d.name);
    // A device host serves its own device: the others belong to other processes.
    if (options_.device_host && dev == nullptr) continue;
    d.compute_supported = dev != nullptr && !static_cast<CudaDevice*>(dev)->lost();
    out.push_back(std::move(d));
  }
  return out;
}

// ---- arrays ----

Expected<std::shared_ptr<Allocation>> Engine::NewAllocation(Session& owner, Device& device, const DType& dtype,
                                                            const std::vector<int64_t>& shape, bool zero,
                                                            bool dedicated) {
  WEFT_RETURN_IF_ERROR(dtype.Validate());
  if (shape.empty() || shape.size() > static_cast<size_t>(kMaxArrayDims))
    return InvalidArgument("array shape must have 1 to 4 dimensions, got " + std::to_string(shape.size()));
  for (int64_t d : shape)
    if (d < 0) return InvalidArgument("array shape " + ShapeString(shape) + " has a negative dimension");
  uint64_t bytes = 0;
  if (!CheckedShapeProduct(shape, dtype.ElementSize(), &bytes))
    return ResourceExhausted("array of shape " + ShapeString(shape) + " and dtype " + dtype.Name() +
                             " is absurdly large (more than " + std::to_string(kMaxCheckedSize) + " bytes)");
  if (bytes > memory_limit_)
    return ResourceExhausted("array of shape " + ShapeString(shape) + " and dtype " + dtype.Name() + " needs " +
                             std::to_string(bytes) + " bytes, more than this machine's memory + swap (" +
                             std::to_string(memory_limit_) + ")");
  // Reserve before allocating: the quota counts reserved bytes, not touched pages.
  const std::string session_id = owner.id(), principal = owner.options().principal;
  const uint64_t reserved = device.ReservedSize(bytes);
  WEFT_RETURN_IF_ERROR(quota_->Reserve(session_id, principal, reserved));
  auto block = device.Allocate(bytes, session_id, dedicated);
  if (!block.ok()) {
    quota_->Release(session_id, principal, reserved);
    return block.status();
  }
  auto a = std::make_shared<Allocation>();
  a->handle = next_handle_++;
  a->dtype = dtype;
  a->shape = shape;
  a->strides = ContiguousStrides(shape, dtype.ElementSize());
  a->byte_size = bytes;
  a->device = device.name();
  a->block = *block;
  const uint64_t handle = a->handle, size = a->byte_size;
  Device* pool = &device;
  MemoryQuota* quota = quota_.get();
  a->release = [this, pool, quota, handle, size, session_id, principal, reserved](const ShmSlabPool::Block& b) {
    {
      std::lock_guard<std::mutex> lock(alloc_mu_);
      allocations_.erase(handle);
    }
    live_bytes_ -= size;
    pool->Free(b);
    quota->Release(session_id, principal, reserved);
  };
  live_bytes_ += size;
  {
    std::lock_guard<std::mutex> lock(alloc_mu_);
    allocations_[a->handle] = a;
  }
  if (zero && !a->block.zeroed && a->byte_size) {   // new CPU slabs are zero already
    if (device.is_cpu()) {
      std::memset(a->block.data, 0, a->byte_size);
    } else {
      ArrayView v;
      v.alloc = a;
      v.shape = a->shape;
      v.strides = a->strides;
      WEFT_RETURN_IF_ERROR(device.Fill(owner, v, std::string(dtype.ElementSize(), '\0')));
    }
  }
  return a;
}

Status Engine::MoveToOwnSlab(Allocation& a, Session& owner) {
  {
    std::lock_guard<std::mutex> lock(a.block_mu);
    if (a.block.dedicated || a.retired_block.data) return Status::Ok();
  }
  // The new slab is reserved too (the old block stays reserved until the array dies).
  const std::string session_id = a.block.owner, principal = owner.options().principal;
  Device* pool = devices_->Find(a.device);
  if (!pool) return Internal("array " + std::to_string(a.handle) + " lives on unknown device '" + a.device + "'");
  const uint64_t reserved = pool->ReservedSize(a.byte_size);
  WEFT_RETURN_IF_ERROR(quota_->Reserve(session_id, principal, reserved));
  auto fresh = pool->Allocate(a.byte_size, session_id, /*dedicated=*/true);
  if (!fresh.ok()) {
    quota_->Release(session_id, principal, reserved);
    return fresh.status();
  }
  if (Status copied = pool->CopyBlock(owner, *fresh, a.block, a.byte_size); !copied.ok()) {
    pool->Free(*fresh);
    quota_->Release(session_id, principal, reserved);
    return copied;
  }
  MemoryQuota* quota = quota_.get();
  std::lock_guard<std::mutex> lock(a.block_mu);
  a.retired_block = a.block;
  a.block = *fresh;
  a.release_retired = [pool, quota, session_id, principal, reserved](const ShmSlabPool::Block& b) {
    pool->Free(b);
    quota->Release(session_id, principal, reserved);
  };
  return Status::Ok();
}

MemoryUsage Engine::MemoryUsageOf(const Session& s) const { return quota_->Usage(s.id(), s.options().principal); }

void Engine::PageLock(Allocation& a) {
  a.pinned = true;
  if (a.byte_size == 0 || !a.block.dedicated) return;
  for (const auto& gpu : devices_->gpus()) {
    if (!gpu->RegisterHost(a.block.data, a.byte_size)) continue;
    a.page_locked = true;
    CudaDevice* registered = gpu.get();
    a.release = [registered, inner = std::move(a.release)](const ShmSlabPool::Block& b) {
      registered->UnregisterHost(b.data);
      if (inner) inner(b);
    };
    return;
  }
}

ArrayDesc Engine::Describe(const Session& s, const Allocation& a) const {
  ArrayDesc d;
  d.handle = a.handle;
  d.pinned = a.pinned;
  d.page_locked = a.page_locked;
  d.dtype = a.dtype;
  d.shape = a.shape;
  d.strides = a.strides;
  d.device = a.device;
  d.byte_size = a.byte_size;
  d.grad_handle = a.grad ? a.grad->handle : 0;
  // A local session gets the name of a slab only when mapping it shows nothing but memory it
  // may see: a slab of its own (it holds only this session's arrays), or a slab holding this
  // one allocation and nothing else (an exported array, a big array). Otherwise it moves the
  // bytes with Read/Write.
  if (s.options().local) {
    std::lock_guard<std::mutex> lock(a.block_mu);
    if (a.block.owner == s.id() || a.block.dedicated) {
      if (a.device == "cpu") {
        d.shm_name = a.block.slab_name;
        d.shm_offset = a.block.offset;
        d.shm_size = a.block.slab_size;
      } else {
        d.cuda_ipc_handle = a.block.ipc_handle;
        d.cuda_ipc_offset = a.block.offset;
        d.cuda_slab_size = a.block.slab_size;
        d.cuda_slab_id = a.block.slab_id;
      }
    }
  }
  return d;
}

Expected<std::shared_ptr<Allocation>> Engine::Held(const Session& s, uint64_t handle) const {
  if (handle == 0) return InvalidArgument("array handle 0 (None)");
  auto a = s.Find(handle);
  if (!a)
    return NotFound("unknown array handle " + std::to_string(handle) +
                    " (never created, already freed, or not held by this session)");
  return a;
}

Expected<ArrayDesc> Engine::CreateArray(Session& s, const CreateArrayParams& p) {
  WEFT_ASSIGN_OR_RETURN(Device * device, devices_->Resolve(s.id(), p.device));
  const uint64_t esize = p.dtype.ElementSize();
  // Check the initial value before allocating anything.
  if (p.init == CreateArrayParams::Init::kFill && p.value.size() != esize)
    return InvalidArgument("fill value has " + std::to_string(p.value.size()) + " bytes; one element of " +
                           p.dtype.Name() + " has " + std::to_string(esize));
  if (p.init == CreateArrayParams::Init::kData) {
    uint64_t want = 0;
    if (p.dtype.Validate().ok() && CheckedShapeProduct(p.shape, esize, &want) && p.value.size() != want)
      return InvalidArgument("data has " + std::to_string(p.value.size()) + " bytes; shape " + ShapeString(p.shape) +
                             " of " + p.dtype.Name() + " needs " + std::to_string(want));
  }
  const bool zero = p.init == CreateArrayParams::Init::kZeros;
  const bool pinned = p.pinned && device->is_cpu();
  WEFT_ASSIGN_OR_RETURN(auto a, NewAllocation(s, *device, p.dtype, p.shape, zero, pinned));
  if (pinned) PageLock(*a);
  if (p.requires_grad) {
    WEFT_ASSIGN_OR_RETURN(auto g, NewAllocation(s, *device, p.dtype, p.shape, true, pinned));
    g->is_grad = true;
    if (pinned) PageLock(*g);
    a->grad = std::move(g);
  }
  if (p.init == CreateArrayParams::Init::kFill) {
    ArrayView v;
    v.alloc = a;
    v.shape = a->shape;
    v.strides = a->strides;
    WEFT_RETURN_IF_ERROR(device->Fill(s, v, p.value));
  } else if (p.init == CreateArrayParams::Init::kData && !p.value.empty()) {
    WEFT_RETURN_IF_ERROR(device->Upload(s, a->block, 0, p.value.data(), p.value.size()));
  }
  s.Hold(a);
  return Describe(s, *a);
}

Status Engine::FreeArray(Session& s, uint64_t handle) {
  if (!s.Holds(handle))
    return NotFound("unknown array handle " + std::to_string(handle) +
                    " (never created, already freed, or not held by this session)");
  // A free is ordered after the commands the session queued before it: released here when the
  // executor is idle, else behind them (a queued tape BACKWARD still reads the arrays its
  // launches recorded, which no command snapshot holds).
  s.queue().RunHereOrPost([&s, handle] {
    std::shared_ptr<Allocation> keep = s.Find(handle);   // dropped after Release, outside locks
    s.Release(handle);
  });
  return Status::Ok();
}

Expected<ArrayDesc> Engine::DescribeArray(Session& s, uint64_t handle) const {
  WEFT_ASSIGN_OR_RETURN(auto a, Held(s, handle));
  return Describe(s, *a);
}

Status Engine::ReadArray(Session& s, uint64_t handle, uint64_t offset, uint64_t count, uint32_t chunk,
                         const std::function<bool(uint64_t, const char*, size_t)>& sink) {
  WEFT_ASSIGN_OR_RETURN(auto a, Held(s, handle));
  if (offset > a->byte_size)
    return OutOfRange("read offset " + std::to_string(offset) + " is past the end of array " +
                      std::to_string(handle) + " (" + std::to_string(a->byte_size) + " bytes)");
  if (count == 0) count = a->byte_size - offset;
  if (count > a->byte_size - offset)
    return OutOfRange("read of " + std::to_string(count) + " bytes at offset " + std::to_string(offset) +
                      " runs past the end of array " + std::to_string(handle) + " (" +
                      std::to_string(a->byte_size) + " bytes)");
  if (chunk == 0) chunk = 1u << 20;
  if (chunk > (32u << 20)) chunk = 32u << 20;
  s.queue().WaitIdle();
  if (a->device != "cpu") {
    // GPU: each chunk is downloaded after the session's queued work on the device.
    Device* d = devices_->Find(a->device);
    if (!d) return Internal("array " + std::to_string(handle) + " lives on unknown device '" + a->device + "'");
    std::vector<char> buf(std::min<uint64_t>(chunk, count));
    for (uint64_t done = 0; done < count;) {
      size_t n = static_cast<size_t>(std::min<uint64_t>(chunk, count - done));
      WEFT_RETURN_IF_ERROR(d->Download(s, a->block, offset + done, buf.data(), n));
      if (!sink(offset + done, buf.data(), n)) return Status(StatusCode::kCancelled, "read cancelled");
      done += n;
    }
    return Status::Ok();
  }
  const char* base = a->data();
  for (uint64_t done = 0; done < count;) {
    size_t n = static_cast<size_t>(std::min<uint64_t>(chunk, count - done));
    if (!sink(offset + done, base + offset + done, n)) return Status(StatusCode::kCancelled, "read cancelled");
    done += n;
  }
  return Status::Ok();
}

Status Engine::WriteArray(Session& s, uint64_t handle, uint64_t offset, const void* data, size_t size) {
  WEFT_ASSIGN_OR_RETURN(auto a, Held(s, handle));
  if (offset > a->byte_size || size > a->byte_size - offset)
    return OutOfRange("write of " + std::to_string(size) + " bytes at offset " + std::to_string(offset) +
                      " runs past the end of array " + std::to_string(handle) + " (" +
                      std::to_string(a->byte_size) + " bytes)");
  s.queue().WaitIdle();
  if (a->device != "cpu") {
    Device* d = devices_->Find(a->device);
    if (!d) return Internal("array " + std::to_string(handle) + " lives on unknown device '" + a->device + "'");
    return d->Upload(s, a->block, offset, data, size);
  }
  if (size) std::memcpy(a->data() + offset, data, size);
  return Status::Ok();
}

Expected<std::string> Engine::ExportArray(Session& s, uint64_t handle) {
  WEFT_ASSIGN_OR_RETURN(auto a, Held(s, handle));
  if (a->imported)
    return FailedPrecondition("array " + std::to_string(handle) +
                              " is GPU memory of this client imported by CUDA IPC; it cannot be shared with other "
                              "sessions (share a weft copy: wp.clone)");
  std::lock_guard<std::mutex> lock(a->export_mu);
  if (a->export_secret.empty()) {
    // Before its first export an array is held by its owner only. Move it (and its gradient)
    // into slabs of their own, on the owner's executor so no queued command of the owner runs
    // meanwhile: an importer then maps this array's bytes and nothing else.
    Status moved = Status::Ok();
    s.queue().RunAndWait([&] {
      moved = MoveToOwnSlab(*a, s);
      if (moved.ok() && a->grad) moved = MoveToOwnSlab(*a->grad, s);
    });
    WEFT_RETURN_IF_ERROR(moved);
    // Other sessions may map these slabs from now on: never reused for the owner's next arrays.
    if (Device* pool = devices_->Find(a->device)) {
      std::lock_guard<std::mutex> block_lock(a->block_mu);
      pool->MarkShared(a->block);
      if (a->grad) {
        std::lock_guard<std::mutex> grad_lock(a->grad->block_mu);
        pool->MarkShared(a->grad->block);
      }
    }
    a->export_secret = NewIpcSecret();
    a->export_principal = s.options().principal;
  } else if (a->export_principal != s.options().principal) {
    return PermissionDenied("array " + std::to_string(handle) + " was exported under other credentials");
  }
  return FormatIpcToken({a->handle, a->export_secret});
}

Expected<ArrayDesc> Engine::ImportArray(Session& s, const std::string& token) {
  WEFT_ASSIGN_OR_RETURN(IpcToken t, ParseIpcToken(token));
  std::shared_ptr<Allocation> a;
  {
    std::lock_guard<std::mutex> lock(alloc_mu_);
    auto it = allocations_.find(t.handle);
    if (it != allocations_.end()) a = it->second.lock();
  }
  // Same message for "gone" and "wrong secret": a token reveals nothing about other arrays.
  const Status gone = NotFound("IPC token does not name a live exported array (freed, or a wrong token)");
  if (!a) return gone;
  {
    std::lock_guard<std::mutex> lock(a->export_mu);
    if (a->export_secret.empty() || !SecretsEqual(a->export_secret, t.secret)) return gone;
    if (a->export_principal != s.options().principal)
      return PermissionDenied("IPC token was exported by a session with other credentials");
  }
  s.Hold(a);
  return Describe(s, *a);
}

Expected<std::shared_ptr<Allocation>> Engine::ImportedAllocation(Session& s, CudaDevice& gpu, const DType& dtype,
                                                                const std::vector<int64_t>& shape, uint64_t bytes,
                                                                const CudaMemoryRef& ref, const char* what) {
  WEFT_ASSIGN_OR_RETURN(auto mem, gpu.OpenImport(s.id(), ref.ipc_handle, ref.allocation_id));
  if (ref.byte_offset > mem->size || bytes > mem->size - ref.byte_offset)
    return OutOfRange(std::string("CUDA import: the ") + what + " (" + std::to_string(bytes) + " bytes at offset " +
                      std::to_string(ref.byte_offset) + ") runs past the end of the imported allocation (" +
                      std::to_string(mem->size) + " bytes)");
  if ((mem->base + ref.byte_offset) % dtype.ComponentSize() != 0)
    return InvalidArgument(std::string("CUDA import: the ") + what + " at offset " + std::to_string(ref.byte_offset) +
                           " is not aligned for " + dtype.Name());
  auto a = std::make_shared<Allocation>();
  a->handle = next_handle_++;
  a->dtype = dtype;
  a->shape = shape;
  a->strides = ContiguousStrides(shape, dtype.ElementSize());
  a->byte_size = bytes;
  a->device = gpu.name();
  a->imported = true;
  a->block.data = reinterpret_cast<void*>(static_cast<uintptr_t>(mem->base + ref.byte_offset));
  a->block.size = bytes;
  a->block.offset = ref.byte_offset;
  a->block.generation = mem->generation;
  // No slab: Describe gives the client no handle (the memory is its own already).
  a->release = [mem](const ShmSlabPool::Block&) {};   // holds the mapping while the array lives
  return a;
}

Expected<ArrayDesc> Engine::ImportCudaArray(Session& s, const CudaImportParams& p) {
  if (!s.options().local)
    return PermissionDenied("CUDA IPC import needs a local (Unix-socket) session: the memory must belong to a "
                            "process on the daemon's machine");
  if (p.device.rfind("cuda:", 0) != 0)
    return InvalidArgument("CUDA import: device '" + p.device + "' is not a GPU (\"cuda:N\")");
  WEFT_RETURN_IF_ERROR(p.dtype.Validate());
  if (p.shape.empty() || p.shape.size() > static_cast<size_t>(kMaxArrayDims))
    return InvalidArgument("array shape must have 1 to 4 dimensions, got " + std::to_string(p.shape.size()));
  for (int64_t d : p.shape)
    if (d < 0) return InvalidArgument("array shape " + ShapeString(p.shape) + " has a negative dimension");
  uint64_t bytes = 0;
  if (!CheckedShapeProduct(p.shape, p.dtype.ElementSize(), &bytes))
    return OutOfRange("CUDA import: shape " + ShapeString(p.shape) + " of " + p.dtype.Name() +
                      " overflows (more than " + std::to_string(kMaxCheckedSize) + " bytes)");
  for (const CudaMemoryRef* ref : {&p.data, p.has_grad ? &p.grad : nullptr}) {
    if (!ref) continue;
    if (ref->ipc_handle.size() != 64)
      return InvalidArgument("CUDA import: an IPC handle has 64 bytes, got " + std::to_string(ref->ipc_handle.size()));
    if (ref->allocation_id == 0) return InvalidArgument("CUDA import: the allocation id is 0");
    if (ref->byte_offset > kMaxCheckedSize)
      return OutOfRange("CUDA import: byte offset " + std::to_string(ref->byte_offset) + " is absurdly large");
  }
  WEFT_ASSIGN_OR_RETURN(Device * device, devices_->Resolve(s.id(), p.device));
  if (device->is_cpu()) return InvalidArgument("CUDA import: device '" + p.device + "' is not a GPU");
  auto& gpu = static_cast<CudaDevice&>(*device);
  WEFT_ASSIGN_OR_RETURN(auto a, ImportedAllocation(s, gpu, p.dtype, p.shape, bytes, p.data, "array"));
  if (p.has_grad) {
    WEFT_ASSIGN_OR_RETURN(auto g, ImportedAllocation(s, gpu, p.dtype, p.shape, bytes, p.grad, "gradient"));
    g->is_grad = true;
    a->grad = std::move(g);
  }
  WEFT_RETURN_IF_ERROR(CheckAllocationConsistent(*a));
  s.Hold(a);
  return Describe(s, *a);
}

// ---- commands ----

std::function<void()> Engine::BatchTask(Session& s, std::vector<Command> commands) {
  auto snapshot = std::make_shared<HandleSnapshot>();
  std::vector<uint64_t> handles;
  for (const Command& c : commands) CollectHandles(c, &handles);
  for (uint64_t h : handles) {
    if (h == 0 || snapshot->count(h)) continue;
    if (auto a = s.Find(h)) (*snapshot)[h] = std::move(a);
  }
  auto batch = std::make_shared<std::vector<Command>>(std::move(commands));
  CommandExecutor* exec = executor_.get();
  Session* sp = &s;
  std::atomic<uint64_t>* run = &commands_run_;
  std::atomic<uint64_t>* run_ns = &command_run_ns_;
  return [exec, sp, batch, snapshot, run, run_ns] {
    const auto start = std::chrono::steady_clock::now();
    uint64_t ran = 0;
    for (const Command& c : *batch) {
      if (sp->cancelled()) break;   // closing: the rest of the batch does not run
      if (sp->failed() && !RunsAfterFailure(c)) {
        sp->CountSkipped();
        continue;
      }
      Status st = exec->Execute(*sp, c, *snapshot);
      ++ran;
      if (!st.ok()) {
        spdlog::warn("session {}: command failed: {}", sp->label(), st.ToString());
        sp->Fail(st, c.origin);
      }
    }
    sp->queued_commands -= batch->size();
    snapshot->clear();
    run->fetch_add(ran, std::memory_order_relaxed);
    run_ns->fetch_add(static_cast<uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                                std::chrono::steady_clock::now() - start)
                                                .count()),
                      std::memory_order_relaxed);
  };
}

Status Engine::AdmitBatch(Session& s, const std::vector<Command>& commands) {
  if (s.cancelled()) return FailedPrecondition("session " + s.label() + " is closing");
  WEFT_RETURN_IF_ERROR(CheckCommandBatch(commands, options_.limits, s.queued_commands.load()));
  s.queued_commands += commands.size();
  return Status::Ok();
}

Expected<uint64_t> Engine::Submit(Session& s, std::vector<Command> commands, bool run_here_when_idle) {
  const uint64_t n = commands.size();
  if (n == 0) return n;
  WEFT_RETURN_IF_ERROR(AdmitBatch(s, commands));
  if (run_here_when_idle) s.queue().RunHereOrPost(BatchTask(s, std::move(commands)));
  else s.queue().Post(BatchTask(s, std::move(commands)));
  return n;
}

Expected<Session::SyncResult> Engine::SubmitAndSynchronize(Session& s, std::vector<Command> commands) {
  if (commands.empty()) {
    s.queue().WaitIdle();
  } else {
    WEFT_RETURN_IF_ERROR(AdmitBatch(s, commands));
    s.queue().RunAndWait(BatchTask(s, std::move(commands)));
  }
  SynchronizeDevices(s);
  return s.TakeResult();
}

Expected<std::optional<Session::SyncResult>> Engine::SubmitAndRun(Session& s, std::vector<Command> commands) {
  if (commands.empty()) {
    s.queue().WaitIdle();
  } else {
    WEFT_RETURN_IF_ERROR(AdmitBatch(s, commands));
    s.queue().RunAndWait(BatchTask(s, std::move(commands)));
  }
  if (!s.failed()) return std::optional<Session::SyncResult>();
  SynchronizeDevices(s);
  return std::optional<Session::SyncResult>(s.TakeResult());
}

Session::SyncResult Engine::Synchronize(Session& s) {
  s.queue().WaitIdle();
  SynchronizeDevices(s);
  return s.TakeResult();
}

Expected<double> Engine::EventElapsed(Session& s, const std::string& device, uint64_t start_id, uint64_t end_id) {
  WEFT_ASSIGN_OR_RETURN(Device * d, devices_->Resolve(s.id(), device));
  auto* gpu = dynamic_cast<CudaDevice*>(d);
  if (gpu == nullptr) return InvalidArgument("'" + device + "' is not a GPU (timing events time GPU work)");
  s.queue().WaitIdle();
  SynchronizeDevices(s);
  return gpu->TimedEventElapsed(s, start_id, end_id);
}

Expected<CudaDevice::KernelProperties> Engine::KernelPropertiesOf(Session& s, const std::string& module_id,
                                                                  const std::string& kernel,
                                                                  const std::string& device) {
  WEFT_ASSIGN_OR_RETURN(Device * d, devices_->Resolve(s.id(), device));
  auto* gpu = dynamic_cast<CudaDevice*>(d);
  if (gpu == nullptr) return InvalidArgument("'" + device + "' is not a GPU (kernel properties are a CUDA kernel's)");
  if (!store_) return FailedPrecondition("this daemon has no module store");
  std::shared_ptr<const LoadedModule> module = store_->Find(module_id);
  if (!module) return NotFound("unknown module '" + module_id + "' (compile it first with ModuleService.Compile)");
  if (module->target != Target::kCuda)
    return InvalidArgument("module '" + module_id + "' was compiled for the CPU, not for " + gpu->name());
  const LoadedKernel* k = module->Find(kernel);
  if (!k) return NotFound("module '" + module_id + "' has no kernel '" + kernel + "'");
  return gpu->PropertiesOf(*module, *k);
}

void Engine::SynchronizeDevices(Session& s) {
  for (auto& g : devices_->gpus()) {
    DeviceSyncResult r = g->Synchronize(s);
    if (!r.output.empty()) s.AppendOutput(r.output);
    if (!r.error.ok()) {
      spdlog::warn("session {}: {}: {}", s.label(), g->name(), r.error.ToString());
      s.Fail(r.error, r.origin);
    }
  }
  // After a TimingCommand END: the timed operations, or none when a command failed (Warp
  // discards them when timing_end's synchronize raises).
  if (s.timing_collect.exchange(false)) {
    const bool keep = !s.failed();
    std::vector<TimedActivity> timed;
    uint64_t dropped = 0;
    for (auto& g : devices_->gpus()) g->TakeTiming(s, &timed, &dropped, keep);
    s.SetTimingResult(std::move(timed), dropped);
  }
}

// ---- modules ----

Expected<std::shared_ptr<const LoadedModule>> Engine::Compile(Session& s, ModuleSource source,
                                                              const std::string& device, CompileReport* report) {
  if (!store_) return FailedPrecondition("this daemon has no module store");
  std::string dev = device.empty() ? "cpu" : device;
  if (dev != "cpu" && dev.rfind("cuda", 0) != 0)
    return InvalidArgument("unknown device '" + dev + "' (expected \"cpu\" or \"cuda:N\")");
  // "cuda" is the session's GPU; without one the store compiles for its default architecture.
  if (dev == "cuda" && !devices_->gpus().empty()) {
    WEFT_ASSIGN_OR_RETURN(Device * placed, devices_->Resolve(s.id(), dev));
    dev = placed->name();
  }
  std::vector<std::string> ignored = DropUncheckedOptions(s, &source);
  auto r = store_->Compile(source, dev, report);
  WarnIgnoredOptions(ignored, report);
  // The name is the client's (checked only by the store): escaped, so it cannot forge log lines.
  if (!r.ok())
    spdlog::info("session {}: compile of module '{}' failed: {}", s.label(), codegen::CommentText(source.name),
                 r.status().message());
  return r;
}

Expected<CudaArchCompile> Engine::CompileForArch(Session& s, ModuleSource source, int arch, CompileReport* report) {
  if (!store_) return FailedPrecondition("this daemon has no module store");
  std::vector<std::string> ignored = DropUncheckedOptions(s, &source);
  auto r = store_->CompileForArch(source, arch, report);
  WarnIgnoredOptions(ignored, report);
  if (!r.ok())
    spdlog::info("session {}: compile of module '{}' for sm_{} failed: {}", s.label(),
                 codegen::CommentText(source.name), arch, r.status().message());
  return r;
}

// Options that weaken a safety net (bounds checks, the loops' cancellation poll) need
// --allow-unchecked; without it they are turned back on (the names are returned for a warning).
std::vector<std::string> Engine::DropUncheckedOptions(const Session& s, ModuleSource* source) {
  std::vector<std::string> ignored;
  for (const char* option : {"bounds_checks", "cancel_poll"}) {
    auto it = source->options.find(option);
    if (it != source->options.end() && (it->second == "false" || it->second == "0" || it->second == "False") &&
        !s.unchecked_allowed) {
      it->second = "true";
      ignored.push_back(option);
    }
  }
  return ignored;
}

void Engine::WarnIgnoredOptions(const std::vector<std::string>& ignored, CompileReport* report) {
  for (const auto& option : ignored) {
    if (!report) break;
    Diagnostic d;
    d.severity = Diagnostic::Severity::kWarning;
    d.message = option + "=false ignored: this session is checked. Unchecked kernels run only in a session opened "
                "unchecked (the module option set before the session opens, or WEFT_UNCHECKED=1), which a weftd "
                "started with --allow-unchecked runs in a process of its own";
    report->diagnostics.push_back(d);
  }
}

bool Engine::AnyGpuLost() const {
  for (const auto& g : devices_->gpus())
    if (g->lost()) return true;
  return false;
}

EngineStats Engine::Stats() const {
  EngineStats st;
  {
    std::lock_guard<std::mutex> lock(mu_);
    st.sessions = static_cast<uint32_t>(sessions_.size());
  }
  {
    std::lock_guard<std::mutex> lock(alloc_mu_);
    st.arrays = allocations_.size();
  }
  st.array_bytes = live_bytes_.load();
  st.cpu_slabs = devices_->cpu().SlabCount();
  st.cpu_slab_bytes = devices_->cpu().SlabBytes();
  for (auto& g : devices_->gpus()) {
    st.gpu_slabs += g->SlabCount();
    st.gpu_slab_bytes += g->SlabBytes();
    CudaDeviceStats gs = g->stats();
    st.gpu_resets += gs.resets;
    st.gpu_coarsened_launches += gs.coarsened_launches;
    if (gs.resets) st.last_gpu_reset_ms = gs.last_reset_ms;
  }
  if (store_) {
    auto ms = store_->stats();
    st.module_cache_hits = ms.memory_hits;
    st.module_cache_disk_hits = ms.disk_hits;
    st.module_cache_misses = ms.misses;
  }
  st.sessions_opened_total = sessions_opened_.load();
  st.sessions_reaped_total = sessions_reaped_.load();
  st.commands_run_total = commands_run_.load();
  st.command_run_seconds = static_cast<double>(command_run_ns_.load()) * 1e-9;
  return st;
}

}  // namespace weft
