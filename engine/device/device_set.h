// The devices of a daemon: the CPU and every GPU whose CUDA device could be created (a GPU the
// driver lists but that cannot compute is left out and logged). Resolves device names for a
// session: "cpu", "cuda:N", and "cuda", which places the session on the least loaded GPU (device
// memory held, then sessions placed) the first time it is used; the choice is kept per session.
#pragma once

#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "engine/device/cpu_device.h"
#include "engine/device/cuda_device.h"

namespace weft {

class DeviceSet {
 public:
  DeviceSet(std::unique_ptr<CpuDevice> cpu, std::vector<std::unique_ptr<CudaDevice>> gpus);

  CpuDevice& cpu() { return *cpu_; }
  const CpuDevice& cpu() const { return *cpu_; }
  const std::vector<std::unique_ptr<CudaDevice>>& gpus() const { return gpus_; }
  // Every device, CPU first.
  std::vector<Device*> all() const;
  // The device named exactly `name` ("cpu", "cuda:N"), or null.
  Device* Find(const std::string& name) const;
  // `name` for a session: "" and "cpu" -> the CPU; "cuda" -> the session's GPU (placed on first
  // use); "cuda:N". InvalidArgument for anything else or a GPU that does not compute here.
  Expected<Device*> Resolve(const std::string& session_id, const std::string& name);
  // The GPU "cuda" means for the session ("" when not placed yet).
  std::string Placement(const std::string& session_id) const;
  void Forget(const std::string& session_id);

 private:
  std::unique_ptr<CpuDevice> cpu_;
  std::vector<std::unique_ptr<CudaDevice>> gpus_;
  mutable std::mutex mu_;
  std::map<std::string, CudaDevice*> placement_;   // session id -> its "cuda"
};

}  // namespace weft
