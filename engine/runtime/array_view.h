// Views of allocations (engine twin of weft.v1.ArrayRef): byte offset, shape and byte strides.
// Owns the check that every element of a view lies inside its allocation, and elementwise
// fill/copy over strided views.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/runtime/allocation.h"

namespace weft {

constexpr int kMaxArrayDims = 4;

// As a client names an array in a command. Empty shape = the whole allocation (byte_offset must
// then be 0); empty strides = C-contiguous for the shape.
struct ArrayRef {
  uint64_t handle = 0;
  uint64_t byte_offset = 0;
  std::vector<int64_t> shape;
  std::vector<int64_t> strides;
  bool retain_grad = false;   // a kernel argument: its gradient is kept through stores' adjoints
  // The element type the view reads the bytes as (Warp's array.view(dtype)); empty: the
  // allocation's. A scalar, vector or matrix type (validated), never a struct, over an
  // allocation that holds no structs; bool only over bool or 8-bit integers.
  std::optional<DType> view_dtype = std::nullopt;
};

// A checked view: the allocation it points into and the resolved shape/strides.
struct ArrayView {
  std::shared_ptr<Allocation> alloc;
  uint64_t byte_offset = 0;
  std::vector<int64_t> shape;
  std::vector<int64_t> strides;

  std::optional<DType> view_dtype = std::nullopt;   // as in the ArrayRef it was made from

  // The element type of the view: the ArrayRef's view_dtype, else the allocation's.
  const DType& dtype() const { return view_dtype ? *view_dtype : alloc->dtype; }
  uint64_t element_count() const;
  char* data() const { return alloc->data() + byte_offset; }
  bool contiguous() const;
};

// The element type `ref` reads `alloc`'s bytes as: its view_dtype, else the allocation's.
inline const DType& ViewDType(const Allocation& alloc, const ArrayRef& ref) {
  return ref.view_dtype ? *ref.view_dtype : alloc.dtype;
}

// Names an array in error messages: fixed text, or a function that builds the text only when a
// message needs it (a launch checks every array argument; most checks pass). Holds pointers:
// what it names must outlive it.
class ArrayName {
 public:
  ArrayName(const std::string& text) : text_(&text) {}   // NOLINT: implicit by design
  ArrayName(const char* text) : literal_(text) {}         // NOLINT: implicit by design
  ArrayName(std::string (*build)(const void*), const void* context) : build_(build), context_(context) {}
  std::string Text() const {
    if (build_) return build_(context_);
    return text_ ? *text_ : std::string(literal_ ? literal_ : "");
  }

 private:
  const std::string* text_ = nullptr;
  const char* literal_ = nullptr;
  std::string (*build_)(const void*) = nullptr;
  const void* context_ = nullptr;
};

// Resolves `ref` against `alloc` and checks it: 1..4 dimensions, non-negative extents, offset
// and strides aligned to the element's scalar size, every element inside the allocation (with
// the view's element type, ArrayRef::view_dtype, where one is given).
// `what` names the view in messages ("dst", "argument 'a'").
Expected<ArrayView> MakeView(std::shared_ptr<Allocation> alloc, const ArrayRef& ref,
                             const ArrayName& what);

// Sets every element of `dst` to `value` (one element's bytes). A strided walk checks `cancel`
// (may be null) every 65,536 elements and stops with CANCELLED once it is set.
Status FillView(const ArrayView& dst, const std::string& value, const std::atomic<bool>* cancel = nullptr);
// Copies src to dst elementwise in C order; same element size and element count required.
// Cancellation as FillView.
Status CopyView(const ArrayView& dst, const ArrayView& src, const std::atomic<bool>* cancel = nullptr);

}  // namespace weft
