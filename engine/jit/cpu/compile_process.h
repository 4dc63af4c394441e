// CompileProcess: a CPU (or NVRTC) compile in a child process that can be killed, so that a compile is
// bounded in time (clang in-process cannot be interrupted). The parent side (CompileInChild)
// spawns the weft-cc executable with the compile's settings as arguments, writes the source to
// its stdin, collects the object file (stdout) and clang's diagnostics (stderr), and kills the
// child with SIGKILL when the time limit passes. The child side (CompilerChildMain) is
// weft-cc's main: it compiles with a compile-only CpuJit using the parent's precompiled header,
// under an alarm of its own so that it never outlives a parent that died.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "engine/core/status.h"
#include "engine/jit/cpu/cpu_jit.h"

namespace weft::jit {

// The child's arguments for one compile of file `name` with `options` and the PCH `pch_path`.
std::vector<std::string> CompilerChildArgs(const CpuJitOptions& options, const std::string& pch_path,
                                           std::string_view name, double time_limit_s);

// Runs `executable args...` with `source` on stdin. The object file on success; Internal("clang
// rejected <name>:\n<diagnostics>") when the child reports a compile error (as CpuJit::Compile
// in process); ResourceExhausted naming the limit and `target` ("the CPU", "CUDA sm_90") when
// it ran longer than `time_limit_s` (it is killed); Internal when it could not start or died.
// Also the parent side of NVRTC compiles (`weft-cc --nvrtc`, engine/jit/cuda/nvrtc_child.h).
Expected<std::string> CompileInChild(const std::string& executable, const std::vector<std::string>& args,
                                     std::string_view source, std::string_view name, double time_limit_s,
                                     std::string_view target = "the CPU");

// Daemon shutdown: kills every running compiler process (their compiles fail with Unavailable)
// and refuses new ones, so that no compile holds the daemon past its stop bound.
void StopCompilerChildren();

// weft-cc's main.
int CompilerChildMain(int argc, char** argv);

}  // namespace weft::jit
