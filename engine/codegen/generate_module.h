// The compiler's entry point: ModuleSource -> C++ translation unit + kernel argument layouts.
// Pipeline (engine/codegen/pipeline.cpp): lang::Parse -> sema::Check -> codegen::Emit.
// Expects: functions' param_types already resolved by the client (docs/protocol.md).
// Guarantees: on success the source compiles with only engine/native headers on the include
// path, under clang (Target::kCpu) and NVRTC (Target::kCuda); every user error is a Diagnostic
// with the user's file:line, never an abort.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "engine/core/module_source.h"
#include "engine/core/status.h"

namespace weft {

enum class Target { kCpu, kCuda };

// Where one kernel parameter lives in the packed argument block.
struct ParamLayout {
  std::string name;
  std::string type;       // canonical type string
  uint32_t offset = 0;    // bytes from the start of the block (or of the enclosing struct)
  uint32_t size = 0;
  uint32_t align = 1;
  bool is_array = false;  // occupies a wp::array_abi_t
  std::string array_dtype;  // element type string when is_array
  int array_ndim = 0;
  std::vector<ParamLayout> fields;  // struct parameters: their fields, offsets relative to it
  uint32_t array_elem_size = 0;  // bytes of one element when is_array (the compiled layout's)
};

struct KernelLayout {
  std::string name;
  std::vector<ParamLayout> params;
  uint32_t args_size = 0;
  uint32_t args_align = 8;
  std::string forward_symbol;   // e.g. weft_saxpy_cpu_forward
  std::string backward_symbol;  // empty when backward was not generated
  // Why the kernel has no adjoint (code it reaches whose adjoint cannot be generated, such as a
  // differentiable `a[i].x *= v`): the located error that generating it gives; empty if none.
  std::string adjoint_refused;
  // The CUDA entries stride over the grid (CodegenOptions::grid_stride); false: the launch
  // must use a grid that covers its size, and max_blocks is refused.
  bool grid_stride = true;
  // CPU entries compiled for cooperative blocks of this many lanes (CodegenOptions::cpu_lanes);
  // 1: one thread per block.
  uint32_t lanes = 1;
  // CUDA kernels: the parameters (indices into `params`) it accesses as p[i] with i = wp.tid()
  // (TidIndexedAccess). A launch whose arrays there all hold at least as many elements as it
  // has threads may use the variant built with CodegenOptions::trust_tid_indices.
  std::vector<uint32_t> tid_indexed_params;
  // CUDA, the trusted-index variant only (CodegenOptions::trust_tid_indices, no grid-stride loop,
  // no tiles in the module, some 1-D array parameter loaded at wp.tid()): an entry where each GPU
  // thread runs the forward body for kCoarseFactor logical threads of a 1-D launch, a
  // kCoarseFactor-th of the launch apart (i, i + q, i + 2q, ...; q = ceil(threads / factor)),
  // after prefetching into L2 what the later ones load at their index. Empty when none. The
  // launch picks it for large 1-D forward launches (CudaDevice::LaunchTraced; docs/cuda.md
  // "Coarsened launches"); its grid covers q threads.
  std::string coarse_symbol;
  // Bytes the coarsened entry prefetches per logical thread (the elements of those parameters):
  // a kernel that already has this many bytes of loads in flight per thread gains nothing.
  uint32_t coarse_loaded_bytes = 0;
};

// Logical threads per GPU thread in a coarsened entry (KernelLayout::coarse_symbol).
constexpr int kCoarseFactor = 4;

struct GeneratedModule {
  std::string source;                       // the translation unit
  std::vector<KernelLayout> kernels;
  std::vector<std::string> function_names;  // launch_error_t::function_id -> "file.py:kernel"
};

struct CodegenOptions {
  Target target = Target::kCpu;
  bool enable_backward = false;   // emit adjoint entry points
  bool bounds_checks = true;
  // Parse nesting limits (lang::ParseLimits; values above the parser's maxima are lowered).
  int max_block_depth = 100;
  int max_expression_depth = 1000;
  bool loop_cancel_poll = true;   // loops poll the launch's cancel word (wp::cg_loop_poll)
  // CUDA entries: a grid-stride loop (any grid size, max_blocks) or, false, one index per
  // thread with an early return (Warp's grid_stride=False: fewer registers and instructions,
  // the grid must cover the launch). No effect on CPU entries.
  bool grid_stride = true;
  // CPU entries for cooperative blocks of this many lanes (the module option "cpu_block_dim",
  // wp.config.enable_cpu_blocks): wp.tile(x) has this many elements and the launch runs each
  // block's threads as fibers (engine/runtime/cpu_lanes.h). 1: one thread per block.
  uint32_t cpu_lanes = 1;
  // CUDA: the forward accesses p[i] of a kernel, with p a 1-D array parameter and i the value of
  // wp.tid(), go without their bounds check (KernelLayout::tid_indexed_params lists those p).
  // Only for launches proven in range: every such p has at least as many elements as the launch
  // has threads, so i < threads <= p's extent (the executor checks it before it picks the
  // variant, ModuleStore::WithTrustedTidIndices). Gradient accesses keep their checks.
  bool trust_tid_indices = false;
};

// On failure returns InvalidArgument and appends the user-facing diagnostics to *diags.
Expected<GeneratedModule> GenerateModule(const ModuleSource& module, const CodegenOptions& options,
                                         std::vector<Diagnostic>* diags);

}  // namespace weft
