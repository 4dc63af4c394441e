// GPU memory of a client process imported into the daemon by CUDA IPC: one allocation of the
// client (a framework's cudaMalloc block, e.g. a segment of Torch's caching allocator), opened
// with cuIpcOpenMemHandle in the GPU's context and closed with cuIpcCloseMemHandle when the
// last holder lets go. Holders: the arrays made over it (Allocation::release keeps it) and the
// device's short list of recently imported allocations of the session (so a caching allocator
// handing out the same block again costs no new open).
//
// Why a mapping is never read stale (docs/interop.md has the whole argument):
//   - it is keyed by the handle bytes AND the client's allocation identity
//     (CU_POINTER_ATTRIBUTE_BUFFER_ID, unique for the life of the client process): a block the
//     client freed and allocated again is a new identity even when the driver gives it the
//     same handle bytes, so the old mapping is closed and the new block opened afresh;
//   - the client keeps a reference to the framework tensor for as long as the weft array
//     over it lives, so the framework cannot free or hand out that block meanwhile;
//   - a mapping belongs to one session: another session sending the same handle is refused.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace weft {

struct ImportedMemory {
  uint64_t base = 0;          // device address of the allocation in the daemon
  uint64_t size = 0;          // its size (cuMemGetAddressRange)
  std::string handle;         // the 64 handle bytes
  uint64_t identity = 0;      // the client's allocation id
  std::string session;        // the session that imported it
  uint64_t generation = 0;    // the device generation it was opened in
  std::function<void(ImportedMemory&)> close;   // cuIpcCloseMemHandle (set by the device)

  ImportedMemory() = default;
  ImportedMemory(const ImportedMemory&) = delete;
  ImportedMemory& operator=(const ImportedMemory&) = delete;
  ~ImportedMemory() {
    if (close) close(*this);
  }
};

}  // namespace weft
