// NVRTC in a child process: the arguments of `weft-cc --nvrtc` and its main.
#include "engine/jit/cuda/nvrtc_child.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <iterator>

namespace weft::jit {

std::vector<std::string> NvrtcChildArgs(const NvrtcOptions& options, std::string_view name, double time_limit_s) {
  char limit[32];
  std::snprintf(limit, sizeof(limit), "%g", time_limit_s);
  std::vector<std::string> args = {"--nvrtc", "--name", std::string(name), "--sm", std::to_string(options.sm),
                                   "--cubin", options.cubin ? "1" : "0", "--limit", limit};
  for (const auto& dir : options.include_dirs) args.insert(args.end(), {"--include", dir});
  for (const auto& flag : options.extra_flags) args.insert(args.end(), {"--flag", flag});
  return args;
}

int NvrtcChildMain(int argc, char** argv) {
  NvrtcOptions options;
  std::string name;
  double limit_s = 0;
  bool sm_given = false;
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string key = argv[i], value = argv[i + 1];
    if (key == "--name") name = value;
    else if (key == "--sm") options.sm = std::atoi(value.c_str()), sm_given = true;
    else if (key == "--cubin") options.cubin = value == "1";
    else if (key == "--limit") limit_s = std::atof(value.c_str());
    else if (key == "--include") options.include_dirs.push_back(value);
    else if (key == "--flag") options.extra_flags.push_back(value);
    else {
      std::cerr << "weft-cc --nvrtc: unknown argument " << key << "\n";
      return 3;
    }
  }
  if (argc % 2 != 1 || name.empty() || !sm_given || options.sm <= 0) {
    std::cerr << "weft-cc --nvrtc: the CUDA compiler process of weftd (--name FILE --sm N [--cubin 0|1] "
                 "[--limit S] [--include DIR]... [--flag F]...; CUDA C++ on stdin, CUBIN/PTX on stdout)\n";
    return 3;
  }
  // Never outlive the parent's limit, even when the parent is gone (nobody would kill us).
  if (limit_s > 0) ::alarm(static_cast<unsigned>(std::ceil(limit_s)) + 2);
  std::string source{std::istreambuf_iterator<char>(std::cin), std::istreambuf_iterator<char>()};
  auto out = NvrtcCompile(source, name, options);
  if (!out.ok()) {
    std::cerr << out.status().message();
    return out.status().code() == StatusCode::kInternal ? 1 : 2;
  }
  std::fwrite(out->image.data(), 1, out->image.size(), stdout);
  return std::fflush(stdout) == 0 ? 0 : 2;
}

}  // namespace weft::jit
