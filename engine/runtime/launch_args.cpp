// Argument packing for CPU launches.
#include "engine/runtime/launch_args.h"

#include <cstdlib>
#include <cstring>

#include "engine/native/launch_abi.h"

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
  bool adjoint = false;   // values stay zero; arrays fill `data` only
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
        if (al.device != "cpu")
          return InvalidArgument(Where(path, p) + ": array " + std::to_string(al.handle) + " lives on " +
                                 al.device + ", the launch runs on cpu");
        if (!adjoint && !al.dtype.MatchesParam(p.array_dtype))
          return InvalidArgument(Where(path, p) + ": array " + std::to_string(al.handle) +
                                 " has dtype " + al.dtype.Name() + ", expected " + p.array_dtype);
        if (adjoint && !al.dtype.MatchesParam(p.array_dtype) && al.dtype.ElementSize() == 0)
          return InvalidArgument(Where(path, p) + ": unusable adjoint array");
        WEFT_ASSIGN_OR_RETURN(ArrayView v, MakeView(a.alloc, a.ref, Where(path, p)));
        if (p.array_ndim > 0 && static_cast<int>(v.shape.size()) != p.array_ndim)
          return InvalidArgument(Where(path, p) + ": array has " + std::to_string(v.shape.size()) +
                                 " dimensions " + ShapeString(v.shape) + ", expected " +
                                 std::to_string(p.array_ndim));
        abi.data = v.data();
        abi.grad = (!adjoint && al.grad) ? al.grad->data() + v.byte_offset : nullptr;
        abi.ndim = static_cast<wp::int32>(v.shape.size());
        for (size_t i = 0; i < v.shape.size(); ++i) {
          abi.shape[i] = v.shape[i];
          abi.strides[i] = v.strides[i];
        }
        slot.alloc = a.alloc;
        slot.handle = al.handle;
        slot.byte_offset = v.byte_offset;
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
      if (adjoint) return Status::Ok();   // adjoint value slots are zero whatever was sent
      return InvalidArgument(Where(path, p) + ": expected a value, got " + KindName(a.kind));
    }
    if (adjoint) return Status::Ok();
    if (a.raw.size() != p.size)
      return InvalidArgument(Where(path, p) + ": value has " + std::to_string(a.raw.size()) +
                             " bytes, expected " + std::to_string(p.size));
    std::memcpy(out.block.data() + at, a.raw.data(), a.raw.size());
    return Status::Ok();
  }

  Status PackAll(const std::vector<ResolvedArg>& args) {
    out.block = ArgBlock(kernel.args_size);
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

Expected<PackedArgs> PackArgs(const KernelLayout& kernel, const std::vector<ResolvedArg>& args) {
  Packer p{kernel, false, {}};
  WEFT_RETURN_IF_ERROR(p.PackAll(args));
  return std::move(p.out);
}

Expected<PackedArgs> PackAdjointArgs(const KernelLayout& kernel, const std::vector<ResolvedArg>& adj_args) {
  Packer p{kernel, true, {}};
  WEFT_RETURN_IF_ERROR(p.PackAll(adj_args));
  return std::move(p.out);
}

PackedArgs GradientArgs(const KernelLayout& kernel, const PackedArgs& forward,
                        const std::vector<std::shared_ptr<Allocation>>& live) {
  PackedArgs out;
  out.block = ArgBlock(kernel.args_size);
  for (size_t i = 0; i < forward.arrays.size(); ++i) {
    const PackedArray& slot = forward.arrays[i];
    wp::array_abi_t abi{};
    std::memcpy(&abi, forward.block.data() + slot.offset, sizeof(abi));
    const std::shared_ptr<Allocation>& a = i < live.size() ? live[i] : nullptr;
    abi.data = (a && a->grad) ? a->grad->data() + slot.byte_offset : nullptr;
    abi.grad = nullptr;
    if (a && a->grad) out.keep_alive.push_back(a->grad);
    std::memcpy(out.block.data() + slot.offset, &abi, sizeof(abi));
    out.arrays.push_back(slot);
  }
  return out;
}

}  // namespace weft
