// ValidateArray: device, allocation consistency, element type and size, view bounds, shape.
#include "engine/runtime/array_validation.h"

#include "engine/core/checked_math.h"

namespace weft {

Status CheckAllocationConsistent(const Allocation& a) {
  WEFT_RETURN_IF_ERROR(a.dtype.Validate());
  uint64_t bytes = 0;
  if (a.shape.empty() || a.shape.size() > static_cast<size_t>(kMaxArrayDims) ||
      !CheckedShapeProduct(a.shape, a.dtype.ElementSize(), &bytes) || bytes != a.byte_size ||
      !HasContiguousStrides(a.shape, a.strides, a.dtype.ElementSize()) ||
      a.byte_size > a.block.size || (a.byte_size > 0 && a.block.data == nullptr))
    return Internal("array " + std::to_string(a.handle) + " has an inconsistent layout (shape " +
                    ShapeString(a.shape) + ", " + std::to_string(a.byte_size) + " bytes); this is a daemon bug");
  return Status::Ok();
}

Expected<ArrayView> ValidateArray(std::shared_ptr<Allocation> alloc, const ArrayRef& ref,
                                  const ArrayRequirement& req) {
  const ArrayName what = req.Name();
  if (!alloc) return Internal(what.Text() + ": no allocation to validate (daemon bug)");
  const Allocation& a = *alloc;
  auto name = [&] { return what.Text() + ": array " + std::to_string(a.handle); };
  if (!req.device.empty() && a.device != req.device)
    return InvalidArgument(name() + " lives on " + a.device + ", the command runs on " + req.device);
  WEFT_RETURN_IF_ERROR(CheckAllocationConsistent(a));
  // The element type the command reads: the view's (array.view(dtype), checked by MakeView
  // below before any byte is touched) or the allocation's.
  const DType& dtype = ViewDType(a, ref);
  if (!req.dtype.empty() && req.dtype != "any" && !dtype.MatchesParam(req.dtype))
    return InvalidArgument(name() + " has dtype " + dtype.Name() + ", expected " + req.dtype);
  if (req.element_size != 0 && dtype.ElementSize() != req.element_size)
    return InvalidArgument(name() + " has elements of " + std::to_string(dtype.ElementSize()) + " bytes (dtype " +
                           dtype.Name() + (ref.view_dtype ? " as viewed" : " as created") + "), but the compiled kernel's " +
                           (req.dtype.empty() ? std::string("element type") : req.dtype) + " has " +
                           std::to_string(req.element_size) + " bytes per element");
  WEFT_ASSIGN_OR_RETURN(ArrayView v, MakeView(std::move(alloc), ref, what));
  if (req.ndim > 0 && static_cast<int>(v.shape.size()) != req.ndim)
    return InvalidArgument(name() + " has " + std::to_string(v.shape.size()) + " dimensions " + ShapeString(v.shape) +
                           ", expected " + std::to_string(req.ndim));
  if (req.shape && v.shape != *req.shape)
    return InvalidArgument(name() + " has shape " + ShapeString(v.shape) + ", but the primal array has shape " +
                           ShapeString(*req.shape) + " (an adjoint array must have the primal's shape)");
  return v;
}

}  // namespace weft
