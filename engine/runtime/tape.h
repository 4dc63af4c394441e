// An autodiff tape: the launches recorded while it was active (kernel, dim, packed arguments
// with weak references to their arrays), replayed as adjoint launches in reverse by BACKWARD.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/core/module_source.h"
#include "engine/runtime/launch_args.h"

namespace weft {

struct TapeRecord {
  std::string module_id;
  std::string kernel;
  std::vector<int64_t> dim;
  PackedArgs args;          // keep_alive is empty: the tape does not keep arrays alive
  SourceLocation origin;
  std::string device = "cpu";   // where it ran (the adjoint runs there too)
  uint32_t block_dim = 0;
  uint32_t max_blocks = 0;
  uint64_t marker = 0;      // non-zero: a marker (TapeCommand kMark), not a launch
};

struct Tape {
  std::vector<TapeRecord> records;
  // Every array a recorded launch (or a backward seed) touched, for ZERO.
  std::vector<std::weak_ptr<Allocation>> touched;
  void Touch(const std::shared_ptr<Allocation>& a);
};

}  // namespace weft
