// NVRTC in a child process: the child side of a CUDA compile under a time limit. NVRTC runs
// in-process and cannot be interrupted, so a compile with --compile-time-limit runs it in
// weft-cc (`weft-cc --nvrtc ...`), which the daemon kills when the limit passes (the parent
// side is CompileInChild, engine/jit/cpu/compile_process.h, shared with clang's compiles).
// NvrtcChildArgs builds the child's arguments; NvrtcChildMain is the child's main: CUDA C++ on
// stdin, the CUBIN or PTX on stdout, NVRTC's log on stderr; exit 1 when NVRTC rejects the
// source, 2 on any other failure, 3 on bad arguments.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "engine/jit/cuda/nvrtc_compiler.h"

namespace weft::jit {

// weft-cc's arguments for compiling file `name` with `options` (the first is "--nvrtc").
std::vector<std::string> NvrtcChildArgs(const NvrtcOptions& options, std::string_view name, double time_limit_s);

// weft-cc's main for `weft-cc --nvrtc ...` (argv[0] is "--nvrtc").
int NvrtcChildMain(int argc, char** argv);

}  // namespace weft::jit
