// Argument packing for CPU launches.
#include "engine/runtime/launch_args.h"

#include <cstdlib>
#include <cstring>

#include "engine/native/launch_abi.h"
#include "engine/runtime/array_validation.h"

namespace weft {

ArgBlock::ArgBlock(uint32_t size) : size_(size) {
  size_t n = (static_cast<size_t>(size) + 63) / 64 * 64;
  if (n == 0) n = 64;
  char* p = static_cast<char*>(std::aligned_alloc(64, n));
  std::memset(p, 0, n);
  bytes_ = std::shared_ptr<char>(p, [](char* q) { std::free(q); });
}

namespace {

const char* KindName(ArgValue::Kind k) {
  switch (k) {
    case ArgValue::Kind::kRaw: return "a value";
    case ArgValue::Kind::kArray: return "an array";
    case ArgValue::Kind::kStruct: return "a struct";
  }
  return "?";
}

struct Packer {
  const KernelLayout& kernel;
  bool adjoint = false;   // values as sent (zero when none); arrays fill `data` only
  const PackedArgs* primal = nullptr;   // adjoint: the forward block the shapes must match
  std::string device = "cpu";           // where the launch runs: every array must live there
  PackedArgs out;

  std::string Where(const std::string& path, const ParamLayout& p) const {
    return "kernel '" + kernel.name + "' " + (adjoint ? "adjoint " : "") + "parameter '" + path +
           "' (" + p.type + ")";
  }

  Status Pack(const ParamLayout& p, const ResolvedArg& a, uint32_t base, const std::string& path, int top) {
    const uint32_t at = base + p.offset;
    if (static_cast<uint64_t>(at) + p.size > out.block.size())
      return Internal(Where(path, p) + ": layout outside the argument block (compiler bug)");
    if (p.is_array) {
      if (a.kind != ArgValue::Kind::kArray)
        return InvalidArgument(Where(path, p) + ": expected an array, got " + KindName(a.kind));
      if (p.size < sizeof(wp::array_abi_t))
        return Internal(Where(path, p) + ": array slot smaller than array_abi_t (compiler bug)");
      wp::array_abi_t abi{};
      abi.ndim = p.array_ndim;
      PackedArray slot;
      slot.offset = at;
      slot.param = path;
      slot.top_param = top;
      if (a.alloc) {
        Allocation& al = *a.alloc;
        ArrayRequirement req;
        struct WhereContext {
          const Packer* packer;
          const std::string* path;
          const ParamLayout* param;
        } where{this, &path, &p};
        req.build_what = [](const void* c) {
          const auto* w = static_cast<const WhereContext*>(c);
          return w->packer->Where(*w->path, *w->param);
        };
        req.build_what_context = &where;
        req.device = device;
        req.dtype = p.array_dtype;
        req.element_size = p.array_elem_size;
        req.ndim = p.array_ndim;
        // An adjoint array must have exactly the shape of the primal array in the same slot:
        // the forward replay's bounds checks and the adjoint's index the same elements.
        std::vector<int64_t> primal_shape;
        const void* primal_grad = nullptr;
        if (adjoint && primal) {
          for (const PackedArray& ps : primal->arrays) {
            if (ps.offset != at || ps.handle == 0) continue;
            if (static_cast<uint64_t>(at) + sizeof(wp::array_abi_t) > primal->block.size())
              return Internal(Where(path, p) + ": adjoint layout differs from the forward layout (compiler bug)");
            wp::array_abi_t pabi{};
            std::memcpy(&pabi, primal->block.data() + at, sizeof(pabi));
            const int nd = pabi.ndim < 0 ? 0 : (pabi.ndim > wp::ARRAY_MAX_DIMS ? wp::ARRAY_MAX_DIMS : pabi.ndim);
            primal_shape.assign(pabi.shape, pabi.shape + nd);
            if (!(pabi.flags & wp::ARRAY_FLAG_RETAIN_GRAD)) primal_grad = pabi.grad;
            req.shape = &primal_shape;
          }
        }
        WEFT_ASSIGN_OR_RETURN(ArrayView v, ValidateArray(a.alloc, *a.ref, req));
        abi.data = v.data();
        // A view as another dtype has no gradient (Warp's array.view gives an array without one).
        const bool viewed = a.ref->view_dtype.has_value();
        abi.grad = (!adjoint && al.grad && !viewed) ? al.grad->data() + v.byte_offset : nullptr;
        if (!adjoint && a.ref->retain_grad) abi.flags = wp::ARRAY_FLAG_RETAIN_GRAD;
        // The primal array's own gradient (its .grad when packed) is consumed by stores'
        // adjoints, as Warp's adj_array_store does when adj_buf.data == buf.grad.
        if (primal_grad != nullptr && primal_grad == abi.data) abi.flags = wp::ARRAY_FLAG_CONSUME_ADJOINT;
        abi.ndim = static_cast<wp::int32>(v.shape.size());
        for (size_t i = 0; i < v.shape.size(); ++i) {
          abi.shape[i] = v.shape[i];
          abi.strides[i] = v.strides[i];
        }
        slot.alloc = a.alloc;
        slot.handle = al.handle;
        slot.byte_offset = v.byte_offset;
        slot.viewed = viewed;
        out.keep_alive.push_back(a.alloc);
      }
      std::memcpy(out.block.data() + at, &abi, sizeof(abi));
      out.arrays.push_back(std::move(slot));
      return Status::Ok();
    }
    if (!p.fields.empty() || p.type.rfind("struct(", 0) == 0) {
      if (a.kind != ArgValue::Kind::kStruct)
        return InvalidArgument(Where(path, p) + ": expected a struct, got " + KindName(a.kind));
      if (a.fields.size() != p.fields.size())
        return InvalidArgument(Where(path, p) + ": struct has " + std::to_string(p.fields.size()) +
                               " fields, got " + std::to_string(a.fields.size()));
      for (size_t i = 0; i < p.fields.size(); ++i)
        WEFT_RETURN_IF_ERROR(Pack(p.fields[i], a.fields[i], at, path + "." + p.fields[i].name, top));
      return Status::Ok();
    }
    if (a.kind != ArgValue::Kind::kRaw) {
      if (adjoint) return Status::Ok();   // no adjoint value sent: the slot stays zero
      return InvalidArgument(Where(path, p) + ": expected a value, got " + KindName(a.kind));
    }
    // An adjoint value slot starts at the value sent (Warp's adj_inputs of value parameters;
    // zero by default), as the primal's does.
    if (a.raw.size() != p.size)
      return InvalidArgument(Where(path, p) + ": value has " + std::to_string(a.raw.size()) +
                             " bytes, expected " + std::to_string(p.size));
    std::memcpy(out.block.data() + at, a.raw.data(), a.raw.size());
    return Status::Ok();
  }

  Status PackAll(const std::vector<ResolvedArg>& args) {
    out.block = ArgBlock(kernel.args_size);
    out.arrays.reserve(kernel.params.size());
    out.keep_alive.reserve(kernel.params.size());
    if (args.size() != kernel.params.size())
      return InvalidArgument("kernel '" + kernel.name + "'" + (adjoint ? " adjoint" : "") + " takes " +
                             std::to_string(kernel.params.size()) + " arguments, got " +
                             std::to_string(args.size()));
    for (size_t i = 0; i < args.size(); ++i)
      WEFT_RETURN_IF_ERROR(Pack(kernel.params[i], args[i], 0, kernel.params[i].name, static_cast<int>(i)));
    return Status::Ok();
  }
};

}  // namespace

Expected<PackedArgs> PackArgs(const KernelLayout& kernel, const std::vector<ResolvedArg>& args,
                              const std::string& device) {
  Packer p{kernel, false, nullptr, device, {}};
  WEFT_RETURN_IF_ERROR(p.PackAll(args));
  return std::move(p.out);
}

Expected<PackedArgs> PackAdjointArgs(const KernelLayout& kernel, const PackedArgs& primal,
                                     const std::vector<ResolvedArg>& adj_args, const std::string& device) {
  Packer p{kernel, true, &primal, device, {}};
  WEFT_RETURN_IF_ERROR(p.PackAll(adj_args));
  return std::move(p.out);
}

Expected<PackedArgs> GradientArgs(const KernelLayout& kernel, const PackedArgs& forward,
                                  const std::vector<std::shared_ptr<Allocation>>& live) {
  PackedArgs out;
  out.block = ArgBlock(kernel.args_size);
  for (size_t i = 0; i < forward.arrays.size(); ++i) {
    const PackedArray& slot = forward.arrays[i];
    if (static_cast<uint64_t>(slot.offset) + sizeof(wp::array_abi_t) > out.block.size())
      return Internal("kernel '" + kernel.name + "': recorded array slot outside the argument block (daemon bug)");
    wp::array_abi_t abi{};
    std::memcpy(&abi, forward.block.data() + slot.offset, sizeof(abi));
    const std::shared_ptr<Allocation>& a = i < live.size() ? live[i] : nullptr;
    // The array's .grad when the launch was recorded (none to consume with retain_grad).
    const void* recorded_grad = (abi.flags & wp::ARRAY_FLAG_RETAIN_GRAD) ? nullptr : abi.grad;
    abi.flags = 0;
    abi.data = nullptr;
    abi.grad = nullptr;
    if (a && a->grad && !slot.viewed) {
      // The gradient goes through the same validation as every array: the recorded view
      // (offset, shape, strides) must lie inside the gradient allocation.
      const int nd = abi.ndim < 0 ? 0 : (abi.ndim > wp::ARRAY_MAX_DIMS ? wp::ARRAY_MAX_DIMS : abi.ndim);
      ArrayRef ref;
      ref.handle = a->grad->handle;
      ref.byte_offset = slot.byte_offset;
      ref.shape.assign(abi.shape, abi.shape + nd);
      ref.strides.assign(abi.strides, abi.strides + nd);
      ArrayRequirement req;
      req.what = "kernel '" + kernel.name + "' gradient of '" + slot.param + "'";
      req.device = a->device;
      req.dtype = a->dtype.Name();
      req.element_size = a->dtype.ElementSize();
      req.shape = &ref.shape;
      WEFT_ASSIGN_OR_RETURN(ArrayView v, ValidateArray(a->grad, ref, req));
      // Consumed by stores' adjoints when it is the gradient the array had when recorded.
      if (recorded_grad != nullptr && recorded_grad == v.data()) abi.flags = wp::ARRAY_FLAG_CONSUME_ADJOINT;
      abi.data = v.data();
      out.keep_alive.push_back(a->grad);
    }
    std::memcpy(out.block.data() + slot.offset, &abi, sizeof(abi));
    out.arrays.push_back(slot);
  }
  return out;
}

bool TidIndicesInRange(const KernelLayout& kernel, const PackedArgs& args, const std::vector<int64_t>& dim) {
  if (kernel.tid_indexed_params.empty() || dim.empty()) return false;
  uint64_t threads = 1;
  for (int64_t d : dim)
    if (d <= 0 || __builtin_mul_overflow(threads, static_cast<uint64_t>(d), &threads)) return false;
  for (uint32_t p : kernel.tid_indexed_params) {
    if (p >= kernel.params.size()) return false;
    const PackedArray* slot = nullptr;
    for (const PackedArray& a : args.arrays)
      if (a.top_param == static_cast<int>(p) && a.param == kernel.params[p].name) slot = &a;
    if (!slot || static_cast<uint64_t>(slot->offset) + sizeof(wp::array_abi_t) > args.block.size()) return false;
    wp::array_abi_t abi{};
    std::memcpy(&abi, args.block.data() + slot->offset, sizeof abi);
    if (abi.data == nullptr || abi.ndim != 1 || abi.shape[0] < 0 || static_cast<uint64_t>(abi.shape[0]) < threads)
      return false;
  }
  return true;
}

}  // namespace weft
