// Moving an allocation's bytes through the daemon's chunked Read/Write streams (remote
// clients, GPU arrays, or whenever shared memory cannot be mapped).
#pragma once

#include <cstddef>
#include <cstdint>

#include "client_core.h"

namespace weft::inline client_v1::detail {

// Reads bytes [offset, offset + n) of allocation `handle` into dst; DATA_LOSS when the daemon
// sends fewer bytes or chunks outside the range.
Status ReadChunked(ClientCore& core, std::uint64_t handle, std::uint64_t offset, void* dst,
                   std::size_t n);
// Writes src to bytes [offset, offset + n) of allocation `handle`, in chunks of
// core.options().chunk_size; the daemon checks the range.
Status WriteChunked(ClientCore& core, std::uint64_t handle, std::uint64_t offset,
                    const void* src, std::size_t n);

}  // namespace weft::client_v1::detail
