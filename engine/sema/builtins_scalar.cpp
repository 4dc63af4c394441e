// Registry rows: scalar math, scalar operators, comparisons-free elementwise helpers
// (min/max/clamp/abs/sign/step), rounding and classification. Data only; see builtins.h.
#include "engine/sema/builtins.h"

namespace weft::sema {

void AddScalarBuiltins(std::vector<BuiltinOverload>* rows) {
  auto add = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone, const char* native = "") {
    rows->push_back(Builtin("Scalar math", sig, doc, flags, native));
  };
  add("min(a: Scalar, b: Scalar) -> Scalar", "Smaller of two scalars (as C fmin: a NaN operand is ignored); the gradient goes to `b` on ties (as Warp).");
  add("min(a: vec(N,Scalar), b: vec(N,Scalar)) -> vec(N,Scalar)", "Componentwise minimum.");
  add("min(a: vec(N,Scalar)) -> Scalar", "Smallest component (NaN components are ignored unless all are NaN).");
  add("max(a: Scalar, b: Scalar) -> Scalar", "Larger of two scalars (as C fmax: a NaN operand is ignored); the gradient goes to `b` on ties (as Warp).");
  add("max(a: vec(N,Scalar), b: vec(N,Scalar)) -> vec(N,Scalar)", "Componentwise maximum.");
  add("max(a: vec(N,Scalar)) -> Scalar", "Largest component (NaN components are ignored unless all are NaN).");
  add("clamp(x: Scalar, low: Scalar, high: Scalar) -> Scalar",
      "`x` limited to [low, high], as min(max(low, x), high); gradient 1 inside, 0 outside (to the bound that clamps).");
  add("abs(x: Scalar) -> Scalar", "Absolute value; subgradient 1 at 0 (as Warp).");
  add("abs(x: vec(N,Scalar)) -> vec(N,Scalar)", "Componentwise absolute value.");
  add("sign(x: Scalar) -> Scalar", "-1 if x < 0 else 1; gradient 0.");
  add("sign(x: vec(N,Scalar)) -> vec(N,Scalar)", "Componentwise sign; gradient 0.");
  add("copysign(x: Float, y: Float) -> Float", "|x| with the sign of y; d/dx is +1 when the sign bits agree, else -1.");
  add("step(x: Scalar) -> Scalar", "1 if x < 0 else 0; gradient 0.");
  add("nonzero(x: Scalar) -> Scalar", "1 if x != 0 else 0; gradient 0.");
  const char* unary[][2] = {
      {"sin", "Sine (radians)."},
      {"cos", "Cosine (radians)."},
      {"tan", "Tangent (radians)."},
      {"asin", "Arc sine; input clamped to [-1, 1]."},
      {"acos", "Arc cosine; input clamped to [-1, 1]."},
      {"atan", "Arc tangent."},
      {"sinh", "Hyperbolic sine."},
      {"cosh", "Hyperbolic cosine."},
      {"tanh", "Hyperbolic tangent."},
      {"sqrt", "Square root."},
      {"cbrt", "Cube root."},
      {"exp", "e**x."},
      {"log", "Natural logarithm."},
      {"log2", "Base-2 logarithm."},
      {"log10", "Base-10 logarithm."},
      {"degrees", "Radians to degrees."},
      {"radians", "Degrees to radians."},
      {"erf", "Error function."},
      {"erfc", "Complementary error function."},
      {"erfinv", "Inverse error function."},
      {"erfcinv", "Inverse complementary error function."},
  };
  std::vector<std::string> sigs;  // composed signatures (Builtin() copies what it needs)
  for (auto& u : unary) {
    sigs.push_back(std::string(u[0]) + "(x: Float) -> Float");
    add(sigs.back().c_str(), u[1]);
  }
  const char* rounding[][2] = {
      {"round", "Round half away from zero; gradient 0."},
      {"rint", "Round half to even; gradient 0."},
      {"trunc", "Round toward zero; gradient 0."},
      {"floor", "Round down; gradient 0."},
      {"ceil", "Round up; gradient 0."},
      {"frac", "x - trunc(x); gradient 1."},
  };
  for (auto& u : rounding) {
    sigs.push_back(std::string(u[0]) + "(x: Float) -> Float");
    add(sigs.back().c_str(), u[1]);
  }
  add("atan2(y: Float, x: Float) -> Float", "Angle of (x, y) in (-pi, pi].");
  add("pow(x: Float, y: Float) -> Float", "x**y (also the `**` operator).");
  for (const char* pat : {"Float", "vec(N,Float)", "quat(Float)", "mat(N,M,Float)"}) {
    for (const char* fn : {"isfinite", "isnan", "isinf"}) {
      sigs.push_back(std::string(fn) + "(a: " + pat + ") -> bool");
      add(sigs.back().c_str(), "Classification of every component; not differentiable.", kBuiltinNotDiff);
    }
  }
  add("lerp(a: Float, b: Float, t: Float) -> Float", "a * (1 - t) + b * t.");
  add("smoothstep(a: Float, b: Float, x: Float) -> Float", "Hermite step from 0 at a to 1 at b.");

  auto op = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone) {
    rows->push_back(Builtin("Operators", sig, doc, flags));
  };
  op("add(a: Scalar, b: Scalar) -> Scalar", "`a + b`.");
  op("sub(a: Scalar, b: Scalar) -> Scalar", "`a - b`.");
  op("mul(a: Scalar, b: Scalar) -> Scalar", "`a * b`.");
  op("div(a: Scalar, b: Scalar) -> Scalar", "`a / b` (integers: truncating, as C).");
  op("div_approx(a: Float, b: Float) -> Float", "`a / b`, approximate (fast) division on CUDA; exact on CPU.");
  op("floordiv(a: Scalar, b: Scalar) -> Scalar", "`a // b`.");
  op("mod(a: Scalar, b: Scalar) -> Scalar", "`a % b`.");
  op("neg(x: Scalar) -> Scalar", "`-x`.");
  op("pos(x: Scalar) -> Scalar", "`+x`.");
  op("bit_and(a: Int, b: Int) -> Int", "`a & b`.", kBuiltinNotDiff);
  op("bit_or(a: Int, b: Int) -> Int", "`a | b`.", kBuiltinNotDiff);
  op("bit_xor(a: Int, b: Int) -> Int", "`a ^ b`.", kBuiltinNotDiff);
  op("lshift(a: Int, b: Int) -> Int", "`a << b`.", kBuiltinNotDiff);
  op("rshift(a: Int, b: Int) -> Int", "`a >> b`.", kBuiltinNotDiff);
  op("invert(a: Int) -> Int", "`~a`.", kBuiltinNotDiff);
  add("bit_count(x: Int) -> int32", "Number of set bits in x's fixed-width two's-complement pattern (-1 as int8: 8).",
      kBuiltinNotDiff);
  op("unot(a: Cond) -> bool", "`not a`: true when a is false / zero.", kBuiltinNotDiff);
  for (const char* sig : {"unot(a: array(X,1)) -> bool", "unot(a: array(X,2)) -> bool", "unot(a: array(X,3)) -> bool",
                          "unot(a: array(X,4)) -> bool"}) {
    op(sig, "`not a` on an array: true when it is None.", kBuiltinNotDiff);
  }
  op("bit_and(a: vec(N,Int), b: vec(N,Int)) -> vec(N,Int)", "Componentwise `&`.", kBuiltinNotDiff);
  op("bit_or(a: vec(N,Int), b: vec(N,Int)) -> vec(N,Int)", "Componentwise `|`.", kBuiltinNotDiff);
  op("bit_xor(a: vec(N,Int), b: vec(N,Int)) -> vec(N,Int)", "Componentwise `^`.", kBuiltinNotDiff);
  op("lshift(a: vec(N,Int), b: vec(N,Int)) -> vec(N,Int)", "Componentwise `<<`.", kBuiltinNotDiff);
  op("rshift(a: vec(N,Int), b: vec(N,Int)) -> vec(N,Int)", "Componentwise `>>`.", kBuiltinNotDiff);
  op("invert(a: vec(N,Int)) -> vec(N,Int)", "Componentwise `~`.", kBuiltinNotDiff);
  op("bit_and(a: mat(N,M,Int), b: mat(N,M,Int)) -> mat(N,M,Int)", "Componentwise `&`.", kBuiltinNotDiff);
  op("bit_or(a: mat(N,M,Int), b: mat(N,M,Int)) -> mat(N,M,Int)", "Componentwise `|`.", kBuiltinNotDiff);
  op("bit_xor(a: mat(N,M,Int), b: mat(N,M,Int)) -> mat(N,M,Int)", "Componentwise `^`.", kBuiltinNotDiff);
  op("lshift(a: mat(N,M,Int), b: mat(N,M,Int)) -> mat(N,M,Int)", "Componentwise `<<`.", kBuiltinNotDiff);
  op("rshift(a: mat(N,M,Int), b: mat(N,M,Int)) -> mat(N,M,Int)", "Componentwise `>>`.", kBuiltinNotDiff);
  op("invert(a: mat(N,M,Int)) -> mat(N,M,Int)", "Componentwise `~`.", kBuiltinNotDiff);
}

}  // namespace weft::sema
