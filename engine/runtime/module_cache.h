// Content-addressed module cache: the key of a module (SHA-256 over a canonical serialization of
// everything that decides its code), the artifact stored per key, the disk cache (one verified
// file per key, written atomically) and the in-memory LRU of loaded modules with coalescing of
// concurrent builds of one key.
// Expects: callers build artifacts deterministically from the key's inputs.
// Guarantees: a corrupted or truncated file is detected (hash mismatch), removed and rebuilt,
// never loaded; one build per key at a time; thread safe.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "engine/codegen/generate_module.h"
#include "engine/core/module_source.h"
#include "engine/core/status.h"
#include "engine/runtime/module_store.h"

namespace weft {

// Everything besides the source that decides a module's code.
struct ModuleKeyContext {
  std::string native_version;  // NativeLibraryVersion() of the headers compiled in
  std::string target_id;       // CPU: CpuJit::target_id(); CUDA: "sm_90" etc.
  std::string build_id;        // the compiler itself (weft version + binary identity)
  bool verified_for_cuda = false;
};

// Deterministic text of a module: functions and structs in order (their order is meaningful),
// symbols sorted, options sorted; every string length-prefixed so no two inputs collide.
std::string CanonicalModuleText(const ModuleSource& source);
// SHA-256 hex of the canonical text + codegen options + context.
std::string ModuleCacheKey(const ModuleSource& source, const CodegenOptions& codegen,
                           const ModuleKeyContext& context);

// SHA-256 hex over every regular file under `native_dir` (relative path + contents, sorted).
Expected<std::string> NativeLibraryVersion(const std::string& native_dir);

// What the disk cache keeps for one key.
struct ModuleArtifact {
  std::string object;                       // CPU: relocatable ELF object; CUDA: CUBIN
  std::vector<KernelLayout> kernels;
  std::vector<std::string> function_names;
  std::string generated_source;             // for debugging (also written as <key>.cpp)
};

std::string SerializeArtifact(const ModuleArtifact& artifact);
Expected<ModuleArtifact> DeserializeArtifact(std::string_view payload);

// One file per key under a directory: header (magic, format version, payload size, SHA-256 of
// the payload) + payload. Disabled (every Load is NotFound, Store a no-op) when dir is empty.
// Bounded: after a Store, while the files of the directory (<key>.wmod + <key>.cpp) exceed
// `capacity_bytes` (0 = no bound), the least recently used keys are removed (use = the .wmod's
// mtime, set by Store and by every successful Load), never the key just stored.
class DiskModuleCache {
 public:
  static constexpr uint32_t kFormatVersion = 7;

  explicit DiskModuleCache(std::string dir, uint64_t capacity_bytes = 0)
      : dir_(std::move(dir)), capacity_bytes_(capacity_bytes) {}
  // Creates the directory.
  Status Init() const;
  bool enabled() const { return !dir_.empty(); }

  // NotFound when there is no file; DataLoss when it is corrupt or truncated (the file is then
  // removed so the next Store replaces it).
  Expected<ModuleArtifact> Load(const std::string& key) const;
  // Writes a temporary file and renames it into place (readers never see half a file).
  Status Store(const std::string& key, const ModuleArtifact& artifact) const;
  std::string PathFor(const std::string& key) const;
  // Removes least recently used keys (never `keep`) until the directory fits the bound;
  // returns how many keys were removed.
  size_t EvictToCapacity(const std::string& keep) const;

 private:
  std::string dir_;
  uint64_t capacity_bytes_ = 0;
};

// Memory LRU of loaded modules + disk cache + one build per key.
class ModuleCache {
 public:
  using Module = std::shared_ptr<const LoadedModule>;
  enum class Source { kMemory, kDisk, kBuilt };

  // How to turn an artifact into loaded code, and how to build an artifact. `build` may fill
  // diagnostics (user errors); they reach every caller waiting on that build.
  struct Callbacks {
    std::function<Expected<Module>(const ModuleArtifact&)> load;
    std::function<Expected<ModuleArtifact>(std::vector<Diagnostic>*)> build;
  };

  ModuleCache(std::string dir, size_t memory_capacity, uint64_t disk_capacity_bytes = 0);
  Status Init() const { return disk_.Init(); }

  // The module of `key`: from memory, else from disk, else built (and stored). Concurrent
  // calls for one key wait for the first one's result. `source` and `diagnostics` may be null.
  Expected<Module> Get(const std::string& key, const Callbacks& callbacks, Source* source,
                       std::vector<Diagnostic>* diagnostics);
  // Only from memory (no load, no build); nullptr if absent.
  Module Peek(const std::string& key);

  ModuleStoreStats stats() const;
  const DiskModuleCache& disk() const { return disk_; }

 private:
  struct InFlight {
    bool done = false;
    Status status;
    Module module;
    std::vector<Diagnostic> diagnostics;
  };

  Expected<Module> LoadOrBuild(const std::string& key, const Callbacks& callbacks, Source* source,
                               std::vector<Diagnostic>* diagnostics);
  void InsertLocked(const std::string& key, Module module);

  DiskModuleCache disk_;
  size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable build_done_;
  std::list<std::pair<std::string, Module>> lru_;  // front = most recent
  std::unordered_map<std::string, std::list<std::pair<std::string, Module>>::iterator> index_;
  std::unordered_map<std::string, std::shared_ptr<InFlight>> in_flight_;
  ModuleStoreStats stats_;
};

}  // namespace weft
