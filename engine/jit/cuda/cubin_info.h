// CubinInfo: what a CUBIN (the ELF image NVRTC produces for sm_XX) says about each kernel
// entry point: registers per thread (EIATTR_REGCOUNT in .nv.info), code size (.text.<kernel>),
// static shared memory (.nv.shared.<kernel>), local memory per thread (EIATTR_FRAME_SIZE) and
// constant bank 0 (.nv.constant0.<kernel>: the kernel's parameters and the driver's area).
// A pure, bounds-checked parser over bytes: it needs no NVRTC, no driver and no GPU, and a
// malformed image is an error value, never a crash.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "engine/core/status.h"

namespace weft::jit {

struct CubinKernelInfo {
  std::string symbol;          // the entry point's name
  uint32_t registers = 0;      // per thread
  uint64_t code_bytes = 0;     // size of .text.<symbol>
  uint64_t shared_bytes = 0;   // static shared memory (.nv.shared.<symbol>; on sm_90 it includes
                               // the 1 KiB the toolchain reserves when the kernel uses any)
  uint64_t local_bytes = 0;    // stack frame per thread (EIATTR_FRAME_SIZE)
  uint64_t const_bytes = 0;    // constant bank 0 (.nv.constant0.<symbol>)
};

struct CubinInfo {
  uint32_t sm = 0;             // the architecture in the ELF header (e_flags), e.g. 90
  std::vector<CubinKernelInfo> kernels;   // every function with a .text.<name> section
  const CubinKernelInfo* Find(std::string_view symbol) const {
    for (const auto& k : kernels)
      if (k.symbol == symbol) return &k;
    return nullptr;
  }
};

// InvalidArgument when `image` is not a 64-bit little-endian ELF or a table points outside it.
Expected<CubinInfo> ParseCubin(std::string_view image);

}  // namespace weft::jit
