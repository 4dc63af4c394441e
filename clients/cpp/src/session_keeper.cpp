// Holds SessionService.Attach open on a background thread for the life of the session.
#include "session_keeper.h"

namespace weft::inline client_v1::detail {

SessionKeeper::SessionKeeper(v1::SessionService::Stub* stub,
                             std::unique_ptr<grpc::ClientContext> context,
                             std::string session_id)
    : context_(std::move(context)) {
  thread_ = std::thread([this, stub, id = std::move(session_id)] { Run(stub, id); });
}

SessionKeeper::~SessionKeeper() { Stop(); }

void SessionKeeper::Stop() {
  if (thread_.joinable()) {
    context_->TryCancel();
    thread_.join();
  }
  attached_ = false;
}

std::string SessionKeeper::last_event() const {
  std::lock_guard lock(mu_);
  return last_event_;
}

Status SessionKeeper::WaitAttached(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mu_);
  if (!cv_.wait_for(lock, timeout, [&] { return hello_seen_ || ended_; }))
    return Unavailable("SessionService.Attach: the daemon did not confirm the session's stream within " +
                       std::to_string(timeout.count()) + " ms");
  if (!hello_seen_)
    return Unavailable("SessionService.Attach: the stream ended before the daemon claimed it" +
                       (end_message_.empty() ? std::string() : ": " + end_message_));
  return Status::Ok();
}

void SessionKeeper::Run(v1::SessionService::Stub* stub, std::string session_id) {
  auto stream = stub->Attach(context_.get());
  v1::AttachRequest first;
  first.set_session_id(session_id);
  if (stream->Write(first)) {
    v1::AttachEvent event;
    while (stream->Read(&event)) {
      std::lock_guard lock(mu_);
      last_event_ = event.message();
      hello_seen_ = true;
      cv_.notify_all();
    }
  }
  const grpc::Status end = stream->Finish();   // the stream's end is the session's end
  attached_ = false;
  std::lock_guard lock(mu_);
  ended_ = true;
  end_message_ = end.error_message();
  cv_.notify_all();
}

}  // namespace weft::client_v1::detail
