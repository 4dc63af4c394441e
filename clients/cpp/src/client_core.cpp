// The state one Client and its Arrays share: connection, session, command queue, slabs.
#include "client_core.h"

#include <unistd.h>

#include <chrono>
#include <cstdlib>

#include "address.h"
#include "proto_convert.h"
#include "rpc_status.h"

namespace weft::inline client_v1::detail {

namespace {

constexpr auto kCloseDeadline = std::chrono::seconds(5);
constexpr std::size_t kMaxChunkBytes = 16u << 20;

std::string EnvOr(const std::string& value, const char* name) {
  if (!value.empty()) return value;
  const char* v = std::getenv(name);
  return v ? std::string(v) : std::string();
}

}  // namespace

Expected<std::shared_ptr<ClientCore>> ClientCore::Open(const ConnectOptions& options) {
  std::shared_ptr<ClientCore> core(new ClientCore(options));
  const ResolvedAddress address = Resolve(options);
  core->token_ = EnvOr(options.token, "WEFT_TOKEN");
  // weftd caps messages at 64 MiB and Read chunks at 16 MiB.
  if (core->options_.chunk_size == 0) core->options_.chunk_size = 1u << 20;
  if (core->options_.chunk_size > kMaxChunkBytes) core->options_.chunk_size = kMaxChunkBytes;
  if (core->options_.max_pending_commands == 0) core->options_.max_pending_commands = 1;

  std::string target = address.target;
  v1::OpenSessionResponse response;
  // At most twice: the daemon, then the session host it may name for an unchecked session.
  for (int hop = 0; hop < 2; ++hop) {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(-1);
    args.SetMaxSendMessageSize(-1);
    core->channel_ = grpc::CreateCustomChannel(target, grpc::InsecureChannelCredentials(), args);
    const auto deadline = std::chrono::system_clock::now() + options.connect_timeout;
    if (!core->channel_->WaitForConnected(deadline))
      return Unavailable("no weftd answering at " + target + " (waited " +
                         std::to_string(options.connect_timeout.count()) +
                         " ms); start weftd or set WEFT_ADDRESS");

    core->session_stub_ = v1::SessionService::NewStub(core->channel_);
    core->array_stub_ = v1::ArrayService::NewStub(core->channel_);
    core->device_stub_ = v1::DeviceService::NewStub(core->channel_);
    core->exec_stub_ = v1::ExecService::NewStub(core->channel_);
    core->module_stub_ = v1::ModuleService::NewStub(core->channel_);

    v1::OpenSessionRequest request;
    const std::int64_t pid = ::getpid();
    request.set_client_name(options.client_name.empty()
                                ? "weft-cpp pid " + std::to_string(pid)
                                : options.client_name);
    request.set_client_pid(pid);
    request.set_unchecked(options.unchecked);
    request.set_device(options.device);
    response.Clear();
    auto context = core->NewContext();
    // A session or device host may take a while to start (CUDA initialisation): allow it more.
    context->set_deadline(std::chrono::system_clock::now() + options.connect_timeout + std::chrono::milliseconds(60000));
    WEFT_CLIENT_RETURN_IF_ERROR(
        FromRpc(core->session_stub_->Open(context.get(), request, &response), "SessionService.Open"));
    if (response.session_host().empty() || hop == 1) break;
    target = "unix:" + response.session_host();
  }
  if (response.session_id().empty())
    return Internal("SessionService.Open: the daemon returned no session id");

  core->session_.session_id = response.session_id();
  core->session_.daemon_version = response.daemon_version();
  core->session_.local = response.local();
  core->session_.daemon_pid = response.daemon_pid();
  core->session_.address = target;
  core->local_ = response.local() && address.unix_socket && options.map_shared_memory;
  core->keeper_ = std::make_unique<SessionKeeper>(core->session_stub_.get(), core->NewContext(),
                                                  core->session_.session_id);
  // Connect returns once the daemon holds the Attach stream: a process killed right after
  // Connect is then reaped at once, not after the unattached-session timeout.
  WEFT_CLIENT_RETURN_IF_ERROR(core->keeper_->WaitAttached(
      std::chrono::duration_cast<std::chrono::milliseconds>(options.connect_timeout)));
  return core;
}

ClientCore::~ClientCore() { (void)Close(); }

Status ClientCore::CheckOpen() const {
  if (closed_.load()) return FailedPrecondition("the weft session is closed");
  return Status::Ok();
}

std::unique_ptr<grpc::ClientContext> ClientCore::NewContext() const {
  auto context = std::make_unique<grpc::ClientContext>();
  if (!session_.session_id.empty()) context->AddMetadata("weft-session", session_.session_id);
  if (!token_.empty()) context->AddMetadata("authorization", "Bearer " + token_);
  return context;
}

Status ClientCore::Close() {
  if (closed_.exchange(true)) return Status::Ok();
  Status result;
  if (session_stub_ && !session_.session_id.empty()) {
    {
      std::lock_guard lock(queue_mu_);
      pending_.clear();   // the session's end drops what was never sent
    }
    v1::CloseSessionRequest request;
    request.set_session_id(session_.session_id);
    v1::CloseSessionResponse response;
    auto context = NewContext();
    context->set_deadline(std::chrono::system_clock::now() + kCloseDeadline);
    result = FromRpc(session_stub_->Close(context.get(), request, &response),
                     "SessionService.Close");
  }
  if (keeper_) keeper_->Stop();
  return result;
}

Status ClientCore::Enqueue(Command command) {
  WEFT_CLIENT_RETURN_IF_ERROR(CheckOpen());
  std::lock_guard lock(queue_mu_);
  pending_.push_back(std::move(command));
  if (pending_.size() >= options_.max_pending_commands) return FlushLocked();
  return Status::Ok();
}

Status ClientCore::EnqueueAll(std::vector<Command> commands) {
  WEFT_CLIENT_RETURN_IF_ERROR(CheckOpen());
  std::lock_guard lock(queue_mu_);
  for (auto& c : commands) pending_.push_back(std::move(c));
  return FlushLocked();
}

Status ClientCore::Flush() {
  WEFT_CLIENT_RETURN_IF_ERROR(CheckOpen());
  std::lock_guard lock(queue_mu_);
  return FlushLocked();
}

Status ClientCore::FlushLocked() {
  if (pending_.empty()) return Status::Ok();
  v1::SubmitRequest request;
  for (const auto& c : pending_) ToProto(c, request.add_commands());
  pending_.clear();
  v1::SubmitResponse response;
  auto context = NewContext();
  return FromRpc(exec_stub_->Submit(context.get(), request, &response), "ExecService.Submit");
}

Status ClientCore::Synchronize() {
  WEFT_CLIENT_RETURN_IF_ERROR(CheckOpen());
  std::lock_guard lock(queue_mu_);
  WEFT_CLIENT_RETURN_IF_ERROR(FlushLocked());
  v1::SynchronizeResponse response;
  auto context = NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(FromRpc(
      exec_stub_->Synchronize(context.get(), v1::SynchronizeRequest(), &response),
      "ExecService.Synchronize"));
  if (!response.output().empty()) {
    std::lock_guard out_lock(output_mu_);
    output_ += response.output();
  }
  if (response.error().empty()) return Status::Ok();
  std::string message = response.error();
  if (response.has_error_origin() && !response.error_origin().file().empty()) {
    message += " (at " + response.error_origin().file() + ":" +
               std::to_string(response.error_origin().line()) + ")";
  }
  const auto code = response.error_code() == 0 ? StatusCode::kUnknown
                                                : static_cast<StatusCode>(response.error_code());
  return Status(code, message);
}

std::string ClientCore::TakeOutput() {
  std::lock_guard lock(output_mu_);
  return std::exchange(output_, std::string());
}

Status ClientCore::FreeHandle(std::uint64_t handle) {
  WEFT_CLIENT_RETURN_IF_ERROR(Flush());
  v1::FreeArrayRequest request;
  request.set_handle(handle);
  v1::FreeArrayResponse response;
  auto context = NewContext();
  return FromRpc(array_stub_->Free(context.get(), request, &response), "ArrayService.Free");
}

}  // namespace weft::client_v1::detail
