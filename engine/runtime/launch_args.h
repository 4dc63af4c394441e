// Kernel argument blocks: checks each client argument against the compiler's ParamLayout and
// packs it (arrays as wp::array_abi_t, structs by their fields), and builds the adjoint block
// whose array slots point at gradient memory.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/codegen/generate_module.h"
#include "engine/core/status.h"
#include "engine/runtime/array_view.h"
#include "engine/runtime/commands.h"

namespace weft {

// What a ResolvedArg names until it is resolved: no view (a value, a struct, or None).
inline const ArrayRef kNoArrayRef{};

// An argument whose array views are resolved to allocations held by the session.
struct ResolvedArg {
  ArgValue::Kind kind = ArgValue::Kind::kRaw;
  std::string raw;
  // The view as the launch command names it, not a copy of its shape and strides: the command
  // outlives its arguments' resolution and packing (both happen within the launch call).
  const ArrayRef* ref = &kNoArrayRef;
  std::shared_ptr<Allocation> alloc;   // null for None (handle 0)
  std::vector<ResolvedArg> fields;
};

// One array slot in a packed block.
struct PackedArray {
  uint32_t offset = 0;           // of the array_abi_t inside the block
  std::string param;             // "a" or "s.field"
  int top_param = -1;            // index of the kernel parameter it belongs to
  std::weak_ptr<Allocation> alloc;   // expired-check for tapes; empty for None
  uint64_t handle = 0;
  uint64_t byte_offset = 0;      // view offset (gradients share the array's layout)
  bool viewed = false;           // the bytes read as another dtype (array.view): no gradient
};

// 64-byte aligned bytes.
class ArgBlock {
 public:
  ArgBlock() = default;
  explicit ArgBlock(uint32_t size);
  char* data() { return bytes_.get(); }
  const char* data() const { return bytes_.get(); }
  uint32_t size() const { return size_; }
 private:
  std::shared_ptr<char> bytes_;
  uint32_t size_ = 0;
};

struct PackedArgs {
  ArgBlock block;
  std::vector<PackedArray> arrays;
  std::vector<std::shared_ptr<Allocation>> keep_alive;   // for the duration of the launch
};

// Packs forward arguments. Errors name the kernel and the parameter.
// Every array must live on `device` (the launch's).
Expected<PackedArgs> PackArgs(const KernelLayout& kernel, const std::vector<ResolvedArg>& args,
                              const std::string& device = "cpu");

// Adjoint block from explicit adjoint arguments (LaunchCommand.adjoint): array slots take the
// given arrays' data; value slots are zero. Each adjoint array passes ValidateArray with the
// compiled element type and size, and must have the shape of the primal array in the same slot
// of `primal` (the packed forward block).
Expected<PackedArgs> PackAdjointArgs(const KernelLayout& kernel, const PackedArgs& primal,
                                     const std::vector<ResolvedArg>& adj_args, const std::string& device = "cpu");

// Adjoint block for a recorded launch: each array slot points at that array's own gradient
// (data = null when it has none), validated like every array; value slots are zero. The forward
// allocations must be alive.
Expected<PackedArgs> GradientArgs(const KernelLayout& kernel, const PackedArgs& forward,
                                  const std::vector<std::shared_ptr<Allocation>>& live);

// Whether every array the kernel accesses as p[wp.tid()] (kernel.tid_indexed_params) holds at
// least as many elements as a launch of `dim` has threads, read from the packed block (whose
// arrays passed the one validation): then those accesses are in bounds and the kernel's
// trusted-index variant may run (CodegenOptions::trust_tid_indices). False for an empty list, a
// missing or null array, a thread count that overflows, or a launch of no threads.
bool TidIndicesInRange(const KernelLayout& kernel, const PackedArgs& args, const std::vector<int64_t>& dim);

}  // namespace weft
