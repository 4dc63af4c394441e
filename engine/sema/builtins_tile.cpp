// Registry rows: tiles (Warp's tile programming; engine/native/tile.h). Data only; see
// builtins.h. Operators on tiles (+ - * / % // ** << >> & | ^, unary - + ~) apply element-wise
// through tile_map (sema/check_tile.cpp), so every element type the scalar builtin takes works. The forms that take a shape (tile_zeros, tile_load, tile_broadcast, tile_sum
// along an axis, ...) are rewritten by sema/check_tile.cpp into these rows: a `like` argument
// (a tile of the result's type, never read) carries the shape the call asked for, and a tuple
// offset becomes one index argument per dimension.
#include <string>

#include "engine/sema/builtins.h"

namespace weft::sema {

void AddTileBuiltins(std::vector<BuiltinOverload>* rows) {
  const char* dims[] = {"M", "M,N", "M,N,K", "M,N,K,L"};
  const char* idx[] = {"i: Index", "i: Index, j: Index", "i: Index, j: Index, k: Index",
                       "i: Index, j: Index, k: Index, l: Index"};
  auto row = [rows](const std::string& sig, const char* doc, unsigned flags = kBuiltinNone, const char* native = "") {
    rows->push_back(Builtin("Tiles", sig.c_str(), doc, flags, native));
  };
  for (int d = 1; d <= 4; ++d) {
    const std::string t = std::string("tile(X,") + dims[d - 1] + ")";
    const std::string ts = std::string("tile(Scalar,") + dims[d - 1] + ")";
    const std::string a = "array(X," + std::to_string(d) + ")";
    row("tile_load(like: " + t + ", a: " + a + ", " + idx[d - 1] + ") -> " + t,
        "Called as wp.tile_load(a, shape=..., offset=...): the tile of a at the offset; elements outside a read as zero. "
        "Adjoint: adds the tile's gradient into a's gradient array.");
    row("tile_store(a: " + a + ", " + idx[d - 1] + ", t: " + t + ") -> None",
        "Called as wp.tile_store(a, t, offset=...): writes t into a at the offset; elements outside a are skipped.",
        kBuiltinSideEffect | kBuiltinVoidAdjoint);
    row("tile_atomic_add(a: " + a + ", " + idx[d - 1] + ", t: " + t + ") -> " + t,
        "Called as wp.tile_atomic_add(a, t, offset=...): adds t into a at the offset atomically; returns the old "
        "values (zero outside a).", kBuiltinSideEffect);
    row("tile_insert(a: " + t + ", " + idx[d - 1] + ", value: X) -> " + t,
        "a with one element replaced (t[i, j] = value); an index outside the tile is a launch error.", kBuiltinNeedsLoc);
    const std::string off4 = "o0: int64, o1: int64, o2: int64, o3: int64";
    row("tile_load_indexed(like: " + t + ", a: " + a + ", indices: tile(int32,G), axis: int32, " + off4 + ") -> " + t,
        "Called as wp.tile_load_indexed(a, indices, shape, offset, axis): tile_load where the coordinate along the "
        "axis is offset + indices[c]; elements outside a read as zero.");
    row("tile_store_indexed(a: " + a + ", indices: tile(int32,G), t: " + t + ", axis: int32, " + off4 + ") -> None",
        "Called as wp.tile_store_indexed(a, indices, t, offset, axis): tile_store through the index tile.",
        kBuiltinSideEffect | kBuiltinVoidAdjoint);
    row("tile_atomic_add_indexed(a: " + a + ", indices: tile(int32,G), t: " + t + ", axis: int32, " + off4 + ") -> " + t,
        "Called as wp.tile_atomic_add_indexed(a, indices, t, offset, axis): tile_atomic_add through the index tile.",
        kBuiltinSideEffect);
    row("tile_scatter_add(a: " + t + ", " + idx[d - 1] + ", value: X, has_value: bool) -> " + t,
        "Called as wp.tile_scatter_add(a, i, ..., value, has_value[, atomic]): the block's one thread adds value into "
        "a at the indices when has_value (structs field by field), assigned to a; the index is checked then.",
        kBuiltinNeedsLoc);
    row("tile_scatter_masked(a: " + t + ", " + idx[d - 1] + ", value: X, has_value: bool) -> " + t,
        "Called as wp.tile_scatter_masked(a, i, ..., value, has_value): writes value into a at the indices when "
        "has_value, assigned to a.", kBuiltinNeedsLoc);
    for (const char* op : {"and", "or", "xor"})
      row("tile_lanes_bit_" + std::string(op) + "(a: " + t + ", " + idx[d - 1] + ", value: X) -> " + t,
          "Called as t[i, ...] op= v (&=, |=, ^=) in a kernel compiled for cooperative CPU blocks: every lane's v "
          "combined into the element, assigned to t.", kBuiltinNeedsLoc | kBuiltinNotDiff);
    row("tile_extract(a: " + t + ", " + idx[d - 1] + ") -> X",
        "The element of a at the indices (also a[i, j]); an index outside the tile is a launch error.", kBuiltinNeedsLoc);
    row("tile_sum(a: " + t + ") -> tile(X,1)", "The sum of all elements, as a tile of shape (1,).");
    row("tile_max(a: " + ts + ") -> tile(Scalar,1)", "The largest element, as a tile of shape (1,). Adjoint: to the first largest.");
    row("tile_min(a: " + ts + ") -> tile(Scalar,1)", "The smallest element, as a tile of shape (1,). Adjoint: to the first smallest.");
    row("tile_argmax(a: " + ts + ") -> tile(int32,1)", "The flat position of the first largest element.", kBuiltinNotDiff);
    row("tile_argmin(a: " + ts + ") -> tile(int32,1)", "The flat position of the first smallest element.", kBuiltinNotDiff);
    row("tile_dot(a: " + ts + ", b: " + ts + ") -> tile(Scalar,1)", "The sum of a[k] * b[k], as a tile of shape (1,).");
    const std::string tv = std::string("tile(vec(P,Float),") + dims[d - 1] + ")";
    const std::string tm = std::string("tile(mat(P,Q,Float),") + dims[d - 1] + ")";
    row("tile_dot(a: " + tv + ", b: " + tv + ") -> tile(Float,1)",
        "Tiles of vectors: the sum of dot(a[k], b[k]), as a scalar tile of shape (1,).");
    row("tile_dot(a: " + tm + ", b: " + tm + ") -> tile(Float,1)",
        "Tiles of matrices: the sum of ddot(a[k], b[k]) (every element product), as a scalar tile of shape (1,).");
    row("tile_axpy(alpha: Scalar, src: " + ts + ", dest: " + ts + ") -> " + ts,
        "Called as wp.tile_axpy(alpha, src, dest): dest + alpha * src, assigned to dest.");
    row("tile_axpy(alpha: Float, src: " + tv + ", dest: " + tv + ") -> " + tv,
        "Tiles of vectors, a scalar alpha: dest + alpha * src, assigned to dest.");
    row("tile_axpy(alpha: Float, src: " + tm + ", dest: " + tm + ") -> " + tm,
        "Tiles of matrices, a scalar alpha: dest + alpha * src, assigned to dest.");
    row("tile_scan_inclusive(a: " + ts + ") -> " + ts, "Running sums over the elements in row-major order.");
    row("tile_scan_exclusive(a: " + ts + ") -> " + ts, "Running sums of the elements before each one (the first: 0).");
    row("tile_scan_max_inclusive(a: " + ts + ") -> " + ts, "Running maxima in row-major order.", kBuiltinNotDiff);
    row("tile_scan_min_inclusive(a: " + ts + ") -> " + ts, "Running minima in row-major order.", kBuiltinNotDiff);
  }
  // A sub-tile's place: offsets and steps by dimension, and which dimensions it keeps.
  const std::string region = "o0: int64, o1: int64, o2: int64, o3: int64, s0: int64, s1: int64, s2: int64, s3: int64, dims: int32";
  const char* like_forms[] = {"A)", "A,B)", "A,B,C)", "A,B,C,E)"};
  for (int r = 1; r <= 4; ++r) {
    for (int d = 1; d <= 4; ++d) {
      const std::string t = std::string("tile(X,") + dims[d - 1] + ")";
      const std::string like = std::string("tile(X,") + like_forms[r - 1];
      const std::string like_other = std::string("tile(Y,") + like_forms[r - 1];
      if (d <= r)
        row("tile_broadcast(like: " + like + ", a: " + t + ") -> " + like,
            "Called as wp.tile_broadcast(a, shape=...): a repeated along its extents of 1 (trailing dimensions aligned).");
      if (r == d - 1)
        row("tile_sum_axis(like: " + like + ", a: " + t + ", axis: int32) -> " + like,
            "Called as wp.tile_sum(a, axis=k): sums along a constant axis.");
      if (r == d) {
        row("tile_astype(like: " + like_other + ", a: " + t + ") -> " + like_other,
            "Called as wp.tile_astype(a, dtype): each element converted; the gradient converts back (float "
            "elements).");
      }
      row("tile_reshape(like: " + like + ", a: " + t + ") -> " + like,
          "Called as wp.tile_reshape(a, shape) or wp.tile_squeeze(a[, axis]): the elements in row-major order "
          "under another shape of the same size.");
      if (r == d)
        row("tile_gather(like: " + like + ", a: " + t + ", idx: tile(Int,G), axis: int32) -> " + like,
            "Called as t[idx, :] with idx a 1-D tile of integers: the slices along the axis idx names; an index "
            "outside the tile is a launch error.", kBuiltinNeedsLoc);
      if (r <= d)
        row("tile_assign(dst: " + t + ", src: " + like + ", " + region + ") -> " + t,
            "Called as wp.tile_assign(dst, src, offset=...), t[i] = row or t[a:b, :] = block: dst with src written at "
            "the offset (assigned to dst); an offset that does not fit is a launch error.", kBuiltinNeedsLoc);
      if (r <= d)
        row("tile_view(like: " + like + ", a: " + t + ", " + region + ") -> " + like,
            "Called as wp.tile_view(a, offset, shape) or a[i], a[i:j, :]: a copy of the sub-tile at the offset; an "
            "offset that does not fit is a launch error.", kBuiltinNeedsLoc);
    }
  }
  row("tile(x: X) -> tile(X,1)", "The thread's value as a tile of shape (1,) (one thread per block).");
  row("tile_lanes(like: tile(X,M), x: X) -> tile(X,M)",
      "Called as wp.tile(x) in a kernel compiled for cooperative CPU blocks (wp.config.enable_cpu_blocks): lane l's x "
      "at element l of a tile of the block's lanes.", kBuiltinNeedsLoc);
  row("tile_split_lanes(like: tile(Scalar,N,M), x: vec(N,Scalar)) -> tile(Scalar,N,M)",
      "Called as wp.tile(v) of a vector with cooperative CPU blocks: lane l's components in column l.", kBuiltinNeedsLoc);
  row("tile_split_lanes(like: tile(Scalar,N,M,K), x: mat(N,M,Scalar)) -> tile(Scalar,N,M,K)",
      "Called as wp.tile(m) of a matrix with cooperative CPU blocks: lane l's components at [:, :, l].", kBuiltinNeedsLoc);
  row("untile_lanes(a: tile(X,M)) -> X",
      "Called as wp.untile(t) with cooperative CPU blocks: the lane's element of a tile of the block's lanes.",
      kBuiltinNeedsLoc);
  row("untile_lanes(a: tile(Scalar,N,M)) -> vec(N,Scalar)",
      "Called as wp.untile(t) with cooperative CPU blocks: the vector in the lane's column.", kBuiltinNeedsLoc);
  row("untile_lanes(a: tile(Scalar,N,M,K)) -> mat(N,M,Scalar)",
      "Called as wp.untile(t) with cooperative CPU blocks: the matrix at the lane's [:, :, l].", kBuiltinNeedsLoc);
  row("untile(a: tile(X,1)) -> X", "The value of a tile of shape (1,) (one thread per block).");
  row("tile_split(x: vec(N,Scalar)) -> tile(Scalar,N,1)",
      "Called as wp.tile(v) of a vector: its components as a tile of shape (n, 1) (one thread per block).");
  row("tile_split(x: mat(N,M,Scalar)) -> tile(Scalar,N,M,1)",
      "Called as wp.tile(m) of a matrix: its components as a tile of shape (rows, cols, 1).");
  row("untile(a: tile(Scalar,N,1)) -> vec(N,Scalar)", "The vector a tile of shape (n, 1) holds (wp.tile(v) reversed).");
  row("untile(a: tile(Scalar,N,M,1)) -> mat(N,M,Scalar)", "The matrix a tile of shape (rows, cols, 1) holds.");
  row("tile_transpose(a: tile(X,M,N)) -> tile(X,N,M)", "The transpose of a 2-D tile.");
  row("tile_stack_push_slot(s: tile_stack(X,N), value: X, has_value: bool) -> int32",
      "Called as wp.tile_stack_push(s, value, has_value): the slot the value goes to (-1 when the stack is full or "
      "has_value is False); the pushed stack is assigned to s.", kBuiltinNeedsLoc | kBuiltinNotDiff);
  row("tile_stack_pushed(s: tile_stack(X,N), value: X, has_value: bool) -> tile_stack(X,N)",
      "The stack after wp.tile_stack_push.", kBuiltinNeedsLoc | kBuiltinNotDiff);
  row("tile_stack_top(s: tile_stack(X,N)) -> tuple(X,int32)",
      "Called as value, slot = wp.tile_stack_pop(s): the top value and its slot (zero and -1 when empty); the "
      "popped stack is assigned to s.", kBuiltinNeedsLoc | kBuiltinNotDiff);
  row("tile_stack_popped(s: tile_stack(X,N)) -> tile_stack(X,N)", "The stack after wp.tile_stack_pop.", kBuiltinNeedsLoc | kBuiltinNotDiff);
  row("tile_stack_cleared(s: tile_stack(X,N)) -> tile_stack(X,N)",
      "Called as wp.tile_stack_clear(s): the empty stack, assigned to s.", kBuiltinNeedsLoc | kBuiltinNotDiff);
  row("tile_stack_count(s: tile_stack(X,N)) -> int32", "The number of values on the stack.", kBuiltinNotDiff);
  row("tile_diag_add(a: tile(X,N,N), d: tile(X,N)) -> tile(X,N,N)", "a with d added to its diagonal.");
  const char* struct_doc = " of two Warp structs field by field, for the elements of struct tiles only (t + u, "
                           "t[i] += s, wp.tile_sum, wp.tile_scatter_add): fields of [u]int32, [u]int64, float16, "
                           "bfloat16, float32 or float64 scalars, vectors, matrices, quaternions and transforms, and "
                           "nested structs; other fields keep a's value.";
  row("add(a: S, b: S) -> S", (std::string("The sum") + struct_doc).c_str(), kBuiltinNone, "struct_add");
  row("sub(a: S, b: S) -> S", (std::string("The difference") + struct_doc).c_str(), kBuiltinNone, "struct_sub");
  row("neg(a: S) -> S", (std::string("The negation") + struct_doc).c_str(), kBuiltinNone, "struct_neg");
  row("tile_sort(keys: tile(Scalar,N), values: tile(X,N)) -> tuple(tile(Scalar,N),tile(X,N))",
      "Called as wp.tile_sort(keys, values): keys sorted ascending (stable) and values in their order, assigned to "
      "the arguments.", kBuiltinNotDiff);
  for (int d = 1; d <= 4; ++d) {
    const std::string t = std::string("tile(vec(2,Float),") + dims[d - 1] + ")";
    row("tile_fft(inout: " + t + ") -> " + t,
        "Called as wp.tile_fft(t): the unnormalized discrete Fourier transform of each row (last dimension) of a "
        "complex tile (vec2: real, imaginary), assigned to t.", kBuiltinNone);
    row("tile_ifft(inout: " + t + ") -> " + t,
        "Called as wp.tile_ifft(t): the unnormalized inverse transform (ifft(fft(x)) = n x), assigned to t.");
  }
  row("tile_cholesky(A: tile(Float,N,N), upper: bool) -> tile(Float,N,N)",
      "Called as wp.tile_cholesky(A[, fill_mode]): L with A = L L^T (\"lower\", the default) or U with A = U^T U "
      "(\"upper\"), the other triangle zero; wp.tile_cholesky_inplace(A) assigns it to A. Adjoint: Warp's.");
  for (const char* y : {"tile(Float,N)", "tile(Float,N,K)"}) {
    const std::string ys = y;
    row("tile_lower_solve(L: tile(Float,N,N), y: " + ys + ") -> " + ys,
        "z with L z = y (L lower triangular; y a vector or columns); wp.tile_lower_solve_inplace(L, y) assigns it to y.");
    row("tile_upper_solve(U: tile(Float,N,N), z: " + ys + ") -> " + ys,
        "x with U x = z (U upper triangular); wp.tile_upper_solve_inplace(U, z) assigns it to z.");
    row("tile_cholesky_solve(L: tile(Float,N,N), y: " + ys + ", upper: bool) -> " + ys,
        "Called as wp.tile_cholesky_solve(L, y[, fill_mode]): x with A x = y for the factor of tile_cholesky; "
        "wp.tile_cholesky_solve_inplace(L, y) assigns it to y.");
  }
  row("tile_matmul(a: tile(Float,M,K), b: tile(Float,K,N), c: tile(Float,M,N), alpha: Float, beta: Float) -> tile(Float,M,N)",
      "alpha * a @ b + beta * c. wp.tile_matmul(a, b) is alpha 1 over zeros; wp.tile_matmul(a, b, out[, alpha, beta]) "
      "assigns the result to out (alpha, beta default 1).", kBuiltinNone, "tile_matmul_acc");
}

}  // namespace weft::sema
