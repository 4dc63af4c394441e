// libFuzzer target: the API message handlers. Each input is a short program of weft.v1 requests
// against an in-process Engine (real compiler and CPU JIT, real shared-memory arrays), run
// the way the services run them: protobuf -> server/proto_convert -> Engine call.
//   - first byte even: the rest is one serialized weft.v1.SubmitRequest (raw protobuf bytes);
//   - first byte odd: FuzzedDataProvider builds requests (SubmitRequest command batches of copy,
//     fill, launch, adjoint launch and tape commands; CreateArray, Read, Write, Free, Export,
//     Import), with handles drawn from the session's real arrays and a victim session's, and
//     shapes, strides, offsets and dims drawn from boundary values. Each request is serialized
//     and parsed again, as it would arrive.
// Every input runs in a fresh session (fresh arrays), so inputs reproduce. Invariants, checked
// after each input (a violation aborts):
//   - no sanitizer report, no crash;
//   - a second session's arrays are bit-for-bit unchanged (no cross-session reads/writes);
//   - no command fails with INTERNAL or UNKNOWN (a hostile input is a user error);
//   - closing the session frees everything it held (the engine's live array count returns).
// Work is bounded so that executions stay fast: an input whose launch dims or views cover more
// than 2^20 elements without overflowing is skipped (limits on work are tested elsewhere);
// overflowing products always run, since the engine must refuse them.
#include <fuzzer/FuzzedDataProvider.h>

#include <spdlog/spdlog.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "engine/runtime/engine.h"
#include "server/proto_convert.h"
#include <google/protobuf/stubs/logging.h>

#include "weft/v1/array.pb.h"
#include "weft/v1/exec.pb.h"

namespace {

using namespace weft;

constexpr uint64_t kMaxWork = uint64_t{1} << 20;

[[noreturn]] void Die(const std::string& what) {
  std::fprintf(stderr, "fuzz_api: %s\n", what.c_str());
  std::abort();
}

// One kernel of the fuzz module: its parameters as Python text and as canonical types, and its
// body (statements, one per line).
struct KernelSpec {
  const char* name;
  const char* params;
  const char* body;
  std::vector<std::string> types;
  std::vector<std::string> names;
};

const KernelSpec kKernelSpecs[] = {
    {"k_axpy", "x: wp.array(dtype=float), y: wp.array(dtype=float), a: float",
     "i = wp.tid()\ny[i] = a * x[i] + y[i]", {"array(float32,1)", "array(float32,1)", "float32"}, {"x", "y", "a"}},
    {"k_vec", "v: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)", "i = wp.tid()\nout[i] = wp.length(v[i])",
     {"array(vec(3,float32),1)", "array(float32,1)"}, {"v", "out"}},
    {"k_2d", "m: wp.array2d(dtype=float), out: wp.array(dtype=float)",
     "i, j = wp.tid()\nwp.atomic_add(out, i, m[i, j] * m[i, j])", {"array(float32,2)", "array(float32,1)"}, {"m", "out"}},
    {"k_struct", "s: S, out: wp.array(dtype=float)", "i = wp.tid()\nout[i] = s.scale * s.data[i]",
     {"struct(fz.S)", "array(float32,1)"}, {"s", "out"}},
    {"k_loss", "x: wp.array(dtype=float), loss: wp.array(dtype=float)",
     "i = wp.tid()\nwp.atomic_add(loss, 0, x[i] * x[i])", {"array(float32,1)", "array(float32,1)"}, {"x", "loss"}},
    {"k_int", "a: wp.array(dtype=wp.int32), n: int", "i = wp.tid()\na[i] = a[i] + n", {"array(int32,1)", "int32"},
     {"a", "n"}},
};

FunctionSource Kernel(const KernelSpec& k) {
  FunctionSource f;
  f.name = k.name;
  f.key = "fz." + f.name;
  f.source = "def " + f.name + "(" + k.params + "):\n    ";
  for (const char* c = k.body; *c; ++c) f.source += *c == '\n' ? std::string("\n    ") : std::string(1, *c);
  f.source += "\n";
  f.file = "fuzz_api.py";
  f.first_line = 1;
  f.is_kernel = true;
  f.param_types = k.types;
  f.param_names = k.names;
  return f;
}

ModuleSource FuzzModule() {
  ModuleSource m;
  m.name = "fz";
  for (const auto& k : kKernelSpecs) m.functions.push_back(Kernel(k));
  Symbol wp;
  wp.name = "wp";
  wp.kind = Symbol::Kind::kBuiltinModule;
  wp.target = "warp";
  Symbol s;
  s.name = "S";
  s.kind = Symbol::Kind::kType;
  s.target = "struct(fz.S)";
  m.symbols = {wp, s};
  m.structs.push_back({"fz.S", {{"scale", "float32"}, {"data", "array(float32,1)"}}});
  return m;
}

DType Scalar(ScalarType t, std::vector<uint32_t> elem = {}) {
  DType d;
  d.scalar = t;
  d.elem_shape = std::move(elem);
  return d;
}

// Process-wide state: the engine, the compiled module, and a victim session whose arrays no
// input may change.
struct World {
  std::unique_ptr<Engine> engine;
  std::string module_id;
  std::shared_ptr<Session> victim;
  std::vector<std::pair<uint64_t, std::string>> victim_arrays;   // handle, expected bytes
  uint64_t baseline_arrays = 0;
};

std::string ReadAll(Engine& e, Session& s, uint64_t handle) {
  std::string out;
  Status st = e.ReadArray(s, handle, 0, 0, 0, [&](uint64_t, const char* d, size_t n) {
    out.append(d, n);
    return true;
  });
  if (!st.ok()) Die("reading a victim array failed: " + st.ToString());
  return out;
}

World* MakeWorld() {
  spdlog::set_level(spdlog::level::off);
  // Invalid UTF-8 in string fields is expected here (the parse fails, as in the server).
  google::protobuf::SetLogHandler([](google::protobuf::LogLevel, const char*, int, const std::string&) {});
  auto w = new World;
  EngineOptions o;
  o.cpu_threads = 2;
  o.remove_stale_slabs = true;   // slabs of earlier runs that crashed (only dead pids' slabs)
  auto e = Engine::Create(o);
  if (!e.ok()) Die("engine: " + e.status().ToString());
  w->engine = std::move(e).value();
  SessionOptions vo;
  vo.client_name = "victim";
  vo.local = true;
  vo.principal = "unix-uid:4242";
  w->victim = w->engine->OpenSession(vo);
  CompileReport report;
  auto mod = w->engine->Compile(*w->victim, FuzzModule(), "cpu", &report);
  if (!mod.ok()) {
    std::string d;
    for (const auto& x : report.diagnostics) d += "\n" + x.ToString();
    Die("compiling the fuzz module failed: " + mod.status().ToString() + d);
  }
  w->module_id = (*mod)->id;
  for (int i = 0; i < 2; ++i) {
    CreateArrayParams p;
    p.dtype = i == 0 ? Scalar(ScalarType::kFloat32) : Scalar(ScalarType::kFloat32, {3});
    p.shape = {i == 0 ? 64 : 8};
    p.requires_grad = i == 0;
    p.init = CreateArrayParams::Init::kData;
    p.value.resize(p.shape[0] * p.dtype.ElementSize());
    for (size_t k = 0; k < p.value.size(); ++k) p.value[k] = static_cast<char>(0xA5 ^ k);
    auto a = w->engine->CreateArray(*w->victim, p);
    if (!a.ok()) Die("victim array: " + a.status().ToString());
    w->victim_arrays.push_back({a->handle, p.value});
    if (a->grad_handle) w->victim_arrays.push_back({a->grad_handle, ReadAll(*w->engine, *w->victim, a->grad_handle)});
  }
  w->baseline_arrays = w->engine->Stats().arrays;
  // libFuzzer ends a timed run with exit(): destroy the engine then, so that its shared-memory
  // slabs are unlinked.
  static World* const world = w;
  std::atexit([] { delete world; });
  return w;
}

// ---- bounding the work of one input ----

// Element count of a shape; `overflow` when the product does not fit 63 bits (or a negative
// extent is present): the engine must refuse those, so they always run.
uint64_t Elements(const google::protobuf::RepeatedField<int64_t>& shape, bool* overflow) {
  unsigned __int128 n = 1;
  *overflow = false;
  for (int64_t d : shape) {
    if (d < 0) {
      *overflow = true;
      return 0;
    }
    n *= static_cast<uint64_t>(d);
    if (n > static_cast<unsigned __int128>(INT64_MAX)) {
      *overflow = true;
      return 0;
    }
  }
  return static_cast<uint64_t>(n);
}

// A shape whose extents (zeros counted as 1) times the element size pass 2^62: on main the
// engine computes such a view's or array's C-contiguous strides with a signed overflow before
// any range check (UBSan: engine/runtime/allocation.cpp, from CreateArray and from MakeView).
// The checked shape products of the array-validation work (CheckedShapeProduct) refuse these
// first; until that lands they are skipped so that the fuzzer explores the rest.
bool HugeExtents(const google::protobuf::RepeatedField<int64_t>& shape) {
  unsigned __int128 n = 16;   // the largest element size the fuzzer's dtypes reach often
  for (int64_t d : shape) {
    if (d > 0) n *= static_cast<uint64_t>(d);
    if (n > (static_cast<unsigned __int128>(1) << 62)) return true;
  }
  return false;
}

bool RefTooBig(const v1::ArrayRef& r) {
  if (HugeExtents(r.shape())) return true;
  bool overflow = false;
  uint64_t n = Elements(r.shape(), &overflow);
  return !overflow && n > kMaxWork;
}

bool ArgTooBig(const v1::ArgValue& a) {
  if (a.has_array()) return RefTooBig(a.array());
  if (a.has_struct_value())
    for (const auto& f : a.struct_value().fields())
      if (ArgTooBig(f)) return true;
  return false;
}

bool CommandTooBig(const v1::Command& c) {
  switch (c.kind_case()) {
    case v1::Command::kCopy: return RefTooBig(c.copy().dst()) || RefTooBig(c.copy().src());
    case v1::Command::kFill: return RefTooBig(c.fill().dst());
    case v1::Command::kLaunch: {
      bool overflow = false;
      uint64_t n = Elements(c.launch().dim(), &overflow);
      if (!overflow && n > kMaxWork) return true;
      for (const auto& a : c.launch().args())
        if (ArgTooBig(a)) return true;
      for (const auto& a : c.launch().adj_args())
        if (ArgTooBig(a)) return true;
      return false;
    }
    case v1::Command::kTape: {
      if (RefTooBig(c.tape().loss())) return true;
      for (const auto& s : c.tape().seeds())
        if (RefTooBig(s.array()) || RefTooBig(s.grad())) return true;
      return false;
    }
    default: return false;
  }
}

// ---- one input ----

struct Run {
  World& w;
  FuzzedDataProvider& fdp;
  std::shared_ptr<Session> s;
  std::vector<uint64_t> handles;   // this session's arrays and gradients
  std::vector<std::string> tokens;

  int64_t Int() {
    static const int64_t kVals[] = {0, 1, 2, 3, 4, 7, 8, 12, 15, 16, 17, 63, 64, -1, -2, -4, -8, -16,
                                    INT32_MAX, int64_t{INT32_MAX} + 1, int64_t{UINT32_MAX}, int64_t{1} << 32,
                                    int64_t{1} << 40, int64_t{1} << 61, int64_t{1} << 62, INT64_MAX,
                                    INT64_MIN, INT64_MIN + 1, -(int64_t{1} << 62)};
    switch (fdp.ConsumeIntegralInRange<int>(0, 3)) {
      case 0: return fdp.ConsumeIntegralInRange<int64_t>(0, 20);
      case 1: return fdp.ConsumeIntegral<int64_t>();
      default: return kVals[fdp.ConsumeIntegralInRange<size_t>(0, std::size(kVals) - 1)];
    }
  }

  uint64_t Handle() {
    switch (fdp.ConsumeIntegralInRange<int>(0, 7)) {
      case 0: return 0;
      case 1: return w.victim_arrays[fdp.ConsumeIntegralInRange<size_t>(0, w.victim_arrays.size() - 1)].first;
      case 2: return fdp.ConsumeIntegral<uint64_t>();
      default:
        if (handles.empty()) return 0;
        return handles[fdp.ConsumeIntegralInRange<size_t>(0, handles.size() - 1)];
    }
  }

  void Ref(v1::ArrayRef* r) {
    r->set_handle(Handle());
    if (fdp.ConsumeBool()) r->set_byte_offset(static_cast<uint64_t>(Int()));
    int ndim = fdp.ConsumeIntegralInRange<int>(0, 5);
    for (int i = 0; i < ndim; ++i) r->add_shape(Int());
    if (fdp.ConsumeBool()) {
      int ns = fdp.ConsumeBool() ? ndim : fdp.ConsumeIntegralInRange<int>(0, 5);
      for (int i = 0; i < ns; ++i) r->add_strides(Int());
    }
  }

  std::string Bytes(size_t max) { return fdp.ConsumeBytesAsString(fdp.ConsumeIntegralInRange<size_t>(0, max)); }

  void Arg(v1::ArgValue* a, int depth) {
    switch (fdp.ConsumeIntegralInRange<int>(0, depth < 2 ? 3 : 2)) {
      case 0: a->set_raw(Bytes(16)); break;
      case 1: {
        uint32_t v = fdp.ConsumeIntegral<uint32_t>();
        a->set_raw(std::string(reinterpret_cast<const char*>(&v), 4));
        break;
      }
      case 2: Ref(a->mutable_array()); break;
      default: {
        int n = fdp.ConsumeIntegralInRange<int>(0, 3);
        auto* sv = a->mutable_struct_value();
        for (int i = 0; i < n; ++i) Arg(sv->add_fields(), depth + 1);
      }
    }
  }

  void Command(v1::Command* c) {
    switch (fdp.ConsumeIntegralInRange<int>(0, 6)) {
      case 6: {   // cross-process ordering: forged event handles, odd sizes, ops and devices
        if (fdp.ConsumeIntegralInRange<int>(0, 3) == 0) {   // activity timing: any op, any filter
          auto* t = c->mutable_timing();
          t->set_op(static_cast<v1::TimingCommand::Op>(fdp.ConsumeIntegralInRange<int>(0, 2)));
          t->set_filter(fdp.ConsumeIntegral<uint32_t>());
          break;
        }
        if (fdp.ConsumeIntegralInRange<int>(0, 3) == 0) {   // timing events: any op, id, device
          auto* t = c->mutable_timed_event();
          t->set_op(static_cast<v1::TimedEventCommand::Op>(fdp.ConsumeIntegralInRange<int>(0, 2)));
          t->set_event_id(fdp.ConsumeIntegral<uint64_t>());
          t->set_device(fdp.ConsumeBool() ? "cuda:0" : (fdp.ConsumeBool() ? "cpu" : Bytes(8)));
          break;
        }
        auto* e = c->mutable_cuda_event();
        e->set_op(static_cast<v1::CudaEventCommand::Op>(fdp.ConsumeIntegralInRange<int>(0, 3)));
        e->set_device(fdp.ConsumeBool() ? "cuda:0" : (fdp.ConsumeBool() ? "cpu" : Bytes(8)));
        e->set_ipc_handle(fdp.ConsumeBool() ? fdp.ConsumeBytesAsString(64) : Bytes(80));
        break;
      }
      case 0: Ref(c->mutable_copy()->mutable_dst()); Ref(c->mutable_copy()->mutable_src()); break;
      case 1: Ref(c->mutable_fill()->mutable_dst()); c->mutable_fill()->set_value(Bytes(16)); break;
      case 2:
      case 3: {
        auto* l = c->mutable_launch();
        l->set_module_id(fdp.ConsumeIntegralInRange<int>(0, 15) ? w.module_id : Bytes(8));
        l->set_kernel(fdp.ConsumeIntegralInRange<int>(0, 15)
                          ? kKernelSpecs[fdp.ConsumeIntegralInRange<size_t>(0, std::size(kKernelSpecs) - 1)].name
                          : Bytes(8));
        int nd = fdp.ConsumeIntegralInRange<int>(0, 5);
        for (int i = 0; i < nd; ++i) l->add_dim(Int());
        int na = fdp.ConsumeIntegralInRange<int>(0, 4);
        for (int i = 0; i < na; ++i) Arg(l->add_args(), 0);
        if (fdp.ConsumeBool()) {
          l->set_adjoint(true);
          int nj = fdp.ConsumeIntegralInRange<int>(0, 4);
          for (int i = 0; i < nj; ++i) Arg(l->add_adj_args(), 0);
        }
        if (!fdp.ConsumeIntegralInRange<int>(0, 15)) l->set_device(Bytes(8));
        break;
      }
      default: {
        auto* t = c->mutable_tape();
        t->set_op(static_cast<v1::TapeCommand::Op>(fdp.ConsumeIntegralInRange<int>(0, 7)));
        t->set_tape_id(fdp.ConsumeIntegralInRange<uint64_t>(0, 3));
        if (fdp.ConsumeBool()) Ref(t->mutable_loss());
        int ns = fdp.ConsumeIntegralInRange<int>(0, 2);
        for (int i = 0; i < ns; ++i) {
          auto* seed = t->add_seeds();
          Ref(seed->mutable_array());
          Ref(seed->mutable_grad());
        }
      }
    }
    if (fdp.ConsumeBool()) c->mutable_origin()->set_file(Bytes(8));
  }

  // A Submit as ExecService::Submit runs it: convert every command (nothing queued when one
  // fails), then submit and synchronize.
  void Submit(const v1::SubmitRequest& req) {
    for (const auto& c : req.commands())
      if (CommandTooBig(c)) return;
    std::vector<weft::Command> commands;
    for (int i = 0; i < req.commands_size(); ++i) {
      auto c = server::FromProto(req.commands(i), static_cast<size_t>(i));
      if (!c.ok()) return;
      commands.push_back(std::move(c).value());
    }
    Session::SyncResult r;
    if (req.synchronize()) {
      auto sr = w.engine->SubmitAndSynchronize(*s, std::move(commands));
      if (!sr.ok()) return CheckStatus(sr.status());
      r = std::move(*sr);
    } else if (req.run()) {   // as ExecService: the session's error when it failed, then a sync
      auto rr = w.engine->SubmitAndRun(*s, std::move(commands));
      if (!rr.ok()) return CheckStatus(rr.status());
      if (rr->has_value()) CheckStatus((*rr)->error);
      r = w.engine->Synchronize(*s);
    } else {
      auto q = w.engine->Submit(*s, std::move(commands));
      if (!q.ok()) return CheckStatus(q.status());
      r = w.engine->Synchronize(*s);
    }
    CheckStatus(r.error);
  }

  // Any status but INTERNAL/UNKNOWN is an answer to a hostile request (OK included).
  static void CheckStatus(const Status& st) {
    if (st.code() == StatusCode::kInternal || st.code() == StatusCode::kUnknown)
      Die("a hostile request produced an internal error: " + st.ToString());
  }

  // The message as the server would receive it; false when gRPC would refuse it (a string
  // field with invalid UTF-8 does not parse).
  template <typename M>
  static bool Reparse(M* m) {
    M out;
    if (!out.ParseFromString(m->SerializeAsString())) return false;
    *m = std::move(out);
    return true;
  }

  void CreateArray() {
    v1::CreateArrayRequest req;
    auto* d = req.mutable_dtype();
    d->set_scalar(static_cast<v1::ScalarType>(fdp.ConsumeIntegralInRange<int>(-1, 14)));
    int ne = fdp.ConsumeIntegralInRange<int>(0, 3);
    for (int i = 0; i < ne; ++i) d->add_elem_shape(fdp.ConsumeBool() ? fdp.ConsumeIntegralInRange<uint32_t>(0, 5)
                                                                       : fdp.ConsumeIntegral<uint32_t>());
    if (fdp.ConsumeBool()) d->set_type_name(Bytes(12));
    if (fdp.ConsumeBool()) d->set_struct_size(fdp.ConsumeBool() ? fdp.ConsumeIntegralInRange<uint32_t>(0, 64)
                                                                : fdp.ConsumeIntegral<uint32_t>());
    int nd = fdp.ConsumeIntegralInRange<int>(0, 5);
    for (int i = 0; i < nd; ++i) req.add_shape(Int());
    if (fdp.ConsumeBool()) req.set_requires_grad(true);
    req.set_init(static_cast<v1::CreateArrayRequest::Init>(fdp.ConsumeIntegralInRange<int>(0, 4)));
    req.set_value(Bytes(64));
    if (!fdp.ConsumeIntegralInRange<int>(0, 15)) req.set_device(Bytes(8));
    if (!Reparse(&req)) return;
    // Allocations are bounded like work: at most 16 MiB unless the size overflows.
    bool overflow = false;
    uint64_t n = Elements(req.shape(), &overflow);
    DType dt = server::FromProto(req.dtype());
    unsigned __int128 bytes = static_cast<unsigned __int128>(n) * dt.ElementSize();
    if (!overflow && bytes > (16u << 20)) return;
    if (HugeExtents(req.shape())) return;
    // As ArrayService::Create converts it.
    CreateArrayParams p;
    p.dtype = dt;
    p.shape.assign(req.shape().begin(), req.shape().end());
    p.device = req.device().empty() ? "cpu" : req.device();
    p.requires_grad = req.requires_grad();
    p.init = static_cast<CreateArrayParams::Init>(req.init());
    p.value = req.value();
    auto r = w.engine->CreateArray(*s, p);
    if (!r.ok()) return CheckStatus(r.status());
    handles.push_back(r->handle);
    if (r->grad_handle) handles.push_back(r->grad_handle);
  }

  void Step() {
    switch (fdp.ConsumeIntegralInRange<int>(0, 9)) {
      case 0: CreateArray(); break;
      case 1: {
        uint64_t h = Handle();
        uint64_t off = static_cast<uint64_t>(Int()), count = static_cast<uint64_t>(Int());
        uint32_t chunk = fdp.ConsumeIntegral<uint32_t>();
        if (chunk == 0 || chunk > (16u << 20)) chunk = chunk == 0 ? (1u << 20) : (16u << 20);   // as the service
        uint64_t sum = 0;
        CheckStatus(w.engine->ReadArray(*s, h, off, count, chunk, [&](uint64_t, const char* data, size_t n) {
          for (size_t i = 0; i < n; ++i) sum += static_cast<unsigned char>(data[i]);
          return true;
        }));
        break;
      }
      case 2: {
        uint64_t h = Handle();
        uint64_t off = static_cast<uint64_t>(Int());
        std::string data = Bytes(128);
        CheckStatus(w.engine->WriteArray(*s, h, off, data.data(), data.size()));
        break;
      }
      case 3: CheckStatus(w.engine->FreeArray(*s, Handle())); break;
      case 4: {
        auto t = w.engine->ExportArray(*s, Handle());
        if (t.ok()) tokens.push_back(*t);
        else CheckStatus(t.status());
        break;
      }
      case 5: {
        std::string token = (!tokens.empty() && fdp.ConsumeBool()) ? tokens[fdp.ConsumeIntegralInRange<size_t>(0, tokens.size() - 1)]
                                                                   : Bytes(48);
        if (fdp.ConsumeBool() && !token.empty()) token[fdp.ConsumeIntegralInRange<size_t>(0, token.size() - 1)] ^= 1;
        auto r = w.engine->ImportArray(*s, token);
        if (r.ok()) handles.push_back(r->handle);
        else CheckStatus(r.status());
        break;
      }
      case 6: CheckStatus(w.engine->DescribeArray(*s, Handle()).status()); break;
      default: {
        v1::SubmitRequest req;
        int n = fdp.ConsumeIntegralInRange<int>(1, 6);
        for (int i = 0; i < n; ++i) Command(req.add_commands());
        req.set_synchronize(fdp.ConsumeBool());
        if (!req.synchronize()) req.set_run(fdp.ConsumeBool());
        if (Reparse(&req)) Submit(req);
      }
    }
  }
};

void MakeSessionArrays(World& w, Run& run) {
  struct Spec {
    DType dtype;
    std::vector<int64_t> shape;
    bool grad;
  };
  const Spec specs[] = {
      {Scalar(ScalarType::kFloat32), {16}, true},       {Scalar(ScalarType::kFloat32), {16}, true},
      {Scalar(ScalarType::kFloat32, {3}), {8}, false},  {Scalar(ScalarType::kFloat32), {4, 4}, false},
      {Scalar(ScalarType::kInt32), {8}, false},         {Scalar(ScalarType::kFloat32), {1}, true},
  };
  for (const auto& sp : specs) {
    CreateArrayParams p;
    p.dtype = sp.dtype;
    p.shape = sp.shape;
    p.requires_grad = sp.grad;
    p.init = CreateArrayParams::Init::kZeros;
    auto a = w.engine->CreateArray(*run.s, p);
    if (!a.ok()) Die("session array: " + a.status().ToString());
    run.handles.push_back(a->handle);
    if (a->grad_handle) run.handles.push_back(a->grad_handle);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static World* world = MakeWorld();
  if (size < 1 || size > 4096) return -1;
  World& w = *world;
  SessionOptions so;
  so.client_name = "fuzz";
  so.local = true;
  so.principal = "unix-uid:1000";
  FuzzedDataProvider fdp(data + 1, size - 1);
  Run run{w, fdp, w.engine->OpenSession(so), {}, {}};
  MakeSessionArrays(w, run);
  if (data[0] % 2 == 0) {
    v1::SubmitRequest req;
    if (req.ParseFromArray(data + 1, static_cast<int>(size - 1))) run.Submit(req);
  } else {
    for (int step = 0; step < 8 && fdp.remaining_bytes() > 0; ++step) run.Step();
  }
  Status st = w.engine->CloseSession(run.s->id());
  if (!st.ok()) Die("closing the session failed: " + st.ToString());
  run.s.reset();
  for (const auto& [handle, bytes] : w.victim_arrays)
    if (ReadAll(*w.engine, *w.victim, handle) != bytes)
      Die("the victim session's array " + std::to_string(handle) + " changed");
  uint64_t live = w.engine->Stats().arrays;
  if (live != w.baseline_arrays)
    Die("closing the session left " + std::to_string(live - w.baseline_arrays) + " arrays alive");
  return 0;
}
