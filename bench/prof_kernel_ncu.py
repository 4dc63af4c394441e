"""The saxpy and particle-integration kernels of bench/bench_cuda.py, a few launches each at one
size, for a hardware-counter profiler to compare weft's generated kernels with warp-lang's
(the same source under each library). Run it under Nsight Compute on the GPU machine:

    ncu --target-processes all --clock-control none -k 'regex:saxpy|integrate' \
        --metrics gpu__time_duration.sum,dram__bytes_read.sum,... \
        python3 bench/prof_kernel_ncu.py --lib weft --n 1e7

(--lib weft starts its own weftd, a child that ncu follows; --lib warp imports warp-lang.)
Prints the kernels' results' error against a float64 reference so a wrong kernel is not timed."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import bench_common as bc  # noqa: E402
import bench_cuda  # noqa: E402

# The kernels of bench/bench_cuda.py (saxpy, integrate), so both measure the same code.
SOURCE = bench_cuda.SOURCE


def run(lib, n: int, launches: int) -> None:
    mod = bc.load_kernels(SOURCE, lib.__name__, "ncu")
    rng = np.random.default_rng()
    dev = "cuda:0"
    x0 = rng.standard_normal(n).astype(np.float32)
    y0 = rng.standard_normal(n).astype(np.float32)
    x = lib.array(x0, dtype=float, device=dev)
    y = lib.array(y0, dtype=float, device=dev)
    for _ in range(launches):
        lib.launch(mod.saxpy, dim=n, inputs=[x, y, 2.0], device=dev)
    lib.synchronize()
    ref = y0.astype(np.float64)
    for _ in range(launches):
        ref = 2.0 * x0.astype(np.float64) + ref
    err = float(np.max(np.abs(y.numpy() - ref) / np.maximum(np.abs(ref), 1e-3)))
    del x, y
    p = lib.array(rng.standard_normal((n, 3)).astype(np.float32), dtype=lib.vec3, device=dev)
    v = lib.array(rng.standard_normal((n, 3)).astype(np.float32), dtype=lib.vec3, device=dev)
    g = lib.vec3(0.0, -9.8, 0.0)
    for _ in range(launches):
        lib.launch(mod.integrate, dim=n, inputs=[p, v, g, 0.01], device=dev)
    lib.synchronize()
    print(f"{lib.__name__}: n={n} saxpy x{launches} rel. error {err:.2e}; integrate x{launches} done")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--lib", choices=["weft", "warp"], default="weft")
    ap.add_argument("--n", type=float, default=1e7)
    ap.add_argument("--launches", type=int, default=3)
    args = ap.parse_args()
    if args.lib == "warp":
        lib = bc.import_warp()
        if lib is None:
            return
        run(lib, int(args.n), args.launches)
        return
    with bc.WeftSession() as (weft, _rt):
        run(weft, int(args.n), args.launches)


if __name__ == "__main__":
    main()
