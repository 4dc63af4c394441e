"""Hash grids: wp.HashGrid.build and a neighbour-count query launch, weft against warp-lang on the
same device in the same run.

    python bench/bench_hash_grid.py [--device cpu|cuda:0] [--quick]

Per point count N (uniform in a cube, about 8 neighbours within the radius per point, a 128^3
grid): the build (grid.build(points, radius), synchronized; on a GPU weft sorts on the device,
docs/geometry.md) and a launch counting each point's neighbours within the radius (launch +
sync), median of several runs. The error column counts, over 256 of the points, the neighbour
counts that differ from a float64 brute-force count (pairs within 1e-5 of the radius, where
float32 and float64 may disagree, left out). Ratio = warp time / weft time (higher is better
for weft).
"""
from __future__ import annotations

import sys

import numpy as np

import bench_common as bc

SOURCE = '''
@wp.kernel
def count(grid: wp.uint64, points: wp.array(dtype=wp.vec3), radius: float, out: wp.array(dtype=int)):
    tid = wp.tid()
    i = wp.hash_grid_point_id(grid, tid)
    p = points[i]
    query = wp.hash_grid_query(grid, p, radius)
    index = int(0)
    n = int(0)
    while wp.hash_grid_query_next(query, index):
        if wp.length(points[index] - p) <= radius:
            n += 1
    out[i] = n
'''

SIZES = [10_000, 100_000, 1_000_000, 4_000_000]
TOL = 1e-5


def run(lib, mod, pts, radius, device):
    points = lib.array(pts, dtype=lib.vec3, device=device)
    out = lib.zeros(len(pts), dtype=int, device=device)
    grid = lib.HashGrid(128, 128, 128, device=device)

    def build():
        grid.build(points, radius)
        lib.synchronize_device(device)

    build()
    t_build = bc.median_time(build, repeat=7)
    groups = lib.zeros(len(pts), dtype=lib.int32, device=device)

    def build_grouped():
        grid.build(points, radius, groups=groups)
        lib.synchronize_device(device)

    build_grouped()
    t_grouped = bc.median_time(build_grouped, repeat=3)
    build()

    def query():
        lib.launch(mod.count, dim=len(pts), inputs=[grid.id, points, radius, out], device=device)
        lib.synchronize_device(device)

    query()
    t_query = bc.median_time(query, repeat=5)
    got = out.numpy()
    p64 = pts.astype(np.float64)
    wrong = 0
    for k in range(0, len(pts), max(1, len(pts) // 256)):
        d = np.linalg.norm(p64 - p64[k], axis=1)
        lo, hi = int((d <= radius - TOL).sum()), int((d <= radius + TOL).sum())
        wrong += not (lo <= got[k] <= hi)
    return t_build, t_grouped, t_query, wrong


def main():
    import weft

    device = "cpu"
    if "--device" in sys.argv:
        device = sys.argv[sys.argv.index("--device") + 1]
    weft.init()
    weft_mod = bc.load_kernels(SOURCE, "weft", "hash_grid")
    warp = bc.import_warp()
    warp_mod = bc.load_kernels(SOURCE, "warp", "hash_grid") if warp is not None else None
    rng = np.random.default_rng(0)
    sizes = SIZES[:2] if "--quick" in sys.argv else SIZES
    rows = []
    for n in sizes:
        side = (n / 8.0 * (4.0 / 3.0) * np.pi) ** (1.0 / 3.0)   # ~8 neighbours within radius 1
        pts = rng.uniform(0.0, side, size=(n, 3)).astype(np.float32)
        radius = 1.0
        print(f"  {n:,} points ...", file=sys.stderr, flush=True)
        wb, wg, wq, we = run(weft, weft_mod, pts, radius, device)
        xb = xg = xq = xe = None
        if warp is not None:
            xb, xg, xq, xe = run(warp, warp_mod, pts, radius, device)
        rows.append([f"{n:,}", bc.fmt_time(wb), f"{n / wb / 1e6:,.1f} M/s", bc.fmt_time(xb), bc.fmt_ratio(wb, xb),
                     bc.fmt_time(wg), bc.fmt_time(xg), bc.fmt_ratio(wg, xg),
                     bc.fmt_time(wq), f"{we}/256", bc.fmt_time(xq), "n/a" if xe is None else f"{xe}/256",
                     bc.fmt_ratio(wq, xq)])
    header = ["points", "build weft", "points/s", "warp", "ratio", "grouped weft", "warp", "ratio", "query weft", "wrong counts",
              "warp", "warp wrong", "ratio"]
    bc.print_table(f"wp.HashGrid on {device}: build (synchronized) and a neighbour-count launch (launch + sync)",
                   header, rows)


if __name__ == "__main__":
    main()
