// weft-cc: the child process in which weftd compiles a module when a compile time limit is
// set: for the CPU with clang (engine/jit/cpu/compile_process.h), or with `--nvrtc` first for
// CUDA with NVRTC (engine/jit/cuda/nvrtc_child.h). Not meant to be run by hand.
#include <cstring>

#include "engine/jit/cpu/compile_process.h"
#if WEFT_CC_NVRTC
#include "engine/jit/cuda/nvrtc_child.h"
#endif

int main(int argc, char** argv) {
#if WEFT_CC_NVRTC
  if (argc > 1 && std::strcmp(argv[1], "--nvrtc") == 0) return weft::jit::NvrtcChildMain(argc - 1, argv + 1);
#endif
  return weft::jit::CompilerChildMain(argc, argv);
}
