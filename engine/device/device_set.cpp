// DeviceSet: lookup and session placement on the least loaded GPU.
#include "engine/device/device_set.h"

namespace weft {

DeviceSet::DeviceSet(std::unique_ptr<CpuDevice> cpu, std::vector<std::unique_ptr<CudaDevice>> gpus)
    : cpu_(std::move(cpu)), gpus_(std::move(gpus)) {
  std::vector<CudaDevice*> peers;
  for (auto& g : gpus_) peers.push_back(g.get());
  for (auto& g : gpus_) g->SetPeers(peers);
}

std::vector<Device*> DeviceSet::all() const {
  std::vector<Device*> out{cpu_.get()};
  for (auto& g : gpus_) out.push_back(g.get());
  return out;
}

Device* DeviceSet::Find(const std::string& name) const {
  if (name == "cpu") return cpu_.get();
  for (auto& g : gpus_)
    if (g->name() == name) return g.get();
  return nullptr;
}

Expected<Device*> DeviceSet::Resolve(const std::string& session_id, const std::string& name) {
  if (name.empty() || name == "cpu") return static_cast<Device*>(cpu_.get());
  if (name == "cuda") {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = placement_.find(session_id);
    if (it != placement_.end()) return static_cast<Device*>(it->second);
    if (gpus_.empty()) return InvalidArgument("device 'cuda': this daemon has no GPU it can compute on");
    // Least loaded: device memory held, then sessions already placed there.
    CudaDevice* best = nullptr;
    uint64_t best_bytes = 0;
    size_t best_sessions = 0;
    for (auto& g : gpus_) {
      if (g->lost()) continue;
      size_t placed = 0;
      for (auto& [id, d] : placement_) placed += d == g.get() ? 1 : 0;
      const uint64_t bytes = g->SlabBytes();
      if (!best || bytes < best_bytes || (bytes == best_bytes && placed < best_sessions)) {
        best = g.get();
        best_bytes = bytes;
        best_sessions = placed;
      }
    }
    if (!best) return static_cast<Device*>(gpus_.front().get());   // every GPU lost: its error says so
    placement_[session_id] = best;
    return static_cast<Device*>(best);
  }
  if (Device* d = Find(name)) return d;
  if (name.rfind("cuda:", 0) == 0)
    return InvalidArgument("device '" + name + "': no such GPU in this daemon (" + std::to_string(gpus_.size()) +
                           " usable)");
  return InvalidArgument("unknown device '" + name + "' (expected \"cpu\", \"cuda\" or \"cuda:N\")");
}

std::string DeviceSet::Placement(const std::string& session_id) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = placement_.find(session_id);
  return it == placement_.end() ? std::string() : it->second->name();
}

void DeviceSet::Forget(const std::string& session_id) {
  std::lock_guard<std::mutex> lock(mu_);
  placement_.erase(session_id);
}

}  // namespace weft
