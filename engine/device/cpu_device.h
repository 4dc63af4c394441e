// The CPU device: arrays in shared-memory slabs (ShmSlabPool), work run synchronously on the
// session's executor thread, launches on the thread pool under the launch watchdog (session
// cancel + per-launch time limit).
#pragma once

#include <memory>
#include <string>

#include "engine/device/device.h"
#include "engine/runtime/launch_watchdog.h"
#include "engine/runtime/thread_pool.h"

namespace weft {

struct CpuDeviceOptions {
  ShmSlabPoolOptions slabs;
  uint64_t print_capacity = 1 << 20;   // per launch
  double launch_time_limit_s = 0;      // 0 = none
};

class CpuDevice final : public Device {
 public:
  CpuDevice(ThreadPool& pool, LaunchWatchdog* watchdog, CpuDeviceOptions options);
  const std::string& name() const override { return name_; }
  bool is_cpu() const override { return true; }

  uint64_t ReservedSize(uint64_t bytes) const override { return slabs_.ReservedSize(bytes); }
  Expected<MemoryBlock> Allocate(uint64_t bytes, const std::string& owner, bool dedicated) override {
    return slabs_.Allocate(bytes, owner, dedicated);
  }
  void Free(const MemoryBlock& block) override { slabs_.Free(block); }
  uint64_t SlabBytes() const override { return slabs_.stats().slab_bytes; }
  uint32_t SlabCount() const override { return slabs_.stats().slabs; }

  Status Upload(Session& s, const MemoryBlock& dst, uint64_t offset, const void* src, uint64_t n) override;
  Status Download(Session& s, const MemoryBlock& src, uint64_t offset, void* dst, uint64_t n) override;
  Status CopyBlock(Session& s, const MemoryBlock& dst, const MemoryBlock& src, uint64_t n) override;
  Status Fill(Session& s, const ArrayView& dst, const std::string& value) override;
  Status Copy(Session& s, const ArrayView& dst, const ArrayView& src) override;
  Status Launch(Session& s, const KernelLaunch& launch, std::string* output) override;
  DeviceSyncResult Synchronize(Session&) override { return {}; }
  void CloseSession(Session&) override {}

 private:
  std::string name_ = "cpu";
  ThreadPool& pool_;
  LaunchWatchdog* watchdog_;
  CpuDeviceOptions options_;
  ShmSlabPool slabs_;
};

}  // namespace weft
