// ArrayView: range checks and strided elementwise fill/copy.
#include "engine/runtime/array_view.h"

#include <atomic>
#include <cstring>
#include <limits>

#include "engine/core/checked_math.h"

namespace weft {

uint64_t ArrayView::element_count() const {
  uint64_t n = 1;
  for (int64_t d : shape) n *= static_cast<uint64_t>(d);
  return n;
}

bool ArrayView::contiguous() const {
  return HasContiguousStrides(shape, strides, dtype().ElementSize());
}

Expected<ArrayView> MakeView(std::shared_ptr<Allocation> alloc, const ArrayRef& ref,
                             const ArrayName& what) {
  ArrayView v;
  const uint64_t handle = alloc->handle;
  auto name = [&] { return what.Text() + " (array " + std::to_string(handle) + ")"; };
  if (ref.view_dtype) {   // the bytes read as another element type (array.view(dtype))
    const DType& d = *ref.view_dtype;
    if (Status valid = d.Validate(); !valid.ok()) return InvalidArgument(name() + ": view dtype: " + valid.message());
    if (d.is_struct() || alloc->dtype.is_struct())
      return InvalidArgument(name() + ": a view as another dtype is for scalar, vector and matrix types, not structs (" +
                             alloc->dtype.Name() + " as " + d.Name() + ")");
    const ScalarType from = alloc->dtype.scalar;
    if (d.scalar == ScalarType::kBool && from != ScalarType::kBool && from != ScalarType::kInt8 &&
        from != ScalarType::kUInt8)
      return InvalidArgument(name() + ": " + alloc->dtype.Name() + " cannot be viewed as bool (only bool, int8 or uint8)");
    if (ref.shape.empty()) return InvalidArgument(name() + ": a view as another dtype needs its shape and strides");
    v.view_dtype = d;
  }
  const DType& dtype = ViewDType(*alloc, ref);
  const uint64_t esize = dtype.ElementSize();
  if (ref.shape.empty()) {
    if (ref.byte_offset != 0 || !ref.strides.empty())
      return InvalidArgument(name() + ": a view with an empty shape means the whole array; give a shape with byte_offset/strides");
    v.shape = alloc->shape;
    v.strides = alloc->strides;
    v.byte_offset = 0;
    v.alloc = std::move(alloc);
    return v;
  }
  if (ref.shape.size() > kMaxArrayDims)
    return InvalidArgument(name() + ": view has " + std::to_string(ref.shape.size()) +
                           " dimensions; at most 4");
  if (!ref.strides.empty() && ref.strides.size() != ref.shape.size())
    return InvalidArgument(name() + ": view has " + std::to_string(ref.shape.size()) +
                           " dimensions but " + std::to_string(ref.strides.size()) + " strides");
  for (int64_t d : ref.shape)
    if (d < 0) return InvalidArgument(name() + ": negative extent in view shape " + ShapeString(ref.shape));
  // The view's logical size (elements x element size) must fit kMaxCheckedSize, checked without
  // wrapping: element counts, contiguous strides and temporaries are then exact in 64 bits.
  uint64_t logical_bytes = 0;
  if (!CheckedShapeProduct(ref.shape, esize, &logical_bytes))
    return InvalidArgument(name() + ": view shape " + ShapeString(ref.shape) + " has too many elements (more than " +
                           std::to_string(kMaxCheckedSize) + " bytes of " + dtype.Name() + ")");
  v.shape = ref.shape;
  v.strides = ref.strides.empty() ? ContiguousStrides(ref.shape, esize) : ref.strides;
  v.byte_offset = ref.byte_offset;
  const uint32_t unit = dtype.ComponentSize();
  if (unit > 1) {
    if (ref.byte_offset % unit)
      return InvalidArgument(name() + ": byte_offset " + std::to_string(ref.byte_offset) +
                             " is not a multiple of the scalar size " + std::to_string(unit));
    for (int64_t s : v.strides)
      if (s % static_cast<int64_t>(unit))
        return InvalidArgument(name() + ": stride " + std::to_string(s) +
                               " is not a multiple of the scalar size " + std::to_string(unit));
  }
  // Lowest and highest byte touched, in 128-bit arithmetic to survive absurd inputs.
  __int128 lo = static_cast<__int128>(ref.byte_offset), hi = lo;
  bool empty = false;
  for (size_t i = 0; i < v.shape.size(); ++i) {
    if (v.shape[i] == 0) empty = true;
    __int128 span = static_cast<__int128>(v.shape[i] - 1) * v.strides[i];
    if (span < 0) lo += span; else hi += span;
  }
  const __int128 size = static_cast<__int128>(alloc->byte_size);
  if (empty) {
    if (ref.byte_offset > alloc->byte_size)
      return OutOfRange(name() + ": byte_offset " + std::to_string(ref.byte_offset) +
                        " is past the end of the allocation (" + std::to_string(alloc->byte_size) + " bytes)");
  } else if (lo < 0 || hi + static_cast<__int128>(esize) > size) {
    return OutOfRange(name() + ": view (offset " + std::to_string(ref.byte_offset) + ", shape " +
                      ShapeString(v.shape) + ", strides " + ShapeString(v.strides) +
                      ") reaches outside the allocation of " + std::to_string(alloc->byte_size) +
                      " bytes (array shape " + ShapeString(alloc->shape) + ")");
  }
  v.alloc = std::move(alloc);
  return v;
}

namespace {

// Calls fn(byte offset of element) for every element of (shape, strides) in C order. Checks
// `cancel` (may be null) every kCancelCheckElements elements and returns false when it is set.
constexpr uint64_t kCancelCheckElements = 1 << 16;

template <typename Fn>
bool ForEachElement(const std::vector<int64_t>& shape, const std::vector<int64_t>& strides, Fn&& fn,
                    const std::atomic<bool>* cancel = nullptr) {
  const size_t nd = shape.size();
  for (int64_t d : shape)
    if (d == 0) return true;
  int64_t idx[kMaxArrayDims] = {0, 0, 0, 0};
  int64_t off = 0;
  uint64_t until_check = kCancelCheckElements;
  while (true) {
    if (cancel && --until_check == 0) {
      if (cancel->load(std::memory_order_relaxed)) return false;
      until_check = kCancelCheckElements;
    }
    fn(off);
    size_t k = nd;
    while (k > 0) {
      --k;
      if (++idx[k] < shape[k]) {
        off += strides[k];
        break;
      }
      off -= strides[k] * (shape[k] - 1);
      idx[k] = 0;
      if (k == 0) return true;
    }
    if (nd == 0) return true;
  }
}

Status CancelledWork(const char* what) {
  return Status(StatusCode::kCancelled, std::string(what) + " cancelled: its session was closed");
}

// Byte offset of the current element of (shape, strides), advanced in C order by Next().
struct Odometer {
  const std::vector<int64_t>& shape;
  const std::vector<int64_t>& strides;
  int64_t idx[kMaxArrayDims] = {0, 0, 0, 0};
  int64_t offset = 0;
  Odometer(const std::vector<int64_t>& sh, const std::vector<int64_t>& st) : shape(sh), strides(st) {}
  void Next() {
    for (size_t k = shape.size(); k-- > 0;) {
      if (++idx[k] < shape[k]) {
        offset += strides[k];
        return;
      }
      offset -= strides[k] * (shape[k] - 1);
      idx[k] = 0;
    }
  }
};

}  // namespace

Status FillView(const ArrayView& dst, const std::string& value, const std::atomic<bool>* cancel) {
  const uint64_t esize = dst.dtype().ElementSize();
  if (value.size() != esize)
    return InvalidArgument("fill: value has " + std::to_string(value.size()) +
                           " bytes; one element of " + dst.dtype().Name() + " has " +
                           std::to_string(esize));
  char* base = dst.data();
  const uint64_t n = dst.element_count();
  if (n == 0) return Status::Ok();
  if (dst.contiguous()) {
    bool zero = true;
    for (char c : value) zero = zero && c == 0;
    if (zero) {
      std::memset(base, 0, n * esize);
      return Status::Ok();
    }
    // Doubling memcpy: fill one element, then copy the filled prefix.
    std::memcpy(base, value.data(), esize);
    uint64_t done = 1;
    while (done < n) {
      uint64_t m = done < n - done ? done : n - done;
      std::memcpy(base + done * esize, base, m * esize);
      done += m;
    }
    return Status::Ok();
  }
  if (!ForEachElement(dst.shape, dst.strides, [&](int64_t off) { std::memcpy(base + off, value.data(), esize); },
                      cancel))
    return CancelledWork("fill");
  return Status::Ok();
}

Status CopyView(const ArrayView& dst, const ArrayView& src, const std::atomic<bool>* cancel) {
  const uint64_t esize = dst.dtype().ElementSize();
  if (src.dtype().ElementSize() != esize)   // a byte copy: any two types of one size (Warp's rule)
    return InvalidArgument("copy: element sizes differ (dst " + dst.dtype().Name() + ", " + std::to_string(esize) +
                           " bytes; src " + src.dtype().Name() + ", " + std::to_string(src.dtype().ElementSize()) +
                           " bytes)");
  if (src.element_count() != dst.element_count())
    return InvalidArgument("copy: dst has " + std::to_string(dst.element_count()) + " elements " +
                           ShapeString(dst.shape) + ", src has " + std::to_string(src.element_count()) +
                           " " + ShapeString(src.shape));
  const uint64_t n = dst.element_count();
  if (n == 0) return Status::Ok();
  if (dst.contiguous() && src.contiguous()) {
    std::memmove(dst.data(), src.data(), n * esize);
    return Status::Ok();
  }
  // Walk both views in C order with one odometer each. When they share an allocation (they may
  // overlap), read the source from a snapshot of the allocation's bytes: its size is the
  // allocation's, never derived from the view's element count (a stride-0 view may name far more
  // elements than the allocation holds).
  std::vector<char> snapshot;
  const char* sbase = src.data();
  const std::vector<int64_t>& sshape = src.shape;
  const std::vector<int64_t>& sstrides = src.strides;
  if (src.alloc == dst.alloc) {
    snapshot.assign(src.alloc->data(), src.alloc->data() + src.alloc->byte_size);
    sbase = snapshot.data() + src.byte_offset;
  }
  Odometer so(sshape, sstrides);
  char* dbase = dst.data();
  if (!ForEachElement(dst.shape, dst.strides, [&](int64_t off) {
        std::memcpy(dbase + off, sbase + so.offset, esize);
        so.Next();
      }, cancel))
    return CancelledWork("copy");
  return Status::Ok();
}

}  // namespace weft
