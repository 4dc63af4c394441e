// CommandBatch: an ordered list of copy / fill / launch / tape commands.
#include "weft/client/commands.h"

namespace weft {
inline namespace client_v1 {

CommandBatch& CommandBatch::Copy(ArrayView dst, ArrayView src, CommandOrigin origin) {
  commands_.push_back(Command{CopyOp{std::move(dst), std::move(src)}, std::move(origin)});
  return *this;
}

CommandBatch& CommandBatch::Fill(ArrayView dst, std::vector<std::byte> value,
                                 CommandOrigin origin) {
  commands_.push_back(Command{FillOp{std::move(dst), std::move(value)}, std::move(origin)});
  return *this;
}

CommandBatch& CommandBatch::Launch(LaunchSpec launch, CommandOrigin origin) {
  commands_.push_back(Command{std::move(launch), std::move(origin)});
  return *this;
}

CommandBatch& CommandBatch::Tape(TapeOp op, CommandOrigin origin) {
  commands_.push_back(Command{std::move(op), std::move(origin)});
  return *this;
}

}  // namespace client_v1
}  // namespace weft
