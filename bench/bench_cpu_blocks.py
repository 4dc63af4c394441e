"""Cooperative CPU blocks (wp.config.enable_cpu_blocks, docs/tiles.md): a block sum of every
lane's value (wp.tile(x), tile_sum, one tile_atomic_add per block) and a stream compaction of
the positive values through a tile stack (every lane pushes, the block's count is stored), weft
against warp-lang with the same setting on the CPU in the same run.

    python bench/bench_cpu_blocks.py [--quick]

Time: launch + synchronize, median of several runs after a warm-up that compiles. Throughput:
million threads per second. Error: the block sums' largest difference to float64 NumPy relative
to the largest reference sum; the counts must match exactly (else "WRONG"). Ratio = warp time /
weft time (higher is better for weft).
"""
from __future__ import annotations

import sys

import numpy as np

import bench_common as bc

SOURCE = '''
BLOCK = wp.constant({block})


@wp.kernel
def block_sums(x: wp.array(dtype=float), sums: wp.array(dtype=float)):
    i = wp.tid()
    t = wp.tile(x[i] * 1.0)
    wp.tile_atomic_add(sums, wp.tile_sum(t), offset=i // BLOCK)


@wp.kernel
def compact(x: wp.array(dtype=float), counts: wp.array(dtype=int)):
    i = wp.tid()
    s = wp.tile_stack(capacity=BLOCK, dtype=float)
    wp.tile_stack_push(s, x[i], x[i] > 0.0)
    if i % BLOCK == 0:
        counts[i // BLOCK] = wp.tile_stack_count(s)
'''


def run(wp, mod, x, block):
    n = x.shape[0]
    X = wp.array(x, dtype=float, device="cpu")
    S = wp.zeros(n // block, dtype=float, device="cpu")
    C = wp.zeros(n // block, dtype=int, device="cpu")

    def sums():
        S.zero_()
        wp.launch(mod.block_sums, dim=n, inputs=[X, S], block_dim=block, device="cpu")
        wp.synchronize_device("cpu")

    def counts():
        wp.launch(mod.compact, dim=n, inputs=[X, C], block_dim=block, device="cpu")
        wp.synchronize_device("cpu")

    sums()
    counts()
    t_sum = bc.median_time(sums, repeat=5)
    t_count = bc.median_time(counts, repeat=5)
    ref = x.astype(np.float64).reshape(-1, block).sum(axis=1)
    err = float(np.abs(S.numpy() - ref).max() / np.abs(ref).max())
    right = bool(np.array_equal(C.numpy(), (x.reshape(-1, block) > 0).sum(axis=1)))
    return t_sum, err, t_count, right


def main():
    import weft

    _, quick = bc.device_and_quick()
    weft.init()
    weft.config.enable_cpu_blocks = True
    warp = bc.import_warp()
    if warp is not None:
        warp.config.enable_cpu_blocks = True
    rng = np.random.default_rng(0)
    cases = [(1 << 14, 64)] if quick else [(1 << 14, 64), (1 << 17, 64), (1 << 17, 256)]
    rows = []
    for n, block in cases:
        src = SOURCE.format(block=block)
        weft_mod = bc.load_kernels(src, "weft", f"cpublocks{block}")
        warp_mod = bc.load_kernels(src, "warp", f"cpublocks{block}") if warp is not None else None
        x = (rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4, n)).astype(np.float32)
        print(f"  {n} threads, blocks of {block} ...", file=sys.stderr, flush=True)
        ws, werr, wc, wright = run(weft, weft_mod, x, block)
        xs = xerr = xc = None
        xright = True
        if warp is not None:
            xs, xerr, xc, xright = run(warp, warp_mod, x, block)
        rows.append([f"{n} / {block}", bc.fmt_time(ws), f"{n / ws / 1e6:,.1f}", f"{werr:.1e}", bc.fmt_time(xs),
                     "n/a" if xerr is None else f"{xerr:.1e}", bc.fmt_ratio(ws, xs),
                     bc.fmt_time(wc) + ("" if wright else " WRONG"), f"{n / wc / 1e6:,.1f}",
                     bc.fmt_time(xc) + ("" if xright else " WRONG"), bc.fmt_ratio(wc, xc)])
    header = ["threads / block", "sum weft", "Mthreads/s", "rel err", "warp", "warp rel err", "ratio",
              "stack weft", "Mthreads/s", "warp", "ratio"]
    bc.print_table("Cooperative CPU blocks: block sums (wp.tile) and stack compaction (launch + sync)", header, rows)


if __name__ == "__main__":
    main()
