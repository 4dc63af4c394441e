// Registry rows of the geometry builtins (wp.HashGrid, wp.Bvh, wp.Mesh queries) and their query
// struct types. Data only; see builtins.h. The natives live in engine/native/{hash_grid,bvh,mesh}.h
// and take (ctx, function id, line) first: an id that names no live object of the launching
// session is a launch error at that line. docs/geometry.md describes the design.
#include <string>

#include "engine/sema/builtins.h"

namespace weft::sema {

const StructTable& GeometryStructs() {
  static const StructTable* table = [] {
    auto* t = new StructTable();
    auto add = [t](const char* name, std::vector<StructField> fields) {
      StructInfo info;
      info.name = name;
      info.cpp_name = StructCppName(name);
      info.fields = std::move(fields);
      (*t)[name] = std::move(info);
    };
    const Type f32 = Type::Float32(), i32 = Type::Int32(), b = Type::Bool();
    add("HashGridQuery", {});
    const Type points = Type::Array(Type::Vector(3, ScalarKind::kFloat32), 1);
    add("Mesh", {{"points", points}, {"velocities", points}, {"indices", Type::Array(i32, 1)}});
    add("BvhQuery", {});
    add("MeshQueryAABB", {});
    add("BvhQueryTiled", {});
    add("MeshQueryAABBTiled", {});
    add("MeshQueryPoint", {{"result", b}, {"sign", f32}, {"face", i32}, {"u", f32}, {"v", f32}});
    add("MeshQueryRay", {{"result", b}, {"sign", f32}, {"face", i32}, {"t", f32}, {"u", f32}, {"v", f32},
                         {"normal", Type::Vector(3, ScalarKind::kFloat32)}});
    return t;
  }();
  return *table;
}

void AddGeometryBuiltins(std::vector<BuiltinOverload>* rows) {
  const unsigned q = kBuiltinNeedsLoc | kBuiltinNotDiff;
  auto hg = [rows](const char* sig, const char* doc, unsigned flags) {
    rows->push_back(Builtin("Hash grids", sig, doc, flags));
  };
  hg("hash_grid_query(id: uint64, point: vec(3,float32), max_dist: float32) -> struct(HashGridQuery)",
     "Start a query of the points in the cells within max_dist of point (filter by distance yourself).", q);
  hg("hash_grid_query(id: uint64, point: vec(3,float64), max_dist: float64) -> struct(HashGridQuery)",
     "hash_grid_query with a float64 point (converted to float32, the grid's precision).", q);
  hg("hash_grid_query(id: uint64, point: vec(3,float16), max_dist: float16) -> struct(HashGridQuery)",
     "hash_grid_query with a float16 point (converted to float32, the grid's precision).", q);
  hg("hash_grid_query(id: uint64, point: vec(3,float32), max_dist: float32, group: int32) -> struct(HashGridQuery)",
     "hash_grid_query visiting only the points of `group` (HashGrid.build(..., groups=); on a grid built "
     "without groups every point is in group 0).", q);
  hg("hash_grid_query(id: uint64, point: vec(3,float64), max_dist: float64, group: int32) -> struct(HashGridQuery)",
     "The grouped hash_grid_query with a float64 point.", q);
  hg("hash_grid_query(id: uint64, point: vec(3,float16), max_dist: float16, group: int32) -> struct(HashGridQuery)",
     "The grouped hash_grid_query with a float16 point.", q);
  hg("hash_grid_query_next(query: struct(HashGridQuery), index: int32) -> bool",
     "Next point index of the query into `index`; false when done.", kBuiltinNotDiff | kBuiltinWritesArgs);
  hg("hash_grid_point_id(id: uint64, index: int32) -> int32",
     "The point at position index of the grid's cell order (-1 outside [0, points)).", q);

  auto bvh = [rows](const char* sig, const char* doc, unsigned flags) {
    rows->push_back(Builtin("BVH", sig, doc, flags));
  };
  bvh("bvh_query_aabb(id: uint64, low: vec(3,float32), high: vec(3,float32)) -> struct(BvhQuery)",
      "Start a query of the items whose bounds overlap [low, high].", q);
  bvh("bvh_query_aabb(id: uint64, low: vec(3,float32), high: vec(3,float32), root: int32) -> struct(BvhQuery)",
      "bvh_query_aabb from node `root` (-1: the root).", q);
  bvh("bvh_query_ray(id: uint64, start: vec(3,float32), dir: vec(3,float32)) -> struct(BvhQuery)",
      "Start a query of the items whose bounds the ray start + t dir (t >= 0) meets.", q);
  bvh("bvh_query_ray(id: uint64, start: vec(3,float32), dir: vec(3,float32), root: int32) -> struct(BvhQuery)",
      "bvh_query_ray from node `root` (-1: the root).", q);
  bvh("bvh_query_sphere(id: uint64, center: vec(3,float32), radius: float32) -> struct(BvhQuery)",
      "Start a query of the items whose bounds come within radius of center.", q);
  bvh("bvh_query_sphere(id: uint64, center: vec(3,float32), radius: float32, root: int32) -> struct(BvhQuery)",
      "bvh_query_sphere from node `root` (-1: the root).", q);
  bvh("bvh_query_capsule(id: uint64, start: vec(3,float32), dir: vec(3,float32), radius: float32) -> struct(BvhQuery)",
      "Start a query of the items whose bounds, inflated by radius, the ray start + t dir meets "
      "(t in [0, max_dist] of bvh_query_next: max_dist 1 bounds it to the segment start..start+dir).", q);
  bvh("bvh_query_capsule(id: uint64, start: vec(3,float32), dir: vec(3,float32), radius: float32, root: int32) -> struct(BvhQuery)",
      "bvh_query_capsule from node `root` (-1: the root).", q);
  bvh("bvh_get_group_root(id: uint64, group: int32) -> int32",
      "The root node of `group`'s subtree in a Bvh built with groups (pass it as a query's root); -1 when "
      "there is no such group (a query from -1 walks the whole tree).", q);
  bvh("bvh_query_next(query: struct(BvhQuery), index: int32) -> bool",
      "Next item index of the query into `index`; false when done.", kBuiltinNotDiff | kBuiltinWritesArgs);
  bvh("bvh_query_next(query: struct(BvhQuery), index: int32, max_dist: float32) -> bool",
      "bvh_query_next; ray and capsule queries skip items whose bounds start beyond max_dist.", kBuiltinNotDiff | kBuiltinWritesArgs);

  // Warp's tiled queries, one thread per block (engine/native/geometry_tiled.h); the *_tiled
  // names are Warp's deprecated aliases.
  for (const char* name : {"tile_bvh_query_aabb", "bvh_query_aabb_tiled"})
    rows->push_back(Builtin("BVH", (std::string(name) + "(id: uint64, low: vec(3,float32), high: vec(3,float32)) -> "
                                    "struct(BvhQueryTiled)").c_str(),
                            "Start a tiled query of the items whose bounds overlap [low, high] (iterate with "
                            "tile_bvh_query_next while tile_query_valid).", q, "tile_bvh_query_aabb"));
  for (const char* name : {"tile_bvh_query_ray", "bvh_query_ray_tiled"})
    rows->push_back(Builtin("BVH", (std::string(name) + "(id: uint64, start: vec(3,float32), dir: vec(3,float32)) -> "
                                    "struct(BvhQueryTiled)").c_str(),
                            "Start a tiled query of the items whose bounds the ray start + t dir (t >= 0) meets.", q,
                            "tile_bvh_query_ray"));
  for (const char* name : {"tile_bvh_query_next", "bvh_query_next_tiled"})
    rows->push_back(Builtin("BVH", (std::string(name) + "(query: struct(BvhQueryTiled)) -> tile(int32,1)").c_str(),
                            "The next item as a tile of shape (1,) (one thread per block): its index, or -1 once the "
                            "query is done (tile_query_valid then turns false).",
                            kBuiltinNotDiff | kBuiltinWritesArgs, "tile_bvh_query_next"));
  rows->push_back(Builtin("BVH", "tile_bvh_query_next_lanes(like: tile(int32,M), query: struct(BvhQueryTiled)) -> tile(int32,M)",
                          "Called as tile_bvh_query_next with cooperative CPU blocks (docs/tiles.md): the next M items "
                          "(the block's lanes), -1 past the last.", kBuiltinNotDiff | kBuiltinWritesArgs));
  rows->push_back(Builtin("Meshes",
                          "tile_mesh_query_aabb_next_lanes(like: tile(int32,M), query: struct(MeshQueryAABBTiled)) -> "
                          "tile(int32,M)",
                          "Called as tile_mesh_query_aabb_next with cooperative CPU blocks: the next M faces, -1 past "
                          "the last.", kBuiltinNotDiff | kBuiltinWritesArgs));
  rows->push_back(Builtin("BVH", "tile_query_valid(query: struct(BvhQueryTiled)) -> bool",
                          "False once tile_bvh_query_next found no further item.", kBuiltinNotDiff));
  rows->push_back(Builtin("Meshes", "tile_query_valid(query: struct(MeshQueryAABBTiled)) -> bool",
                          "False once tile_mesh_query_aabb_next found no further face.", kBuiltinNotDiff));
  for (const char* name : {"tile_mesh_query_aabb", "mesh_query_aabb_tiled"})
    rows->push_back(Builtin("Meshes", (std::string(name) + "(id: uint64, low: vec(3,float32), high: vec(3,float32)) -> "
                                       "struct(MeshQueryAABBTiled)").c_str(),
                            "Start a tiled query of the faces whose bounds overlap [low, high].", q,
                            "tile_mesh_query_aabb"));
  for (const char* name : {"tile_mesh_query_aabb_next", "mesh_query_aabb_next_tiled"})
    rows->push_back(Builtin("Meshes", (std::string(name) + "(query: struct(MeshQueryAABBTiled)) -> tile(int32,1)").c_str(),
                            "The next face as a tile of shape (1,): its index, or -1 once the query is done.",
                            kBuiltinNotDiff | kBuiltinWritesArgs, "tile_mesh_query_aabb_next"));

  auto mesh = [rows](const char* sig, const char* doc, unsigned flags) {
    rows->push_back(Builtin("Meshes", sig, doc, flags));
  };
  mesh("mesh_query_point(id: uint64, point: vec(3,float32), max_dist: float32) -> struct(MeshQueryPoint)",
       "Closest point within max_dist; sign -1 inside / 1 outside by a vote of 3 axis rays on the orientation "
       "of their closest hits (a miss votes outside; outward winding assumed, as Warp 1.19).", q);
  mesh("mesh_query_point_no_sign(id: uint64, point: vec(3,float32), max_dist: float32) -> struct(MeshQueryPoint)",
       "Closest point within max_dist (sign 0).", q);
  mesh("mesh_query_point_sign_normal(id: uint64, point: vec(3,float32), max_dist: float32) -> struct(MeshQueryPoint)",
       "Closest point; sign from the angle-weighted pseudo-normal of the closest feature.", q);
  mesh("mesh_query_point_sign_normal(id: uint64, point: vec(3,float32), max_dist: float32, epsilon: float32) -> struct(MeshQueryPoint)",
       "mesh_query_point_sign_normal with the tie tolerance epsilon.", q);
  mesh("mesh_query_point_sign_parity(id: uint64, point: vec(3,float32), max_dist: float32, n_sample: int32, perturbation_scale: float32) -> struct(MeshQueryPoint)",
       "Closest point; sign by the majority parity of n_sample (at most 6) fixed ray directions.", q);
  mesh("mesh_query_point_sign_winding_number(id: uint64, point: vec(3,float32), max_dist: float32) -> struct(MeshQueryPoint)",
       "Closest point; sign -1 where the exact winding number exceeds 0.5.", q);
  mesh("mesh_query_point_sign_winding_number(id: uint64, point: vec(3,float32), max_dist: float32, accuracy: float32, threshold: float32) -> struct(MeshQueryPoint)",
       "Closest point; sign -1 where the exact winding number exceeds threshold (accuracy is ignored: exact).", q);
  mesh("mesh_query_ray(id: uint64, start: vec(3,float32), dir: vec(3,float32), max_t: float32) -> struct(MeshQueryRay)",
       "Closest hit of the ray within t in [0, max_t] (rays parallel to a face miss it).", q);
  mesh("mesh_query_ray(id: uint64, start: vec(3,float32), dir: vec(3,float32), max_t: float32, root: int32) -> struct(MeshQueryRay)",
       "mesh_query_ray over the subtree at node `root` (mesh_get_group_root; -1: the whole mesh).", q);
  mesh("mesh_query_aabb(id: uint64, low: vec(3,float32), high: vec(3,float32)) -> struct(MeshQueryAABB)",
       "Start a query of the faces whose bounds overlap [low, high].", q);
  mesh("mesh_query_sphere(id: uint64, center: vec(3,float32), radius: float32) -> struct(MeshQueryAABB)",
       "Start a query of the faces within radius of center (exact distance), iterated like mesh_query_aabb.", q);
  mesh("mesh_query_aabb_next(query: struct(MeshQueryAABB), index: int32) -> bool",
       "Next face index of the query into `index`; false when done.", kBuiltinNotDiff | kBuiltinWritesArgs);
  mesh("mesh_query_next(query: struct(MeshQueryAABB), index: int32) -> bool",
       "Same as mesh_query_aabb_next.", kBuiltinNotDiff | kBuiltinWritesArgs);
  mesh("mesh_query_ray_anyhit(id: uint64, start: vec(3,float32), dir: vec(3,float32), max_t: float32) -> bool",
       "Whether the ray hits any face within t in [0, max_t].", q);
  mesh("mesh_query_ray_count_intersections(id: uint64, start: vec(3,float32), dir: vec(3,float32)) -> int32",
       "Number of faces the ray (t >= 0) crosses.", q);
  mesh("mesh_query_ray_anyhit(id: uint64, start: vec(3,float32), dir: vec(3,float32), max_t: float32, root: int32) -> bool",
       "mesh_query_ray_anyhit over the subtree at node `root` (-1: the whole mesh).", q);
  mesh("mesh_query_ray_count_intersections(id: uint64, start: vec(3,float32), dir: vec(3,float32), root: int32) -> int32",
       "mesh_query_ray_count_intersections over the subtree at node `root` (-1: the whole mesh).", q);
  mesh("mesh_query_furthest_point_no_sign(id: uint64, point: vec(3,float32), min_dist: float32) -> struct(MeshQueryPoint)",
       "The furthest mesh point (a vertex) at distance >= min_dist.", q);
  // Warp's older forms with out-parameters (local variables written by the call).
  mesh("mesh_query_point(id: uint64, point: vec(3,float32), max_dist: float32, inside: float32, face: int32, bary_u: float32, bary_v: float32) -> bool",
       "Out-parameter form of mesh_query_point (inside = sign).", q);
  mesh("mesh_query_point_no_sign(id: uint64, point: vec(3,float32), max_dist: float32, face: int32, bary_u: float32, bary_v: float32) -> bool",
       "Out-parameter form of mesh_query_point_no_sign.", q);
  mesh("mesh_query_point_sign_normal(id: uint64, point: vec(3,float32), max_dist: float32, inside: float32, face: int32, bary_u: float32, bary_v: float32) -> bool",
       "Out-parameter form of mesh_query_point_sign_normal.", q);
  mesh("mesh_query_point_sign_normal(id: uint64, point: vec(3,float32), max_dist: float32, inside: float32, face: int32, bary_u: float32, bary_v: float32, epsilon: float32) -> bool",
       "Out-parameter form of mesh_query_point_sign_normal with epsilon.", q);
  mesh("mesh_query_point_sign_winding_number(id: uint64, point: vec(3,float32), max_dist: float32, inside: float32, face: int32, bary_u: float32, bary_v: float32) -> bool",
       "Out-parameter form of mesh_query_point_sign_winding_number.", q);
  mesh("mesh_query_point_sign_winding_number(id: uint64, point: vec(3,float32), max_dist: float32, inside: float32, face: int32, bary_u: float32, bary_v: float32, accuracy: float32, threshold: float32) -> bool",
       "Out-parameter form of mesh_query_point_sign_winding_number with accuracy and threshold.", q);
  mesh("mesh_query_ray(id: uint64, start: vec(3,float32), dir: vec(3,float32), max_t: float32, t: float32, bary_u: float32, bary_v: float32, sign: float32, normal: vec(3,float32), face: int32) -> bool",
       "Out-parameter form of mesh_query_ray.", q);
  mesh("mesh_query_ray(id: uint64, start: vec(3,float32), dir: vec(3,float32), max_t: float32, t: float32, bary_u: float32, bary_v: float32, sign: float32, normal: vec(3,float32), face: int32, root: int32) -> bool",
       "Out-parameter form of mesh_query_ray from node `root`.", q);
  mesh("mesh_get_group_root(id: uint64, group: int32) -> int32",
       "The root node of `group`'s faces in a Mesh built with groups; -1 when there is no such group.", q);
  mesh("mesh_get_bvh(id: uint64) -> uint64",
       "The id of the mesh's own BVH over its faces, for bvh_query_aabb/ray/sphere/capsule (items are face indices).", q);
  mesh("mesh_eval_position(id: uint64, face: int32, bary_u: float32, bary_v: float32) -> vec(3,float32)",
       "u * p0 + v * p1 + (1 - u - v) * p2 of face.", q);
  mesh("mesh_eval_velocity(id: uint64, face: int32, bary_u: float32, bary_v: float32) -> vec(3,float32)",
       "The velocities interpolated like mesh_eval_position.", q);
  mesh("mesh_eval_face_normal(id: uint64, face: int32) -> vec(3,float32)", "Unit normal of face (zero if degenerate).", q);
  mesh("mesh_get_point(id: uint64, index: int32) -> vec(3,float32)", "points[indices[index]].", q);
  mesh("mesh_get_velocity(id: uint64, index: int32) -> vec(3,float32)", "velocities[indices[index]].", q);
  mesh("mesh_get_index(id: uint64, index: int32) -> int32", "indices[index].", q);
  mesh("mesh_get(id: uint64) -> struct(Mesh)",
       "The mesh's arrays: points, velocities (a None array without them) and indices (the caller's "
       "arrays; the queries read the daemon's checked copy of the indices). No gradients flow through them.", q);
}

}  // namespace weft::sema
