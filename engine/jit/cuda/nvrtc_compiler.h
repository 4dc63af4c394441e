// NVRTC wrapper: one CUDA C++ translation unit (a generated module including engine/native
// headers) -> CUBIN for a real architecture (sm_90 by default) or PTX for a virtual one.
// Needs only libnvrtc: no GPU, no driver. Thread safe (each call owns its nvrtcProgram).
// This header carries no CUDA types.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "engine/core/status.h"

namespace weft::jit {

struct NvrtcOptions {
  int sm = 90;                            // compute capability * 10
  bool cubin = true;                      // true: sm_XX CUBIN; false: compute_XX PTX
  std::vector<std::string> include_dirs;  // engine/native first
  std::vector<std::string> extra_flags;   // e.g. "-DWEFT_DEBUG=1", "-lineinfo"
};

struct NvrtcOutput {
  std::string image;      // CUBIN bytes or PTX text (NUL-terminated, ready for cuModuleLoadData)
  bool is_cubin = false;
  std::string log;        // warnings, if any
  double compile_ms = 0;
};

// Errors: InvalidArgument never (generated code is ours); Internal with NVRTC's log when it
// rejects the source; Unavailable when NVRTC cannot run.
Expected<NvrtcOutput> NvrtcCompile(std::string_view source, std::string_view name,
                                   const NvrtcOptions& options);

// "major.minor" of the NVRTC in use, or a Status if it cannot be queried.
Expected<std::string> NvrtcVersion();
// Whether NVRTC can compile for sm_XX.
bool NvrtcSupportsArch(int sm);

}  // namespace weft::jit
