// libFuzzer target: the module cache's artifact parser (DeserializeArtifact, what the disk cache
// reads back after the file's SHA-256 matched). Any bytes must give DATA_LOSS or an artifact;
// an artifact must serialize to bytes that parse again, to an artifact with the same
// serialization (flags such as is_array are normalized, so the input itself may differ).
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string_view>

#include "engine/runtime/module_cache.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string_view in(reinterpret_cast<const char*>(data), size);
  auto a = weft::DeserializeArtifact(in);
  if (!a.ok()) {
    if (a.status().code() != weft::StatusCode::kDataLoss) {
      std::fprintf(stderr, "fuzz_artifact: unexpected error %s\n", a.status().ToString().c_str());
      std::abort();
    }
    return 0;
  }
  std::string out = weft::SerializeArtifact(*a);
  auto again = weft::DeserializeArtifact(out);
  if (!again.ok() || weft::SerializeArtifact(*again) != out) {
    std::fprintf(stderr, "fuzz_artifact: a parsed artifact does not round-trip (%zu input bytes, %zu serialized)\n",
                 in.size(), out.size());
    std::abort();
  }
  return 0;
}
