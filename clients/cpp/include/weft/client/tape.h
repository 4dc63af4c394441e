// weft::Tape: an autodiff tape that lives in the daemon, per session (Warp's wp.Tape). While
// it records (between Begin and End), launches are recorded; Backward seeds the loss gradient
// and runs the recorded adjoints in reverse. All operations are queued commands, run in order
// with launches; errors surface at Client::Synchronize. The destructor forgets the tape.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "weft/client/array.h"
#include "weft/client/commands.h"
#include "weft/client/status.h"

namespace weft {
inline namespace client_v1 {

class Client;

class Tape {
 public:
  explicit Tape(Client& client);
  Tape(Tape&& other) noexcept;
  Tape& operator=(Tape&& other) = delete;
  Tape(const Tape&) = delete;
  Tape& operator=(const Tape&) = delete;
  ~Tape();   // queues the tape's FREE

  std::uint64_t id() const { return id_; }

  // Starts / stops recording launches (the session records on one tape at a time).
  Status Begin();
  Status End();
  // Sets every element of loss's gradient to 1 and runs the adjoints of the recorded
  // launches in reverse (loss must have requires_grad).
  Status Backward(const Array& loss);
  // Backward with explicit seeds: each grad is copied into its array's gradient first.
  Status Backward(const std::vector<TapeOp::Seed>& seeds);
  // Zeroes the gradients of every array the tape touched.
  Status Zero();
  // Zeroes them and forgets the recorded launches.
  Status Reset();

 private:
  Status Queue(TapeOp op);

  std::shared_ptr<detail::ClientCore> core_;
  std::uint64_t id_ = 0;
};

}  // namespace client_v1
}  // namespace weft
