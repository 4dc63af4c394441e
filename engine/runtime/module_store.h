// Compiled modules: ModuleSource -> (content hash) -> cache (memory LRU + disk) -> loaded code.
// Owns: module ids, coalescing of concurrent compiles of one key, lazy backward variants.
// Uses: GenerateModule (codegen), CpuJit (jit/cpu), ModuleCache (disk/memory artifacts).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

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

struct ModuleStoreOptions {
  std::string cache_dir;          // disk cache; empty = memory only
  std::string native_dir;         // engine/native headers for the JIT
  size_t memory_capacity = 256;   // modules kept loaded (LRU)
  bool verify_cuda = false;       // also compile every generated module with NVRTC (sm_90)
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
  virtual ModuleStoreStats stats() const = 0;
};

}  // namespace weft
