// Limits on what one command batch may ask of a session, checked when it is submitted, before
// anything is queued: threads per launch, elements per fill or copy (a stride-0 view of a few
// bytes may name 2^40 elements), commands queued per session, and valid tape ops.
#pragma once

#include <cstdint>
#include <vector>

#include "engine/core/status.h"
#include "engine/runtime/commands.h"

namespace weft {

struct CommandLimits {
  uint64_t max_launch_threads = uint64_t{1} << 32;   // product of a launch's dim; also fill/copy elements
  uint64_t max_queued_commands = 65536;              // per session, submitted and not yet run
  uint64_t max_graph_commands = 65536;               // commands of one graph (GraphCommand CREATE)
};

// RESOURCE_EXHAUSTED naming the limit (and its weftd flag) for a launch or view over the limit;
// INVALID_ARGUMENT for an unknown tape op. `already_queued` = the session's queued commands.
Status CheckCommandBatch(const std::vector<Command>& commands, const CommandLimits& limits,
                         uint64_t already_queued);

}  // namespace weft
