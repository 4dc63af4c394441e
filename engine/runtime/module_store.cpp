// ModuleStore implementation: ModuleSource -> cache key -> memory / disk / compile -> loaded code.
// Skeleton: Create works so the daemon links; Compile reports Unimplemented until the JIT lands.
#include "engine/runtime/module_store.h"

#include <mutex>

namespace weft {
namespace {

class ModuleStoreImpl final : public ModuleStore {
 public:
  explicit ModuleStoreImpl(ModuleStoreOptions options) : options_(std::move(options)) {}

  Expected<std::shared_ptr<const LoadedModule>> Compile(const ModuleSource& source,
                                                        const std::string& device,
                                                        CompileReport* report) override {
    return Unimplemented("module compilation is not implemented yet");
  }
  std::shared_ptr<const LoadedModule> Find(const std::string& module_id) const override {
    return nullptr;
  }
  Expected<std::shared_ptr<const LoadedModule>> WithBackward(const std::string& module_id) override {
    return NotFound("unknown module id: " + module_id);
  }
  ModuleStoreStats stats() const override {
    std::lock_guard<std::mutex> lock(mutex_);
    return stats_;
  }

 private:
  ModuleStoreOptions options_;
  mutable std::mutex mutex_;
  ModuleStoreStats stats_;
};

}  // namespace

Expected<std::unique_ptr<ModuleStore>> ModuleStore::Create(const ModuleStoreOptions& options) {
  return std::unique_ptr<ModuleStore>(std::make_unique<ModuleStoreImpl>(options));
}

}  // namespace weft
