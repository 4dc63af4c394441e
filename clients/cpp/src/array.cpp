// weft::Array: RAII ownership of one daemon allocation, its views, zero-copy mapping and
// transfers, and the queued commands that act on it.
#include "weft/client/array.h"

#include <cstring>

#include "chunked_transfer.h"
#include "client_core.h"
#include "proto_convert.h"
#include "rpc_status.h"

namespace weft {
inline namespace client_v1 {

namespace {

Status NoArray() { return FailedPrecondition("weft::Array is empty (freed, released or moved)"); }

}  // namespace

Array::Array(std::shared_ptr<detail::ClientCore> core, ArrayInfo info, bool owns)
    : core_(std::move(core)), info_(std::move(info)), owns_(owns) {}

Array::Array(Array&& other) noexcept
    : core_(std::move(other.core_)),
      info_(std::exchange(other.info_, ArrayInfo())),
      owns_(std::exchange(other.owns_, false)),
      slab_(std::move(other.slab_)) {}

Array& Array::operator=(Array&& other) noexcept {
  if (this != &other) {
    (void)Free();
    core_ = std::move(other.core_);
    info_ = std::exchange(other.info_, ArrayInfo());
    owns_ = std::exchange(other.owns_, false);
    slab_ = std::move(other.slab_);
  }
  return *this;
}

Array::~Array() { (void)Free(); }

ArrayView Array::view() const { return ArrayView{info_.handle, 0, info_.shape, info_.strides}; }

Expected<ArrayView> Array::Slice(std::int64_t begin, std::int64_t end) const {
  if (!valid()) return NoArray();
  if (info_.shape.empty()) return InvalidArgument("cannot slice a 0-dimensional array");
  const std::int64_t n = info_.shape[0];
  if (begin < 0) begin += n;
  if (end < 0) end += n;
  if (begin < 0 || end > n || begin > end)
    return OutOfRange("slice [" + std::to_string(begin) + ", " + std::to_string(end) +
                      ") outside the first dimension of extent " + std::to_string(n));
  ArrayView v = view();
  std::int64_t row_stride = 0;
  if (!info_.strides.empty()) {
    row_stride = info_.strides[0];
  } else {
    row_stride = static_cast<std::int64_t>(info_.dtype.element_size());
    for (std::size_t i = 1; i < info_.shape.size(); ++i) row_stride *= info_.shape[i];
  }
  v.byte_offset = static_cast<std::uint64_t>(begin * row_stride);
  v.shape[0] = end - begin;
  return v;
}

bool Array::mappable() const {
  return valid() && core_ && core_->local() && !info_.shm_name.empty() &&
         info_.device.rfind("cpu", 0) == 0;
}

Expected<std::shared_ptr<detail::MappedSlab>> Array::EnsureMapped() {
  if (!valid()) return NoArray();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  if (slab_) return slab_;
  if (!mappable())
    return FailedPrecondition("array " + std::to_string(info_.handle) + " on " + info_.device +
                              " cannot be mapped (" +
                              (core_->local() ? "no shared-memory slab" : "not a local client") +
                              "); use Read/Write");
  if (info_.shm_offset + info_.byte_size > info_.shm_size)
    return DataLoss("array " + std::to_string(info_.handle) + " lies outside its slab " +
                    info_.shm_name);
  WEFT_CLIENT_ASSIGN_OR_RETURN(slab_, core_->slabs().Map(info_.shm_name, info_.shm_size));
  return slab_;
}

Expected<std::span<std::byte>> Array::Map() {
  WEFT_CLIENT_ASSIGN_OR_RETURN(auto slab, EnsureMapped());
  return std::span<std::byte>(slab->data() + info_.shm_offset, info_.byte_size);
}

Status Array::Read(void* dst, std::size_t n) {
  if (!valid()) return NoArray();
  if (n != info_.byte_size)
    return InvalidArgument("Read: destination has " + std::to_string(n) + " bytes; array " +
                           std::to_string(info_.handle) + " has " +
                           std::to_string(info_.byte_size));
  WEFT_CLIENT_RETURN_IF_ERROR(core_->Synchronize());
  if (mappable()) {
    if (auto bytes = Map(); bytes.ok()) {
      if (n != 0) std::memcpy(dst, bytes->data(), n);
      return Status::Ok();
    }
  }
  return detail::ReadChunked(*core_, info_.handle, 0, dst, n);
}

Status Array::Write(const void* src, std::size_t n) {
  if (!valid()) return NoArray();
  if (n != info_.byte_size)
    return InvalidArgument("Write: source has " + std::to_string(n) + " bytes; array " +
                           std::to_string(info_.handle) + " has " +
                           std::to_string(info_.byte_size));
  WEFT_CLIENT_RETURN_IF_ERROR(core_->Synchronize());
  if (mappable()) {
    if (auto bytes = Map(); bytes.ok()) {
      if (n != 0) std::memcpy(bytes->data(), src, n);
      return Status::Ok();
    }
  }
  return detail::WriteChunked(*core_, info_.handle, 0, src, n);
}

Status Array::Fill(double value) {
  if (!valid()) return NoArray();
  WEFT_CLIENT_ASSIGN_OR_RETURN(auto element, EncodeFillValue(info_.dtype, value));
  return core_->Enqueue(Command{FillOp{view(), std::move(element)}, {}});
}

Status Array::FillBytes(const void* element, std::size_t n) {
  if (!valid()) return NoArray();
  if (n != info_.dtype.element_size())
    return InvalidArgument("fill value has " + std::to_string(n) + " bytes; one " +
                           info_.dtype.ToString() + " element has " +
                           std::to_string(info_.dtype.element_size()));
  const auto* p = static_cast<const std::byte*>(element);
  return core_->Enqueue(Command{FillOp{view(), std::vector<std::byte>(p, p + n)}, {}});
}

Status Array::Zero() {
  if (!valid()) return NoArray();
  return core_->Enqueue(
      Command{FillOp{view(), std::vector<std::byte>(info_.dtype.element_size())}, {}});
}

Status Array::CopyFrom(const Array& src) {
  if (!valid() || !src.valid()) return NoArray();
  if (src.core_ != core_)
    return InvalidArgument("CopyFrom: the arrays belong to different sessions");
  return core_->Enqueue(Command{CopyOp{view(), src.view()}, {}});
}

Expected<ArrayInfo> Array::Describe() {
  if (!valid()) return NoArray();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  v1::DescribeArrayRequest request;
  request.set_handle(info_.handle);
  v1::DescribeArrayResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->arrays().Describe(context.get(), request, &response), "ArrayService.Describe"));
  ArrayInfo fresh = detail::FromProto(response.info());
  if (fresh.shm_name != info_.shm_name || fresh.shm_size != info_.shm_size) slab_.reset();
  info_ = fresh;
  return info_;
}

Expected<Array> Array::Grad() {
  if (!valid()) return NoArray();
  if (info_.grad_handle == 0)
    return FailedPrecondition("array " + std::to_string(info_.handle) +
                              " has no gradient (create it with requires_grad)");
  WEFT_CLIENT_RETURN_IF_ERROR(core_->CheckOpen());
  v1::DescribeArrayRequest request;
  request.set_handle(info_.grad_handle);
  v1::DescribeArrayResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->arrays().Describe(context.get(), request, &response), "ArrayService.Describe"));
  return Array(core_, detail::FromProto(response.info()), false);
}

Expected<std::string> Array::Export() {
  if (!valid()) return NoArray();
  WEFT_CLIENT_RETURN_IF_ERROR(core_->Flush());
  v1::ExportArrayRequest request;
  request.set_handle(info_.handle);
  v1::ExportArrayResponse response;
  auto context = core_->NewContext();
  WEFT_CLIENT_RETURN_IF_ERROR(detail::FromRpc(
      core_->arrays().Export(context.get(), request, &response), "ArrayService.Export"));
  // The first export moves an array that shared a slab into a slab of its own (an importer maps
  // the exported bytes and nothing else): refresh where it lives so later mappings follow it.
  WEFT_CLIENT_RETURN_IF_ERROR(Describe().status());
  return response.token();
}

Status Array::Free() {
  const bool owned = owns_ && valid();
  const std::uint64_t handle = info_.handle;
  auto core = std::move(core_);
  info_ = ArrayInfo();
  owns_ = false;
  slab_.reset();
  if (!owned || !core || core->closed()) return Status::Ok();
  return core->FreeHandle(handle);
}

std::uint64_t Array::Release() {
  const std::uint64_t handle = info_.handle;
  core_.reset();
  info_ = ArrayInfo();
  owns_ = false;
  slab_.reset();
  return handle;
}

}  // namespace client_v1
}  // namespace weft
