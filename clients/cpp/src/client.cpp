// weft::Client: session lifetime, devices, stats, array creation, import, queued commands.
#include "weft/client/client.h"

#include <cstring>
#include <limits>

#include "chunked_transfer.h"
#include "client_core.h"
#include "proto_convert.h"
#include "rpc_status.h"

namespace weft {
inline namespace client_v1 {

namespace {

enum Init { kEmpty = 0, kZeros = 1, kFill = 2, kData = 3 };

const SessionInfo& NoSession() {
  static const SessionInfo kNone;
  return kNone;
}

Status NotConnected() { return FailedPrecondition("weft::Client is not connected"); }

// Element count of `shape`, checking 0..4 non-negative dimensions and that neither the count
// nor its byte size overflows 64 bits.
Expected<std::uint64_t> ElementCount(const std::vector<std::int64_t>& shape,
                                     std::size_t element_size) {
  if (shape.size() > 4)
    return InvalidArgument("arrays have at most 4 dimensions, got " +
                           std::to_string(shape.size()));
  std::uint64_t n = 1;
  for (auto d : shape) {
    if (d < 0) return InvalidArgument("negative array extent " + std::to_string(d));
    if (d != 0 && n > std::numeric_limits<std::uint64_t>::max() / static_cast<std::uint64_t>(d))
      return InvalidArgument("array shape overflows 64-bit size");
    n *= static_cast<std::uint64_t>(d);
  }
  if (element_size != 0 && n > std::numeric_limits<std::uint64_t>::max() / element_size)
    return InvalidArgument("array byte size overflows 64 bits");
  return n;
}

}  // namespace

Expected<Client> Client::Connect(ConnectOptions options) {
  auto core = detail::ClientCore::Open(options);
  if (!core.ok()) return core.status();
  return Client(std::move(core).value());
}

Client& Client::operator=(Client&& other) noexcept {
  if (this != &other) {
    (void)Close();
    core_ = std::move(other.core_);
  }
  return *this;
}

Client::~Client() { (void)Close(); }

bool Client::connected() const { return core_ && !core_->closed(); }

const SessionInfo& Client::session() const { return core_ ? core_->session() : NoSession(); }

bool Client::local() const { return core_ && core_->local(); }

Status Client::Close() {
  if (!core_) return Status::Ok();
  return core_->Close();
}

Expected<std::vector<DeviceInfo>> Client::ListDevices() {
  if (!core_) return NotConnected();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  v1::ListDevicesResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->devices().List(context.get(), v1::ListDevicesRequest(), &response),
      "DeviceService.List"));
  std::vector<DeviceInfo> devices;
  for (const auto& d : response.devices()) devices.push_back(detail::FromProto(d));
  return devices;
}

Expected<DaemonStats> Client::Stats() {
  if (!core_) return NotConnected();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  v1::StatsResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->sessions().Stats(context.get(), v1::StatsRequest(), &response),
      "SessionService.Stats"));
  return detail::FromProto(response);
}

Expected<Array> Client::Create(const DType& dtype, std::vector<std::int64_t> shape,
                               const ArrayOptions& options, int init, const void* value,
                               std::size_t value_size) {
  if (!core_) return NotConnected();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  WEFT_CLIENT_RETURN_IF_ERROR(dtype.Validate());
  WEFT_CLIENT_ASSIGN_OR_RETURN(const std::uint64_t count, ElementCount(shape, dtype.element_size()));
  if (init == kFill && value_size != dtype.element_size())
    return InvalidArgument("fill value has " + std::to_string(value_size) +
                           " bytes; one " + dtype.ToString() + " element has " +
                           std::to_string(dtype.element_size()));
  if (init == kData && value_size != count * dtype.element_size())
    return InvalidArgument("data has " + std::to_string(value_size) + " bytes; an array of " +
                           std::to_string(count) + " " + dtype.ToString() + " elements has " +
                           std::to_string(count * dtype.element_size()));
  v1::CreateArrayRequest request;
  detail::ToProto(dtype, request.mutable_dtype());
  for (auto d : shape) request.add_shape(d);
  request.set_device(options.device);
  request.set_requires_grad(options.requires_grad);
  request.set_init(static_cast<v1::CreateArrayRequest::Init>(init));
  if (value != nullptr && value_size != 0)
    request.set_value(static_cast<const char*>(value), value_size);
  v1::CreateArrayResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->arrays().Create(context.get(), request, &response), "ArrayService.Create"));
  return Array(core_, detail::FromProto(response.info()), true);
}

Expected<Array> Client::Empty(const DType& dtype, std::vector<std::int64_t> shape,
                              const ArrayOptions& options) {
  return Create(dtype, std::move(shape), options, kEmpty, nullptr, 0);
}

Expected<Array> Client::Zeros(const DType& dtype, std::vector<std::int64_t> shape,
                              const ArrayOptions& options) {
  return Create(dtype, std::move(shape), options, kZeros, nullptr, 0);
}

Expected<Array> Client::Full(const DType& dtype, std::vector<std::int64_t> shape, double value,
                             const ArrayOptions& options) {
  WEFT_CLIENT_ASSIGN_OR_RETURN(auto element, EncodeFillValue(dtype, value));
  return Create(dtype, std::move(shape), options, kFill, element.data(), element.size());
}

Expected<Array> Client::FullBytes(const DType& dtype, std::vector<std::int64_t> shape,
                                  const void* element, std::size_t n,
                                  const ArrayOptions& options) {
  return Create(dtype, std::move(shape), options, kFill, element, n);
}

Expected<Array> Client::FromBytes(const DType& dtype, std::vector<std::int64_t> shape,
                                  const void* data, std::size_t n, const ArrayOptions& options) {
  if (!core_) return NotConnected();
  WEFT_CLIENT_RETURN_IF_ERROR(dtype.Validate());
  WEFT_CLIENT_ASSIGN_OR_RETURN(const std::uint64_t count, ElementCount(shape, dtype.element_size()));
  if (n != count * dtype.element_size())
    return InvalidArgument("data has " + std::to_string(n) + " bytes; an array of " +
                           std::to_string(count) + " " + dtype.ToString() + " elements has " +
                           std::to_string(count * dtype.element_size()));
  // Small arrays travel inside the Create call; large ones are created empty and then
  // written in place (local) or in chunks (remote), so no message grows with the array.
  const bool cpu = options.device.empty() || options.device == "cpu";
  if (n <= core_->options().chunk_size && !(core_->local() && cpu))
    return Create(dtype, std::move(shape), options, kData, data, n);
  WEFT_CLIENT_ASSIGN_OR_RETURN(Array array, Empty(dtype, std::move(shape), options));
  if (array.mappable()) {
    if (auto bytes = array.Map(); bytes.ok()) {
      if (n != 0) std::memcpy(bytes->data(), data, n);
      return array;
    }
  }
  WEFT_CLIENT_RETURN_IF_ERROR(detail::WriteChunked(*core_, array.handle(), 0, data, n));
  return array;
}

Expected<ArrayInfo> Client::Describe(std::uint64_t handle) {
  if (!core_) return NotConnected();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  v1::DescribeArrayRequest request;
  request.set_handle(handle);
  v1::DescribeArrayResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->arrays().Describe(context.get(), request, &response), "ArrayService.Describe"));
  return detail::FromProto(response.info());
}

Status Client::Free(std::uint64_t handle) {
  if (!core_) return NotConnected();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  return core_->FreeHandle(handle);
}

Expected<Array> Client::Import(const std::string& token) {
  if (!core_) return NotConnected();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  v1::ImportArrayRequest request;
  request.set_token(token);
  v1::ImportArrayResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->arrays().Import(context.get(), request, &response), "ArrayService.Import"));
  return Array(core_, detail::FromProto(response.info()), true);
}

Status Client::Copy(const ArrayView& dst, const ArrayView& src, CommandOrigin origin) {
  if (!core_) return NotConnected();
  return core_->Enqueue(Command{CopyOp{dst, src}, std::move(origin)});
}

Status Client::Fill(const ArrayView& dst, std::vector<std::byte> element, CommandOrigin origin) {
  if (!core_) return NotConnected();
  return core_->Enqueue(Command{FillOp{dst, std::move(element)}, std::move(origin)});
}

Status Client::Launch(LaunchSpec launch, CommandOrigin origin) {
  if (!core_) return NotConnected();
  return core_->Enqueue(Command{std::move(launch), std::move(origin)});
}

Status Client::Submit(CommandBatch batch) {
  if (!core_) return NotConnected();
  return core_->EnqueueAll(std::move(batch.commands()));
}

Status Client::Flush() {
  if (!core_) return NotConnected();
  return core_->Flush();
}

Status Client::Synchronize() {
  if (!core_) return NotConnected();
  return core_->Synchronize();
}

std::string Client::TakeOutput() { return core_ ? core_->TakeOutput() : std::string(); }

}  // namespace client_v1
}  // namespace weft
