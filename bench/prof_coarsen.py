"""Coarsened CUDA entries on and off (docs/cuda.md "Coarsened launches"): memory-bound 1-D
kernels that load 4 to 24 bytes per thread at wp.tid(), each timed against one weftd started
with WEFT_COARSEN=0 and one that takes every kernel's coarsened entry
(WEFT_COARSEN_MAX_LOADED_BYTES=1024, so the table shows where the default limit on loaded bytes
belongs), in child clients of their own. Per kernel and size: time per launch (best of 5 rounds
of R launches + one synchronize), the rate of the bytes the kernel must move, the max relative
error of the first 1e6 results against float64, and the ratio (time off / time on: > 1.0 means
the coarsened entry is faster). Launches below the threshold (CoarsenMinThreads) run the plain
entry both times.
Usage: python3 bench/prof_coarsen.py [--sizes 1e7,1e8]   (WEFT_DAEMON: the weftd)"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

SOURCE = '''
@wp.kernel(grid_stride=False)
def scale(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = 2.0 * x[i]

@wp.kernel(grid_stride=False)
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]

@wp.kernel(grid_stride=False)
def sum3(x: wp.array(dtype=float), y: wp.array(dtype=float), z: wp.array(dtype=float),
         out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = x[i] + y[i] + z[i]

@wp.kernel(grid_stride=False)
def daxpy(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64), a: wp.float64):
    i = wp.tid()
    y[i] = a * x[i] + y[i]

@wp.kernel(grid_stride=False)
def vec4_scale(v: wp.array(dtype=wp.vec4), out: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    out[i] = v[i] * 2.0

@wp.kernel(grid_stride=False)
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), g: wp.vec3, dt: float):
    i = wp.tid()
    vi = v[i] + g * dt
    v[i] = vi
    x[i] = x[i] + vi * dt
'''

# name: (bytes loaded per thread at wp.tid(), bytes moved per thread)
KERNELS = {"scale": (4, 8), "saxpy": (8, 12), "sum3": (12, 16), "daxpy": (16, 24),
           "vec4_scale": (16, 32), "integrate": (24, 48)}


def client(sizes: list[int]) -> None:
    import numpy as np  # noqa: PLC0415

    import bench_common as bc  # noqa: PLC0415
    import weft as wp  # noqa: PLC0415

    wp.init()
    mod = bc.load_kernels(SOURCE, "weft", "prof_coarsen")
    dev = "cuda:0"
    rng = np.random.default_rng(7)
    results = {}
    import time  # noqa: PLC0415

    for n in sizes:
        m = min(n, 1_000_000)
        reps = 20 if n >= 50_000_000 else 100
        f = lambda *shape: rng.standard_normal(shape).astype(np.float32)  # noqa: E731
        x0, y0, z0 = f(n), f(n), f(n)
        x, y, z = (wp.array(a, dtype=float, device=dev) for a in (x0, y0, z0))
        out = wp.empty(n, dtype=float, device=dev)
        cases = {
            "scale": (lambda: wp.launch(mod.scale, dim=n, inputs=[x, out], device=dev),
                      lambda: (out, 2.0 * x0[:m].astype(np.float64))),
            "sum3": (lambda: wp.launch(mod.sum3, dim=n, inputs=[x, y, z, out], device=dev),
                     lambda: (out, x0[:m].astype(np.float64) + y0[:m] + z0[:m])),
            "saxpy": (lambda: wp.launch(mod.saxpy, dim=n, inputs=[x, y, 1.0], device=dev), None),
        }
        for name, (launch, check) in cases.items():
            if name == "saxpy":      # y changes with every launch: checked after one launch
                y.assign(y0)
                launch()
                err = float(np.max(np.abs(y[:m].numpy() - (x0[:m].astype(np.float64) + y0[:m])) /
                                   np.maximum(np.abs(x0[:m].astype(np.float64) + y0[:m]), 1e-3)))
            else:
                launch()
                arr, ref = check()
                err = float(np.max(np.abs(arr[:m].numpy() - ref) / np.maximum(np.abs(ref), 1e-3)))
            results[f"{name} {n:.0e}"] = (best(wp, launch, reps, time), err)
        del x, y, z, out
        xd0 = rng.standard_normal(n)
        yd0 = rng.standard_normal(n)
        xd = wp.array(xd0, dtype=wp.float64, device=dev)
        yd = wp.array(yd0, dtype=wp.float64, device=dev)
        launch = lambda: wp.launch(mod.daxpy, dim=n, inputs=[xd, yd, 1.0], device=dev)  # noqa: E731
        launch()
        err = float(np.max(np.abs(yd[:m].numpy() - (xd0[:m] + yd0[:m])) / np.maximum(np.abs(xd0[:m] + yd0[:m]), 1e-3)))
        results[f"daxpy {n:.0e}"] = (best(wp, launch, reps, time), err)
        del xd, yd
        v0 = f(n, 4)
        v = wp.array(v0, dtype=wp.vec4, device=dev)
        vo = wp.empty(n, dtype=wp.vec4, device=dev)
        launch = lambda: wp.launch(mod.vec4_scale, dim=n, inputs=[v, vo], device=dev)  # noqa: E731
        launch()
        ref = 2.0 * v0[:m].astype(np.float64)
        err = float(np.max(np.abs(vo[:m].numpy() - ref) / np.maximum(np.abs(ref), 1e-3)))
        results[f"vec4_scale {n:.0e}"] = (best(wp, launch, reps, time), err)
        del v, vo
        p0, q0 = f(n, 3), f(n, 3)
        p = wp.array(p0, dtype=wp.vec3, device=dev)
        q = wp.array(q0, dtype=wp.vec3, device=dev)
        g, dt = wp.vec3(0.0, -9.8, 0.0), 1.0 / 60.0
        launch = lambda: wp.launch(mod.integrate, dim=n, inputs=[p, q, g, dt], device=dev)  # noqa: E731
        launch()
        d = np.float64(np.float32(dt))
        vr = q0[:m].astype(np.float64) + np.array([0.0, np.float32(-9.8), 0.0]) * d
        xr = p0[:m].astype(np.float64) + vr * d
        err = float(np.max(np.abs(p[:m].numpy() - xr) / np.maximum(np.abs(xr), 1e-3)))
        results[f"integrate {n:.0e}"] = (best(wp, launch, reps, time), err)
        del p, q
        wp.synchronize()
    print("RESULT " + json.dumps(results), flush=True)


def best(wp, launch, reps, time) -> float:
    times = []
    for _ in range(5):
        wp.synchronize()
        t0 = time.perf_counter()
        for _ in range(reps):
            launch()
        wp.synchronize()
        times.append((time.perf_counter() - t0) / reps)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="1e7,1e8")
    parser.add_argument("--client", action="store_true")
    args = parser.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    if args.client:
        client(sizes)
        return
    import bench_common as bc  # noqa: PLC0415

    runs = {}
    for setting in ("0", "1"):
        os.environ["WEFT_COARSEN"] = setting          # read by the weftd started next
        os.environ.setdefault("WEFT_COARSEN_MAX_LOADED_BYTES", "1024")   # every kernel here
        daemon = bc.BenchDaemon()
        try:
            env = dict(os.environ, WEFT_ADDRESS=daemon.address)
            out = subprocess.run([sys.executable, __file__, "--client", "--sizes", args.sizes],
                                 env=env, capture_output=True, text=True, timeout=900)
            line = next((t for t in out.stdout.splitlines() if t.startswith("RESULT ")), None)
            if line is None:
                raise SystemExit(f"client failed:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}")
            runs[setting] = json.loads(line[len("RESULT "):])
        finally:
            daemon.stop()
    rows = []
    for key in runs["0"]:
        name = key.split()[0]
        loaded, moved = KERNELS[name]
        n = float(key.split()[1])
        off, err_off = runs["0"][key]
        on, err_on = runs["1"][key]
        rows.append([key, str(loaded), bc.fmt_time(off), f"{moved * n / off / 1e9:.0f} GB/s", bc.fmt_time(on),
                     f"{moved * n / on / 1e9:.0f} GB/s", f"{off / on:.2f}", f"{max(err_off, err_on):.1e}"])
    bc.print_table("coarsened entries off (WEFT_COARSEN=0) and on (default), cuda:0",
                   ["kernel n", "B loaded/thread", "off", "off rate", "on", "on rate", "off/on",
                    "max rel err vs float64"], rows)


if __name__ == "__main__":
    main()
