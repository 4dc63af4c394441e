// ModuleStore implementation: ModuleSource -> cache key -> memory / disk / compile -> loaded code.
// CPU: a miss runs GenerateModule (engine/codegen), optionally NVRTC on the CUDA flavour
// (verify_cuda), then CpuJit::Compile; the object goes to the disk cache and CpuJit::Load maps it.
// CUDA (cuda:N): GenerateModule for kCuda + NVRTC for the device's sm; the CUBIN is cached the
// same way and handed out in LoadedModule::cuda_image (the CUDA runtime loads it).
// Module ids are forward cache keys; the backward variant has its own key but the same id.
#include "engine/runtime/module_store.h"

#include <sys/stat.h>

#include <cctype>
#include <chrono>
#include <cstdlib>
#include <mutex>
#include <regex>
#include <set>
#include <system_error>
#include <thread>
#include <unordered_map>

#include "engine/runtime/module_cache.h"
#include "spdlog/spdlog.h"

#if WEFT_WITH_CPU_JIT
#include "engine/jit/cpu/cpu_jit.h"
#include "engine/native/host_symbols.h"
#endif
#if WEFT_WITH_CUDA
#include "engine/device/cuda_driver.h"
#include "engine/jit/cuda/cubin_info.h"
#include "engine/jit/cuda/nvrtc_child.h"
#if WEFT_WITH_CPU_JIT
#include "engine/jit/cpu/compile_process.h"
#endif
#include "engine/jit/cuda/nvrtc_compiler.h"
#endif

#ifndef WEFT_VERSION
#define WEFT_VERSION "dev"
#endif

namespace weft {
namespace {

#if WEFT_WITH_CPU_JIT
// A loaded CPU module keeps its code alive for as long as anyone holds the module.
struct CpuLoadedModule final : LoadedModule {
  std::shared_ptr<jit::CpuCode> code;
};
#endif

// The generator used when ModuleStoreOptions::generate is empty: engine/codegen.
GenerateModuleFn DefaultGenerator() { return &GenerateModule; }

std::string DefaultBuildId() {
  std::string id = std::string("weft ") + WEFT_VERSION;
  struct stat st {};
  if (::stat("/proc/self/exe", &st) == 0) {
    id += " exe=" + std::to_string(st.st_size) + ":" + std::to_string(st.st_mtim.tv_sec) + "." +
          std::to_string(st.st_mtim.tv_nsec);
  }
  return id;
}

struct DeviceRef {
  Target target = Target::kCpu;
  int ordinal = 0;
};

// "cpu" -> kCpu; "cuda" (= cuda:0 here; the engine places sessions) and "cuda:N" -> kCuda.
Expected<DeviceRef> ParseDevice(const std::string& device) {
  if (device == "cpu" || device.empty()) return DeviceRef{Target::kCpu, 0};
  if (device == "cuda") return DeviceRef{Target::kCuda, 0};
  if (device.rfind("cuda:", 0) == 0 && device.size() > 5 && device.size() < 10 &&
      device.find_first_not_of("0123456789", 5) == std::string::npos) {
    return DeviceRef{Target::kCuda, std::stoi(device.substr(5))};
  }
  return InvalidArgument("unknown device '" + device + "' (expected cpu, cuda or cuda:N)");
}

// A compiler rejected generated code: a weft bug, never the client's. The client gets the
// error lines located in the user's code — the generated translation unit (`main_file`) or a
// file the module's functions name (#line) — message only, never source text; lines located
// anywhere else (the native headers, any other daemon-side file) are only counted: their text
// stays in the daemon log, so no daemon file content reaches a client; such an error that a
// note traces back to a user's line is reported at that line, without its text.
void AppendCompilerDiagnostics(const std::string& log, const std::string& main_file, const ModuleSource& source,
                               std::vector<Diagnostic>* diags) {
  std::set<std::string> user_files{main_file};
  for (const auto& f : source.functions) user_files.insert(f.file);
  static const std::regex kClang(R"(^(.+?):(\d+):(\d+): (?:fatal )?error: (.*)$)");
  static const std::regex kNvrtc(R"(^(.+?)\((\d+)\): (?:catastrophic )?error: (.*)$)");
  // clang's "note: in instantiation of ... requested here" lines after an error in a native
  // header name the user's line (generated code carries #line directives).
  static const std::regex kClangNote(R"(^(.+?):(\d+):(\d+): note: .*$)");
  constexpr size_t kMaxMessageBytes = 300;
  int elsewhere = 0;
  std::vector<std::string> lines;
  for (size_t start = 0; start < log.size();) {
    size_t end = log.find('\n', start);
    if (end == std::string::npos) end = log.size();
    lines.push_back(log.substr(start, end - start));
    start = end + 1;
  }
  for (size_t li = 0; li < lines.size(); ++li) {
    const std::string& line = lines[li];
    std::smatch m;
    std::string file, message;
    uint32_t line_no = 0;
    if (std::regex_match(line, m, kClang) || std::regex_match(line, m, kNvrtc)) {
      file = m[1];
      line_no = static_cast<uint32_t>(std::stoul(m[2].str().substr(0, 9)));
      message = m[m.size() - 1].str();
    } else {
      continue;
    }
    if (!user_files.count(file)) {
      std::string user_file;
      uint32_t user_line = 0;
      for (size_t n = li + 1; n < lines.size(); ++n) {
        std::smatch nm;
        if (std::regex_match(lines[n], nm, kClang) || std::regex_match(lines[n], nm, kNvrtc)) break;
        if (std::regex_match(lines[n], nm, kClangNote) && user_files.count(nm[1].str()) && nm[1].str() != main_file) {
          user_file = nm[1].str();
          user_line = static_cast<uint32_t>(std::stoul(nm[2].str().substr(0, 9)));
          break;
        }
      }
      if (user_file.empty()) {
        ++elsewhere;
        continue;
      }
      Diagnostic d;
      d.location = {user_file, user_line, 0};
      d.message = "internal compiler error in weft's native library, instantiated from this line (the daemon log "
                  "has the compiler's output)";
      diags->push_back(std::move(d));
      continue;
    }
    if (message.size() > kMaxMessageBytes) message = message.substr(0, kMaxMessageBytes) + "...";
    Diagnostic d;
    d.location = {file == main_file ? "<generated code of module " + source.name + ">" : file, line_no, 0};
    d.message = "internal compiler error: " + message;
    diags->push_back(std::move(d));
  }
  if (elsewhere > 0) {
    Diagnostic d;
    d.location = {"<weft native library>", 0, 0};
    d.message = "internal compiler error: " + std::to_string(elsewhere) +
                " error(s) in daemon-side files (their text is only in the daemon log)";
    diags->push_back(std::move(d));
  }
}

// What the client is told when a compiler rejected generated code; the whole compiler output
// goes to the daemon log only.
Status GeneratedCodeRejected(const std::string& module_name, const std::string& target,
                             const Status& compiler_status) {
  spdlog::error("module {}: the generated code does not compile for {} (weft bug):\n{}", module_name, target,
                compiler_status.message());
  return Internal("module " + module_name + " does not compile for " + target +
                  " (weft bug, please report it; the daemon log has the compiler's output)");
}

std::string SafeName(const std::string& name) {
  std::string out;
  for (char c : name) out += (std::isalnum(static_cast<unsigned char>(c)) || c == '_') ? c : '_';
  if (out.empty()) out = "module";
  return out.substr(0, 64);
}

class ModuleStoreImpl final : public ModuleStore {
 public:
  explicit ModuleStoreImpl(ModuleStoreOptions options) : options_(std::move(options)) {}

  Status Init() {
    if (options_.native_dir.empty()) options_.native_dir = WEFT_NATIVE_DIR;
    if (!options_.generate) options_.generate = DefaultGenerator();
    auto native_version = NativeLibraryVersion(options_.native_dir);
    if (!native_version.ok()) {
      return FailedPrecondition("module store: " + native_version.status().message());
    }
    context_.native_version = *native_version;
    context_.build_id = options_.build_id.empty() ? DefaultBuildId() : options_.build_id;
    context_.verified_for_cuda = options_.verify_cuda;
#if !WEFT_WITH_CUDA
    if (options_.verify_cuda) return FailedPrecondition("verify_cuda needs a build with NVRTC");
#endif
#if WEFT_WITH_CUDA
    if (auto version = jit::NvrtcVersion(); version.ok()) nvrtc_version_ = *version;
#endif
    if (options_.verify_cuda) {
      if (options_.verify_cuda_archs.empty()) options_.verify_cuda_archs = {options_.verify_cuda_sm};
      std::set<int> unique(options_.verify_cuda_archs.begin(), options_.verify_cuda_archs.end());
      options_.verify_cuda_archs.assign(unique.begin(), unique.end());
      std::string archs;
      for (int arch : options_.verify_cuda_archs) {
        if (Status known = CheckArch(arch); !known.ok()) return FailedPrecondition("verify_cuda: " + known.message());
        archs += (archs.empty() ? "" : ",") + std::to_string(arch);
      }
      // Modules checked for other architectures are other cache entries.
      if (archs != "90") context_.build_id += " verify-cuda=" + archs;
    }
    cache_ = std::make_unique<ModuleCache>(options_.cache_dir, options_.memory_capacity,
                                           options_.disk_capacity_bytes);
    WEFT_RETURN_IF_ERROR(cache_->Init());
#if WEFT_WITH_CPU_JIT
    jit::CpuJitOptions jit_options;
    jit_options.include_dirs = {options_.native_dir};
    jit_options.host_symbols = native::HostSymbols();  // print's snprintf, ...
    jit_options.compile_time_limit_s = options_.compile_time_limit_s;
    auto cpu_jit = jit::CpuJit::Create(jit_options);
    if (!cpu_jit.ok()) {
      // A native header that does not precompile must not keep the daemon down: every module
      // compile will then report the same clang errors.
      spdlog::error("module store: {}; compiling without a precompiled header",
                    cpu_jit.status().ToString());
      jit_options.pch_header.clear();
      cpu_jit = jit::CpuJit::Create(jit_options);
      if (!cpu_jit.ok()) return cpu_jit.status();
    }
    cpu_jit_ = std::move(*cpu_jit);
    compiler_child_ = jit::DefaultCompilerChild();
    context_.target_id = cpu_jit_->target_id();
#endif
    return Status::Ok();
  }

  Expected<std::shared_ptr<const LoadedModule>> Compile(const ModuleSource& source,
                                                        const std::string& device,
                                                        CompileReport* report) override {
    auto start = std::chrono::steady_clock::now();
    CompileReport local;
    if (!report) report = &local;
    WEFT_ASSIGN_OR_RETURN(DeviceRef where, ParseDevice(device));
    // The request's names and size are checked before it is hashed, cached or compiled.
    WEFT_RETURN_IF_ERROR(codegen::CheckModuleSource(source, options_.limits));
    Variant variant = VariantOf(source, where.target);
    if (where.target == Target::kCuda) {
      WEFT_ASSIGN_OR_RETURN(variant.sm, CudaArchitecture(where.ordinal));
    }

    const std::string id = Key(variant);
    // A CUDA module with bounds checks: its trusted-index variant, which launches proven in
    // range take, is built beside it (one more thread), so that the first such launch does not
    // wait for a second NVRTC compile after this one.
    std::thread beside;
    if (where.target == Target::kCuda && variant.codegen.bounds_checks && options_.build_trusted_beside &&
        !cache_->Peek(id)) {
      try {
        beside = std::thread([this, &variant, &id] { BuildTrustedBeside(variant, id); });
      } catch (const std::system_error& e) {   // no thread to be had: the first launch builds it
        spdlog::warn("module {}: no thread for its trusted-index variant ({})", id, e.what());
      }
    }
    ModuleCache::Source from = ModuleCache::Source::kBuilt;
    auto module = Get(id, id, variant, &from, &report->diagnostics);
    if (beside.joinable()) beside.join();
    report->cache_hit = module.ok() && from == ModuleCache::Source::kMemory;
    report->disk_hit = module.ok() && from == ModuleCache::Source::kDisk;
    report->compile_ms = std::chrono::duration<double, std::milli>(
                             std::chrono::steady_clock::now() - start).count();
    if (!module.ok()) return module.status();
    std::lock_guard<std::mutex> lock(registry_mutex_);
    auto& entry = registry_[id];
    if (!entry.known) {
      entry.known = true;
      entry.variant = std::move(variant);
    }
    entry.forward = *module;
    return *module;
  }

  Expected<CudaArchCompile> CompileForArch(const ModuleSource& source, int arch, CompileReport* report) override {
#if WEFT_WITH_CUDA
    auto start = std::chrono::steady_clock::now();
    CompileReport local;
    if (!report) report = &local;
    WEFT_RETURN_IF_ERROR(CheckArch(arch));
    WEFT_RETURN_IF_ERROR(codegen::CheckModuleSource(source, options_.limits));
    Variant variant = VariantOf(source, Target::kCuda);
    variant.sm = arch;
    // The adjoint entry points too, unless the module turns them off (Warp's enable_backward).
    auto backward = source.options.find("enable_backward");
    variant.codegen.enable_backward =
        backward == source.options.end() ||
        (backward->second != "false" && backward->second != "False" && backward->second != "0");
    const std::string key = Key(variant);
    ModuleCache::Source from = ModuleCache::Source::kBuilt;
    auto module = Get(key, key, variant, &from, &report->diagnostics);
    report->cache_hit = module.ok() && from == ModuleCache::Source::kMemory;
    report->disk_hit = module.ok() && from == ModuleCache::Source::kDisk;
    report->compile_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (!module.ok()) return module.status();
    CudaArchCompile out;
    out.arch = arch;
    out.image = (*module)->cuda_image;
    out.nvrtc_version = nvrtc_version_;
    auto cubin = jit::ParseCubin(out.image);
    if (!cubin.ok()) return Internal("module " + source.name + ": NVRTC's CUBIN for sm_" + std::to_string(arch) +
                                     " cannot be read (weft bug): " + cubin.status().message());
    if (cubin->sm != static_cast<uint32_t>(arch))
      return Internal("module " + source.name + ": NVRTC built sm_" + std::to_string(cubin->sm) + " for sm_" +
                      std::to_string(arch) + " (weft bug)");
    for (const LoadedKernel& k : (*module)->kernels) {
      for (bool adjoint : {false, true}) {
        const std::string& symbol = adjoint ? k.layout.backward_symbol : k.layout.forward_symbol;
        if (symbol.empty()) continue;
        const jit::CubinKernelInfo* info = cubin->Find(symbol);
        if (!info) return Internal("module " + source.name + ": entry point " + symbol + " missing from the CUBIN");
        CudaKernelReport r;
        r.kernel = k.layout.name;
        r.adjoint = adjoint;
        r.symbol = symbol;
        r.registers = info->registers;
        r.code_bytes = info->code_bytes;
        r.shared_bytes = info->shared_bytes;
        r.local_bytes = info->local_bytes;
        r.const_bytes = info->const_bytes;
        out.kernels.push_back(std::move(r));
      }
    }
    return out;
#else
    (void)source, (void)arch, (void)report;
    return Unimplemented("this weft was built without CUDA (NVRTC)");
#endif
  }

  std::shared_ptr<const LoadedModule> Find(const std::string& module_id) const override {
    Variant variant;
    {
      std::lock_guard<std::mutex> lock(registry_mutex_);
      auto it = registry_.find(module_id);
      if (it == registry_.end()) return nullptr;
      if (auto alive = it->second.forward.lock()) return alive;
      variant = it->second.variant;
    }
    // Evicted and dropped by everyone: bring it back (memory, disk, or a rebuild).
    auto module = Get(module_id, module_id, variant, nullptr, nullptr);
    if (!module.ok()) return nullptr;
    std::lock_guard<std::mutex> lock(registry_mutex_);
    registry_[module_id].forward = *module;
    return *module;
  }

  Expected<std::shared_ptr<const LoadedModule>> WithBackward(const std::string& module_id) override {
    Variant variant;
    {
      std::lock_guard<std::mutex> lock(registry_mutex_);
      auto it = registry_.find(module_id);
      if (it == registry_.end()) return NotFound("unknown module id " + module_id);
      if (auto alive = it->second.backward.lock()) return alive;
      variant = it->second.variant;
    }
    variant.codegen.enable_backward = true;
    WEFT_ASSIGN_OR_RETURN(ModuleCache::Module module, GetVariant(module_id, variant));
    std::lock_guard<std::mutex> lock(registry_mutex_);
    registry_[module_id].backward = module;
    return module;
  }

  Expected<std::shared_ptr<const LoadedModule>> WithGridStride(const std::string& module_id, bool backward) override {
    return DerivedVariant(module_id, &Registered::strided, backward, [&](Variant& variant) -> Status {
      if (variant.codegen.target != Target::kCuda)
        return FailedPrecondition("module " + module_id + " is compiled for the CPU, whose entries take index ranges");
      if (!variant.stride_allowed)
        return FailedPrecondition("module " + module_id + " was compiled without a grid-stride loop (grid_stride=False)");
      variant.codegen.grid_stride = true;
      return Status::Ok();
    });
  }

  Expected<std::shared_ptr<const LoadedModule>> WithTrustedTidIndices(const std::string& module_id,
                                                                     bool backward) override {
    return DerivedVariant(module_id, &Registered::trusted, backward, [&](Variant& variant) -> Status {
      if (variant.codegen.target != Target::kCuda || !variant.codegen.bounds_checks)
        return FailedPrecondition("module " + module_id + " has no trusted-index variant");
      variant.codegen.trust_tid_indices = true;
      return Status::Ok();
    });
  }

  ModuleStoreStats stats() const override { return cache_->stats(); }

 private:
  // What one module id stands for: the source, how it is generated, and (CUDA) for which sm.
  struct Variant {
    ModuleSource source;
    CodegenOptions codegen;
    int sm = 0;  // CUDA compute capability * 10
    // CUDA: a grid-stride variant may be built for launches that need the loop (the module did
    // not ask for grid_stride=False).
    bool stride_allowed = true;
  };
  struct Registered {
    bool known = false;
    Variant variant;
    std::weak_ptr<const LoadedModule> forward;
    std::weak_ptr<const LoadedModule> backward;
    std::weak_ptr<const LoadedModule> strided[2];   // WithGridStride: forward only, with backward
    std::weak_ptr<const LoadedModule> trusted[2];   // WithTrustedTidIndices: the same
  };

  // A variant of a registered module (grid-stride, trusted-index), forward only or with
  // backward, kept in `slots` of its registry entry while it is alive: `adjust` turns the
  // module's own variant into it (or refuses).
  Expected<std::shared_ptr<const LoadedModule>> DerivedVariant(
      const std::string& module_id, std::weak_ptr<const LoadedModule> (Registered::*slots)[2], bool backward,
      const std::function<Status(Variant&)>& adjust) {
    Variant variant;
    {
      std::lock_guard<std::mutex> lock(registry_mutex_);
      auto it = registry_.find(module_id);
      if (it == registry_.end()) return NotFound("unknown module id " + module_id);
      if (auto alive = (it->second.*slots)[backward ? 1 : 0].lock()) return alive;
      variant = it->second.variant;
    }
    WEFT_RETURN_IF_ERROR(adjust(variant));
    variant.codegen.enable_backward = backward;
    WEFT_ASSIGN_OR_RETURN(ModuleCache::Module module, GetVariant(module_id, variant));
    std::lock_guard<std::mutex> lock(registry_mutex_);
    (registry_[module_id].*slots)[backward ? 1 : 0] = module;
    return module;
  }

  // The forward trusted-index variant of `variant` (module `id`), as WithTrustedTidIndices asks
  // for it, built or loaded into the cache when some kernel indexes a parameter by the thread
  // (so it may be used); errors stay here: the first launch that needs it asks again.
  void BuildTrustedBeside(const Variant& variant, const std::string& id) const {
    Variant trusted = variant;
    trusted.codegen.trust_tid_indices = true;
    trusted.codegen.enable_backward = false;
    std::vector<Diagnostic> ignored;
    auto generated = options_.generate(trusted.source, trusted.codegen, &ignored);
    if (!generated.ok()) return;
    bool indexed_by_thread = false;
    for (const KernelLayout& k : generated->kernels) indexed_by_thread |= !k.tid_indexed_params.empty();
    if (!indexed_by_thread) return;
    ModuleCache::Callbacks callbacks;   // Get's, building from the code generated above
    callbacks.build = [&](std::vector<Diagnostic>* diags) { return BuildGenerated(trusted, std::move(*generated), diags); };
    callbacks.load = [&](const ModuleArtifact& artifact) { return Load(artifact, id, trusted); };
    auto module = cache_->Get(Key(trusted), callbacks, nullptr, &ignored);
    if (!module.ok()) spdlog::warn("module {}: its trusted-index variant built beside it failed: {}", id,
                                   module.status().message());
  }

  // How `source` is generated for `target` (the module options that change the code).
  Variant VariantOf(const ModuleSource& source, Target target) const {
    Variant variant;
    variant.source = source;
    variant.codegen.target = target;
    variant.codegen.max_block_depth = options_.limits.max_block_depth;
    variant.codegen.max_expression_depth = options_.limits.max_expression_depth;
    auto checks = source.options.find("bounds_checks");
    variant.codegen.bounds_checks =
        checks == source.options.end() ||
        (checks->second != "false" && checks->second != "False" && checks->second != "0");
    auto poll = source.options.find("cancel_poll");
    variant.codegen.loop_cancel_poll =
        poll == source.options.end() || (poll->second != "false" && poll->second != "False" && poll->second != "0");
    // CUDA entries run one index per thread: with a grid-stride loop around an inlined body the
    // compiler hoists the body's loop-invariant work (the bounds checks' error paths) into every
    // thread's prologue, which costs a memory-bound kernel 15% on an H200 (docs/cuda.md, "The
    // entry without a loop"). A launch that needs the loop gets the grid-stride variant
    // (WithGridStride), unless the module asked for grid_stride=False.
    auto stride = source.options.find("grid_stride");
    variant.stride_allowed =
        stride == source.options.end() || (stride->second != "false" && stride->second != "False" && stride->second != "0");
    variant.codegen.grid_stride = false;
    const int lanes = CpuLanesOption(source);   // 0 (malformed) is refused by the checker
    variant.codegen.cpu_lanes = target == Target::kCpu && lanes > 1 ? static_cast<uint32_t>(lanes) : 1;
    return variant;
  }

  // An architecture a client asked for: one of kCudaArchs that this NVRTC supports.
  static Status CheckArch(int arch) {
    std::string known;
    bool found = false;
    for (int a : kCudaArchs) {
#if WEFT_WITH_CUDA
      if (!jit::NvrtcSupportsArch(a)) continue;
#endif
      known += (known.empty() ? "" : ", ") + std::to_string(a);
      found = found || a == arch;
    }
    if (found) return Status::Ok();
    return InvalidArgument("unknown CUDA architecture " + std::to_string(arch) + " (this daemon's NVRTC compiles for " +
                           (known.empty() ? std::string("none") : known) + ")");
  }

  std::string Key(const Variant& variant) const {
    if (variant.codegen.target == Target::kCpu) {
      return ModuleCacheKey(variant.source, variant.codegen, context_);
    }
    ModuleKeyContext cuda = context_;
    cuda.target_id = "cuda;sm=" + std::to_string(variant.sm) + ";nvrtc=" + nvrtc_version_;
    return ModuleCacheKey(variant.source, variant.codegen, cuda);
  }

  // The architecture to compile cuda:N for: the device's own when a driver is present,
  // else verify_cuda_sm (compile-only machines).
  Expected<int> CudaArchitecture(int ordinal) const {
#if WEFT_WITH_CUDA
    auto driver = jit::CudaDriver::Get();
    if (!driver.ok()) return options_.verify_cuda_sm;
    int count = 0;
    WEFT_RETURN_IF_ERROR((*driver)->Check((*driver)->DeviceGetCount(&count), "cuDeviceGetCount"));
    if (ordinal < 0 || ordinal >= count) {
      return InvalidArgument("no device cuda:" + std::to_string(ordinal) + " (" +
                             std::to_string(count) + " CUDA devices)");
    }
    return (*driver)->ComputeCapability(ordinal);
#else
    return Unimplemented("this weft was built without CUDA");
#endif
  }

  // Another variant of module `module_id` (backward entries, grid-stride entries): compiled on
  // first request, its compiler diagnostics appended to the error.
  Expected<ModuleCache::Module> GetVariant(const std::string& module_id, const Variant& variant) const {
    std::vector<Diagnostic> diagnostics;
    auto module = Get(Key(variant), module_id, variant, nullptr, &diagnostics);
    if (module.ok()) return module;
    std::string text = module.status().message();
    for (const auto& d : diagnostics) text += "\n" + d.ToString();
    return Status(module.status().code(), text);
  }

  // The module of cache key `key`, presented to clients as module `id`.
  Expected<ModuleCache::Module> Get(const std::string& key, const std::string& id,
                                    const Variant& variant, ModuleCache::Source* from,
                                    std::vector<Diagnostic>* diagnostics) const {
    ModuleCache::Callbacks callbacks;
    callbacks.build = [&](std::vector<Diagnostic>* diags) { return Build(variant, diags); };
    callbacks.load = [&](const ModuleArtifact& artifact) { return Load(artifact, id, variant); };
    return cache_->Get(key, callbacks, from, diagnostics);
  }

#if WEFT_WITH_CUDA
  // CUBIN for an architecture NVRTC knows, else PTX for the newest virtual one it knows (the
  // driver JIT-compiles it at load).
  jit::NvrtcOptions NvrtcFor(int sm) const {
    jit::NvrtcOptions nvrtc;
    nvrtc.sm = sm;
    nvrtc.include_dirs = {options_.native_dir};
    if (!jit::NvrtcSupportsArch(sm)) {
      nvrtc.cubin = false;
      int best = 0;
      for (int a : {52, 60, 70, 75, 80, 86, 89, 90, 100, 120})
        if (a <= sm && jit::NvrtcSupportsArch(a)) best = a;
      if (best) nvrtc.sm = best;
    }
    return nvrtc;
  }

 public:
  Expected<std::string> CompileCudaSource(const std::string& source, const std::string& name, int sm) override {
    auto compiled = jit::NvrtcCompile(source, name, NvrtcFor(sm));
    if (!compiled.ok()) return compiled.status();
    return std::move(compiled->image);
  }

 private:
  // NVRTC under the compile time limit: in a child process (weft-cc --nvrtc) killed when the
  // limit passes, as clang's compiles; in process when there is no limit (or no CPU JIT, whose
  // weft-cc it is).
  Expected<jit::NvrtcOutput> NvrtcBounded(const std::string& source, const std::string& name,
                                          const jit::NvrtcOptions& nvrtc) const {
#if WEFT_WITH_CPU_JIT
    const double limit = options_.compile_time_limit_s;
    if (limit > 0) {
      const std::string target = std::string("CUDA ") + (nvrtc.cubin ? "sm_" : "compute_") + std::to_string(nvrtc.sm);
      auto image = jit::CompileInChild(compiler_child_, jit::NvrtcChildArgs(nvrtc, name, limit), source, name, limit,
                                       target + " (NVRTC)");
      if (!image.ok()) return image.status();
      jit::NvrtcOutput out;
      out.image = std::move(*image);
      out.is_cubin = nvrtc.cubin;
      return out;
    }
#endif
    return jit::NvrtcCompile(source, name, nvrtc);
  }

  // NVRTC for `sm`; a rejection is a weft bug (Internal) with the log as diagnostics too.
  // `bounded`: under the compile time limit (a module a client compiles for a GPU or an
  // architecture); verify_cuda's checks run in process, unbounded, as a development check.
  Expected<std::string> CompileCuda(const ModuleSource& source, const std::string& cuda_source,
                                    int sm, std::vector<Diagnostic>* diags, bool bounded = true) const {
    jit::NvrtcOptions nvrtc = NvrtcFor(sm);
    // Warp's module options: fast_math, lineinfo, mode="debug".
    auto flag = [&](const char* option) {
      auto it = source.options.find(option);
      return it != source.options.end() && (it->second == "true" || it->second == "True" || it->second == "1");
    };
    // No FMA contraction unless fast_math: the CPU JIT compiles with -ffp-contract=off, so a
    // kernel gives the same float results on both (and matches NumPy's separate roundings).
    nvrtc.extra_flags.push_back(flag("fast_math") ? "--use_fast_math" : "--fmad=false");
    if (flag("lineinfo")) nvrtc.extra_flags.push_back("-lineinfo");
    if (auto mode = source.options.find("mode"); mode != source.options.end() && mode->second == "debug")
      nvrtc.extra_flags.push_back("-G");
    const std::string main_file = SafeName(source.name) + ".cu";
    auto compiled = bounded ? NvrtcBounded(cuda_source, main_file, nvrtc) : jit::NvrtcCompile(cuda_source, main_file, nvrtc);
    // The compile time limit (the client's module) or the daemon stopping: not a weft bug.
    if (!compiled.ok() && (compiled.status().code() == StatusCode::kResourceExhausted ||
                           compiled.status().code() == StatusCode::kUnavailable))
      return compiled.status();
    if (!compiled.ok()) {
      AppendCompilerDiagnostics(compiled.status().message(), main_file, source, diags);
      return GeneratedCodeRejected(source.name, "CUDA sm_" + std::to_string(sm) + " (NVRTC)", compiled.status());
    }
    return std::move(compiled->image);
  }
#endif

#if WEFT_WITH_CUDA
  // verify_cuda: the CUDA flavour of a CPU module compiled by NVRTC for every architecture of
  // verify_cuda_archs, one thread each (NVRTC calls are independent).
  Status VerifyCuda(const Variant& variant, std::vector<Diagnostic>* diags) const {
    CodegenOptions cuda = variant.codegen;
    cuda.target = Target::kCuda;
    WEFT_ASSIGN_OR_RETURN(GeneratedModule cuda_module, options_.generate(variant.source, cuda, diags));
    const auto& archs = options_.verify_cuda_archs;
    std::vector<Status> results(archs.size());
    std::vector<std::vector<Diagnostic>> found(archs.size());
    auto check = [&](size_t i) {
      results[i] = CompileCuda(variant.source, cuda_module.source, archs[i], &found[i], /*bounded=*/false).status();
    };
    std::vector<std::thread> threads;
    for (size_t i = 1; i < archs.size(); ++i) threads.emplace_back(check, i);
    if (!archs.empty()) check(0);
    for (auto& t : threads) t.join();
    for (size_t i = 0; i < archs.size(); ++i) {
      if (results[i].ok()) continue;
      diags->insert(diags->end(), found[i].begin(), found[i].end());
      return results[i];
    }
    return Status::Ok();
  }
#else
  Status VerifyCuda(const Variant&, std::vector<Diagnostic>*) const { return Status::Ok(); }
#endif

  Expected<ModuleArtifact> Build(const Variant& variant, std::vector<Diagnostic>* diags) const {
    WEFT_ASSIGN_OR_RETURN(GeneratedModule generated, options_.generate(variant.source, variant.codegen, diags));
    return BuildGenerated(variant, std::move(generated), diags);
  }

  // Build's compile step, for code generated from `variant`.
  Expected<ModuleArtifact> BuildGenerated(const Variant& variant, GeneratedModule generated,
                                          std::vector<Diagnostic>* diags) const {
    const ModuleSource& source = variant.source;
    ModuleArtifact artifact;
    if (variant.codegen.target == Target::kCuda) {
#if WEFT_WITH_CUDA
      WEFT_ASSIGN_OR_RETURN(artifact.object, CompileCuda(source, generated.source, variant.sm, diags));
#else
      return Unimplemented("this weft was built without CUDA");
#endif
    } else {
#if WEFT_WITH_CUDA
      if (options_.verify_cuda) WEFT_RETURN_IF_ERROR(VerifyCuda(variant, diags));
#endif
#if WEFT_WITH_CPU_JIT
      const std::string main_file = SafeName(source.name);
      auto object = cpu_jit_->Compile(generated.source, main_file);
      // The compile time limit (the client's module) or the daemon stopping: not a weft bug.
      if (!object.ok() && (object.status().code() == StatusCode::kResourceExhausted ||
                           object.status().code() == StatusCode::kUnavailable))
        return object.status();
      if (!object.ok()) {
        AppendCompilerDiagnostics(object.status().message(), main_file, source, diags);
        return GeneratedCodeRejected(source.name, "the CPU (clang)", object.status());
      }
      artifact.object = std::move(*object);
#else
      return Unimplemented("this weft was built without the CPU JIT");
#endif
    }
    artifact.kernels = std::move(generated.kernels);
    artifact.function_names = std::move(generated.function_names);
    artifact.generated_source = std::move(generated.source);
    return artifact;
  }

  Expected<ModuleCache::Module> Load(const ModuleArtifact& artifact, const std::string& id,
                                     const Variant& variant) const {
    const bool backward = variant.codegen.enable_backward;
    if (variant.codegen.target == Target::kCuda) {
      auto module = std::make_shared<LoadedModule>();
      module->id = id;
      module->target = Target::kCuda;
      module->function_names = artifact.function_names;
      module->has_backward = backward;
      module->grid_stride = variant.codegen.grid_stride;
      module->trusts_tid_indices = variant.codegen.trust_tid_indices;
      module->cuda_image = artifact.object;
      module->cuda_sm = variant.sm;
      for (const KernelLayout& layout : artifact.kernels) {
        LoadedKernel kernel;
        kernel.layout = layout;
        module->kernels.push_back(std::move(kernel));
      }
      return ModuleCache::Module(std::move(module));
    }
#if WEFT_WITH_CPU_JIT
    WEFT_ASSIGN_OR_RETURN(std::shared_ptr<jit::CpuCode> code,
                          cpu_jit_->Load(artifact.object, SafeName(variant.source.name)));
    auto module = std::make_shared<CpuLoadedModule>();
    module->id = id;
    module->target = Target::kCpu;
    module->function_names = artifact.function_names;
    module->has_backward = backward;
    module->code = code;
    for (const KernelLayout& layout : artifact.kernels) {
      LoadedKernel kernel;
      kernel.layout = layout;
      WEFT_ASSIGN_OR_RETURN(void* forward, code->Lookup(layout.forward_symbol));
      kernel.cpu_forward = reinterpret_cast<CpuForwardFn>(forward);
      if (backward && !layout.backward_symbol.empty()) {
        WEFT_ASSIGN_OR_RETURN(void* adjoint, code->Lookup(layout.backward_symbol));
        kernel.cpu_backward = reinterpret_cast<CpuBackwardFn>(adjoint);
      }
      module->kernels.push_back(std::move(kernel));
    }
    return ModuleCache::Module(std::move(module));
#else
    return Unimplemented("this weft was built without the CPU JIT");
#endif
  }

  ModuleStoreOptions options_;
  ModuleKeyContext context_;
  std::string nvrtc_version_ = "none";
  std::unique_ptr<ModuleCache> cache_;
#if WEFT_WITH_CPU_JIT
  std::unique_ptr<jit::CpuJit> cpu_jit_;
  std::string compiler_child_;   // weft-cc: clang's and NVRTC's compiles under the time limit
#endif
  mutable std::mutex registry_mutex_;
  mutable std::unordered_map<std::string, Registered> registry_;
};

}  // namespace

Expected<std::unique_ptr<ModuleStore>> ModuleStore::Create(const ModuleStoreOptions& options) {
  auto store = std::make_unique<ModuleStoreImpl>(options);
  WEFT_RETURN_IF_ERROR(store->Init());
  return std::unique_ptr<ModuleStore>(std::move(store));
}

}  // namespace weft
