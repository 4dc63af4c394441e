// frame_trace: the WEFT_LANE_TRACE flag and the per-thread phase record.
#include "engine/core/frame_trace.h"

#include <cstdlib>

namespace weft::frame_trace {

bool Enabled() {
  static const bool on = [] {
    const char* v = std::getenv("WEFT_LANE_TRACE");
    return v != nullptr && *v != '\0';
  }();
  return on;
}

Phases& Current() {
  thread_local Phases phases;
  return phases;
}

}  // namespace weft::frame_trace
