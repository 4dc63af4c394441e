// Cross-process stream ordering on a CudaDevice by stream memory operations: counters in a
// session's GPU array (8-byte elements) that the client's framework stream and the session's
// stream write (cuStreamWriteValue64) and wait on (cuStreamWaitValue64, GEQ), so that a launch
// ordered with a Torch/CuPy stream costs no daemon round trip (docs/interop.md, "Ordering by
// stream memory operations"). A wait the client never satisfies would block the session's
// stream for good: the session's waits are remembered (the largest value per address, with the
// allocation kept alive) and released by the daemon — the values written from the stream's
// cancel stream — when the session is cancelled, the launch time limit passes, or the stream is
// destroyed.
#include <algorithm>

#include "engine/device/cuda_device.h"
#include "engine/runtime/session.h"

namespace weft {

bool CudaDevice::StreamMemOpsSupported() const {
  return driver_->StreamWaitValue64 != nullptr && driver_->StreamWriteValue64 != nullptr && stream_mem_ops_;
}

Status CudaDevice::StreamValue(Session& s, const MemoryBlock& order, uint64_t byte_offset, uint64_t value, bool write,
                               std::shared_ptr<const void> keep) {
  if (!StreamMemOpsSupported())
    return FailedPrecondition(name_ + " (or its driver) does not support 64-bit stream memory operations "
                                      "(cuStreamWaitValue64); order with CUDA events instead");
  if (byte_offset + sizeof(uint64_t) > order.size)
    return OutOfRange("cuda_value: byte offset " + std::to_string(byte_offset) + " is past the order array's block");
  std::shared_lock<std::shared_mutex> reset(reset_mu_);
  WEFT_RETURN_IF_ERROR(CheckBlock(order, "the order array"));
  WEFT_RETURN_IF_ERROR(MakeCurrent());
  WEFT_ASSIGN_OR_RETURN(Stream * st, StreamOf(s.id()));
  const jit::CuDevicePtr address = reinterpret_cast<jit::CuDevicePtr>(order.data) + byte_offset;
  if (write)
    return driver_->Check(driver_->StreamWriteValue64(st->stream, address, value, 0), "cuStreamWriteValue64");
  WEFT_RETURN_IF_ERROR(
      driver_->Check(driver_->StreamWaitValue64(st->stream, address, value, jit::kCuStreamWaitValueGeq),
                     "cuStreamWaitValue64"));
  std::lock_guard<std::mutex> lock(st->value_waits_mu);
  Stream::ValueWait& w = st->value_waits[address];
  // GEQ compares (int64_t)(*address - value) >= 0: the later of two values is the larger one.
  if (!w.keep || static_cast<int64_t>(value - w.value) > 0) w.value = value;
  w.keep = std::move(keep);
  return Status::Ok();
}

void CudaDevice::ReleaseValueWaits(Stream& st) {
  std::lock_guard<std::mutex> lock(st.value_waits_mu);
  for (const auto& [address, w] : st.value_waits)
    (void)driver_->StreamWriteValue64(st.cancel_stream ? st.cancel_stream : st.stream, address, w.value, 0);
  if (!st.value_waits.empty() && st.cancel_stream) (void)driver_->StreamSynchronize(st.cancel_stream);
  st.value_waits.clear();
}

void CudaDevice::ForgetValueWaits(Stream& st) {
  std::lock_guard<std::mutex> lock(st.value_waits_mu);
  st.value_waits.clear();
}

}  // namespace weft
