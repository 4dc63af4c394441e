// Registry rows of the wp.Volume builtins (sampling, lookups, stores, voxel indices, transforms).
// Data only; see builtins.h. The natives live in engine/native/volume.h and take (ctx, function
// id, line) first, adjoints too. `dtype=` forms (volume_sample, volume_sample_grad,
// volume_lookup) pass a value of the type as their last argument (check_expr.cpp); the forms
// with Warp's out-parameter `grad` return (value, grad), of which sema assigns the gradient to
// the argument. docs/geometry.md ("Volumes") describes the design.
#include <string>

#include "engine/sema/builtins.h"

namespace weft::sema {

namespace {

struct VolumeType {
  const char* type;   // kernel type
  const char* grad;   // its spatial gradient
  bool real;          // interpolated and differentiable (floating-point values)
};
constexpr VolumeType kVolumeTypes[] = {
    {"float32", "vec(3,float32)", true},          {"float64", "vec(3,float64)", true},
    {"vec(3,float32)", "mat(3,3,float32)", true}, {"vec(3,float64)", "mat(3,3,float64)", true},
    {"vec(4,float32)", "mat(4,3,float32)", true}, {"vec(4,float64)", "mat(4,3,float64)", true},
    {"int32", "vec(3,int32)", false},              {"int64", "vec(3,int64)", false},
    {"uint32", "vec(3,uint32)", false},
};

}  // namespace

void AddVolumeBuiltins(std::vector<BuiltinOverload>* rows) {
  const unsigned diff = kBuiltinNeedsLoc, nd = kBuiltinNeedsLoc | kBuiltinNotDiff;
  auto v = [rows](const std::string& sig, const char* doc, unsigned flags) {
    rows->push_back(Builtin("Volumes", sig.c_str(), doc, flags));
  };
  const std::string id = "id: uint64", uvw = "uvw: vec(3,float32)", mode = "sampling_mode: int32";
  const std::string ijk = "i: int32, j: int32, k: int32";
  for (const VolumeType& t : kVolumeTypes) {
    const std::string T = t.type;
    v("volume_sample(" + id + ", " + uvw + ", " + mode + ", dtype: " + T + ") -> " + T,
      "The volume's value at index-space uvw: sampling_mode wp.Volume.CLOSEST (the nearest voxel) or "
      "wp.Volume.LINEAR (trilinear); call as volume_sample(id, uvw, mode, dtype=T).",
      t.real ? diff : nd);
    if (t.real)
      v("volume_sample_grad(" + id + ", " + uvw + ", " + mode + ", dtype: " + T + ") -> tuple(" + T + ", " + t.grad + ")",
        "volume_sample with its gradient with respect to uvw; call as volume_sample_grad(id, uvw, mode, grad, dtype=T) "
        "(grad: an out-parameter, zero for CLOSEST).",
        diff);
    v("volume_lookup(" + id + ", " + ijk + ", dtype: " + T + ") -> " + T,
      "The value of voxel (i, j, k) (the background outside the leaves); call as volume_lookup(id, i, j, k, dtype=T).", nd);
    v("volume_store(" + id + ", " + ijk + ", value: " + T + ") -> None",
      "Writes voxel (i, j, k) of a leaf (nothing outside the leaves).", nd | kBuiltinSideEffect);
    if (t.real) {
      v("volume_sample_index(" + id + ", " + uvw + ", " + mode + ", voxel_data: array(" + T + ",1), background: " + T +
            ") -> " + T,
        "Samples voxel_data through the volume's voxel indices (volume_lookup_index): background where a voxel has none.",
        diff);
      v("volume_sample_grad_index(" + id + ", " + uvw + ", " + mode + ", voxel_data: array(" + T + ",1), background: " +
            T + ") -> tuple(" + T + ", " + t.grad + ")",
        "volume_sample_index with its gradient; call with grad as the last (out-)argument.", diff);
    }
  }
  v("volume_sample_f(" + id + ", " + uvw + ", " + mode + ") -> float32", "volume_sample of a float volume.", diff);
  v("volume_sample_grad_f(" + id + ", " + uvw + ", " + mode + ") -> tuple(float32, vec(3,float32))",
    "volume_sample_grad of a float volume; call with grad as the last (out-)argument.", diff);
  v("volume_lookup_f(" + id + ", " + ijk + ") -> float32", "volume_lookup of a float volume.", nd);
  v("volume_store_f(" + id + ", " + ijk + ", value: float32) -> None", "volume_store to a float volume.",
    nd | kBuiltinSideEffect);
  v("volume_sample_v(" + id + ", " + uvw + ", " + mode + ") -> vec(3,float32)", "volume_sample of a vec3f volume.", diff);
  v("volume_lookup_v(" + id + ", " + ijk + ") -> vec(3,float32)", "volume_lookup of a vec3f volume.", nd);
  v("volume_store_v(" + id + ", " + ijk + ", value: vec(3,float32)) -> None", "volume_store to a vec3f volume.",
    nd | kBuiltinSideEffect);
  v("volume_sample_i(" + id + ", " + uvw + ") -> int32", "The nearest voxel's value of an int32 volume.", nd);
  v("volume_lookup_i(" + id + ", " + ijk + ") -> int32", "volume_lookup of an int32 volume.", nd);
  v("volume_store_i(" + id + ", " + ijk + ", value: int32) -> None", "volume_store to an int32 volume.",
    nd | kBuiltinSideEffect);
  v("volume_lookup_index(" + id + ", " + ijk + ") -> int32",
    "The voxel's index: leaf * 512 + (i&7)*64 + (j&7)*8 + (k&7) in value and Index grids, the rank among the "
    "active voxels in OnIndex grids; -1 where there is none.",
    nd);
  v("volume_voxel_count(" + id + ") -> int32", "The number of voxel indices (volume_lookup_index < it).", nd);
  for (const char* s : {"float32", "float64"}) {
    const std::string V = std::string("vec(3,") + s + ")";
    v("volume_index_to_world(" + id + ", uvw: " + V + ") -> " + V, "Index space to world space (M uvw + t).", diff);
    v("volume_world_to_index(" + id + ", xyz: " + V + ") -> " + V, "World space to index space (M^-1 (xyz - t)).", diff);
    v("volume_index_to_world_dir(" + id + ", uvw: " + V + ") -> " + V, "A direction from index to world space (M uvw).",
      diff);
    v("volume_world_to_index_dir(" + id + ", xyz: " + V + ") -> " + V,
      "A direction from world to index space (M^-1 xyz).", diff);
  }
}

}  // namespace weft::sema
