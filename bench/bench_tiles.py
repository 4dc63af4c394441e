"""Tiles (docs/tiles.md): a tiled matrix product C = A B (M x K times K x N, float32, tiles of
TILE x TILE, one tile of C per tile index, K / TILE products accumulated with tile_matmul) and a
tiled row sum (tile_load of a row block, tile_sum along the rows, tile_store), weft against
warp-lang on the same device in the same run.

    python bench/bench_tiles.py [--device cpu|cuda:0] [--quick]

Time: launch + synchronize, median of several runs after a warm-up that compiles. Throughput:
GFLOP/s (2 M N K) for the product, GB/s of input for the sum. Error: the largest difference to
float64 NumPy relative to the largest reference value. Ratio = warp time / weft time (higher is
better for weft). weft runs each tile on one thread (docs/tiles.md), Warp's GPU tiles use the
block's threads together, so large tiles favour Warp on a GPU.
"""
from __future__ import annotations

import sys

import numpy as np

import bench_common as bc

SOURCE = '''
TILE = wp.constant({tile})


@wp.kernel
def gemm(a: wp.array2d(dtype=float), b: wp.array2d(dtype=float), c: wp.array2d(dtype=float), k_tiles: int):
    i, j = wp.tid()
    acc = wp.tile_zeros(shape=(TILE, TILE), dtype=float)
    for k in range(k_tiles):
        ta = wp.tile_load(a, shape=(TILE, TILE), offset=(i * TILE, k * TILE))
        tb = wp.tile_load(b, shape=(TILE, TILE), offset=(k * TILE, j * TILE))
        wp.tile_matmul(ta, tb, acc)
    wp.tile_store(c, acc, offset=(i * TILE, j * TILE))


@wp.kernel
def row_sums(x: wp.array2d(dtype=float), out: wp.array2d(dtype=float)):
    i = wp.tid()
    t = wp.tile_load(x, shape=(TILE, {cols}), offset=(i * TILE, 0))
    s = wp.tile_sum(t, axis=1)
    wp.tile_store(out, wp.tile_reshape(s, shape=(TILE, 1)), offset=(i * TILE, 0))
'''


def run(wp, mod, a, b, x, tile, device):
    m, k = a.shape
    n = b.shape[1]
    A = wp.array(a, dtype=float, device=device)
    B = wp.array(b, dtype=float, device=device)
    C = wp.zeros((m, n), dtype=float, device=device)
    X = wp.array(x, dtype=float, device=device)
    S = wp.zeros((x.shape[0], 1), dtype=float, device=device)

    def gemm():
        wp.launch_tiled(mod.gemm, dim=[m // tile, n // tile], inputs=[A, B, C, k // tile], block_dim=64, device=device)
        wp.synchronize_device(device)

    def sums():
        wp.launch_tiled(mod.row_sums, dim=[x.shape[0] // tile], inputs=[X, S], block_dim=64, device=device)
        wp.synchronize_device(device)

    gemm()
    sums()
    t_gemm = bc.median_time(gemm, repeat=5)
    t_sum = bc.median_time(sums, repeat=5)
    ref = a.astype(np.float64) @ b.astype(np.float64)
    err_gemm = float(np.abs(C.numpy() - ref).max() / np.abs(ref).max())
    ref_s = x.astype(np.float64).sum(axis=1)
    err_sum = float(np.abs(S.numpy()[:, 0] - ref_s).max() / np.abs(ref_s).max())
    return t_gemm, err_gemm, t_sum, err_sum


def main():
    import weft

    device, quick = bc.device_and_quick()
    weft.init()
    warp = bc.import_warp()
    rng = np.random.default_rng(0)
    sizes = [(256, 16)] if quick else ([(256, 16), (512, 16), (1024, 32)] if device.startswith("cuda") else [(256, 16), (512, 16)])
    rows = []
    for size, tile in sizes:
        cols = 64
        src = SOURCE.format(tile=tile, cols=cols)
        weft_mod = bc.load_kernels(src, "weft", f"tiles{tile}")
        warp_mod = bc.load_kernels(src, "warp", f"tiles{tile}") if warp is not None else None
        a = rng.standard_normal((size, size)).astype(np.float32)
        b = rng.standard_normal((size, size)).astype(np.float32)
        x = rng.standard_normal((size * 16, cols)).astype(np.float32)
        print(f"  {size} x {size}, tiles {tile} ...", file=sys.stderr, flush=True)
        wg, weg, ws, wes = run(weft, weft_mod, a, b, x, tile, device)
        xg = xeg = xs = xes = None
        if warp is not None:
            xg, xeg, xs, xes = run(warp, warp_mod, a, b, x, tile, device)
        flops = 2.0 * size ** 3
        rows.append([f"{size}^3 / {tile}", bc.fmt_time(wg), f"{flops / wg / 1e9:,.2f}", f"{weg:.1e}",
                     bc.fmt_time(xg), "n/a" if xeg is None else f"{xeg:.1e}", bc.fmt_ratio(wg, xg),
                     bc.fmt_time(ws), f"{x.nbytes / ws / 1e9:,.2f}", f"{wes:.1e}", bc.fmt_time(xs),
                     bc.fmt_ratio(ws, xs)])
    header = ["gemm / tile", "weft", "GFLOP/s", "rel err", "warp", "warp rel err", "ratio",
              "row sums weft", "GB/s", "rel err", "warp", "ratio"]
    bc.print_table(f"Tiles on {device}: tile_matmul GEMM and tile_sum row sums (launch + sync)", header, rows)


if __name__ == "__main__":
    main()
