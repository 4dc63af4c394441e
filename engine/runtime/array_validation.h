// The one validation every array a command touches goes through before any code runs: copy and
// fill views, forward kernel arguments (struct fields included), explicit adjoint arguments,
// tape gradients and backward seeds. It checks, from the daemon's own records and never from
// what the client claims:
//   - the allocation is on the command's device and is self-consistent (its byte size is the
//     overflow-checked product of its shape and its element size, inside its memory block);
//   - the element type the command needs (the compiled kernel's parameter type) matches the
//     allocation's, and the element SIZE the compiled code uses equals the allocation's
//     (a struct array created with a small struct_size cannot pass as a bigger struct);
//   - the view's extents and strides keep every element inside the allocation, with every
//     product overflow-checked (MakeView);
//   - the number of dimensions, and for adjoints the exact shape of the primal view.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/runtime/allocation.h"
#include "engine/runtime/array_view.h"

namespace weft {

// What a command requires of one array. Empty / zero fields are not checked.
struct ArrayRequirement {
  std::string what;                 // names the array in messages ("copy dst", "kernel 'k' parameter 'a'")
  // Builds that name instead of `what`, only when a message needs it (launch arguments).
  std::string (*build_what)(const void*) = nullptr;
  const void* build_what_context = nullptr;
  ArrayName Name() const { return build_what ? ArrayName(build_what, build_what_context) : ArrayName(what); }
  std::string device = "cpu";       // where the command runs
  std::string dtype;                // canonical element type the code was compiled for ("" / "any": any)
  uint64_t element_size = 0;        // bytes per element in the compiled layout (0: not compiled code)
  int ndim = 0;                     // number of dimensions the code indexes (0: any)
  const std::vector<int64_t>* shape = nullptr;   // the view must have exactly this shape (adjoints)
};

// Checks `alloc` (not null) and the view `ref` of it against `req`; returns the checked view.
Expected<ArrayView> ValidateArray(std::shared_ptr<Allocation> alloc, const ArrayRef& ref,
                                  const ArrayRequirement& req);

// Checks that an allocation's recorded size matches its dtype and shape (overflow-checked) and
// fits its memory block. Allocations are made by the daemon; this guards the invariant the
// view checks rely on.
Status CheckAllocationConsistent(const Allocation& alloc);

}  // namespace weft
