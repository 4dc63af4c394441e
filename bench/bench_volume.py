"""Sparse volumes: wp.Volume creation from a dense NumPy grid and trilinear sampling (value and
gradient), weft against warp-lang on the same device in the same run.

    python bench/bench_volume.py [--device cpu|cuda:0] [--quick]

Per grid size n^3 (a smooth field, float32): the creation (wp.Volume.load_from_numpy,
synchronized) and a launch of Q samples at random index-space points (volume_sample_grad_f,
LINEAR: the value and its gradient), launch + sync, median of several runs. The error column is
the largest difference, over 4,096 of the samples, between the value and the float64 trilinear
interpolation of the same grid. Ratio = warp time / weft time (higher is better for weft).
"""
from __future__ import annotations

import sys

import numpy as np

import bench_common as bc

SOURCE = '''
@wp.kernel
def sample(volume: wp.uint64, points: wp.array(dtype=wp.vec3), values: wp.array(dtype=float),
           grads: wp.array(dtype=wp.vec3)):
    tid = wp.tid()
    g = wp.vec3()
    values[tid] = wp.volume_sample_grad_f(volume, points[tid], wp.Volume.LINEAR, g)
    grads[tid] = g
'''

SIZES = [64, 128, 256]
QUERIES = 1 << 22


def field(n: int) -> np.ndarray:
    x = np.linspace(-1.0, 1.0, n)
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    return (np.sin(3 * X) * np.cos(2 * Y) + Z * Z - 0.5).astype(np.float32)


def trilinear_f64(grid: np.ndarray, p: np.ndarray) -> np.ndarray:
    base = np.floor(p).astype(np.int64)
    f = p - base
    out = np.zeros(len(p))
    for c in range(8):
        o = np.array([(c >> 2) & 1, (c >> 1) & 1, c & 1])
        w = np.prod(np.where(o == 1, f, 1.0 - f), axis=1)
        idx = base + o
        out += w * grid[idx[:, 0], idx[:, 1], idx[:, 2]].astype(np.float64)
    return out


def run(lib, mod, grid, points, device):
    holder = {}

    def create():
        holder["v"] = lib.Volume.load_from_numpy(grid, (0.0, 0.0, 0.0), 1.0, 0.0, device=device)
        lib.synchronize_device(device)

    t_create = bc.median_time(create, repeat=3)
    vol = holder["v"]
    pts = lib.array(points, dtype=lib.vec3, device=device)
    values = lib.zeros(len(points), dtype=float, device=device)
    grads = lib.zeros(len(points), dtype=lib.vec3, device=device)

    def query():
        lib.launch(mod.sample, dim=len(points), inputs=[vol.id, pts, values, grads], device=device)
        lib.synchronize_device(device)

    query()
    t_query = bc.median_time(query, repeat=5)
    k = np.arange(0, len(points), max(1, len(points) // 4096))
    err = float(np.abs(values.numpy()[k] - trilinear_f64(grid, points[k].astype(np.float64))).max())
    return t_create, t_query, err


def main():
    import weft

    device = "cpu"
    if "--device" in sys.argv:
        device = sys.argv[sys.argv.index("--device") + 1]
    weft.init()
    weft_mod = bc.load_kernels(SOURCE, "weft", "volume")
    warp = bc.import_warp()
    warp_mod = bc.load_kernels(SOURCE, "warp", "volume") if warp is not None else None
    rng = np.random.default_rng(0)
    sizes = SIZES[:2] if "--quick" in sys.argv else SIZES
    nq = QUERIES // 16 if ("--quick" in sys.argv or device == "cpu") else QUERIES
    rows = []
    for n in sizes:
        print(f"  grid {n}^3 ...", file=sys.stderr, flush=True)
        grid = field(n)
        points = rng.uniform(0.0, n - 1.0, size=(nq, 3)).astype(np.float32)
        wc, wq, we = run(weft, weft_mod, grid, points, device)
        xc = xq = xe = None
        if warp is not None:
            xc, xq, xe = run(warp, warp_mod, grid, points, device)
        rows.append([f"{n}^3", bc.fmt_time(wc), bc.fmt_time(xc), bc.fmt_ratio(wc, xc),
                     bc.fmt_time(wq), f"{nq / wq / 1e6:,.1f} M/s", f"{we:.1e}",
                     bc.fmt_time(xq), "n/a" if xe is None else f"{xe:.1e}", bc.fmt_ratio(wq, xq)])
    header = ["grid", "create weft", "warp", "ratio", f"{nq:,} samples weft", "throughput", "abs err",
              "warp", "warp abs err", "ratio"]
    bc.print_table(f"wp.Volume on {device}: load_from_numpy, trilinear samples with gradient (launch + sync)",
                   header, rows)


if __name__ == "__main__":
    main()
