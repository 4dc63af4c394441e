// CpuJit: in-process clang (CompilerInstance, EmitObj into memory) + ORC LLJIT.
// The driver runs once, in Create, to turn flags into a CompilerInvocation; every compile copies
// that invocation, so a compile costs only the frontend and the backend.
#include "engine/jit/cpu/cpu_jit.h"

#include "engine/jit/cpu/compile_process.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <sstream>

#include <unistd.h>

#include "clang/Basic/Diagnostic.h"
#include "clang/Basic/DiagnosticOptions.h"
#include "clang/CodeGen/CodeGenAction.h"
#include "clang/Frontend/CompilerInstance.h"
#include "clang/Frontend/CompilerInvocation.h"
#include "clang/Frontend/FrontendActions.h"
#include "clang/Frontend/TextDiagnosticPrinter.h"
#include "clang/Frontend/Utils.h"
#include "clang/Lex/PreprocessorOptions.h"
#include "llvm/ADT/SmallString.h"
#include "llvm/ExecutionEngine/Orc/Core.h"
#include "llvm/ExecutionEngine/Orc/LLJIT.h"
#include "llvm/Support/FileSystem.h"
#include "llvm/Support/MemoryBuffer.h"
#include "llvm/Support/Path.h"
#include "llvm/Support/TargetSelect.h"
#include "llvm/Support/raw_ostream.h"
#include "llvm/Config/llvm-config.h"
#include "llvm/TargetParser/Host.h"
#include "spdlog/spdlog.h"

namespace weft::jit {
namespace {

double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

std::string ToString(llvm::Error error) { return llvm::toString(std::move(error)); }

void InitializeLlvmOnce() {
  static std::once_flag once;
  std::call_once(once, [] {
    llvm::InitializeNativeTarget();
    llvm::InitializeNativeTargetAsmPrinter();
    llvm::InitializeNativeTargetAsmParser();
  });
}

// A compiler instance whose diagnostics land in a string.
struct DiagnosticsToString {
  std::string text;
  llvm::raw_string_ostream stream{text};
};

bool FileExists(const std::string& path) { return llvm::sys::fs::exists(path); }

}  // namespace

// The LLJIT instance, shared by CpuJit and every CpuCode so code never outlives its session.
// LLJIT's destructor ends the ExecutionSession (removes every JITDylib, frees all code).
struct JitSession {
  std::unique_ptr<llvm::orc::LLJIT> lljit;
  std::atomic<uint64_t> next_dylib{0};
};

struct CpuCode::State {
  std::shared_ptr<JitSession> session;
  llvm::orc::JITDylib* dylib = nullptr;
};

CpuCode::CpuCode(std::unique_ptr<State> state) : state_(std::move(state)) {}

CpuCode::~CpuCode() {
  if (!state_ || !state_->dylib) return;
  auto& es = state_->session->lljit->getExecutionSession();
  if (auto error = es.removeJITDylib(*state_->dylib)) {
    spdlog::warn("weft cpu jit: removing module code failed: {}", ToString(std::move(error)));
  }
}

Expected<void*> CpuCode::Lookup(std::string_view symbol) const {
  auto address = state_->session->lljit->lookup(*state_->dylib, llvm::StringRef(symbol));
  if (!address) {
    std::string message = ToString(address.takeError());
    if (message.find("Symbols not found") != std::string::npos &&
        message.find(std::string(symbol)) != std::string::npos) {
      return NotFound("symbol not found in module: " + std::string(symbol) + " (" + message + ")");
    }
    return Internal("linking JIT code failed: " + message);
  }
  return address->toPtr<void*>();
}

struct CpuJit::Impl {
  CpuJitOptions options;
  std::shared_ptr<clang::CompilerInvocation> base_invocation;  // driver output, no inputs
  std::string pch_path;       // empty = no PCH
  bool owns_pch = true;       // built here (removed with the CpuJit), not a parent's
  double pch_build_ms = 0;
  std::string target_id;
  std::shared_ptr<JitSession> session;   // null when compile_only
  std::string compiler_child;            // with a compile time limit

  ~Impl() {
    if (!pch_path.empty() && owns_pch) llvm::sys::fs::remove(pch_path);
  }

  // A fresh invocation for one compile of `input` (a path, or a remapped in-memory file).
  std::shared_ptr<clang::CompilerInvocation> NewInvocation() const {
    auto invocation = std::make_shared<clang::CompilerInvocation>(*base_invocation);
    invocation->getFrontendOpts().DisableFree = false;   // else ~0.5-0.9 MB leak per compile
    invocation->getCodeGenOpts().DisableFree = false;
    invocation->getFrontendOpts().Inputs.clear();
    return invocation;
  }

  // Runs `action` on a compiler instance; false + diagnostics text on failure.
  static bool Run(const std::shared_ptr<clang::CompilerInvocation>& invocation,
                  clang::FrontendAction& action, std::unique_ptr<llvm::raw_pwrite_stream> output,
                  std::string* diagnostics) {
    DiagnosticsToString diags;
    clang::CompilerInstance compiler;
    compiler.setInvocation(invocation);
    compiler.createDiagnostics(
        new clang::TextDiagnosticPrinter(diags.stream, &invocation->getDiagnosticOpts()),
        /*ShouldOwnClient=*/true);
    compiler.setVerboseOutputStream(diags.stream);
    if (output) compiler.setOutputStream(std::move(output));
    bool ok = compiler.ExecuteAction(action) && !compiler.getDiagnostics().hasErrorOccurred();
    diags.stream.flush();
    *diagnostics = std::move(diags.text);
    return ok;
  }

  Status BuildPch(const std::string& header_path) {
    std::string dir = options.pch_dir;
    if (dir.empty()) {
      const char* tmp = std::getenv("TMPDIR");
      dir = tmp && *tmp ? tmp : "/tmp";
    }
    llvm::SmallString<256> model(dir);
    llvm::sys::path::append(model, "weft-native-%%%%%%%%.pch");
    llvm::SmallString<256> path;
    int fd = -1;
    if (auto ec = llvm::sys::fs::createUniqueFile(model, fd, path)) {
      return Internal("cannot create the PCH file in " + dir + ": " + ec.message());
    }
    ::close(fd);

    auto start = std::chrono::steady_clock::now();
    auto invocation = NewInvocation();
    auto& frontend = invocation->getFrontendOpts();
    frontend.Inputs.emplace_back(
        header_path, clang::InputKind(clang::Language::CXX, clang::InputKind::Source,
                                      /*PP=*/false, clang::InputKind::HeaderUnit_None,
                                      /*HD=*/true));
    frontend.OutputFile = std::string(path);
    frontend.ProgramAction = clang::frontend::GeneratePCH;
    clang::GeneratePCHAction action;
    std::string diagnostics;
    if (!Run(invocation, action, nullptr, &diagnostics)) {
      llvm::sys::fs::remove(path);
      return Internal("precompiling " + header_path + " failed:\n" + diagnostics);
    }
    pch_path = std::string(path);
    pch_build_ms = MillisecondsSince(start);
    return Status::Ok();
  }
};

CpuJit::CpuJit(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
CpuJit::~CpuJit() = default;

Expected<std::unique_ptr<CpuJit>> CpuJit::Create(const CpuJitOptions& options) {
  InitializeLlvmOnce();
  auto impl = std::make_unique<Impl>();
  impl->options = options;

  // Driver flags. No standard headers: the native library uses compiler builtins only.
  std::vector<std::string> flags = {
      "-x", "c++", "-std=c++17", "-O" + std::to_string(options.opt_level),
      "-fPIC",                // JITLink places code anywhere; calls into the process go via GOT/PLT
      "-fno-exceptions", "-fno-rtti", "-fno-math-errno",
      "-ffp-contract=off",    // same float results as the reference (no FMA contraction)
      "-nostdinc", "-w",
  };
  if (options.native_cpu) flags.push_back("-march=native");
  for (const auto& dir : options.include_dirs) flags.push_back("-I" + dir);
  for (const auto& flag : options.extra_flags) flags.push_back(flag);

  std::vector<const char*> argv = {"clang++"};
  for (const auto& f : flags) argv.push_back(f.c_str());
  argv.push_back("-c");
  argv.push_back("-");  // stdin: the driver does not check that it exists

  DiagnosticsToString driver_diags;
  // DiagnosticOptions are reference counted: heap-allocate them, never point at a local.
  llvm::IntrusiveRefCntPtr<clang::DiagnosticOptions> driver_diag_options(
      new clang::DiagnosticOptions());
  clang::CreateInvocationOptions create_options;
  create_options.Diags = clang::CompilerInstance::createDiagnostics(
      driver_diag_options.get(),
      new clang::TextDiagnosticPrinter(driver_diags.stream, driver_diag_options.get()),
      /*ShouldOwnClient=*/true);
  std::shared_ptr<clang::CompilerInvocation> invocation = clang::createInvocation(argv, create_options);
  driver_diags.stream.flush();
  if (!invocation) return Internal("clang driver rejected the JIT flags:\n" + driver_diags.text);
  invocation->getFrontendOpts().Inputs.clear();
  invocation->getFrontendOpts().ProgramAction = clang::frontend::EmitObj;
  impl->base_invocation = std::move(invocation);

  // What the object code depends on, for the module cache key.
  const auto& target_options = impl->base_invocation->getTargetOpts();
  std::vector<std::string> features = target_options.FeaturesAsWritten;
  std::sort(features.begin(), features.end());
  std::ostringstream id;
  id << "triple=" << target_options.Triple << ";cpu=" << target_options.CPU
     << ";llvm=" << LLVM_VERSION_STRING << ";flags=";
  for (const auto& f : flags) id << f << ' ';
  id << ";features=";
  for (const auto& f : features) id << f << ',';
  impl->target_id = id.str();

  if (options.compile_time_limit_s > 0) {
    impl->compiler_child = options.compiler_child.empty() ? DefaultCompilerChild() : options.compiler_child;
    if (::access(impl->compiler_child.c_str(), X_OK) != 0)
      return FailedPrecondition("the compiler process " + impl->compiler_child +
                                " (needed for a compile time limit) is missing or not executable");
  }
  if (!options.existing_pch.empty()) {
    if (!FileExists(options.existing_pch)) return FailedPrecondition("no PCH file " + options.existing_pch);
    impl->pch_path = options.existing_pch;
    impl->owns_pch = false;
  }
  if (options.compile_only) return std::unique_ptr<CpuJit>(new CpuJit(std::move(impl)));

  // The JIT.
  auto lljit = llvm::orc::LLJITBuilder().create();
  if (!lljit) return Internal("cannot create the LLVM JIT: " + ToString(lljit.takeError()));
  impl->session = std::make_shared<JitSession>();
  impl->session->lljit = std::move(*lljit);
  // Link errors also come back from Lookup as a Status; log them instead of printing to stderr.
  impl->session->lljit->getExecutionSession().setErrorReporter([](llvm::Error error) {
    spdlog::warn("weft cpu jit: {}", ToString(std::move(error)));
  });
  if (!options.host_symbols.empty()) {
    auto& jit = *impl->session->lljit;
    llvm::orc::SymbolMap symbols;
    for (const auto& [name, address] : options.host_symbols) {
      symbols[jit.mangleAndIntern(name)] = {
          llvm::orc::ExecutorAddr::fromPtr(address),
          llvm::JITSymbolFlags::Exported | llvm::JITSymbolFlags::Callable};
    }
    auto process = jit.getProcessSymbolsJITDylib();
    if (!process) return Internal("the LLVM JIT has no process-symbols library");
    if (auto error = process->define(llvm::orc::absoluteSymbols(std::move(symbols)))) {
      return Internal("cannot define host symbols: " + ToString(std::move(error)));
    }
  }

  // The precompiled native header, once.
  if (!options.pch_header.empty() && impl->pch_path.empty()) {
    for (const auto& dir : options.include_dirs) {
      llvm::SmallString<256> candidate(dir);
      llvm::sys::path::append(candidate, options.pch_header);
      if (!FileExists(std::string(candidate))) continue;
      llvm::sys::fs::make_absolute(candidate);
      WEFT_RETURN_IF_ERROR(impl->BuildPch(std::string(candidate)));
      break;
    }
  }
  return std::unique_ptr<CpuJit>(new CpuJit(std::move(impl)));
}

Expected<std::string> CpuJit::Compile(std::string_view source, std::string_view name,
                                      CpuCompileTimes* times) {
  auto start = std::chrono::steady_clock::now();
  std::string file_name(name.empty() ? "weft_module" : name);
  if (llvm::sys::path::extension(file_name).empty()) file_name += ".cpp";
  if (impl_->options.compile_time_limit_s > 0) {
    const double limit = impl_->options.compile_time_limit_s;
    auto object = CompileInChild(impl_->compiler_child,
                                 CompilerChildArgs(impl_->options, impl_->pch_path, file_name, limit), source,
                                 file_name, limit);
    const double ms = MillisecondsSince(start);
    if (times) times->frontend_and_codegen_ms = ms;
    spdlog::debug("cpu jit: {} ({} bytes of C++) in a child process: {:.1f} ms{}", file_name, source.size(), ms,
                  object.ok() ? "" : " (" + object.status().message().substr(0, 80) + ")");
    return object;
  }

  auto invocation = impl_->NewInvocation();
  invocation->getFrontendOpts().Inputs.emplace_back(file_name,
                                                    clang::InputKind(clang::Language::CXX));
  invocation->getFrontendOpts().OutputFile = "-";
  invocation->getFrontendOpts().ProgramAction = clang::frontend::EmitObj;
  auto& preprocessor = invocation->getPreprocessorOpts();
  preprocessor.addRemappedFile(
      file_name, llvm::MemoryBuffer::getMemBufferCopy(llvm::StringRef(source), file_name).release());
  preprocessor.RetainRemappedFileBuffers = false;  // the compiler frees the buffer
  if (!impl_->pch_path.empty()) preprocessor.ImplicitPCHInclude = impl_->pch_path;

  auto object = std::make_shared<llvm::SmallString<0>>();
  auto stream = std::make_unique<llvm::raw_svector_ostream>(*object);
  clang::EmitObjAction action;
  std::string diagnostics;
  bool ok = Impl::Run(invocation, action, std::move(stream), &diagnostics);
  const double ms = MillisecondsSince(start);
  if (times) times->frontend_and_codegen_ms = ms;
  spdlog::debug("cpu jit: {} ({} bytes of C++) in process: {:.1f} ms", file_name, source.size(), ms);
  if (!ok) return Internal("clang rejected " + file_name + ":\n" + diagnostics);
  if (object->empty()) return Internal("clang produced no object code for " + file_name);
  return std::string(object->data(), object->size());
}

Expected<std::shared_ptr<CpuCode>> CpuJit::Load(std::string_view object, std::string_view name) {
  if (!impl_->session) return FailedPrecondition("this CpuJit compiles only (no JIT)");
  auto& jit = *impl_->session->lljit;
  std::string dylib_name = "weft." + std::string(name) + "." +
                           std::to_string(impl_->session->next_dylib.fetch_add(1));
  auto dylib = jit.createJITDylib(dylib_name);
  if (!dylib) return Internal("cannot create a JIT library: " + ToString(dylib.takeError()));
  auto state = std::make_unique<CpuCode::State>();
  state->session = impl_->session;
  state->dylib = &*dylib;
  // From here the CpuCode owns the dylib and removes it on every path.
  auto code = std::make_shared<CpuCode>(std::move(state));
  auto buffer = llvm::MemoryBuffer::getMemBufferCopy(llvm::StringRef(object.data(), object.size()),
                                                     dylib_name);
  if (auto error = jit.addObjectFile(*dylib, std::move(buffer))) {
    return Internal("cannot load object code: " + ToString(std::move(error)));
  }
  return code;
}

const std::string& CpuJit::target_id() const { return impl_->target_id; }
bool CpuJit::has_pch() const { return !impl_->pch_path.empty(); }
double CpuJit::pch_build_ms() const { return impl_->pch_build_ms; }
const std::string& CpuJit::pch_path() const { return impl_->pch_path; }

std::string DefaultCompilerChild() {
  char buf[4096];
  ssize_t n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n > 0) {
    llvm::SmallString<256> self(llvm::StringRef(buf, static_cast<size_t>(n)));
    llvm::SmallString<256> next_to(llvm::sys::path::parent_path(self));
    llvm::sys::path::append(next_to, "weft-cc");
    if (::access(next_to.c_str(), X_OK) == 0) return std::string(next_to);
  }
  return WEFT_CC_BUILD_PATH;
}

}  // namespace weft::jit
