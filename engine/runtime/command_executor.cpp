// Command execution: copy, fill, launch, tape, gradient replacement.
#include "engine/runtime/command_executor.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <spdlog/spdlog.h>

#include "engine/device/cuda_device.h"
#include "engine/runtime/array_validation.h"
#include "engine/runtime/array_view.h"
#include "engine/runtime/cpu_launch.h"
#include "engine/runtime/launch_args.h"
#include "engine/runtime/session.h"

namespace weft {

namespace {

Expected<std::shared_ptr<Allocation>> Lookup(const HandleSnapshot& h, uint64_t handle, const ArrayName& what) {
  if (handle == 0) return InvalidArgument(what.Text() + ": array handle 0 (None)");
  auto it = h.find(handle);
  if (it == h.end() || !it->second)
    return NotFound(what.Text() + ": unknown array handle " + std::to_string(handle) +
                    " (never created, already freed, or not held by this session)");
  return it->second;
}

// A checked view of an array a copy, fill or backward seed names (ValidateArray on the array's
// own device: copies move between devices; element types are compared by the operation itself).
Expected<ArrayView> ViewOf(const HandleSnapshot& h, const ArrayRef& ref, const std::string& what) {
  WEFT_ASSIGN_OR_RETURN(auto a, Lookup(h, ref.handle, what));
  ArrayRequirement req;
  req.what = what;
  req.device = a->device;
  return ValidateArray(std::move(a), ref, req);
}

// A checked view of an allocation the daemon picked itself (a gradient, the loss).
Expected<ArrayView> ViewOfAllocation(std::shared_ptr<Allocation> a, const ArrayRef& ref, const std::string& what) {
  ArrayRequirement req;
  req.what = what;
  req.device = a->device;
  return ValidateArray(std::move(a), ref, req);
}

void CollectArg(const ArgValue& a, std::vector<uint64_t>* out) {
  if (a.kind == ArgValue::Kind::kArray && a.array.handle) out->push_back(a.array.handle);
  for (const auto& f : a.fields) CollectArg(f, out);
}

// Where an argument sits ("kernel 'k' argument 2 field 1"), as text only for an error message.
struct ArgPath {
  const std::string* kernel;
  size_t index;
  const ArgPath* parent = nullptr;   // set for a struct field: `index` is the field's
  std::string Text() const {
    return parent ? parent->Text() + " field " + std::to_string(index)
                  : "kernel '" + *kernel + "' argument " + std::to_string(index);
  }
};

// `a` (the launch command's) outlives the result: it points at `a.array` rather than copying it.
Expected<ResolvedArg> ResolveArg(const ArgValue& a, const HandleSnapshot& h, const ArgPath& path) {
  ResolvedArg r;
  r.kind = a.kind;
  r.raw = a.raw;
  r.ref = &a.array;
  if (a.kind == ArgValue::Kind::kArray && a.array.handle != 0) {
    ArrayName what([](const void* p) { return static_cast<const ArgPath*>(p)->Text(); }, &path);
    WEFT_ASSIGN_OR_RETURN(r.alloc, Lookup(h, a.array.handle, what));
  }
  r.fields.reserve(a.fields.size());
  for (size_t i = 0; i < a.fields.size(); ++i) {
    WEFT_ASSIGN_OR_RETURN(ResolvedArg f, ResolveArg(a.fields[i], h, ArgPath{path.kernel, i, &path}));
    r.fields.push_back(std::move(f));
  }
  return r;
}

Expected<std::vector<ResolvedArg>> ResolveArgs(const std::vector<ArgValue>& args, const HandleSnapshot& h,
                                               const std::string& kernel) {
  std::vector<ResolvedArg> out;
  out.reserve(args.size());
  for (size_t i = 0; i < args.size(); ++i) {
    WEFT_ASSIGN_OR_RETURN(ResolvedArg r, ResolveArg(args[i], h, ArgPath{&kernel, i}));
    out.push_back(std::move(r));
  }
  return out;
}

// One element of value 1 in the allocation's scalar type, repeated over vector/matrix components.
Expected<std::string> OneElement(const DType& d) {
  std::string comp;
  switch (d.scalar) {
    case ScalarType::kFloat32: { float v = 1.0f; comp.assign(reinterpret_cast<char*>(&v), 4); break; }
    case ScalarType::kFloat64: { double v = 1.0; comp.assign(reinterpret_cast<char*>(&v), 8); break; }
    case ScalarType::kFloat16: { uint16_t v = 0x3C00; comp.assign(reinterpret_cast<char*>(&v), 2); break; }
    default: return InvalidArgument("backward: the loss must be a float array, got " + d.Name());
  }
  if (d.is_struct()) return InvalidArgument("backward: the loss must be a float array, got " + d.Name());
  std::string out;
  uint64_t n = d.ElementSize() / comp.size();
  for (uint64_t i = 0; i < n; ++i) out += comp;
  return out;
}

}  // namespace

Expected<Device*> CommandExecutor::DeviceOf(const Allocation& a) const {
  Device* d = devices_.Find(a.device);
  if (!d) return Internal("array " + std::to_string(a.handle) + " lives on unknown device '" + a.device + "'");
  return d;
}

Status CommandExecutor::UseGridStrideWhereNeeded(const Device& device, const std::string& module_id,
                                                 const std::string& kernel_name, bool adjoint, const KernelLaunch& launch,
                                                 std::shared_ptr<const LoadedModule>* module,
                                                 const LoadedKernel** kernel) {
  if (device.is_cpu() || (*kernel)->layout.grid_stride) return Status::Ok();
  if (!NeedsGridStride(launch)) return UseTrustedIndicesWhereProven(module_id, kernel_name, adjoint, launch, module, kernel);
  auto strided = store_->WithGridStride(module_id, adjoint);
  if (!strided.ok()) {
    // Built lean on purpose: the device's launch says why the launch is refused.
    if (strided.status().code() == StatusCode::kFailedPrecondition) return Status::Ok();
    return strided.status();
  }
  const LoadedKernel* k = (*strided)->Find(kernel_name);
  if (!k) return Internal("the grid-stride variant of module '" + module_id + "' has no kernel '" + kernel_name + "'");
  *module = *strided;
  *kernel = k;
  return Status::Ok();
}

namespace {

// WEFT_TRUSTED_INDICES=0 keeps every launch on the checked entries (for A/B measurements).
bool TrustedIndicesEnabled() {
  static const bool enabled = [] {
    const char* v = std::getenv("WEFT_TRUSTED_INDICES");
    return v == nullptr || std::strcmp(v, "0") != 0;
  }();
  return enabled;
}

}  // namespace

Status CommandExecutor::UseTrustedIndicesWhereProven(const std::string& module_id, const std::string& kernel_name,
                                                     bool adjoint, const KernelLaunch& launch,
                                                     std::shared_ptr<const LoadedModule>* module,
                                                     const LoadedKernel** kernel) {
  const KernelLayout& layout = (*kernel)->layout;
  if (!TrustedIndicesEnabled() || (*module)->trusts_tid_indices || layout.tid_indexed_params.empty() || !launch.args ||
      !TidIndicesInRange(layout, *launch.args, launch.dim))
    return Status::Ok();
  auto trusted = store_->WithTrustedTidIndices(module_id, adjoint);
  if (!trusted.ok()) {   // the checked entries serve the launch as well
    spdlog::warn("module {}: no trusted-index variant ({}); the launch keeps its checks", module_id,
                 trusted.status().message());
    return Status::Ok();
  }
  const LoadedKernel* k = (*trusted)->Find(kernel_name);
  if (!k || k->layout.params.size() != layout.params.size() || k->layout.args_size != layout.args_size)
    return Internal("the trusted-index variant of module '" + module_id + "' does not match kernel '" + kernel_name + "'");
  *module = *trusted;
  *kernel = k;
  return Status::Ok();
}

Status CommandExecutor::ZeroGradients(Session& s, Tape& tape) {
  for (auto& w : tape.touched) {
    auto a = w.lock();
    if (!a || !a->grad) continue;
    std::shared_ptr<Allocation> g = a->grad;
    WEFT_ASSIGN_OR_RETURN(ArrayView v, ViewOfAllocation(g, ArrayRef{}, "tape gradient"));
    WEFT_ASSIGN_OR_RETURN(Device * d, DeviceOf(*g));
    WEFT_RETURN_IF_ERROR(d->Fill(s, v, std::string(g->dtype.ElementSize(), '\0')));
  }
  return Status::Ok();
}

void CollectHandles(const Command& c, std::vector<uint64_t>* out) {
  if (auto* cp = std::get_if<CopyCommand>(&c.kind)) {
    out->push_back(cp->dst.handle);
    out->push_back(cp->src.handle);
  } else if (auto* f = std::get_if<FillCommand>(&c.kind)) {
    out->push_back(f->dst.handle);
  } else if (auto* l = std::get_if<LaunchCommand>(&c.kind)) {
    for (const auto& a : l->args) CollectArg(a, out);
    for (const auto& a : l->adj_args) CollectArg(a, out);
  } else if (auto* t = std::get_if<TapeCommand>(&c.kind)) {
    if (t->loss.handle) out->push_back(t->loss.handle);
    for (const auto& [a, g] : t->seeds) {
      out->push_back(a.handle);
      out->push_back(g.handle);
    }
  } else if (auto* sg = std::get_if<SetGradCommand>(&c.kind)) {
    out->push_back(sg->array.handle);
    if (sg->grad.handle) out->push_back(sg->grad.handle);
  } else if (auto* v = std::get_if<CudaValueCommand>(&c.kind)) {
    out->push_back(v->order.handle);
  } else if (auto* g = std::get_if<GraphCommand>(&c.kind)) {
    for (const Command& inner : g->commands) CollectHandles(inner, out);
  } else if (auto* geo = std::get_if<GeometryCommand>(&c.kind)) {
    if (geo->request.points) out->push_back(geo->request.points);
    if (geo->request.groups) out->push_back(geo->request.groups);
  }
}

bool RunsAfterFailure(const Command& c) {
  if (auto* v = std::get_if<CudaValueCommand>(&c.kind)) return v->op == CudaValueCommand::Op::kWrite;
  if (auto* t = std::get_if<TapeCommand>(&c.kind))
    return t->op == TapeCommand::Op::kEnd || t->op == TapeCommand::Op::kFree;
  if (auto* g = std::get_if<GraphCommand>(&c.kind)) return g->op == GraphCommand::Op::kDestroy;
  if (auto* tc = std::get_if<TimingCommand>(&c.kind)) return tc->op == TimingCommand::Op::kEnd;
  if (auto* te = std::get_if<TimedEventCommand>(&c.kind)) return te->op == TimedEventCommand::Op::kDestroy;
  if (auto* geo = std::get_if<GeometryCommand>(&c.kind)) return geo->request.op == geometry::GeometryRequest::Op::kFree;
  return false;
}

Status CommandExecutor::Execute(Session& s, const Command& c, const HandleSnapshot& h) {
  if (auto* cp = std::get_if<CopyCommand>(&c.kind)) return Copy(s, *cp, h);
  if (auto* f = std::get_if<FillCommand>(&c.kind)) return Fill(s, *f, h);
  if (auto* l = std::get_if<LaunchCommand>(&c.kind)) return Launch(s, *l, h, c.origin);
  if (auto* t = std::get_if<TapeCommand>(&c.kind)) return TapeOp(s, *t, h);
  if (auto* sg = std::get_if<SetGradCommand>(&c.kind)) return SetGrad(s, *sg, h);
  if (auto* e = std::get_if<CudaEventCommand>(&c.kind)) return CudaEvent(s, *e);
  if (auto* v = std::get_if<CudaValueCommand>(&c.kind)) return CudaValue(s, *v, h);
  if (auto* g = std::get_if<GraphCommand>(&c.kind)) return Graph(s, *g, h);
  if (auto* tc = std::get_if<TimingCommand>(&c.kind)) return Timing(s, *tc);
  if (auto* te = std::get_if<TimedEventCommand>(&c.kind)) return TimedEvent(s, *te);
  if (auto* geo = std::get_if<GeometryCommand>(&c.kind)) {
    if (!geometry_) return Unimplemented("geometry commands are not served here");
    return geometry_(s, geo->request);
  }
  return InvalidArgument("empty command");
}

namespace {

std::string At(const SourceLocation& o) {
  return o.file.empty() ? std::string() : " (at " + o.file + ":" + std::to_string(o.line) + ")";
}

// Whether `c` can go into a CUDA graph of `device`: a launch there, a fill or copy of arrays
// that live there (host and peer copies stage through the daemon's memory: replayed instead).
bool CapturableOn(const Command& c, const std::string& device, const HandleSnapshot& arrays) {
  auto on_device = [&](const ArrayRef& r) {
    auto it = arrays.find(r.handle);
    return it != arrays.end() && it->second && it->second->device == device;
  };
  if (auto* l = std::get_if<LaunchCommand>(&c.kind)) return !l->record_only;
  if (auto* f = std::get_if<FillCommand>(&c.kind)) return on_device(f->dst);
  if (auto* cp = std::get_if<CopyCommand>(&c.kind)) return on_device(cp->dst) && on_device(cp->src);
  return false;
}

}  // namespace

Status CommandExecutor::Graph(Session& s, const GraphCommand& c, const HandleSnapshot& h) {
  const std::string which = "graph " + std::to_string(c.graph_id);
  if (c.op == GraphCommand::Op::kDestroy) {
    s.graphs.erase(c.graph_id);
    return Status::Ok();
  }
  if (c.op == GraphCommand::Op::kLaunch) {
    auto it = s.graphs.find(c.graph_id);
    if (it == s.graphs.end())
      return NotFound(which + ": unknown (never created, destroyed, or its creation failed)");
    const CommandGraph& g = it->second;
    s.in_graph = true;
    Status st = Status::Ok();
    if (g.device_graph) {
      WEFT_ASSIGN_OR_RETURN(Device * device, devices_.Resolve(s.id(), g.device));
      auto* gpu = dynamic_cast<CudaDevice*>(device);
      st = gpu ? gpu->LaunchGraph(s, *std::static_pointer_cast<CudaDevice::Graph>(g.device_graph))
               : Internal(which + ": a device graph on a device without graphs");
    } else {
      for (const Command& inner : g.commands) {
        st = Execute(s, inner, g.arrays);
        if (!st.ok()) {   // reported with the captured command's file:line
          s.in_graph = false;
          s.Fail(Status(st.code(), which + ": " + st.message()), inner.origin);
          return Status::Ok();
        }
      }
    }
    s.in_graph = false;
    return st;
  }
  if (c.op != GraphCommand::Op::kCreate) return InvalidArgument(which + ": unknown op");
  if (!s.graphs.count(c.graph_id) && s.graphs.size() >= kMaxGraphsPerSession)
    return ResourceExhausted("the session holds " + std::to_string(s.graphs.size()) + " graphs, the limit " +
                             "(destroy some: a wp.Graph is destroyed when it is collected)");
  WEFT_ASSIGN_OR_RETURN(Device * device, devices_.Resolve(s.id(), c.device));
  CommandGraph g;
  g.device = device->name();
  g.commands = c.commands;
  std::vector<uint64_t> handles;
  for (const Command& inner : c.commands) CollectHandles(inner, &handles);
  for (uint64_t handle : handles) {
    if (handle == 0 || g.arrays.count(handle)) continue;
    WEFT_ASSIGN_OR_RETURN(g.arrays[handle], Lookup(h, handle, which));
  }
  s.graphs.erase(c.graph_id);
  auto* gpu = dynamic_cast<CudaDevice*>(device);
  bool capturable = gpu != nullptr && gpu->GraphsSupported() && !c.commands.empty();
  for (const Command& inner : c.commands) {
    if (!capturable) break;
    capturable = CapturableOn(inner, g.device, g.arrays);
    if (auto* l = std::get_if<LaunchCommand>(&inner.kind)) {
      auto resolved = devices_.Resolve(s.id(), l->device);
      capturable = capturable && resolved.ok() && *resolved == device;
    }
  }
  if (capturable && gpu->BeginCapture(s).ok()) {
    s.in_graph = true;
    Status st = Status::Ok();
    for (const Command& inner : c.commands) {
      st = Execute(s, inner, g.arrays);
      if (!st.ok()) {
        st = Status(st.code(), which + ": " + st.message() + At(inner.origin));
        break;
      }
    }
    s.in_graph = false;
    auto captured = gpu->EndCapture(s, st.ok());
    const bool refused = !captured.ok() && captured.status().message().rfind("graph capture:", 0) == 0;
    if (captured.ok()) {
      g.device_graph = std::move(*captured);
    } else if (!st.ok() && !refused) {
      return st;   // the command itself is wrong: no graph
    } else {       // the device cannot capture these commands: replayed command by command
      spdlog::debug("session {}: {} replays command by command: {}", s.label(), which, captured.status().ToString());
    }
  }
  s.graphs.emplace(c.graph_id, std::move(g));
  return Status::Ok();
}

namespace {

// A ref that names its whole allocation: offset 0, the allocation's shape (or none),
// contiguous strides (or none).
Status CheckWhole(const Allocation& a, const ArrayRef& ref, const std::string& what) {
  if (ref.byte_offset != 0 || (!ref.shape.empty() && ref.shape != a.shape) ||
      (!ref.strides.empty() && ref.strides != a.strides))
    return InvalidArgument(what + ": must name the whole array " + std::to_string(a.handle) + " " +
                           ShapeString(a.shape) + " (offset 0, contiguous), not a view of it");
  return Status::Ok();
}

}  // namespace

Status CommandExecutor::CudaValue(Session& s, const CudaValueCommand& c, const HandleSnapshot& h) {
  if (c.op != CudaValueCommand::Op::kWait && c.op != CudaValueCommand::Op::kWrite)
    return InvalidArgument("cuda_value: unknown op " + std::to_string(static_cast<int>(c.op)));
  WEFT_ASSIGN_OR_RETURN(auto a, Lookup(h, c.order.handle, "cuda_value order array"));
  WEFT_RETURN_IF_ERROR(CheckWhole(*a, c.order, "cuda_value order array"));
  if (a->dtype.ElementSize() != sizeof(uint64_t) || a->shape.size() != 1)
    return InvalidArgument("cuda_value: the order array must be 1-D with 8-byte elements (uint64), got " +
                           a->dtype.Name() + " " + ShapeString(a->shape));
  if (a->imported)
    return InvalidArgument("cuda_value: the order array must be memory weftd allocated, not imported memory");
  if (c.index >= a->element_count())
    return OutOfRange("cuda_value: index " + std::to_string(c.index) + " is out of range for the order array of " +
                      std::to_string(a->element_count()) + " elements");
  WEFT_ASSIGN_OR_RETURN(Device * device, DeviceOf(*a));
  auto* gpu = dynamic_cast<CudaDevice*>(device);
  if (gpu == nullptr)
    return InvalidArgument("cuda_value: the order array lives on '" + a->device +
                           "', not a GPU (stream memory operations order GPU work)");
  return gpu->StreamValue(s, a->block, c.index * sizeof(uint64_t), c.value, c.op == CudaValueCommand::Op::kWrite, a);
}

Status CommandExecutor::CudaEvent(Session& s, const CudaEventCommand& c) {
  if (c.op != CudaEventCommand::Op::kWait && c.op != CudaEventCommand::Op::kRecord &&
      c.op != CudaEventCommand::Op::kShare)
    return InvalidArgument("cuda_event: unknown op " + std::to_string(static_cast<int>(c.op)));
  // An IPC event handle names an event of a process on this machine: a remote session has none
  // of its own, and must not reach local processes' events by guessing handles.
  if (!s.options().local)
    return PermissionDenied("cuda_event: CUDA IPC events are for local sessions (Unix socket); this session "
                            "is remote");
  WEFT_ASSIGN_OR_RETURN(Device * device, devices_.Resolve(s.id(), c.device));
  auto* gpu = dynamic_cast<CudaDevice*>(device);
  if (gpu == nullptr) return InvalidArgument("cuda_event: '" + c.device + "' is not a GPU (CUDA events order GPU work)");
  const CudaDevice::EventUse use = c.op == CudaEventCommand::Op::kRecord  ? CudaDevice::EventUse::kRecord
                                   : c.op == CudaEventCommand::Op::kShare ? CudaDevice::EventUse::kShare
                                                                          : CudaDevice::EventUse::kWait;
  return gpu->IpcEvent(s, c.handle, use);
}

Status CommandExecutor::Timing(Session& s, const TimingCommand& c) {
  if (c.op != TimingCommand::Op::kBegin && c.op != TimingCommand::Op::kEnd)
    return InvalidArgument("timing: unknown op " + std::to_string(static_cast<int>(c.op)));
  const uint32_t filter = c.op == TimingCommand::Op::kBegin ? c.filter : 0;
  Status result = Status::Ok();
  for (auto& gpu : devices_.gpus()) {   // Warp times every GPU's activity
    Status st = gpu->SetTiming(s, filter);
    if (result.ok() && !st.ok()) result = st;
  }
  if (c.op == TimingCommand::Op::kEnd) s.timing_collect.store(true);
  return result;
}

Status CommandExecutor::TimedEvent(Session& s, const TimedEventCommand& c) {
  if (c.op != TimedEventCommand::Op::kRecord && c.op != TimedEventCommand::Op::kDestroy)
    return InvalidArgument("timed_event: unknown op " + std::to_string(static_cast<int>(c.op)));
  WEFT_ASSIGN_OR_RETURN(Device * device, devices_.Resolve(s.id(), c.device));
  auto* gpu = dynamic_cast<CudaDevice*>(device);
  if (gpu == nullptr)
    return InvalidArgument("timed_event: '" + c.device + "' is not a GPU (events time GPU work)");
  if (c.op == TimedEventCommand::Op::kDestroy) {
    gpu->DestroyTimedEvent(s, c.event_id);
    return Status::Ok();
  }
  return gpu->RecordTimedEvent(s, c.event_id);
}

Status CommandExecutor::SetGrad(Session& s, const SetGradCommand& c, const HandleSnapshot& h) {
  WEFT_ASSIGN_OR_RETURN(auto a, Lookup(h, c.array.handle, "set_grad array"));
  WEFT_RETURN_IF_ERROR(CheckWhole(*a, c.array, "set_grad array"));
  std::shared_ptr<Allocation> g;
  if (c.grad.handle != 0) {
    WEFT_ASSIGN_OR_RETURN(g, Lookup(h, c.grad.handle, "set_grad gradient"));
    WEFT_RETURN_IF_ERROR(CheckWhole(*g, c.grad, "set_grad gradient"));
    if (g == a) return InvalidArgument("set_grad: an array cannot be its own gradient");
    if (g == a->grad) return Status::Ok();
    // The gradient may have a gradient of its own (Warp: `a.grad = wp.ones_like(a)` where `a`
    // requires grad); only its data is a's gradient. Refused when a is on g's gradient chain:
    // the arrays would own each other. Chains are acyclic, so the walk ends.
    for (const Allocation* x = g->grad.get(); x != nullptr; x = x->grad.get())
      if (x == a.get())
        return InvalidArgument("set_grad: array " + std::to_string(a->handle) + " is on the gradient chain of array " +
                               std::to_string(g->handle) + " (a gradient cycle)");
    if (g->device != a->device)
      return InvalidArgument("set_grad: the gradient lives on " + g->device + ", the array on " + a->device);
    if (g->dtype.ElementSize() != a->dtype.ElementSize() || g->dtype.Name() != a->dtype.Name() ||
        g->shape != a->shape)
      return InvalidArgument("set_grad: gradient " + g->dtype.Name() + " " + ShapeString(g->shape) +
                             " does not match the array's " + a->dtype.Name() + " " + ShapeString(a->shape));
  }
  s.ReplaceGrad(a, std::move(g));
  return Status::Ok();
}

Status CommandExecutor::Copy(Session& s, const CopyCommand& c, const HandleSnapshot& h) {
  WEFT_ASSIGN_OR_RETURN(ArrayView dst, ViewOf(h, c.dst, "copy dst"));
  WEFT_ASSIGN_OR_RETURN(ArrayView src, ViewOf(h, c.src, "copy src"));
  // A GPU side does the copy (the destination's GPU first); CPU to CPU stays on the CPU.
  WEFT_ASSIGN_OR_RETURN(Device * d, DeviceOf(*dst.alloc));
  if (d->is_cpu()) {
    WEFT_ASSIGN_OR_RETURN(d, DeviceOf(*src.alloc));
  }
  return d->Copy(s, dst, src);
}

Status CommandExecutor::Fill(Session& s, const FillCommand& c, const HandleSnapshot& h) {
  WEFT_ASSIGN_OR_RETURN(ArrayView dst, ViewOf(h, c.dst, "fill dst"));
  WEFT_ASSIGN_OR_RETURN(Device * d, DeviceOf(*dst.alloc));
  return d->Fill(s, dst, c.value);
}

Status CommandExecutor::Launch(Session& s, const LaunchCommand& c, const HandleSnapshot& h,
                               const SourceLocation& origin) {
  WEFT_ASSIGN_OR_RETURN(Device * device, devices_.Resolve(s.id(), c.device));
  if (!store_) return FailedPrecondition("this daemon has no module store");
  WEFT_RETURN_IF_ERROR(CheckLaunchDim(c.dim));
  std::shared_ptr<const LoadedModule> module = store_->Find(c.module_id);
  if (!module) return NotFound("unknown module '" + c.module_id + "' (compile it first with ModuleService.Compile)");
  if ((module->target == Target::kCpu) != device->is_cpu())
    return InvalidArgument("module '" + c.module_id + "' was compiled for " +
                           (module->target == Target::kCpu ? std::string("the CPU") : std::string("CUDA")) +
                           "; the launch runs on " + device->name() + " (compile it for that device)");
  const LoadedKernel* kernel = module->Find(c.kernel);
  if (!kernel) return NotFound("module '" + c.module_id + "' has no kernel '" + c.kernel + "'");
  if (c.record_only && c.adjoint)
    return InvalidArgument("launch of '" + c.kernel + "': record_only applies to forward launches, not adjoint ones");
  WEFT_ASSIGN_OR_RETURN(std::vector<ResolvedArg> args, ResolveArgs(c.args, h, c.kernel));
  WEFT_ASSIGN_OR_RETURN(PackedArgs packed, PackArgs(kernel->layout, args, device->name()));
  if (c.record_only) {
    if (s.active_tape != 0) RecordOnTape(s, c, device->name(), origin, std::move(packed));
    return Status::Ok();
  }

  KernelLaunch launch;
  launch.dim = c.dim;
  launch.args = &packed;
  launch.block_dim = c.block_dim;
  launch.max_blocks = c.max_blocks;
  launch.origin = origin;
  std::string output;
  Status st;
  PackedArgs adj_packed;
  if (!c.adjoint) {
    launch.module = module;
    launch.kernel = kernel;
    WEFT_RETURN_IF_ERROR(
        UseGridStrideWhereNeeded(*device, c.module_id, c.kernel, false, launch, &launch.module, &launch.kernel));
    st = device->Launch(s, launch, &output);
  } else {
    WEFT_ASSIGN_OR_RETURN(std::shared_ptr<const LoadedModule> bmod, store_->WithBackward(c.module_id));
    const LoadedKernel* bk = bmod->Find(c.kernel);
    if (!bk || (device->is_cpu() ? !bk->cpu_backward : bk->layout.backward_symbol.empty()))
      return Internal("module '" + c.module_id + "' has no backward for kernel '" + c.kernel + "'");
    WEFT_ASSIGN_OR_RETURN(std::vector<ResolvedArg> adj, ResolveArgs(c.adj_args, h, c.kernel + " (adjoint)"));
    WEFT_ASSIGN_OR_RETURN(adj_packed, PackAdjointArgs(bk->layout, packed, adj, device->name()));
    launch.module = bmod;
    launch.kernel = bk;
    launch.adj_args = &adj_packed;
    WEFT_RETURN_IF_ERROR(
        UseGridStrideWhereNeeded(*device, c.module_id, c.kernel, true, launch, &launch.module, &launch.kernel));
    st = device->Launch(s, launch, &output);
  }
  if (!output.empty()) s.AppendOutput(output);
  WEFT_RETURN_IF_ERROR(st);

  // Record forward launches on the active tape.
  if (!c.adjoint && s.active_tape != 0) RecordOnTape(s, c, device->name(), origin, std::move(packed));
  return Status::Ok();
}

void CommandExecutor::RecordOnTape(Session& s, const LaunchCommand& c, const std::string& device,
                                   const SourceLocation& origin, PackedArgs packed) {
  if (s.in_graph) return;   // launches of graphs are not recorded (as Warp's graph launches)
  Tape& tape = s.tapes[s.active_tape];
  TapeRecord r;
  r.module_id = c.module_id;
  r.kernel = c.kernel;
  r.dim = c.dim;
  r.origin = origin;
  r.device = device;
  r.block_dim = c.block_dim;
  r.max_blocks = c.max_blocks;
  for (auto& a : packed.keep_alive) tape.Touch(a);
  r.args = std::move(packed);
  r.args.keep_alive.clear();   // tapes do not keep arrays alive
  tape.records.push_back(std::move(r));
}

Status CommandExecutor::TapeOp(Session& s, const TapeCommand& c, const HandleSnapshot& h) {
  if (c.tape_id == 0) return InvalidArgument("tape id 0 is reserved");
  WEFT_RETURN_IF_ERROR(CheckTapeOp(c.op));
  switch (c.op) {
    case TapeCommand::Op::kBegin:
      if (s.active_tape != 0 && s.active_tape != c.tape_id)
        return FailedPrecondition("tape " + std::to_string(c.tape_id) + ": another tape (" +
                                  std::to_string(s.active_tape) + ") is already recording; nested tapes are not supported");
      s.tapes[c.tape_id];
      s.active_tape = c.tape_id;
      return Status::Ok();
    case TapeCommand::Op::kEnd:
      if (s.active_tape == c.tape_id) s.active_tape = 0;
      return Status::Ok();
    case TapeCommand::Op::kMark: {
      if (c.marker == 0) return InvalidArgument("tape " + std::to_string(c.tape_id) + ": marker 0 is reserved");
      TapeRecord r;
      r.marker = c.marker;
      s.tapes[c.tape_id].records.push_back(std::move(r));
      return Status::Ok();
    }
    case TapeCommand::Op::kFree:
      if (s.active_tape == c.tape_id) s.active_tape = 0;
      s.tapes.erase(c.tape_id);
      return Status::Ok();
    default:
      break;
  }
  auto it = s.tapes.find(c.tape_id);
  if (it == s.tapes.end()) {
    if (c.op == TapeCommand::Op::kBackward)
      return FailedPrecondition("backward on tape " + std::to_string(c.tape_id) + " which recorded nothing");
    return Status::Ok();   // zero/reset of a tape that never recorded: nothing to do
  }
  Tape& tape = it->second;
  switch (c.op) {
    case TapeCommand::Op::kZero:
      return ZeroGradients(s, tape);
    case TapeCommand::Op::kReset:
      WEFT_RETURN_IF_ERROR(ZeroGradients(s, tape));
      tape.records.clear();
      tape.touched.clear();
      return Status::Ok();
    case TapeCommand::Op::kBackward:
      return Backward(s, tape, c, h);
    default:
      return InvalidArgument("unknown tape op " + std::to_string(static_cast<int>(c.op)));
  }
}

Status CommandExecutor::Backward(Session& s, Tape& tape, const TapeCommand& c, const HandleSnapshot& h) {
  if (tape.records.empty())
    return FailedPrecondition("backward on tape " + std::to_string(c.tape_id) + " which recorded no launches");
  if (s.active_tape == c.tape_id)
    return FailedPrecondition("backward on tape " + std::to_string(c.tape_id) + " while it is still recording (leave the `with` block first)");
  if (!store_) return FailedPrecondition("this daemon has no module store");

  // Check everything first, so a failure changes nothing.
  struct Step {
    const TapeRecord* record;
    std::shared_ptr<const LoadedModule> module;
    const LoadedKernel* kernel;
    std::vector<std::shared_ptr<Allocation>> live;
    Device* device = nullptr;
  };
  size_t start = tape.records.size();
  if (c.marker != 0) {
    start = 0;
    while (start < tape.records.size() && tape.records[start].marker != c.marker) ++start;
    if (start == tape.records.size())
      return FailedPrecondition("backward on tape " + std::to_string(c.tape_id) + ": no marker " +
                                std::to_string(c.marker) + " (reset since it was recorded?)");
  }
  std::vector<Step> steps;
  for (size_t i = start; i-- > 0;) {
    const TapeRecord& r = tape.records[i];
    if (r.marker != 0) break;   // a client callback runs here; the next BACKWARD goes on
    Step st{&r, nullptr, nullptr, {}, nullptr};
    for (const PackedArray& slot : r.args.arrays) {
      std::shared_ptr<Allocation> a = slot.alloc.lock();
      if (slot.handle != 0 && (!a || !s.Holds(slot.handle)))
        return FailedPrecondition("tape " + std::to_string(c.tape_id) + " recorded kernel '" + r.kernel +
                                  "' with array '" + slot.param + "' (handle " + std::to_string(slot.handle) +
                                  ") which has since been freed; record the launches again");
      st.live.push_back(std::move(a));
    }
    WEFT_ASSIGN_OR_RETURN(st.module, store_->WithBackward(r.module_id));
    st.kernel = st.module->Find(r.kernel);
    WEFT_ASSIGN_OR_RETURN(st.device, devices_.Resolve(s.id(), r.device));
    if (!st.kernel || (st.device->is_cpu() ? !st.kernel->cpu_backward : st.kernel->layout.backward_symbol.empty()))
      return Internal("module '" + r.module_id + "' has no backward for kernel '" + r.kernel + "'");
    steps.push_back(std::move(st));
  }
  ArrayView loss_grad;
  std::string one;
  if (c.loss.handle != 0) {
    WEFT_ASSIGN_OR_RETURN(auto loss, Lookup(h, c.loss.handle, "backward loss"));
    if (!loss->grad)
      return FailedPrecondition("backward: the loss array " + std::to_string(loss->handle) +
                                " was not created with requires_grad=True");
    WEFT_ASSIGN_OR_RETURN(ArrayView lv, ViewOfAllocation(loss, c.loss, "backward loss"));
    WEFT_ASSIGN_OR_RETURN(one, OneElement(loss->dtype));
    ArrayRef gref = c.loss;
    gref.handle = loss->grad->handle;
    WEFT_ASSIGN_OR_RETURN(loss_grad, ViewOfAllocation(loss->grad, gref, "backward loss gradient"));
    tape.Touch(loss);
  }
  std::vector<std::pair<ArrayView, ArrayView>> seeds;
  for (const auto& [aref, gref] : c.seeds) {
    WEFT_ASSIGN_OR_RETURN(auto a, Lookup(h, aref.handle, "backward seed array"));
    if (!a->grad)
      return FailedPrecondition("backward: seed array " + std::to_string(a->handle) +
                                " was not created with requires_grad=True");
    ArrayRef target = aref;
    target.handle = a->grad->handle;
    WEFT_ASSIGN_OR_RETURN(ArrayView dst, ViewOfAllocation(a->grad, target, "backward seed target"));
    WEFT_ASSIGN_OR_RETURN(ArrayView src, ViewOf(h, gref, "backward seed gradient"));
    seeds.emplace_back(std::move(dst), std::move(src));
    tape.Touch(a);
  }
  // Validate every gradient block before running any adjoint, so a failure changes nothing.
  std::vector<PackedArgs> adjoints;
  for (Step& st : steps) {
    WEFT_ASSIGN_OR_RETURN(PackedArgs adj, GradientArgs(st.kernel->layout, st.record->args, st.live));
    adjoints.push_back(std::move(adj));
  }
  if (loss_grad.alloc) {
    WEFT_ASSIGN_OR_RETURN(Device * d, DeviceOf(*loss_grad.alloc));
    WEFT_RETURN_IF_ERROR(d->Fill(s, loss_grad, one));
  }
  for (auto& [dst, src] : seeds) {
    WEFT_ASSIGN_OR_RETURN(Device * d, DeviceOf(*dst.alloc));
    if (d->is_cpu()) {
      WEFT_ASSIGN_OR_RETURN(d, DeviceOf(*src.alloc));
    }
    WEFT_RETURN_IF_ERROR(d->Copy(s, dst, src));
  }

  for (size_t si = 0; si < steps.size(); ++si) {
    Step& st = steps[si];
    PackedArgs& adj = adjoints[si];
    KernelLaunch launch;
    launch.module = st.module;
    launch.kernel = st.kernel;
    launch.dim = st.record->dim;
    launch.args = &st.record->args;
    launch.adj_args = &adj;
    launch.block_dim = st.record->block_dim;
    launch.max_blocks = st.record->max_blocks;
    launch.origin = st.record->origin;
    WEFT_RETURN_IF_ERROR(UseGridStrideWhereNeeded(*st.device, st.record->module_id, st.record->kernel, true, launch,
                                                  &launch.module, &launch.kernel));
    std::string output;
    Status r = st.device->Launch(s, launch, &output);
    if (!output.empty()) s.AppendOutput(output);
    if (!r.ok()) {
      std::string where = st.record->origin.file.empty()
                              ? std::string()
                              : " (launched at " + st.record->origin.file + ":" + std::to_string(st.record->origin.line) + ")";
      return Status(r.code(), "backward: " + r.message() + where);
    }
  }
  return Status::Ok();
}

}  // namespace weft
