// The builtin registry: every kernel builtin as data (Warp's builtins.py), one row per
// overload: Python name, parameter type patterns, result pattern, the native function in
// engine/native it calls, whether and how it is differentiable, and a one-line doc.
// The rows live in builtins_scalar.cpp, builtins_linalg.cpp and builtins_runtime.cpp; this
// header is the one table sema (overload resolution), codegen (forward + adjoint calls) and
// docs/builtins.md (generated) read.
//
// Pattern language of a signature such as "dot(a: vec(N,Scalar), b: vec(N,Scalar)) -> Scalar":
//   Float | Int | Scalar   a scalar type variable T constrained to float / integer / numeric;
//                          every occurrence in one overload is the same T
//   Index                  any integer scalar, not bound (array indices)
//   Cond                   bool or any integer scalar, not bound
//   X, Y                   any value type, bound (X in one overload is one type)
//   S                      any @wp.struct type, bound
//   N, M, K, D             dimension variables (vector length, matrix rows/cols, array ndim)
//   vec(n,s) mat(r,c,s) quat(s) transform(s) array(p,d)   composites over patterns
//   float32, int32, vec(3,float32), ...   concrete types;  str  a string literal
#pragma once

#include <map>
#include <string>
#include <vector>

#include "engine/core/status.h"
#include "engine/sema/types.h"

namespace weft::sema {

// Options of a builtin row (bit set).
enum BuiltinFlags : unsigned {
  kBuiltinNone = 0,
  kBuiltinNeedsCtx = 1u << 0,     // native takes `const wp::launch_context_t*` first
  kBuiltinSideEffect = 1u << 1,   // writes memory / prints: skipped in the backward pass's replay (print: see emit_cpp)
  kBuiltinNotDiff = 1u << 2,      // no adjoint: gradients stop here
  kBuiltinArrayAccess = 1u << 3,  // first param is an array indexed by the following Index params
  kBuiltinNeedsLoc = 1u << 4,     // native takes (ctx, function id, line) first: it reports launch errors
  kBuiltinWritesArgs = 1u << 5,   // writes local variables passed as arguments (query iterators, out-parameters)
  kBuiltinVoidAdjoint = 1u << 6,  // no result, yet an adjoint: adj(args..., adj_args...) (tile_store)
};

struct BuiltinPattern;  // parsed form of a parameter/result pattern (builtins_registry.cpp)

struct BuiltinOverload {
  std::string name;      // as written in kernels: "sin" (wp.sin)
  std::string group;     // section of docs/builtins.md
  std::string signature; // "sin(x: Float) -> Float"
  std::string native;    // C++ function in namespace wp: "sin"
  std::string adjoint;   // C++ adjoint ("adj_sin"); empty when not differentiable
  unsigned flags = 0;
  std::string doc;       // one line
  // Parsed from `signature` when the registry is built.
  std::vector<std::string> param_names;
  std::vector<std::string> param_patterns;
  std::string result_pattern;

  bool differentiable() const { return !(flags & kBuiltinNotDiff); }
  bool needs_ctx() const { return flags & kBuiltinNeedsCtx; }
  bool side_effect() const { return flags & kBuiltinSideEffect; }
};

// Row constructor used by the builtins_*.cpp tables. `native` empty = same as the name;
// the adjoint is "adj_" + native unless flags has kBuiltinNotDiff.
BuiltinOverload Builtin(const char* group, const char* signature, const char* doc,
                        unsigned flags = kBuiltinNone, const char* native = "");

// The tables (one function per file).
void AddScalarBuiltins(std::vector<BuiltinOverload>* rows);
void AddLinalgBuiltins(std::vector<BuiltinOverload>* rows);
void AddRuntimeBuiltins(std::vector<BuiltinOverload>* rows);
void AddGeometryBuiltins(std::vector<BuiltinOverload>* rows);
void AddVolumeBuiltins(std::vector<BuiltinOverload>* rows);
void AddTileBuiltins(std::vector<BuiltinOverload>* rows);

// The query types of the geometry builtins (HashGridQuery, BvhQuery, MeshQueryPoint,
// MeshQueryRay, MeshQueryAABB): structs defined by engine/native (not emitted per module),
// added to every module's struct table. Client structs may not take these names.
const StructTable& GeometryStructs();

// The result of resolving a call against the registry.
struct BuiltinMatch {
  const BuiltinOverload* overload = nullptr;
  Type result;
  std::vector<Type> param_types;  // the parameter types after binding (== argument types)
};

class BuiltinRegistry {
 public:
  static const BuiltinRegistry& Get();

  bool Has(const std::string& name) const { return by_name_.count(name) != 0; }
  const std::vector<BuiltinOverload>& rows() const { return rows_; }
  std::vector<const BuiltinOverload*> Overloads(const std::string& name) const;

  // First overload (in registry order) whose patterns accept `args` exactly. Arguments that
  // are numeric literals (`literals[i]`: 1 = int literal, 2 = float literal, 0 = not a
  // literal) adapt: an int literal takes any numeric type the overload binds, a float literal
  // any float type; unbound, they keep int32 / float32. match.param_types has the adapted
  // types. On failure the message names the builtin, the argument types and the candidates.
  Expected<BuiltinMatch> Resolve(const std::string& name, const std::vector<Type>& args,
                                 const std::vector<int>* literals = nullptr) const;

  // docs/builtins.md, generated from the rows.
  std::string Markdown() const;

 private:
  BuiltinRegistry();
  std::vector<BuiltinOverload> rows_;
  std::map<std::string, std::vector<size_t>> by_name_;
};

}  // namespace weft::sema
