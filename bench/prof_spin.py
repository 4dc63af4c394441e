"""How long the Python client polls for the reply of a synchronize that waits for GPU work
(WEFT_FAST_LANE_GPU_SPIN_US; 0: the 100 us of WEFT_FAST_LANE_SPIN_US) against GPU launch costs, measured A/B: child clients of one weftd, the settings alternating over
--rounds rounds so that a drift of the machine shows in both columns.

Each child measures, per launch: an empty kernel launched and synchronized each time, an empty
kernel batched (N launches, one synchronize), saxpy 1e6 batched, and saxpy 1e8 in rounds of 5
launches + one synchronize (best round); saxpy's result is checked against a float64
reference. Prints the median over rounds of each setting.
Usage: python3 bench/prof_spin.py [--spins 0,20000] [--var WEFT_FAST_LANE_GPU_SPIN_US] [--rounds 3] [--device cuda:0] [--small]
(starts its own weftd)."""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_common as bc  # noqa: E402

KERNELS = '''
import weft as wp


@wp.kernel
def empty_kernel():
    pass


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]
'''

CHILD = '''
import sys, time
import numpy as np
sys.path.insert(0, {client!r})
sys.path.insert(0, {kdir!r})
import weft as wp
from spin_kernels import empty_kernel, saxpy
dev = {device!r}
def per(fn, reps):
    wp.synchronize(); t = time.perf_counter(); fn(reps); wp.synchronize()
    return (time.perf_counter() - t) / reps
def sync_each(r):
    for _ in range(r):
        wp.launch(empty_kernel, dim=1, device=dev); wp.synchronize()
def batched(r):
    for _ in range(r):
        wp.launch(empty_kernel, dim=1, device=dev)
out = {{}}
for _ in range(2):       # warm-up included: the better pass counts
    out["empty, sync each"] = min(out.get("empty, sync each", 1e9), per(sync_each, 1000))
    out["empty, batched"] = min(out.get("empty, batched", 1e9), per(batched, 2000))
rng = np.random.default_rng()
err = 0.0
for n, reps, rounds in {sizes!r}:
    x0 = rng.standard_normal(n).astype(np.float32); y0 = rng.standard_normal(n).astype(np.float32)
    x = wp.array(x0, dtype=float, device=dev); y = wp.array(y0, dtype=float, device=dev)
    wp.launch(saxpy, dim=n, inputs=[x, y, 1.5], device=dev)
    ref = 1.5 * x0.astype(np.float64) + y0
    got = y.numpy().astype(np.float64)
    err = max(err, float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1e-3))))
    best = 1e9
    for _ in range(rounds):
        def run(r):
            for _ in range(r):
                wp.launch(saxpy, dim=n, inputs=[x, y, 1.5], device=dev)
        best = min(best, per(run, reps))
    out[f"saxpy {{n:.0e}}"] = best
    del x, y
for k, v in out.items():
    print("ROW", k, "|", v)
print("ERR", err)
'''


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--spins", default="0,20000")
    ap.add_argument("--var", default="WEFT_FAST_LANE_GPU_SPIN_US")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--small", action="store_true", help="saxpy 1e4 and 1e6 only (a quick check)")
    args = ap.parse_args()
    spins = [s.strip() for s in args.spins.split(",")]
    kdir = tempfile.mkdtemp(prefix="spin-kernels-")
    Path(kdir, "spin_kernels.py").write_text(KERNELS)
    sizes = (((10_000, 50, 2), (1_000_000, 5, 2)) if args.small
             else ((1_000_000, 500, 3), (100_000_000, 5, 5)))
    code = CHILD.format(client=str(HERE.parent / "clients" / "python"), kdir=kdir,
                        device=args.device, sizes=sizes)
    results: dict = {s: {} for s in spins}
    errors = []
    daemon = bc.BenchDaemon()
    try:
        for r in range(args.rounds):
            for s in spins:
                env = dict(os.environ, WEFT_ADDRESS=daemon.address, **{args.var: s})
                proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                                      text=True, timeout=600)
                if proc.returncode:
                    print(f"(round {r}, spin {s}: child failed: {proc.stderr[-800:]})")
                    continue
                for line in proc.stdout.splitlines():
                    if line.startswith("ROW "):
                        name, value = line[4:].rsplit("|", 1)
                        results[s].setdefault(name.strip(), []).append(float(value))
                    elif line.startswith("ERR "):
                        errors.append(float(line[4:]))
    finally:
        daemon.stop()
    names = list(next(iter(results.values())).keys())
    print(f"\nper launch, median of {args.rounds} alternating rounds "
          f"({args.var}; saxpy max rel. error vs float64: {max(errors or [0]):.1e})")
    print(f"{'case':>18}  " + "  ".join(f"{'spin ' + s + ' us':>16}" for s in spins))
    for name in names:
        cells = [f"{statistics.median(results[s][name]) * 1e6:>13.1f} us" if results[s].get(name)
                 else f"{'n/a':>16}" for s in spins]
        print(f"{name:>18}  " + "  ".join(cells))


if __name__ == "__main__":
    main()
