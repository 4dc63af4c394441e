// Command values: the check that a tape op is one TapeCommand::Op names.
#include "engine/runtime/commands.h"

namespace weft {

Status CheckTapeOp(TapeCommand::Op op) {
  switch (op) {
    case TapeCommand::Op::kBegin:
    case TapeCommand::Op::kEnd:
    case TapeCommand::Op::kBackward:
    case TapeCommand::Op::kZero:
    case TapeCommand::Op::kReset:
    case TapeCommand::Op::kFree:
    case TapeCommand::Op::kMark:
      return Status::Ok();
  }
  return InvalidArgument("unknown tape op " + std::to_string(static_cast<int>(op)) +
                         " (expected BEGIN, END, BACKWARD, ZERO, RESET or FREE)");
}

}  // namespace weft
