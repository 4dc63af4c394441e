"""Device time of a hash grid build apart from the round trips: R builds queued back to back and
one synchronize, per build (weft, and warp-lang beside it when importable), against one build +
synchronize. Usage: WEFT_DAEMON=... python3 bench/prof_hash_grid_build.py [--device cuda:0] [-r 20]
[--sizes 1e4,1e6,4e6] [--single K: only K build + synchronize pairs per size, one process each
size under WEFT_LANE_TRACE shows weftd's phases of that case]"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))
sys.path.insert(0, str(HERE))

import bench_common as bc  # noqa: E402


def per_build(lib, device, n, repeats):
    rng = np.random.default_rng(2)
    side = np.cbrt(n / 8.0)
    pts = lib.array(rng.uniform(0.0, side, size=(n, 3)).astype(np.float32), dtype=lib.vec3, device=device)
    grid = lib.HashGrid(128, 128, 128, device=device)
    grid.build(pts, 1.0)
    lib.synchronize_device(device)
    batched, single = [], []
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(repeats):
            grid.build(pts, 1.0)
        lib.synchronize_device(device)
        batched.append((time.perf_counter() - t) / repeats)
        t = time.perf_counter()
        grid.build(pts, 1.0)
        lib.synchronize_device(device)
        single.append(time.perf_counter() - t)
    return statistics.median(batched), statistics.median(single)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cpu")
    ap.add_argument("-r", type=int, default=20)
    ap.add_argument("--sizes", default="1e4,1e6,4e6", help="point counts, comma-separated")
    ap.add_argument("--single", type=int, default=0,
                    help="only time this many build + synchronize pairs per size (weft; with "
                         "WEFT_LANE_TRACE set, weftd's per-frame phases of exactly that case)")
    args = ap.parse_args()
    import weft
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    if args.single:
        for n in sizes:
            rng = np.random.default_rng(2)
            pts = weft.array(rng.uniform(0.0, np.cbrt(n / 8.0), size=(n, 3)).astype(np.float32),
                             dtype=weft.vec3, device=args.device)
            grid = weft.HashGrid(128, 128, 128, device=args.device)
            times = []
            for _ in range(args.single):
                t = time.perf_counter()
                grid.build(pts, 1.0)
                weft.synchronize_device(args.device)
                times.append(time.perf_counter() - t)
            print(f"{n:>9,} points: weft build + sync {statistics.median(times) * 1e6:8.1f} us "
                  f"(median of {args.single})", flush=True)
        return
    warp = bc.import_warp()
    for n in sizes:
        wb, ws = per_build(weft, args.device, n, args.r)
        line = f"{n:>9,} points: weft {wb * 1e6:8.1f} us a build queued, {ws * 1e6:8.1f} us build + sync"
        if warp is not None:
            xb, xs = per_build(warp, args.device, n, args.r)
            line += f" | warp {xb * 1e6:8.1f} us queued, {xs * 1e6:8.1f} us build + sync"
        print(line, flush=True)


if __name__ == "__main__":
    main()
