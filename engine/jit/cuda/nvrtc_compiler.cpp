// NVRTC wrapper: create program, compile with the include path, fetch CUBIN/PTX and the log.
#include "engine/jit/cuda/nvrtc_compiler.h"

#include <nvrtc.h>

#include <chrono>

namespace weft::jit {
namespace {

std::string ResultText(nvrtcResult result) { return nvrtcGetErrorString(result); }

// Owns an nvrtcProgram.
struct Program {
  nvrtcProgram handle = nullptr;
  ~Program() {
    if (handle) nvrtcDestroyProgram(&handle);
  }
};

std::string ProgramLog(nvrtcProgram program) {
  size_t size = 0;
  if (nvrtcGetProgramLogSize(program, &size) != NVRTC_SUCCESS || size <= 1) return {};
  std::string log(size, '\0');
  if (nvrtcGetProgramLog(program, log.data()) != NVRTC_SUCCESS) return {};
  while (!log.empty() && (log.back() == '\0' || log.back() == '\n')) log.pop_back();
  return log;
}

}  // namespace

Expected<NvrtcOutput> NvrtcCompile(std::string_view source, std::string_view name,
                                   const NvrtcOptions& options) {
  auto start = std::chrono::steady_clock::now();
  std::string source_text(source);
  std::string file_name(name.empty() ? "weft_module.cu" : name);
  Program program;
  nvrtcResult result = nvrtcCreateProgram(&program.handle, source_text.c_str(), file_name.c_str(),
                                          0, nullptr, nullptr);
  if (result != NVRTC_SUCCESS) {
    return Unavailable("nvrtcCreateProgram failed: " + ResultText(result));
  }

  std::vector<std::string> flags = {
      std::string("--gpu-architecture=") + (options.cubin ? "sm_" : "compute_") +
          std::to_string(options.sm),
      "-std=c++17",
      // Lambdas (the element functions of tile_map / tile_reduce) carry no execution space
      // annotation; every other function of the native library and of generated code does.
      "-default-device",
  };
  for (const auto& dir : options.include_dirs) flags.push_back("-I" + dir);
  for (const auto& flag : options.extra_flags) flags.push_back(flag);
  std::vector<const char*> argv;
  for (const auto& f : flags) argv.push_back(f.c_str());

  result = nvrtcCompileProgram(program.handle, int(argv.size()), argv.data());
  NvrtcOutput output;
  output.log = ProgramLog(program.handle);
  if (result != NVRTC_SUCCESS) {
    return Internal("NVRTC rejected " + file_name + " for " + flags[0] + " (" +
                    ResultText(result) + "):\n" + output.log);
  }

  size_t size = 0;
  if (options.cubin) {
    result = nvrtcGetCUBINSize(program.handle, &size);
    if (result == NVRTC_SUCCESS) {
      output.image.resize(size);
      result = nvrtcGetCUBIN(program.handle, output.image.data());
    }
    output.is_cubin = true;
  } else {
    result = nvrtcGetPTXSize(program.handle, &size);  // includes the terminating NUL
    if (result == NVRTC_SUCCESS) {
      output.image.resize(size);
      result = nvrtcGetPTX(program.handle, output.image.data());
    }
  }
  if (result != NVRTC_SUCCESS) {
    return Internal("NVRTC produced no code for " + file_name + ": " + ResultText(result));
  }
  output.compile_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return output;
}

Expected<std::string> NvrtcVersion() {
  int major = 0, minor = 0;
  nvrtcResult result = nvrtcVersion(&major, &minor);
  if (result != NVRTC_SUCCESS) return Unavailable("nvrtcVersion failed: " + ResultText(result));
  return std::to_string(major) + "." + std::to_string(minor);
}

bool NvrtcSupportsArch(int sm) {
  int count = 0;
  if (nvrtcGetNumSupportedArchs(&count) != NVRTC_SUCCESS || count <= 0) return false;
  std::vector<int> archs(count);
  if (nvrtcGetSupportedArchs(archs.data()) != NVRTC_SUCCESS) return false;
  for (int arch : archs)
    if (arch == sm) return true;
  return false;
}

}  // namespace weft::jit
