// Protobuf conversions.
#include "server/proto_convert.h"

namespace weft::server {

DType FromProto(const v1::DType& p) {
  DType d;
  d.scalar = static_cast<ScalarType>(p.scalar());
  d.elem_shape.assign(p.elem_shape().begin(), p.elem_shape().end());
  d.type_name = p.type_name();
  d.struct_size = p.struct_size();
  return d;
}

void ToProto(const DType& d, v1::DType* p) {
  p->set_scalar(static_cast<v1::ScalarType>(d.scalar));
  for (uint32_t e : d.elem_shape) p->add_elem_shape(e);
  p->set_type_name(d.Name());
  p->set_struct_size(d.struct_size);
}

ArrayRef FromProto(const v1::ArrayRef& p) {
  ArrayRef r;
  r.handle = p.handle();
  r.byte_offset = p.byte_offset();
  r.shape.assign(p.shape().begin(), p.shape().end());
  r.strides.assign(p.strides().begin(), p.strides().end());
  r.retain_grad = p.retain_grad();
  if (p.has_view_dtype()) r.view_dtype = FromProto(p.view_dtype());   // validated by MakeView
  return r;
}

void ToProto(const ArrayDesc& d, v1::ArrayInfo* p) {
  p->set_handle(d.handle);
  ToProto(d.dtype, p->mutable_dtype());
  for (int64_t s : d.shape) p->add_shape(s);
  for (int64_t s : d.strides) p->add_strides(s);
  p->set_device(d.device);
  p->set_byte_size(d.byte_size);
  p->set_grad_handle(d.grad_handle);
  p->set_pinned(d.pinned);
  p->set_page_locked(d.page_locked);
  p->set_shm_name(d.shm_name);
  p->set_shm_offset(d.shm_offset);
  p->set_shm_size(d.shm_size);
  if (!d.cuda_ipc_handle.empty()) {
    p->set_cuda_ipc_handle(d.cuda_ipc_handle);
    p->set_cuda_ipc_offset(d.cuda_ipc_offset);
    p->set_cuda_slab_size(d.cuda_slab_size);
    p->set_cuda_slab_id(d.cuda_slab_id);
  }
}

SourceLocation FromProto(const v1::SourceLocation& p) {
  SourceLocation l;
  l.file = p.file();
  l.line = p.line();
  l.column = p.column();
  return l;
}

void ToProto(const SourceLocation& l, v1::SourceLocation* p) {
  p->set_file(l.file);
  p->set_line(l.line);
  p->set_column(l.column);
}

void ToProto(const Diagnostic& d, v1::Diagnostic* p) {
  switch (d.severity) {
    case Diagnostic::Severity::kError: p->set_severity(v1::Diagnostic::ERROR); break;
    case Diagnostic::Severity::kWarning: p->set_severity(v1::Diagnostic::WARNING); break;
    case Diagnostic::Severity::kNote: p->set_severity(v1::Diagnostic::NOTE); break;
  }
  p->set_message(d.message);
  ToProto(d.location, p->mutable_location());
  p->set_source_line(d.source_line);
  p->set_kind(d.kind);
}

void ToProto(const DeviceInfo& d, v1::DeviceInfo* p) {
  p->set_name(d.name);
  p->set_kind(d.kind);
  p->set_description(d.description);
  p->set_total_memory(d.total_memory);
  p->set_free_memory(d.free_memory);
  p->set_compute_capability_major(d.compute_capability_major);
  p->set_compute_capability_minor(d.compute_capability_minor);
  p->set_cores(d.cores);
  p->set_max_shared_memory_per_block(d.max_shared_memory_per_block);
  p->set_compute_supported(d.compute_supported);
}

ModuleSource FromProto(const v1::ModuleSource& p) {
  ModuleSource m;
  m.name = p.name();
  for (const auto& f : p.functions()) {
    FunctionSource fs;
    fs.name = f.name();
    fs.source = f.source();
    fs.file = f.file();
    fs.first_line = f.first_line() ? f.first_line() : 1;
    fs.is_kernel = f.is_kernel();
    fs.param_types.assign(f.param_types().begin(), f.param_types().end());
    fs.param_names.assign(f.param_names().begin(), f.param_names().end());
    fs.return_type = f.return_type();
    fs.key = f.key();
    m.functions.push_back(std::move(fs));
  }
  for (const auto& s : p.symbols()) {
    Symbol sym;
    sym.name = s.name();
    switch (s.kind_case()) {
      case v1::Symbol::kConstant:
        sym.kind = Symbol::Kind::kConstant;
        sym.constant.type = s.constant().type();
        sym.constant.value = s.constant().value();
        break;
      case v1::Symbol::kFunction:
        sym.kind = Symbol::Kind::kFunction;
        sym.target = s.function();
        break;
      case v1::Symbol::kType:
        sym.kind = Symbol::Kind::kType;
        sym.target = s.type();
        break;
      case v1::Symbol::kBuiltinModule:
        sym.kind = Symbol::Kind::kBuiltinModule;
        sym.target = s.builtin_module();
        break;
      default:
        sym.kind = Symbol::Kind::kConstant;
        break;
    }
    m.symbols.push_back(std::move(sym));
  }
  for (const auto& sd : p.structs()) {
    StructDef d;
    d.name = sd.name();
    for (const auto& f : sd.fields()) d.fields.push_back({f.name(), f.type()});
    m.structs.push_back(std::move(d));
  }
  for (const auto& [k, v] : p.options()) m.options[k] = v;
  return m;
}

namespace {

ArgValue ArgFromProto(const v1::ArgValue& p) {
  ArgValue a;
  switch (p.kind_case()) {
    case v1::ArgValue::kArray:
      a.kind = ArgValue::Kind::kArray;
      a.array = FromProto(p.array());
      break;
    case v1::ArgValue::kStructValue:
      a.kind = ArgValue::Kind::kStruct;
      a.fields.reserve(static_cast<size_t>(p.struct_value().fields_size()));
      for (const auto& f : p.struct_value().fields()) a.fields.push_back(ArgFromProto(f));
      break;
    default:
      a.kind = ArgValue::Kind::kRaw;
      a.raw = p.raw();
      break;
  }
  return a;
}

}  // namespace

Expected<geometry::GeometryRequest> FromProto(const v1::GeometryRequest& req) {
  geometry::GeometryRequest r;
  int op = static_cast<int>(req.op());
  if (op < 1 || op > 8) return InvalidArgument("geometry: unknown operation " + std::to_string(op));
  r.op = static_cast<geometry::GeometryRequest::Op>(op);
  r.id = req.id();
  r.device = req.device().empty() ? "cpu" : req.device();
  if (r.op == geometry::GeometryRequest::Op::kCreateHashGrid) {
    if (req.dim_size() != 3) return InvalidArgument("HashGrid: dim must have 3 values");
    for (int k = 0; k < 3; ++k) r.dim[k] = req.dim(k);
  }
  r.points = req.points();
  r.indices = req.indices();
  r.velocities = req.velocities();
  r.lowers = req.lowers();
  r.uppers = req.uppers();
  r.radius = req.radius();
  r.groups = req.groups();
  r.leaves = req.leaves();
  r.masks = req.masks();
  r.values = req.values();
  r.value_type = static_cast<uint32_t>(req.value_type());
  if (req.background().size() > 64) return InvalidArgument("Volume: the background value is too long");
  r.background = req.background();
  if (req.transform_size() > 12) return InvalidArgument("Volume: the transform has more than 12 values");
  r.transform.assign(req.transform().begin(), req.transform().end());
  return r;
}

Expected<Command> FromProto(const v1::Command& p, size_t index) {
  Command c;
  c.origin = FromProto(p.origin());
  switch (p.kind_case()) {
    case v1::Command::kCopy:
      c.kind = CopyCommand{FromProto(p.copy().dst()), FromProto(p.copy().src())};
      break;
    case v1::Command::kFill:
      c.kind = FillCommand{FromProto(p.fill().dst()), p.fill().value()};
      break;
    case v1::Command::kLaunch: {
      const auto& l = p.launch();
      LaunchCommand lc;
      lc.module_id = l.module_id();
      lc.kernel = l.kernel();
      lc.dim.assign(l.dim().begin(), l.dim().end());
      lc.args.reserve(static_cast<size_t>(l.args_size()));
      for (const auto& a : l.args()) lc.args.push_back(ArgFromProto(a));
      lc.adjoint = l.adjoint();
      lc.adj_args.reserve(static_cast<size_t>(l.adj_args_size()));
      for (const auto& a : l.adj_args()) lc.adj_args.push_back(ArgFromProto(a));
      lc.device = l.device();
      lc.block_dim = l.block_dim();
      lc.max_blocks = l.max_blocks();
      lc.record_only = l.record_only();
      c.kind = std::move(lc);
      break;
    }
    case v1::Command::kTape: {
      const auto& t = p.tape();
      TapeCommand tc;
      tc.op = static_cast<TapeCommand::Op>(t.op());
      tc.tape_id = t.tape_id();
      tc.marker = t.marker();
      tc.loss = FromProto(t.loss());
      for (const auto& s : t.seeds()) tc.seeds.emplace_back(FromProto(s.array()), FromProto(s.grad()));
      c.kind = std::move(tc);
      break;
    }
    case v1::Command::kSetGrad:
      c.kind = SetGradCommand{FromProto(p.set_grad().array()), FromProto(p.set_grad().grad())};
      break;
    case v1::Command::kCudaEvent: {
      const auto& e = p.cuda_event();
      if (e.op() != v1::CudaEventCommand::WAIT && e.op() != v1::CudaEventCommand::RECORD &&
          e.op() != v1::CudaEventCommand::SHARE)
        return InvalidArgument("command " + std::to_string(index) + ": unknown cuda_event op " + std::to_string(e.op()));
      if (e.ipc_handle().size() != 64)
        return InvalidArgument("command " + std::to_string(index) + ": a CUDA IPC event handle has 64 bytes, got " +
                               std::to_string(e.ipc_handle().size()));
      const CudaEventCommand::Op op = e.op() == v1::CudaEventCommand::RECORD  ? CudaEventCommand::Op::kRecord
                                      : e.op() == v1::CudaEventCommand::SHARE ? CudaEventCommand::Op::kShare
                                                                              : CudaEventCommand::Op::kWait;
      c.kind = CudaEventCommand{op, e.device(), e.ipc_handle()};
      break;
    }
    case v1::Command::kTiming: {
      const auto& t = p.timing();
      if (t.op() != v1::TimingCommand::BEGIN && t.op() != v1::TimingCommand::END)
        return InvalidArgument("command " + std::to_string(index) + ": unknown timing op " + std::to_string(t.op()));
      c.kind = TimingCommand{t.op() == v1::TimingCommand::END ? TimingCommand::Op::kEnd : TimingCommand::Op::kBegin,
                             t.filter()};
      break;
    }
    case v1::Command::kTimedEvent: {
      const auto& t = p.timed_event();
      if (t.op() != v1::TimedEventCommand::RECORD && t.op() != v1::TimedEventCommand::DESTROY)
        return InvalidArgument("command " + std::to_string(index) + ": unknown timed_event op " + std::to_string(t.op()));
      c.kind = TimedEventCommand{t.op() == v1::TimedEventCommand::DESTROY ? TimedEventCommand::Op::kDestroy
                                                                          : TimedEventCommand::Op::kRecord,
                                 t.event_id(), t.device()};
      break;
    }
    case v1::Command::kCudaValue: {
      const auto& v = p.cuda_value();
      if (v.op() != v1::CudaValueCommand::WAIT && v.op() != v1::CudaValueCommand::WRITE)
        return InvalidArgument("command " + std::to_string(index) + ": unknown cuda_value op " + std::to_string(v.op()));
      c.kind = CudaValueCommand{v.op() == v1::CudaValueCommand::WRITE ? CudaValueCommand::Op::kWrite
                                                                      : CudaValueCommand::Op::kWait,
                                FromProto(v.order()), v.index(), v.value()};
      break;
    }
    case v1::Command::kGeometry: {
      WEFT_ASSIGN_OR_RETURN(geometry::GeometryRequest r, FromProto(p.geometry()));
      using Op = geometry::GeometryRequest::Op;
      if (r.op != Op::kBuildHashGrid && r.op != Op::kRefit && r.op != Op::kRebuild && r.op != Op::kFree)
        return InvalidArgument("command " + std::to_string(index) +
                               ": a geometry command builds a HashGrid, refits / rebuilds a Bvh or Mesh, or frees one (op " +
                               std::to_string(static_cast<int>(r.op)) + " goes to GeometryService)");
      c.kind = GeometryCommand{std::move(r)};
      break;
    }
    case v1::Command::kGraph: {
      const auto& g = p.graph();
      if (g.op() != v1::GraphCommand::CREATE && g.op() != v1::GraphCommand::LAUNCH &&
          g.op() != v1::GraphCommand::DESTROY)
        return InvalidArgument("command " + std::to_string(index) + ": unknown graph op " + std::to_string(g.op()));
      GraphCommand gc;
      gc.op = static_cast<GraphCommand::Op>(g.op());
      gc.graph_id = g.graph_id();
      gc.device = g.device();
      if (gc.op != GraphCommand::Op::kCreate && g.commands_size() != 0)
        return InvalidArgument("command " + std::to_string(index) + ": only a graph CREATE carries commands");
      gc.commands.reserve(static_cast<size_t>(g.commands_size()));
      for (int i = 0; i < g.commands_size(); ++i) {
        const v1::Command& inner = g.commands(i);
        if (inner.kind_case() != v1::Command::kLaunch && inner.kind_case() != v1::Command::kCopy &&
            inner.kind_case() != v1::Command::kFill)
          return InvalidArgument("command " + std::to_string(index) + ": graph command " + std::to_string(i) +
                                 " is not a launch, copy or fill (a graph holds only those)");
        WEFT_ASSIGN_OR_RETURN(Command converted, FromProto(inner, static_cast<size_t>(i)));
        gc.commands.push_back(std::move(converted));
      }
      c.kind = std::move(gc);
      break;
    }
    default:
      return InvalidArgument("command " + std::to_string(index) +
                             " is empty (no copy/fill/launch/tape/set_grad/cuda_event/cuda_value/graph/geometry)");
  }
  return c;
}

}  // namespace weft::server
