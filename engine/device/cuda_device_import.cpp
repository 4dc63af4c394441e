// CUDA IPC import of a client process's GPU allocation into a CudaDevice (imported_memory.h
// says why a mapping is never read stale): open, cache per session, close.
#include <algorithm>
#include <cstring>

#include "engine/device/cuda_device.h"
#include "engine/runtime/session.h"

namespace weft {

std::string IpcHandlePrefix(const std::string& handle) {
  static const char* hex = "0123456789abcdef";
  std::string s;
  for (size_t i = 0; i < std::min<size_t>(8, handle.size()); ++i) {
    s += hex[static_cast<unsigned char>(handle[i]) >> 4];
    s += hex[static_cast<unsigned char>(handle[i]) & 15];
  }
  return s;
}

Expected<std::shared_ptr<ImportedMemory>> CudaDevice::OpenImport(const std::string& session_id,
                                                                 const std::string& handle, uint64_t identity) {
  if (handle.size() != sizeof(jit::CuIpcMemHandle))
    return InvalidArgument("a CUDA IPC handle has " + std::to_string(sizeof(jit::CuIpcMemHandle)) + " bytes, got " +
                           std::to_string(handle.size()));
  if (identity == 0) return InvalidArgument("CUDA import: the allocation id is 0 (the client must send its buffer id)");
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckUsable());
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (const auto& [id, slab] : slabs_)
      if (!slab->ipc.empty() && slab->ipc == handle)
        return InvalidArgument("the CUDA IPC handle names weft's own memory on " + name_ +
                               " (pass the weft array itself, not its memory)");
  }
  const uint64_t gen = generation_.load();
  std::vector<std::shared_ptr<ImportedMemory>> drop;   // released after the lock
  std::shared_ptr<ImportedMemory> stale;
  {
    std::lock_guard<std::mutex> lock(imports_mu_);
    auto it = imports_.find(handle);
    std::shared_ptr<ImportedMemory> live = it == imports_.end() ? nullptr : it->second.lock();
    if (live && live->generation != gen) live = nullptr;   // went with a device reset
    if (live) {
      if (live->session != session_id)
        return PermissionDenied("this CUDA IPC handle (" + IpcHandlePrefix(handle) +
                                "...) is imported by another session; a session imports memory of its own "
                                "client process only");
      auto& recent = recent_imports_[session_id];
      auto pos = std::find(recent.begin(), recent.end(), live);
      if (live->identity == identity) {   // the same block again: no new open
        if (pos != recent.end()) recent.erase(pos);
        recent.push_back(live);
        if (recent.size() > kRecentImports) {
          drop.push_back(recent.front());
          recent.erase(recent.begin());
        }
        return live;
      }
      // The same handle bytes for another allocation: the client freed the old block and the
      // driver reused its handle. The old mapping must go before the new block is opened.
      if (pos != recent.end()) {
        drop.push_back(*pos);
        recent.erase(pos);
      }
      stale = std::move(live);
      imports_.erase(it);
    }
  }
  if (stale) {
    drop.clear();                      // the recent-list reference is gone with this
    if (stale.use_count() > 1)
      return FailedPrecondition(
          "CUDA import: the allocation behind this IPC handle changed (allocation id " +
          std::to_string(stale->identity) + " -> " + std::to_string(identity) +
          ") while arrays of this session still use the old one; free those arrays first");
    stale.reset();                     // closes the old mapping
  }
  drop.clear();
  jit::CuIpcMemHandle h{};
  std::memcpy(h.reserved, handle.data(), sizeof(h.reserved));
  jit::CuDevicePtr p = 0;
  // The driver requires CU_IPC_MEM_LAZY_ENABLE_PEER_ACCESS (0 is refused with INVALID_VALUE);
  // memory of another GPU then opens too (mapped with peer access; the ordinal check below
  // refuses it only where the driver reports the other GPU).
  jit::CuResult r = driver_->IpcOpenMemHandle(&p, h, jit::kCuIpcMemLazyEnablePeerAccess);
  if (r != 0)
    return InvalidArgument("the CUDA IPC handle (" + IpcHandlePrefix(handle) + "...) could not be opened on " + name_ +
                           " (" + driver_->ErrorName(r) +
                           "): not the handle of a live cudaMalloc allocation of a process on this machine and GPU");
  int ordinal = -1;
  jit::CuDevicePtr base = 0;
  size_t size = 0;
  jit::CuResult ro = driver_->PointerGetAttribute(&ordinal, jit::kCuPointerAttributeDeviceOrdinal, p);
  jit::CuResult rr = driver_->MemGetAddressRange(&base, &size, p);
  if (ro != 0 || rr != 0 || ordinal != options_.ordinal) {
    driver_->IpcCloseMemHandle(p);
    if (ro == 0 && ordinal != options_.ordinal)
      return InvalidArgument("the CUDA IPC handle names memory on cuda:" + std::to_string(ordinal) +
                             ", not on " + name_);
    return Internal("CUDA import: the opened mapping cannot be described (" + driver_->ErrorName(ro != 0 ? ro : rr) +
                    ")");
  }
  auto mem = std::make_shared<ImportedMemory>();
  mem->base = base;
  mem->size = size;
  mem->handle = handle;
  mem->identity = identity;
  mem->session = session_id;
  mem->generation = gen;
  const jit::CudaDriver* driver = driver_;
  CudaDevice* self = this;
  mem->close = [driver, self](ImportedMemory& m) {
    // A device reset took the mapping with the old context.
    if (m.generation != self->generation_.load()) return;
    driver->CtxSetCurrent(self->ctx_);
    driver->IpcCloseMemHandle(m.base);
  };
  ++import_opens_;
  {
    std::lock_guard<std::mutex> lock(imports_mu_);
    imports_[handle] = mem;
    auto& recent = recent_imports_[session_id];
    recent.push_back(mem);
    if (recent.size() > kRecentImports) {
      drop.push_back(recent.front());
      recent.erase(recent.begin());
    }
  }
  return mem;
}

size_t CudaDevice::ImportCount() const {
  std::lock_guard<std::mutex> lock(imports_mu_);
  size_t n = 0;
  for (const auto& [h, w] : imports_) n += w.expired() ? 0 : 1;
  return n;
}

void CudaDevice::ForgetImports(const std::string& session_id) {
  std::vector<std::shared_ptr<ImportedMemory>> drop;
  {
    std::lock_guard<std::mutex> lock(imports_mu_);
    auto it = recent_imports_.find(session_id);
    if (it != recent_imports_.end()) {
      drop = std::move(it->second);
      recent_imports_.erase(it);
    }
    for (auto i = imports_.begin(); i != imports_.end();) i = i->second.expired() ? imports_.erase(i) : std::next(i);
  }
}

}  // namespace weft
