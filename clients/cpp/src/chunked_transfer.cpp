// Moving an allocation's bytes through the daemon's chunked Read/Write streams.
#include "chunked_transfer.h"

#include <algorithm>
#include <cstring>

#include "rpc_status.h"

namespace weft::inline client_v1::detail {

Status ReadChunked(ClientCore& core, std::uint64_t handle, std::uint64_t offset, void* dst,
                   std::size_t n) {
  if (n == 0) return Status::Ok();
  v1::ReadArrayRequest request;
  request.set_handle(handle);
  request.set_byte_offset(offset);
  request.set_byte_count(n);
  request.set_chunk_size(static_cast<std::uint32_t>(core.options().chunk_size));
  auto context = core.NewContext();
  auto reader = core.arrays().Read(context.get(), request);
  v1::ArrayChunk chunk;
  std::uint64_t received = 0;
  auto* out = static_cast<std::byte*>(dst);
  Status bad;
  while (reader->Read(&chunk)) {
    // Chunk offsets are relative to the allocation.
    const std::uint64_t begin = chunk.byte_offset();
    const std::uint64_t size = chunk.data().size();
    if (begin < offset || begin - offset + size > n) {
      bad = DataLoss("ArrayService.Read: chunk [" + std::to_string(begin) + ", " +
                     std::to_string(begin + size) + ") outside the requested range");
      context->TryCancel();
      break;
    }
    std::memcpy(out + (begin - offset), chunk.data().data(), size);
    received += size;
  }
  const grpc::Status finished = reader->Finish();
  if (!bad.ok()) return bad;
  WEFT_CLIENT_RETURN_IF_ERROR(FromRpc(finished, "ArrayService.Read"));
  if (received != n)
    return DataLoss("ArrayService.Read: received " + std::to_string(received) + " of " +
                    std::to_string(n) + " bytes");
  return Status::Ok();
}

Status WriteChunked(ClientCore& core, std::uint64_t handle, std::uint64_t offset,
                    const void* src, std::size_t n) {
  auto context = core.NewContext();
  v1::WriteArrayResponse response;
  auto writer = core.arrays().Write(context.get(), &response);
  const auto* in = static_cast<const std::byte*>(src);
  const std::size_t chunk_size = core.options().chunk_size;
  std::size_t done = 0;
  bool first = true;
  // One message at least, so a zero-byte write still names its handle.
  while (first || done < n) {
    const std::size_t size = std::min(chunk_size, n - done);
    v1::WriteArrayRequest request;
    if (first) request.set_handle(handle);
    request.mutable_chunk()->set_byte_offset(offset + done);
    request.mutable_chunk()->set_data(reinterpret_cast<const char*>(in + done), size);
    first = false;
    done += size;
    if (!writer->Write(request)) break;   // the daemon ended the stream; Finish says why
  }
  writer->WritesDone();
  WEFT_CLIENT_RETURN_IF_ERROR(FromRpc(writer->Finish(), "ArrayService.Write"));
  if (response.bytes_written() != n)
    return DataLoss("ArrayService.Write: the daemon wrote " +
                    std::to_string(response.bytes_written()) + " of " + std::to_string(n) +
                    " bytes");
  return Status::Ok();
}

}  // namespace weft::client_v1::detail
