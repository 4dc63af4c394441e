// weft::Tape: autodiff tape commands queued on the client's session.
#include "weft/client/tape.h"

#include <atomic>

#include "client_core.h"
#include "weft/client/client.h"

namespace weft {
inline namespace client_v1 {

namespace {
// Tape ids are private to a session; one counter per process keeps them unique anyway.
std::atomic<std::uint64_t> next_tape_id{1};
}  // namespace

Tape::Tape(Client& client) : core_(client.core()), id_(next_tape_id++) {}

Tape::Tape(Tape&& other) noexcept
    : core_(std::move(other.core_)), id_(std::exchange(other.id_, 0)) {}

Tape::~Tape() {
  if (core_ && id_ != 0 && !core_->closed()) (void)Queue(TapeOp{TapeOp::Kind::kFree, id_, {}, {}});
}

Status Tape::Queue(TapeOp op) {
  if (!core_) return FailedPrecondition("weft::Tape has no session");
  return core_->Enqueue(Command{std::move(op), {}});
}

Status Tape::Begin() { return Queue(TapeOp{TapeOp::Kind::kBegin, id_, {}, {}}); }
Status Tape::End() { return Queue(TapeOp{TapeOp::Kind::kEnd, id_, {}, {}}); }
Status Tape::Zero() { return Queue(TapeOp{TapeOp::Kind::kZero, id_, {}, {}}); }
Status Tape::Reset() { return Queue(TapeOp{TapeOp::Kind::kReset, id_, {}, {}}); }

Status Tape::Backward(const Array& loss) {
  if (!loss.valid()) return FailedPrecondition("Tape::Backward: the loss array is empty");
  return Queue(TapeOp{TapeOp::Kind::kBackward, id_, loss.view(), {}});
}

Status Tape::Backward(const std::vector<TapeOp::Seed>& seeds) {
  return Queue(TapeOp{TapeOp::Kind::kBackward, id_, {}, seeds});
}

}  // namespace client_v1
}  // namespace weft
