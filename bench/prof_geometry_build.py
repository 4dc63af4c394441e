"""Where a geometry object's construction goes in the client: wp.Bvh over n boxes and wp.Mesh
over a grid of n triangles, each step timed apart (the constructor's return, the synchronize
after it, the free of the previous object), median of 20 rounds; then one round under cProfile.
Usage: WEFT_DAEMON=... python3 bench/prof_geometry_build.py [--device cuda:0] [-n 10000] [--top 20]"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import weft as wp  # noqa: E402


def grid_mesh(n: int):
    side = max(2, int(np.sqrt(n / 2)) + 1)
    x, y = np.meshgrid(np.arange(side, dtype=np.float32), np.arange(side, dtype=np.float32), indexing="ij")
    pts = np.stack([x, y, np.sin(x) * np.cos(y)], -1).reshape(-1, 3).astype(np.float32)
    i, j = np.meshgrid(np.arange(side - 1), np.arange(side - 1), indexing="ij")
    a = (i * side + j).reshape(-1)
    tris = np.stack([a, a + side, a + 1, a + 1, a + side, a + side + 1], -1).reshape(-1)
    return pts, tris.astype(np.int32)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cpu")
    ap.add_argument("-n", type=int, default=10_000)
    ap.add_argument("--top", type=int, default=20)
    args = ap.parse_args()
    dev = args.device
    rng = np.random.default_rng(1)
    c = rng.uniform(0, 20, size=(args.n, 3))
    lowers = wp.array((c - 0.3).astype(np.float32), dtype=wp.vec3, device=dev)
    uppers = wp.array((c + 0.3).astype(np.float32), dtype=wp.vec3, device=dev)
    pts, tris = grid_mesh(args.n)
    points = wp.array(pts, dtype=wp.vec3, device=dev)
    indices = wp.array(tris, dtype=wp.int32, device=dev)
    makers = {"Bvh": lambda: wp.Bvh(lowers, uppers),
              "Mesh": lambda: wp.Mesh(points=points, indices=indices)}
    for name, make in makers.items():
        steps = {"construct": [], "synchronize": [], "free": []}
        obj = make()
        wp.synchronize_device(dev)
        for _ in range(20):
            t0 = time.perf_counter()
            new = make()
            t1 = time.perf_counter()
            wp.synchronize_device(dev)
            t2 = time.perf_counter()
            obj = None   # the last reference: freed here
            t3 = time.perf_counter()
            obj = new
            steps["construct"].append(t1 - t0)
            steps["synchronize"].append(t2 - t1)
            steps["free"].append(t3 - t2)
        line = ", ".join(f"{k} {statistics.median(v) * 1e6:.1f} us" for k, v in steps.items())
        print(f"{name} ({args.n:,} items on {dev}): {line}")
        prof = cProfile.Profile()
        prof.enable()
        for _ in range(10):
            obj = make()
            wp.synchronize_device(dev)
        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(args.top)
        obj = None


if __name__ == "__main__":
    main()
