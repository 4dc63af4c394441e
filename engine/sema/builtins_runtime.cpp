// Registry rows: atomics, array helpers, selection, random numbers, noise, printing and
// expectations. Data only; see builtins.h. (tid, len, range, printf and the type
// constructors have rules of their own in sema/check_calls.cpp; docs/builtins.md lists them.)
#include <string>

#include "engine/sema/builtins.h"

namespace weft::sema {

void AddRuntimeBuiltins(std::vector<BuiltinOverload>* rows) {
  const char* idx[] = {"i: Index", "i: Index, j: Index", "i: Index, j: Index, k: Index",
                       "i: Index, j: Index, k: Index, l: Index"};
  struct Atomic {
    const char* name;
    const char* doc;
    bool diff;
  };
  const Atomic atomics[] = {
      {"atomic_add", "arr[i] += value atomically; returns the old value. Adjoint: adj_value += arr.grad[i]. Scalar types: "
       "[u]int32, [u]int64, float16, bfloat16, float32, float64.", true},
      {"atomic_sub", "arr[i] -= value atomically; returns the old value. Adjoint: adj_value -= arr.grad[i]. Scalar types: "
       "[u]int32, [u]int64, float16, bfloat16, float32, float64.", true},
      {"atomic_min", "arr[i] = min(arr[i], value) atomically; returns the old value. Scalar types: [u]int32, [u]int64, "
       "bfloat16, float32, float64.", true},
      {"atomic_max", "arr[i] = max(arr[i], value) atomically; returns the old value. Scalar types: [u]int32, [u]int64, "
       "bfloat16, float32, float64.", true},
      {"atomic_exch", "arr[i] = value atomically; returns the old value. Scalar types: [u]int32, [u]int64, float32, float64.", false},
      {"atomic_and", "arr[i] &= value atomically ([u]int32, [u]int64); returns the old value.", false},
      {"atomic_or", "arr[i] |= value atomically ([u]int32, [u]int64); returns the old value.", false},
      {"atomic_xor", "arr[i] ^= value atomically ([u]int32, [u]int64); returns the old value.", false},
  };
  for (const auto& a : atomics) {
    for (int d = 1; d <= 4; ++d) {
      std::string sig = std::string(a.name) + "(arr: array(X," + std::to_string(d) + "), " + idx[d - 1] +
                        ", value: X) -> X";
      unsigned flags = kBuiltinSideEffect | kBuiltinArrayAccess | (a.diff ? 0u : kBuiltinNotDiff);
      rows->push_back(Builtin("Atomics", sig.c_str(), a.doc, flags));
    }
  }
  for (int d = 1; d <= 4; ++d) {
    std::string sig = "atomic_cas(arr: array(X," + std::to_string(d) + "), " + idx[d - 1] +
                      ", compare: X, value: X) -> X";
    rows->push_back(Builtin("Atomics", sig.c_str(), "If arr[i] == compare set it to value; returns the old value. Scalar types: [u]int32, "
                            "[u]int64, float32, float64.",
                            kBuiltinSideEffect | kBuiltinArrayAccess | kBuiltinNotDiff));
  }

  auto misc = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone) {
    rows->push_back(Builtin("Utility", sig, doc, flags));
  };
  misc("where(cond: Cond, value_if_true: X, value_if_false: X) -> X", "value_if_true if cond else value_if_false.");
  misc("select(cond: Cond, value_if_false: X, value_if_true: X) -> X", "Deprecated twin of where (argument order reversed).");
  misc("lower_bound(arr: array(Scalar,1), value: Scalar) -> int32",
       "First index i with arr[i] >= value in a sorted array; the last index when every element is smaller "
       "(as Warp).", kBuiltinNotDiff);
  misc("lower_bound(arr: array(Scalar,1), arr_begin: int32, arr_end: int32, value: Scalar) -> int32",
       "lower_bound in arr[arr_begin:arr_end]: arr_end - 1 when every element there is smaller (as Warp).",
       kBuiltinNotDiff);
  misc("block_dim() -> int32", "Threads per block of the launch: blockDim.x on CUDA, 1 on CPU.",
       kBuiltinNeedsCtx | kBuiltinNotDiff);
  misc("print(value: X) -> void", "Print a value; the text reaches the launching client's stdout.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_eq(a: X, b: X) -> void", "Report a launch error when a != b.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_neq(a: X, b: X) -> void", "Report a launch error when a == b.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_near(a: Float, b: Float, tolerance: Float) -> void", "Report a launch error when |a - b| > tolerance.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_near(a: vec(N,Float), b: vec(N,Float), tolerance: Float) -> void",
       "Report a launch error when a component differs by more than tolerance.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_near(a: quat(Float), b: quat(Float), tolerance: Float) -> void",
       "Report a launch error when a component differs by more than tolerance.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_near(a: mat(N,M,Float), b: mat(N,M,Float), tolerance: Float) -> void",
       "Report a launch error when an element differs by more than tolerance.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_near(a: quat(Float), b: quat(Float)) -> void", "expect_near with Warp's default tolerance, 1e-6.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_near(a: mat(N,M,Float), b: mat(N,M,Float)) -> void", "expect_near with Warp's default tolerance, 1e-6.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_near(a: Float, b: Float) -> void", "expect_near with Warp's default tolerance, 1e-6.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);
  misc("expect_near(a: vec(N,Float), b: vec(N,Float)) -> void", "expect_near with Warp's default tolerance, 1e-6.",
       kBuiltinNeedsCtx | kBuiltinSideEffect | kBuiltinNotDiff);

  auto rnd = [rows](const char* sig, const char* doc) {
    rows->push_back(Builtin("Random", sig, doc, kBuiltinNotDiff));
  };
  rnd("rand_init(seed: int32) -> uint32", "Random state from a seed.");
  rnd("rand_init(seed: int32, offset: int32) -> uint32", "Random state from a seed and a per-thread offset.");
  rnd("randi(state: uint32) -> int32", "Random int32; advances state.");
  rnd("randi(state: uint32, low: int32, high: int32) -> int32", "Random int in [low, high).");
  rnd("randu(state: uint32) -> uint32", "Random uint32.");
  rnd("randu(state: uint32, low: uint32, high: uint32) -> uint32", "Random uint32 in [low, high).");
  rnd("randf(state: uint32) -> float32", "Uniform float in [0, 1).");
  rnd("randf(state: uint32, low: float32, high: float32) -> float32", "Uniform float in [low, high).");
  rnd("randn(state: uint32) -> float32", "Standard normal sample.");
  rnd("sample_cdf(state: uint32, cdf: array(float32,1)) -> int32", "Index sampled from a cumulative distribution.");
  rnd("sample_triangle(state: uint32) -> vec(2,float32)", "Uniform barycentric coordinates on a triangle.");
  rnd("sample_unit_ring(state: uint32) -> vec(2,float32)", "Uniform point on the unit circle.");
  rnd("sample_unit_disk(state: uint32) -> vec(2,float32)", "Uniform point in the unit disk.");
  rnd("sample_unit_sphere_surface(state: uint32) -> vec(3,float32)", "Uniform point on the unit sphere.");
  rnd("sample_unit_sphere(state: uint32) -> vec(3,float32)", "Uniform point in the unit ball.");
  rnd("sample_unit_hemisphere_surface(state: uint32) -> vec(3,float32)", "Uniform point on the upper hemisphere.");
  rnd("sample_unit_hemisphere(state: uint32) -> vec(3,float32)", "Uniform point in the upper half ball.");
  rnd("sample_unit_square(state: uint32) -> vec(2,float32)", "Uniform point in [-0.5, 0.5]^2.");
  rnd("sample_unit_cube(state: uint32) -> vec(3,float32)", "Uniform point in [-0.5, 0.5]^3.");
  rnd("poisson(state: uint32, lam: float32) -> uint32", "Poisson sample with mean lam.");
  // Noise is differentiable in the point (adj_noise/adj_pnoise/adj_curlnoise, noise.h);
  // curlnoise's octaves, lacunarity and gain are optional (1, 2.0, 0.5), as in Warp.
  auto noise = [rows](const std::string& sig, const char* doc) {
    rows->push_back(Builtin("Noise", sig.c_str(), doc, kBuiltinNone));
  };
  noise("noise(state: uint32, x: float32) -> float32", "Perlin noise in 1D.");
  noise("noise(state: uint32, xy: vec(2,float32)) -> float32", "Perlin noise in 2D.");
  noise("noise(state: uint32, xyz: vec(3,float32)) -> float32", "Perlin noise in 3D.");
  noise("noise(state: uint32, xyzt: vec(4,float32)) -> float32", "Perlin noise in 4D.");
  noise("pnoise(state: uint32, x: float32, px: int32) -> float32", "Periodic Perlin noise in 1D.");
  noise("pnoise(state: uint32, xy: vec(2,float32), px: int32, py: int32) -> float32", "Periodic Perlin noise in 2D.");
  noise("pnoise(state: uint32, xyz: vec(3,float32), px: int32, py: int32, pz: int32) -> float32",
        "Periodic Perlin noise in 3D.");
  noise("pnoise(state: uint32, xyzt: vec(4,float32), px: int32, py: int32, pz: int32, pt: int32) -> float32",
        "Periodic Perlin noise in 4D.");
  const char* curl_in[] = {"xy: vec(2,float32)", "xyz: vec(3,float32)", "xyzt: vec(4,float32)"};
  const char* curl_out[] = {"vec(2,float32)", "vec(3,float32)", "vec(3,float32)"};
  const char* curl_doc[] = {"Divergence-free noise in 2D.", "Divergence-free noise in 3D.",
                            "Divergence-free noise in 3D at the time slice t of a 4D point."};
  const char* optional[] = {"", ", octaves: uint32", ", octaves: uint32, lacunarity: float32",
                            ", octaves: uint32, lacunarity: float32, gain: float32"};
  for (int d = 0; d < 3; ++d)
    for (const char* tail : optional)
      noise(std::string("curlnoise(state: uint32, ") + curl_in[d] + tail + ") -> " + curl_out[d], curl_doc[d]);
}

}  // namespace weft::sema
