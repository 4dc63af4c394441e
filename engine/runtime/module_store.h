// Compiled modules: ModuleSource -> (content hash) -> cache (memory LRU + disk) -> loaded code.
// Owns: module ids, coalescing of concurrent compiles of one key, lazy backward variants.
// Uses: GenerateModule (codegen), CpuJit (jit/cpu), ModuleCache (disk/memory artifacts).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "engine/codegen/check_source.h"
#include "engine/codegen/generate_module.h"
#include "engine/core/module_source.h"
#include "engine/core/status.h"
#include "engine/native/launch_abi.h"

namespace weft {

using CpuForwardFn = void (*)(const wp::launch_context_t* ctx, const void* args, wp::int64 begin,
                              wp::int64 end);
using CpuBackwardFn = void (*)(const wp::launch_context_t* ctx, const void* args,
                               const void* adj_args, wp::int64 begin, wp::int64 end);

struct LoadedKernel {
  KernelLayout layout;
  CpuForwardFn cpu_forward = nullptr;
  CpuBackwardFn cpu_backward = nullptr;   // null until the backward variant is loaded
};

struct LoadedModule {
  std::string id;                          // content hash (hex), used by LaunchCommand
  Target target = Target::kCpu;
  std::vector<LoadedKernel> kernels;
  std::vector<std::string> function_names; // launch_error_t::function_id -> name
  bool has_backward = false;
  // target == kCuda: the entries stride over the grid (ModuleStore::WithGridStride's variant);
  // its CUBIN shares the module id and the symbols with the lean one.
  bool grid_stride = false;
  // target == kCuda: built with CodegenOptions::trust_tid_indices (WithTrustedTidIndices).
  bool trusts_tid_indices = false;
  // target == kCuda: the CUBIN for cuda_sm (for cuModuleLoadData; kernels' entry points are
  // layout.forward_symbol / backward_symbol). Empty for CPU modules.
  std::string cuda_image;
  int cuda_sm = 0;
  const LoadedKernel* Find(const std::string& kernel) const {
    for (const auto& k : kernels)
      if (k.layout.name == kernel) return &k;
    return nullptr;
  }
};

struct CompileReport {
  bool cache_hit = false;    // served from memory
  bool disk_hit = false;     // served from the disk cache
  double compile_ms = 0;     // wall time of this call
  std::vector<Diagnostic> diagnostics;
};

// One entry point of a module compiled for a CUDA architecture, as the CUBIN describes it.
struct CudaKernelReport {
  std::string kernel;          // the kernel's name in the module
  bool adjoint = false;        // the backward (adjoint) entry point
  std::string symbol;          // its symbol in the CUBIN
  uint32_t registers = 0;      // per thread
  uint64_t code_bytes = 0;     // machine code
  uint64_t shared_bytes = 0;   // static shared memory
  uint64_t local_bytes = 0;    // stack frame per thread
  uint64_t const_bytes = 0;    // constant bank 0 (parameters and the driver's area)
};

// A module compiled for sm_<arch> without loading it (no GPU needed): the CUBIN and a report
// per entry point (forward, and adjoint unless the module turns enable_backward off).
struct CudaArchCompile {
  int arch = 0;
  std::string image;           // the CUBIN
  std::string nvrtc_version;
  std::vector<CudaKernelReport> kernels;
};

// The architectures CompileForArch accepts (those NVRTC supports among these).
inline constexpr int kCudaArchs[] = {75, 80, 86, 87, 89, 90, 100, 103, 110, 120, 121};

// The compiler front half (engine/codegen's GenerateModule); replaceable for tests.
using GenerateModuleFn = std::function<Expected<GeneratedModule>(
    const ModuleSource&, const CodegenOptions&, std::vector<Diagnostic>*)>;

struct ModuleStoreOptions {
  std::string cache_dir;          // disk cache; empty = memory only
  std::string native_dir;         // engine/native headers for the JIT; empty = WEFT_NATIVE_DIR
  size_t memory_capacity = 256;   // modules kept loaded (LRU)
  uint64_t disk_capacity_bytes = uint64_t{2} << 30;   // disk cache bound (LRU files removed); 0 = none
  // Also compile every generated CPU module's CUDA flavour with NVRTC, for each architecture
  // of verify_cuda_archs (in parallel; empty = {verify_cuda_sm}): a module NVRTC rejects fails
  // to compile (Internal, naming the architecture). A check for CI on machines without a GPU.
  bool verify_cuda = false;
  std::vector<int> verify_cuda_archs;
  int verify_cuda_sm = 90;        // cuda:N's architecture when no driver is present
  GenerateModuleFn generate;      // empty = weft::GenerateModule
  codegen::CompileLimits limits;  // checked on every Compile request (names, size, depth)
  // > 0: each CPU compile runs clang in a child process killed after this many seconds
  // (ResourceExhausted naming --compile-time-limit); 0: in process, unbounded.
  double compile_time_limit_s = 0;
  // CUDA modules with bounds checks: build the trusted-index variant (ModuleStore::
  // WithTrustedTidIndices, forward) in a second thread while the module itself compiles, when
  // some kernel indexes a parameter by the thread. Compile returns when both are done.
  bool build_trusted_beside = true;
  // Identity of the compiler in cache keys; empty = weft version + this executable's size and
  // mtime (a rebuilt daemon never loads code generated by an older one).
  std::string build_id;
};

struct ModuleStoreStats {
  uint64_t memory_hits = 0;
  uint64_t disk_hits = 0;
  uint64_t misses = 0;            // real compiles
};

class ModuleStore {
 public:
  static Expected<std::unique_ptr<ModuleStore>> Create(const ModuleStoreOptions& options);
  virtual ~ModuleStore() = default;

  // Compiles (or finds) the module for `device` ("cpu", "cuda:N"). User errors come back as
  // InvalidArgument with report->diagnostics filled.
  virtual Expected<std::shared_ptr<const LoadedModule>> Compile(const ModuleSource& source,
                                                                const std::string& device,
                                                                CompileReport* report) = 0;
  // A module compiled earlier (by any session), or nullptr.
  virtual std::shared_ptr<const LoadedModule> Find(const std::string& module_id) const = 0;
  // The same module with backward entry points (generated and compiled on first request).
  virtual Expected<std::shared_ptr<const LoadedModule>> WithBackward(const std::string& module_id) = 0;
  // The same CUDA module with grid-stride entries (and backward ones when `backward`), generated
  // and compiled on first request: a module's CUDA entries run one index per thread, and a
  // launch whose grid cannot cover it (max_blocks, more blocks than a grid holds) needs the loop.
  // FailedPrecondition when the module was built lean on purpose (grid_stride=False).
  virtual Expected<std::shared_ptr<const LoadedModule>> WithGridStride(const std::string& module_id, bool backward) {
    (void)module_id, (void)backward;
    return Unimplemented("this module store has no grid-stride variants");
  }
  // The same lean CUDA module whose kernels access p[wp.tid()] of their 1-D array parameters
  // without a bounds check (CodegenOptions::trust_tid_indices), for launches proven in range
  // (CommandExecutor checks every such p against the launch first). FailedPrecondition for CPU
  // modules and modules without bounds checks.
  virtual Expected<std::shared_ptr<const LoadedModule>> WithTrustedTidIndices(const std::string& module_id,
                                                                             bool backward) {
    (void)module_id, (void)backward;
    return Unimplemented("this module store has no trusted-index variants");
  }
  virtual ModuleStoreStats stats() const = 0;
  // Compiles the module with NVRTC for sm_<arch> (a kCudaArchs entry NVRTC supports, else
  // InvalidArgument listing them) and reports each entry point; cached like other modules
  // (memory and disk), never loaded on a device and never given a module id.
  virtual Expected<CudaArchCompile> CompileForArch(const ModuleSource& source, int arch, CompileReport* report) {
    (void)source, (void)arch, (void)report;
    return Unimplemented("this module store cannot compile CUDA");
  }
  // CUDA C++ that is not a weft module (the CUDA device's built-in copy/fill kernels) compiled
  // for sm_XX with the native headers on the include path: a CUBIN, or PTX when NVRTC does not
  // know the architecture.
  virtual Expected<std::string> CompileCudaSource(const std::string& source, const std::string& name, int sm) {
    (void)source, (void)name, (void)sm;
    return Unimplemented("this module store cannot compile CUDA");
  }
};

}  // namespace weft
