"""Where a grouped wp.Bvh build's time goes on a GPU: the build (synchronized, median of 7) of
the same 1,000,000 random boxes without groups and with 1, 64, 4096 and 1,000,000 groups, and
a rebuild() of each (no allocation: the object's buffers are reused).

    python bench/prof_grouped_bvh_build.py [--device cuda:0] [--n 1000000]
"""
from __future__ import annotations

import sys

import numpy as np

import bench_common as bc


def main():
    import weft as wp

    device = sys.argv[sys.argv.index("--device") + 1] if "--device" in sys.argv else "cuda:0"
    n = int(float(sys.argv[sys.argv.index("--n") + 1])) if "--n" in sys.argv else 1_000_000
    rng = np.random.default_rng(0)
    c = rng.uniform(0.0, np.cbrt(n) * 0.5, size=(n, 3))
    h = rng.uniform(0.05, 0.5, size=(n, 3))
    lowers = wp.array((c - h).astype(np.float32), dtype=wp.vec3, device=device)
    uppers = wp.array((c + h).astype(np.float32), dtype=wp.vec3, device=device)
    rows = []
    for groups in (None, 1, 64, 4096, n):
        garr = None if groups is None else wp.array(rng.integers(0, groups, size=n).astype(np.int32),
                                                     dtype=wp.int32, device=device)
        holder = {}

        def build():
            holder["bvh"] = wp.Bvh(lowers, uppers) if garr is None else wp.Bvh(lowers, uppers, groups=garr)
            wp.synchronize_device(device)

        build()
        t_build = bc.median_time(build, repeat=7)

        def rebuild():
            holder["bvh"].rebuild()
            wp.synchronize_device(device)

        rebuild()
        t_rebuild = bc.median_time(rebuild, repeat=7)
        rows.append(["none" if groups is None else f"{groups:,}", bc.fmt_time(t_build), bc.fmt_time(t_rebuild)])
    bc.print_table(f"wp.Bvh of {n:,} boxes on {device}: build and rebuild by number of groups",
                   ["groups", "build", "rebuild"], rows)


if __name__ == "__main__":
    main()
