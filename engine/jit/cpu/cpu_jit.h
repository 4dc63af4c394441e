// CpuJit: the CPU backend. In-process clang compiles one C++ translation unit (a generated
// module, which includes engine/native/weft.h) to an object file in memory; ORC LLJIT loads
// objects, one JITDylib per module so dropping a module frees its code.
// A precompiled header of the native library is built once, when the CpuJit is created.
// With a compile time limit, each compile runs clang in a child process (weft-cc,
// compile_process.h) that is killed when the limit passes; without one, in this process.
// Thread safety: Compile and Load may be called from several threads at once.
// This header carries no LLVM/clang types: the runtime includes it without LLVM's headers.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "engine/core/status.h"

namespace weft::jit {

struct CpuJitOptions {
  std::vector<std::string> include_dirs;  // -I, in order (engine/native first)
  // Header (found on include_dirs) precompiled once and implicitly included in every compile;
  // empty, or not found on include_dirs = no PCH.
  std::string pch_header = "weft.h";
  std::string pch_dir;                    // where the PCH file lives; empty = $TMPDIR or /tmp
  bool native_cpu = true;                 // -march=native (target_id() names the CPU)
  int opt_level = 2;                      // -O<n>
  std::vector<std::string> extra_flags;   // more clang driver flags, e.g. "-DWEFT_DEBUG=1"
  // Symbols generated code may call that the process does not export (name -> address).
  // Everything the process exports (dlsym) is visible too.
  std::map<std::string, void*> host_symbols;
  // > 0: every Compile runs in a child process (`compiler_child`) that is killed after this
  // many seconds; the compile then fails with ResourceExhausted. 0: in this process, unbounded.
  double compile_time_limit_s = 0;
  // The child compiler executable; empty = DefaultCompilerChild().
  std::string compiler_child;
  // Use this existing PCH file instead of building one (the child uses its parent's).
  std::string existing_pch;
  // No JIT (compiles only; the child compiler).
  bool compile_only = false;
};

// Code of one loaded object. Destroying the last reference removes its code from the JIT.
class CpuCode {
 public:
  struct State;
  explicit CpuCode(std::unique_ptr<State> state);
  ~CpuCode();
  CpuCode(const CpuCode&) = delete;
  CpuCode& operator=(const CpuCode&) = delete;

  // Address of a symbol defined by the object (links it on first use). NotFound if absent,
  // Internal if linking failed (an undefined external, for instance).
  Expected<void*> Lookup(std::string_view symbol) const;

 private:
  std::unique_ptr<State> state_;
};

struct CpuCompileTimes {
  double frontend_and_codegen_ms = 0;  // whole clang run (with a child: spawn to exit)
};

// weft-cc next to the running executable (/proc/self/exe), else the one of the build tree.
std::string DefaultCompilerChild();

class CpuJit {
 public:
  static Expected<std::unique_ptr<CpuJit>> Create(const CpuJitOptions& options);
  ~CpuJit();
  CpuJit(const CpuJit&) = delete;
  CpuJit& operator=(const CpuJit&) = delete;

  // C++ source -> relocatable object file bytes (ELF). `name` is the file name clang reports
  // for lines without a #line directive. Errors: Internal with clang's diagnostics text.
  Expected<std::string> Compile(std::string_view source, std::string_view name,
                                CpuCompileTimes* times = nullptr);
  // Loads an object produced by Compile (now or from an earlier run with the same target_id).
  Expected<std::shared_ptr<CpuCode>> Load(std::string_view object, std::string_view name);

  // What the object code depends on besides the source: triple, CPU, features, flags.
  // Part of the module cache key.
  const std::string& target_id() const;
  // True when compiles use the precompiled native header.
  bool has_pch() const;
  // Milliseconds spent building the PCH in Create (0 without one).
  double pch_build_ms() const;
  // The PCH file compiles use (empty without one).
  const std::string& pch_path() const;

  struct Impl;

 private:
  explicit CpuJit(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace weft::jit
