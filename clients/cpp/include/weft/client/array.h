// weft::Array: one allocation in the daemon, owned by this client (RAII: freed when the Array
// is destroyed, unless released). Local CPU arrays are seen zero-copy through the daemon's
// shared-memory slab (mapped once per slab and shared by every Array in it); other arrays move
// their bytes through chunked Read/Write streams.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "weft/client/commands.h"
#include "weft/client/status.h"
#include "weft/client/types.h"

namespace weft {
inline namespace client_v1 {

namespace detail {
class ClientCore;
class MappedSlab;
}  // namespace detail

class Array {
 public:
  Array() = default;                      // no array (valid() is false)
  Array(Array&& other) noexcept;
  Array& operator=(Array&& other) noexcept;
  Array(const Array&) = delete;
  Array& operator=(const Array&) = delete;
  ~Array();                               // frees the allocation if this Array owns it

  bool valid() const { return info_.handle != 0; }
  // False for views handed out by Grad(): destroying them frees nothing.
  bool owns() const { return owns_; }

  const ArrayInfo& info() const { return info_; }
  std::uint64_t handle() const { return info_.handle; }
  const DType& dtype() const { return info_.dtype; }
  const std::vector<std::int64_t>& shape() const { return info_.shape; }
  const std::vector<std::int64_t>& strides() const { return info_.strides; }
  int ndim() const { return info_.ndim(); }
  std::int64_t size() const { return info_.size(); }
  const std::string& device() const { return info_.device; }
  std::uint64_t byte_size() const { return info_.byte_size; }

  // The whole array as a command operand.
  ArrayView view() const;
  // Rows [begin, end) of the first dimension (Python's a[begin:end]; negative indices count
  // from the end). OUT_OF_RANGE when the range does not fit.
  Expected<ArrayView> Slice(std::int64_t begin, std::int64_t end) const;

  // True when the bytes can be seen in place (a local client, a CPU array in a slab).
  bool mappable() const;
  // The allocation's bytes in this process, zero-copy; valid while this Array lives. Does not
  // synchronize: call Client::Synchronize() before reading what queued commands wrote.
  // FAILED_PRECONDITION when !mappable().
  Expected<std::span<std::byte>> Map();
  template <typename T>
  Expected<std::span<T>> MapAs();

  // Copies the whole allocation into dst (n must equal byte_size()), after running every
  // queued command (flush + synchronize): zero-copy memcpy from the slab when mapped, chunked
  // Read stream otherwise.
  Status Read(void* dst, std::size_t n);
  // Overwrites the whole allocation from src (n must equal byte_size()), after the queued
  // commands have run.
  Status Write(const void* src, std::size_t n);
  template <typename T>
  Expected<std::vector<T>> ToVector();
  template <typename T>
  Status Assign(std::span<const T> values);
  template <typename T>
  Status Assign(const std::vector<T>& values) { return Assign(std::span<const T>(values)); }

  // Queued commands (run in order; their errors surface at Client::Synchronize).
  // Every scalar component of every element becomes `value` converted to the scalar type.
  Status Fill(double value);
  // Every element becomes these bytes (n must equal dtype().element_size()).
  Status FillBytes(const void* element, std::size_t n);
  Status Zero();
  // This array's elements become src's (same element type and element count).
  Status CopyFrom(const Array& src);

  // Asks the daemon again (shape, gradient, slab placement).
  Expected<ArrayInfo> Describe();
  // The gradient array (requires_grad); a non-owning Array, freed with this one.
  Expected<Array> Grad();
  // An opaque token another local session with the same credentials can Import.
  Expected<std::string> Export();

  // Frees now; the Array becomes invalid. Freeing an invalid or non-owning Array is a no-op.
  Status Free();
  // Gives up ownership: the allocation stays alive until the session ends; returns its handle.
  std::uint64_t Release();

 private:
  friend class Client;
  Array(std::shared_ptr<detail::ClientCore> core, ArrayInfo info, bool owns);
  Expected<std::shared_ptr<detail::MappedSlab>> EnsureMapped();

  std::shared_ptr<detail::ClientCore> core_;
  ArrayInfo info_;
  bool owns_ = false;
  std::shared_ptr<detail::MappedSlab> slab_;   // set once mapped
};

template <typename T>
Expected<std::span<T>> Array::MapAs() {
  if (byte_size() % sizeof(T) != 0)
    return InvalidArgument("MapAs: array of " + std::to_string(byte_size()) +
                           " bytes is not a whole number of " + std::to_string(sizeof(T)) +
                           "-byte values");
  auto bytes = Map();
  if (!bytes.ok()) return bytes.status();
  return std::span<T>(reinterpret_cast<T*>(bytes->data()), bytes->size() / sizeof(T));
}

template <typename T>
Expected<std::vector<T>> Array::ToVector() {
  if (byte_size() % sizeof(T) != 0)
    return InvalidArgument("ToVector: array of " + std::to_string(byte_size()) +
                           " bytes is not a whole number of " + std::to_string(sizeof(T)) +
                           "-byte values");
  std::vector<T> out(byte_size() / sizeof(T));
  Status s = Read(out.data(), out.size() * sizeof(T));
  if (!s.ok()) return s;
  return out;
}

template <typename T>
Status Array::Assign(std::span<const T> values) {
  return Write(values.data(), values.size_bytes());
}

}  // namespace client_v1
}  // namespace weft
