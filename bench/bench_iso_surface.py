"""Marching cubes (docs/geometry.md "Iso-surfaces"): IsoSurfaceMarchingCubes.extract of a sphere's
signed distance field sampled on an n^3 grid, weft against warp-lang on the same device in the
same run.

    python bench/bench_iso_surface.py [--device cpu|cuda:0] [--quick]

Time: extract + synchronize (and the stateful surface() called again on the field, which may keep
its temporaries), median of several runs after a warm-up that compiles. Throughput:
million grid cells per second. Error: the vertices against a float64 NumPy interpolation of the
same float32 field on the same crossed edges (each vertex matched to its edge), as the largest
difference relative to the grid's extent. Ratio = warp time / weft time (higher is
better for weft).
"""
from __future__ import annotations

import sys

import numpy as np

import bench_common as bc


def sphere(n: int) -> np.ndarray:
    g = np.arange(n, dtype=np.float64)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    c, r = (n - 1) / 2 + 0.123, n / 3
    return (np.sqrt((x - c) ** 2 + (y - c) ** 2 + (z - c) ** 2) - r).astype(np.float32)


def reference_vertices(field: np.ndarray) -> np.ndarray:
    """float64 vertex of every crossed grid edge (node below 0 on one end only), in grid units."""
    f = field.astype(np.float64)
    out = []
    for axis in range(3):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        f0, f1 = f[tuple(lo)], f[tuple(hi)]
        crossed = (f0 < 0.0) != (f1 < 0.0)
        idx = np.argwhere(crossed).astype(np.float64)
        s = -f0[crossed] / (f1[crossed] - f0[crossed])
        idx[:, axis] += s
        out.append(idx)
    return np.concatenate(out)


def by_edge(v: np.ndarray, n: int) -> np.ndarray:
    """The vertices in the order of the grid edges they lie on (the edge: the coordinate farthest
    from an integer runs along it; the others are the edge's node)."""
    frac = np.abs(v - np.round(v))
    axis = np.argmax(frac, axis=1)
    node = np.round(v).astype(np.int64)
    node[np.arange(len(v)), axis] = np.floor(v[np.arange(len(v)), axis]).astype(np.int64)
    key = ((node[:, 0] * n + node[:, 1]) * n + node[:, 2]) * 3 + axis
    return v[np.argsort(key, kind="stable")]


def run(wp, field_np: np.ndarray, device: str):
    import importlib

    geometry = importlib.import_module(f"{wp.__name__}.geometry")
    field = wp.array(field_np, dtype=wp.float32, device=device)
    result = {}

    def extract():
        result["mesh"] = geometry.IsoSurfaceMarchingCubes.extract(field, 0.0)
        wp.synchronize_device(device)

    iso = geometry.IsoSurfaceMarchingCubes(*field_np.shape)

    def surface():   # the stateful form, called again on a field of the same shape
        iso.surface(field, 0.0)
        wp.synchronize_device(device)

    extract()
    surface()
    seconds = bc.median_time(extract, repeat=5)
    surface_seconds = bc.median_time(surface, repeat=5)
    verts, indices = result["mesh"]
    return seconds, surface_seconds, verts.numpy().astype(np.float64), indices.numpy().size // 3


def main():
    import weft

    device, quick = bc.device_and_quick()
    weft.init()
    warp = bc.import_warp()
    sizes = [64] if quick else ([64, 128, 256] if device.startswith("cuda") else [64, 128])
    rows = []
    for n in sizes:
        print(f"  {n}^3 ...", file=sys.stderr, flush=True)
        field = sphere(n)
        ref = by_edge(reference_vertices(field), n)
        extent = float(n - 1)
        t, ts, v, tris = run(weft, field, device)
        err = float(np.abs(by_edge(v, n) - ref).max() / extent) if len(v) == len(ref) else float("nan")
        xt = xts = xerr = None
        if warp is not None:
            xt, xts, xv, _ = run(warp, field, device)
            xerr = float(np.abs(by_edge(xv, n) - ref).max() / extent) if len(xv) == len(ref) else float("nan")
        cells = (n - 1) ** 3
        rows.append([f"{n}^3", f"{len(v):,} / {tris:,}", bc.fmt_time(t), bc.fmt_time(ts), f"{cells / t / 1e6:,.1f}",
                     f"{err:.1e}", bc.fmt_time(xt), bc.fmt_time(xts), "n/a" if xerr is None else f"{xerr:.1e}",
                     bc.fmt_ratio(t, xt), bc.fmt_ratio(ts, xts)])
    header = ["grid", "verts / tris", "extract", "surface()", "Mcells/s", "rel err", "warp extract", "warp surface()",
              "warp rel err", "ratio", "ratio surface()"]
    bc.print_table(f"Marching cubes on {device}: IsoSurfaceMarchingCubes.extract of a sphere SDF", header, rows)


if __name__ == "__main__":
    main()
