// Conversions between the client's plain types and the weft.v1 protobuf messages.
#include "proto_convert.h"

#include <type_traits>

namespace weft::inline client_v1::detail {

void ToProto(const DType& in, v1::DType* out) {
  out->set_scalar(static_cast<v1::ScalarType>(in.scalar));
  for (auto d : in.elem_shape) out->add_elem_shape(d);
  out->set_type_name(in.is_struct() || !in.type_name.empty() ? in.type_name : in.ToString());
  out->set_struct_size(in.struct_size);
}

DType FromProto(const v1::DType& in) {
  DType d;
  d.scalar = static_cast<ScalarType>(in.scalar());
  d.elem_shape.assign(in.elem_shape().begin(), in.elem_shape().end());
  d.type_name = in.type_name();
  d.struct_size = in.struct_size();
  return d;
}

ArrayInfo FromProto(const v1::ArrayInfo& in) {
  ArrayInfo a;
  a.handle = in.handle();
  a.dtype = FromProto(in.dtype());
  a.shape.assign(in.shape().begin(), in.shape().end());
  a.strides.assign(in.strides().begin(), in.strides().end());
  a.device = in.device();
  a.byte_size = in.byte_size();
  a.grad_handle = in.grad_handle();
  a.shm_name = in.shm_name();
  a.shm_offset = in.shm_offset();
  a.shm_size = in.shm_size();
  return a;
}

DeviceInfo FromProto(const v1::DeviceInfo& in) {
  DeviceInfo d;
  d.name = in.name();
  d.kind = in.kind();
  d.description = in.description();
  d.total_memory = in.total_memory();
  d.free_memory = in.free_memory();
  d.compute_capability_major = in.compute_capability_major();
  d.compute_capability_minor = in.compute_capability_minor();
  d.cores = in.cores();
  return d;
}

DaemonStats FromProto(const v1::StatsResponse& in) {
  DaemonStats s;
  s.sessions = in.sessions();
  s.arrays = in.arrays();
  s.array_bytes = in.array_bytes();
  s.cpu_slabs = in.cpu_slabs();
  s.cpu_slab_bytes = in.cpu_slab_bytes();
  s.module_cache_hits = in.module_cache_hits();
  s.module_cache_disk_hits = in.module_cache_disk_hits();
  s.module_cache_misses = in.module_cache_misses();
  s.sessions_opened_total = in.sessions_opened_total();
  s.sessions_reaped_total = in.sessions_reaped_total();
  return s;
}

void ToProto(const ArrayView& in, v1::ArrayRef* out) {
  out->set_handle(in.handle);
  out->set_byte_offset(in.byte_offset);
  for (auto d : in.shape) out->add_shape(d);
  for (auto s : in.strides) out->add_strides(s);
}

void ToProto(const KernelArg& in, v1::ArgValue* out) {
  std::visit(
      [out](const auto& v) {
        using T = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<T, std::vector<std::byte>>) {
          out->set_raw(reinterpret_cast<const char*>(v.data()), v.size());
        } else if constexpr (std::is_same_v<T, ArrayView>) {
          ToProto(v, out->mutable_array());
        } else {
          auto* s = out->mutable_struct_value();
          if (v)
            for (const auto& f : v->fields) ToProto(f, s->add_fields());
        }
      },
      in);
}

void ToProto(const Command& in, v1::Command* out) {
  std::visit(
      [out](const auto& op) {
        using T = std::decay_t<decltype(op)>;
        if constexpr (std::is_same_v<T, CopyOp>) {
          ToProto(op.dst, out->mutable_copy()->mutable_dst());
          ToProto(op.src, out->mutable_copy()->mutable_src());
        } else if constexpr (std::is_same_v<T, FillOp>) {
          ToProto(op.dst, out->mutable_fill()->mutable_dst());
          out->mutable_fill()->set_value(reinterpret_cast<const char*>(op.value.data()),
                                         op.value.size());
        } else if constexpr (std::is_same_v<T, TapeOp>) {
          auto* t = out->mutable_tape();
          t->set_op(static_cast<v1::TapeCommand::Op>(op.kind));
          t->set_tape_id(op.tape_id);
          if (op.loss.handle != 0) ToProto(op.loss, t->mutable_loss());
          for (const auto& seed : op.seeds) {
            auto* ps = t->add_seeds();
            ToProto(seed.array, ps->mutable_array());
            ToProto(seed.grad, ps->mutable_grad());
          }
        } else {
          auto* l = out->mutable_launch();
          l->set_module_id(op.module_id);
          l->set_kernel(op.kernel);
          for (auto d : op.dim) l->add_dim(d);
          for (const auto& a : op.args) ToProto(a, l->add_args());
          l->set_adjoint(op.adjoint);
          for (const auto& a : op.adj_args) ToProto(a, l->add_adj_args());
          l->set_device(op.device);
        }
      },
      in.op);
  if (!in.origin.file.empty() || in.origin.line != 0) {
    out->mutable_origin()->set_file(in.origin.file);
    out->mutable_origin()->set_line(in.origin.line);
  }
}

}  // namespace weft::client_v1::detail
