// Registry rows: vector, matrix, quaternion, transform and spatial functions and the
// arithmetic operators on them. Data only; see builtins.h for the pattern language.
#include "engine/sema/builtins.h"

namespace weft::sema {

void AddLinalgBuiltins(std::vector<BuiltinOverload>* rows) {
  auto op = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone) {
    rows->push_back(Builtin("Operators", sig, doc, flags));
  };
  op("add(a: vec(N,Scalar), b: vec(N,Scalar)) -> vec(N,Scalar)", "`a + b`.");
  op("add(a: mat(N,M,Scalar), b: mat(N,M,Scalar)) -> mat(N,M,Scalar)", "`a + b`.");
  op("add(a: quat(Float), b: quat(Float)) -> quat(Float)", "`a + b`.");
  op("add(a: transform(Float), b: transform(Float)) -> transform(Float)", "`a + b` (componentwise).");
  op("sub(a: vec(N,Scalar), b: vec(N,Scalar)) -> vec(N,Scalar)", "`a - b`.");
  op("sub(a: mat(N,M,Scalar), b: mat(N,M,Scalar)) -> mat(N,M,Scalar)", "`a - b`.");
  op("sub(a: quat(Float), b: quat(Float)) -> quat(Float)", "`a - b`.");
  op("sub(a: transform(Float), b: transform(Float)) -> transform(Float)", "`a - b` (componentwise).");
  op("mul(a: vec(N,Scalar), b: Scalar) -> vec(N,Scalar)", "Vector times scalar.");
  op("mul(a: Scalar, b: vec(N,Scalar)) -> vec(N,Scalar)", "Scalar times vector.");
  op("mul(a: mat(N,M,Scalar), b: Scalar) -> mat(N,M,Scalar)", "Matrix times scalar.");
  op("mul(a: Scalar, b: mat(N,M,Scalar)) -> mat(N,M,Scalar)", "Scalar times matrix.");
  op("mul(a: quat(Float), b: Float) -> quat(Float)", "Quaternion times scalar.");
  op("mul(a: Float, b: quat(Float)) -> quat(Float)", "Scalar times quaternion.");
  op("mul(a: transform(Float), b: Float) -> transform(Float)", "Transform components times scalar.");
  op("mul(a: Float, b: transform(Float)) -> transform(Float)", "Scalar times transform components.");
  op("mul(a: mat(N,M,Scalar), b: vec(M,Scalar)) -> vec(N,Scalar)", "Matrix-vector product (also `@`).");
  op("mul(a: vec(N,Scalar), b: mat(N,M,Scalar)) -> vec(M,Scalar)", "Row vector times matrix.");
  op("mul(a: mat(N,K,Scalar), b: mat(K,M,Scalar)) -> mat(N,M,Scalar)", "Matrix product (also `@`).");
  op("mul(a: quat(Float), b: quat(Float)) -> quat(Float)", "Quaternion product (composition).");
  op("mul(a: transform(Float), b: transform(Float)) -> transform(Float)", "Transform composition.");
  op("div(a: vec(N,Scalar), b: Scalar) -> vec(N,Scalar)", "Vector divided by scalar.");
  op("div(a: Scalar, b: vec(N,Scalar)) -> vec(N,Scalar)", "Scalar divided by each component.");
  op("div(a: mat(N,M,Scalar), b: Scalar) -> mat(N,M,Scalar)", "Matrix divided by scalar.");
  op("div(a: Scalar, b: mat(N,M,Scalar)) -> mat(N,M,Scalar)", "Scalar divided by each component.");
  op("div(a: quat(Float), b: Float) -> quat(Float)", "Quaternion divided by scalar.");
  op("div(a: Float, b: quat(Float)) -> quat(Float)", "Scalar divided by each component (as Warp).");
  op("div_approx(a: vec(N,Float), b: Float) -> vec(N,Float)", "Vector divided by scalar (approximate on CUDA).");
  op("div_approx(a: Float, b: vec(N,Float)) -> vec(N,Float)", "Scalar divided by each component (approximate on CUDA).");
  op("div_approx(a: mat(N,M,Float), b: Float) -> mat(N,M,Float)", "Matrix divided by scalar (approximate on CUDA).");
  op("div_approx(a: Float, b: mat(N,M,Float)) -> mat(N,M,Float)", "Scalar divided by each component (approximate on CUDA).");
  op("div_approx(a: quat(Float), b: Float) -> quat(Float)", "Quaternion divided by scalar (approximate on CUDA).");
  op("div_approx(a: Float, b: quat(Float)) -> quat(Float)", "Scalar divided by each component (approximate on CUDA).");
  op("mod(a: vec(N,Scalar), b: vec(N,Scalar)) -> vec(N,Scalar)", "Componentwise `%`.");
  op("neg(x: vec(N,Scalar)) -> vec(N,Scalar)", "`-x`.");
  op("neg(x: mat(N,M,Scalar)) -> mat(N,M,Scalar)", "`-x`.");
  op("neg(x: quat(Float)) -> quat(Float)", "`-x`.");
  op("pos(x: vec(N,Scalar)) -> vec(N,Scalar)", "`+x`.");
  op("pos(x: mat(N,M,Scalar)) -> mat(N,M,Scalar)", "`+x`.");
  op("pos(x: quat(Float)) -> quat(Float)", "`+x`.");

  auto vec = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone) {
    rows->push_back(Builtin("Vector and matrix", sig, doc, flags));
  };
  vec("dot(a: vec(N,Scalar), b: vec(N,Scalar)) -> Scalar", "Inner product.");
  vec("dot(a: quat(Float), b: quat(Float)) -> Float", "Inner product of quaternions as 4-vectors.");
  vec("ddot(a: mat(N,M,Scalar), b: mat(N,M,Scalar)) -> Scalar", "Double contraction sum(a[i,j]*b[i,j]).");
  vec("outer(a: vec(N,Scalar), b: vec(M,Scalar)) -> mat(N,M,Scalar)", "Outer product a b^T.");
  vec("cross(a: vec(3,Scalar), b: vec(3,Scalar)) -> vec(3,Scalar)", "Cross product.");
  vec("skew(vec: vec(3,Scalar)) -> mat(3,3,Scalar)", "Skew-symmetric matrix with skew(a) b = a x b.");
  vec("length(a: vec(N,Float)) -> Float", "Euclidean norm; gradient 0 at the zero vector.");
  vec("length(a: quat(Float)) -> Float", "Norm of a quaternion.");
  vec("length_sq(a: vec(N,Scalar)) -> Scalar", "Squared norm.");
  vec("length_sq(a: quat(Float)) -> Float", "Squared norm of a quaternion.");
  vec("normalize(a: vec(N,Float)) -> vec(N,Float)", "a / |a|; the zero vector maps to zero (gradient 0).");
  vec("normalize(a: quat(Float)) -> quat(Float)", "Unit quaternion; zero maps to zero.");
  vec("transpose(a: mat(N,M,Scalar)) -> mat(M,N,Scalar)", "Transpose.");
  for (const char* n : {"2", "3", "4"}) {
    static std::string sigs[3][3];
    int k = n[0] - '2';
    sigs[k][0] = std::string("inverse(a: mat(") + n + "," + n + ",Float)) -> mat(" + n + "," + n + ",Float)";
    sigs[k][1] = std::string("determinant(a: mat(") + n + "," + n + ",Float)) -> Float";
    vec(sigs[k][0].c_str(), "Matrix inverse; a singular matrix gives zeros (as Warp).");
    vec(sigs[k][1].c_str(), "Determinant.");
    sigs[k][2] = std::string("inverse_approx(a: mat(") + n + "," + n + ",Float)) -> mat(" + n + "," + n + ",Float)";
    vec(sigs[k][2].c_str(), "Matrix inverse, approximate division on CUDA; singular gives zeros.");
  }
  vec("trace(a: mat(N,N,Scalar)) -> Scalar", "Sum of the diagonal.");
  vec("diag(vec: vec(N,Scalar)) -> mat(N,N,Scalar)", "Diagonal matrix from a vector.");
  vec("get_diag(mat: mat(N,N,Scalar)) -> vec(N,Scalar)", "Diagonal of a square matrix.");
  vec("cw_mul(a: vec(N,Scalar), b: vec(N,Scalar)) -> vec(N,Scalar)", "Componentwise product.");
  vec("cw_mul(a: mat(N,M,Scalar), b: mat(N,M,Scalar)) -> mat(N,M,Scalar)", "Componentwise product.");
  vec("cw_div(a: vec(N,Scalar), b: vec(N,Scalar)) -> vec(N,Scalar)", "Componentwise quotient.");
  vec("cw_div(a: mat(N,M,Scalar), b: mat(N,M,Scalar)) -> mat(N,M,Scalar)", "Componentwise quotient.");
  vec("argmin(a: vec(N,Scalar)) -> uint32", "Index of the smallest component.", kBuiltinNotDiff);
  vec("argmax(a: vec(N,Scalar)) -> uint32", "Index of the largest component.", kBuiltinNotDiff);
  vec("lerp(a: vec(N,Float), b: vec(N,Float), t: Float) -> vec(N,Float)", "a * (1 - t) + b * t.");
  vec("lerp(a: mat(N,M,Float), b: mat(N,M,Float), t: Float) -> mat(N,M,Float)", "a * (1 - t) + b * t.");
  vec("lerp(a: quat(Float), b: quat(Float), t: Float) -> quat(Float)", "a * (1 - t) + b * t.");
  vec("lerp(a: transform(Float), b: transform(Float), t: Float) -> transform(Float)",
      "a * (1 - t) + b * t (componentwise).");
  vec("matrix_from_rows(a: vec(N,Scalar), b: vec(N,Scalar), c: vec(N,Scalar)) -> mat(3,N,Scalar)",
      "Matrix whose rows are a, b, c.");
  vec("matrix_from_cols(a: vec(N,Scalar), b: vec(N,Scalar), c: vec(N,Scalar)) -> mat(N,3,Scalar)",
      "Matrix whose columns are a, b, c.");
  vec("svd3(A: mat(3,3,Float)) -> tuple(mat(3,3,Float),vec(3,Float),mat(3,3,Float))",
      "U, sigma, V with A = U diag(sigma) V^T (`U, s, V = wp.svd3(A)`).");
  vec("svd2(A: mat(2,2,Float)) -> tuple(mat(2,2,Float),vec(2,Float),mat(2,2,Float))",
      "U, sigma, V with A = U diag(sigma) V^T.");
  vec("qr3(A: mat(3,3,Float)) -> tuple(mat(3,3,Float),mat(3,3,Float))", "Q, R with A = Q R.");
  vec("eig3(A: mat(3,3,Float)) -> tuple(mat(3,3,Float),vec(3,Float))",
      "Eigenvectors (columns) and eigenvalues of a symmetric matrix.");

  auto quat = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone) {
    rows->push_back(Builtin("Quaternion", sig, doc, flags));
  };
  quat("quat_from_axis_angle(axis: vec(3,Float), angle: Float) -> quat(Float)",
       "Rotation of `angle` radians about the unit `axis`.");
  quat("quat_to_axis_angle(quat: quat(Float)) -> tuple(vec(3,Float),Float)", "Axis and angle of a rotation.");
  quat("quat_from_matrix(mat: mat(3,3,Float)) -> quat(Float)", "Rotation of an orthonormal matrix.");
  quat("quat_from_matrix(mat: mat(4,4,Float)) -> quat(Float)", "Rotation part of a 4x4 transform matrix.");
  quat("quat_rpy(roll: Float, pitch: Float, yaw: Float) -> quat(Float)", "Rotation from Euler angles.");
  quat("quat_inverse(quat: quat(Float)) -> quat(Float)", "Conjugate (inverse of a unit quaternion).");
  quat("quat_rotate(quat: quat(Float), vec: vec(3,Float)) -> vec(3,Float)", "Rotate a vector.");
  quat("quat_rotate_inv(quat: quat(Float), vec: vec(3,Float)) -> vec(3,Float)", "Rotate by the inverse.");
  quat("quat_slerp(a: quat(Float), b: quat(Float), t: Float) -> quat(Float)", "Spherical interpolation.");
  quat("quat_to_matrix(quat: quat(Float)) -> mat(3,3,Float)", "3x3 rotation matrix.");

  auto xf = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone) {
    rows->push_back(Builtin("Transform", sig, doc, flags));
  };
  xf("transform_get_translation(xform: transform(Float)) -> vec(3,Float)", "Translation p.");
  xf("transform_get_rotation(xform: transform(Float)) -> quat(Float)", "Rotation q.");
  rows->push_back(Builtin("Transform", "transform_set_translation(xform: transform(Float), p: vec(3,Float)) -> transform(Float)",
                          "Sets xform.p (as Warp; weft rebinds `xform` to the updated value; the call returns None).",
                          kBuiltinNone, "transform_with_translation"));
  rows->push_back(Builtin("Transform", "transform_set_rotation(xform: transform(Float), q: quat(Float)) -> transform(Float)",
                          "Sets xform.q (as Warp; weft rebinds `xform` to the updated value; the call returns None).",
                          kBuiltinNone, "transform_with_rotation"));
  xf("transform_multiply(a: transform(Float), b: transform(Float)) -> transform(Float)", "Composition a * b.");
  xf("transform_point(xform: transform(Float), point: vec(3,Float)) -> vec(3,Float)", "q * point + p.");
  xf("transform_point(mat: mat(4,4,Float), point: vec(3,Float)) -> vec(3,Float)", "Homogeneous point transform.");
  xf("transform_vector(xform: transform(Float), vec: vec(3,Float)) -> vec(3,Float)", "q * vec (no translation).");
  xf("transform_vector(mat: mat(4,4,Float), vec: vec(3,Float)) -> vec(3,Float)", "Upper 3x3 times vec.");
  xf("transform_inverse(xform: transform(Float)) -> transform(Float)", "Inverse transform.");

  auto geo = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone) {
    rows->push_back(Builtin("Geometry", sig, doc, flags));
  };
  geo("closest_point_edge_edge(p1: vec(3,Float), q1: vec(3,Float), p2: vec(3,Float), q2: vec(3,Float), epsilon: Float) "
      "-> vec(3,Float)",
      "(s, t, d): closest points p1 + (q1 - p1) s and p2 + (q2 - p2) t of two segments and their distance d.");
  geo("intersect_tri_tri(v0: vec(3,Float), v1: vec(3,Float), v2: vec(3,Float), u0: vec(3,Float), u1: vec(3,Float), "
      "u2: vec(3,Float)) -> int32",
      "1 when the two triangles overlap (touching counts), else 0.", kBuiltinNotDiff);

  auto sp = [rows](const char* sig, const char* doc, unsigned flags = kBuiltinNone) {
    rows->push_back(Builtin("Spatial", sig, doc, flags));
  };
  sp("spatial_adjoint(r: mat(3,3,Float), s: mat(3,3,Float)) -> mat(6,6,Float)", "6x6 adjoint [[r,0],[s,r]].");
  sp("spatial_dot(a: vec(6,Float), b: vec(6,Float)) -> Float", "Dot product of spatial vectors.");
  sp("spatial_cross(a: vec(6,Float), b: vec(6,Float)) -> vec(6,Float)", "Spatial motion cross product.");
  sp("spatial_cross_dual(a: vec(6,Float), b: vec(6,Float)) -> vec(6,Float)", "Spatial force cross product.");
  sp("spatial_top(svec: vec(6,Float)) -> vec(3,Float)", "First three components.");
  sp("spatial_bottom(svec: vec(6,Float)) -> vec(3,Float)", "Last three components.");
}

}  // namespace weft::sema
