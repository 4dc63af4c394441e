"""What the loops' cancellation poll costs: kernels whose time is spent in loops (a tight
scalar recurrence, a nested loop, a `while` loop) compiled twice by one weftd started with
--allow-unchecked, once as is (every loop polls the launch's cancel word: a counter test per
iteration and a load every 1024th) and once with
wp.set_module_options({"cancel_poll": False}, module), timed on the CPU (median of launch +
synchronize over interleaved rounds). Each result is checked against a float64 NumPy
reference, and the two modules' outputs must be identical. Prints a table; exit status 1 when
a check fails. Timing is reported, never asserted.

    .venv/bin/python bench/bench_cancel_poll.py [--threads 4096] [--iters 20000] [--repeat 5]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO_ROOT / "clients" / "python"))

import bench_common as bc  # noqa: E402

SOURCE = '''
@wp.kernel
def recurrence(x: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    v = x[i]
    for k in range(n):
        v = v * 0.999 + 0.001
    out[i] = v

@wp.kernel
def nested(x: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    s = float(0.0)
    for a in range(n // 100):
        for b in range(100):
            s = s + x[i] * 0.5
    out[i] = s

@wp.kernel
def countdown(x: wp.array(dtype=float), n: int, out: wp.array(dtype=float)):
    i = wp.tid()
    k = int(n)
    v = x[i]
    while k > 0:
        v = v * 0.999 + 0.001
        k = k - 1
    out[i] = v
'''


def references(xs: np.ndarray, n: int) -> dict:
    x = xs.astype(np.float64)
    a, b = 0.999, 0.001
    fixed = b / (1 - a)
    rec = fixed + (x - fixed) * a ** n                    # closed form of v = a v + b, n times
    return {"recurrence": rec, "countdown": rec, "nested": x * 0.5 * (n // 100) * 100}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--threads", type=int, default=4096)
    ap.add_argument("--iters", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    daemon = bc.BenchDaemon(["--allow-unchecked"])
    os.environ["WEFT_ADDRESS"] = daemon.address
    os.environ["WEFT_UNCHECKED"] = "1"   # an unchecked session (in a process of its own)
    failures, rows = [], []
    try:
        import weft as wp  # noqa: PLC0415

        wp.init()
        polled = bc.load_kernels(SOURCE, "weft", "poll_on")
        unpolled = bc.load_kernels(SOURCE, "weft", "poll_off")
        wp.set_module_options({"cancel_poll": False}, unpolled)
        wp.load_module(polled, device="cpu")
        wp.load_module(unpolled, device="cpu")
        xs = np.random.default_rng(7).uniform(0.5, 1.5, args.threads).astype(np.float32)
        x = wp.array(xs, dtype=float, device="cpu")
        refs = references(xs, args.iters)
        for name in ("recurrence", "nested", "countdown"):
            runs, outs = {}, {}
            for label, module in (("poll", polled), ("no poll", unpolled)):
                out = wp.zeros(args.threads, dtype=float, device="cpu")
                kernel = getattr(module, name)

                def run(kernel=kernel, out=out):
                    wp.launch(kernel, dim=args.threads, inputs=[x, args.iters, out], device="cpu")
                    wp.synchronize()

                run()
                outs[label] = out.numpy().copy()
                runs[label] = run
            samples = {"poll": [], "no poll": []}
            for r in range(args.repeat):
                order = ("poll", "no poll") if r % 2 == 0 else ("no poll", "poll")
                for label in order:
                    samples[label].append(bc.median_time(runs[label], repeat=3))
            t = {k: statistics.median(v) for k, v in samples.items()}
            ref = refs[name]
            err = max(float(np.max(np.abs(o.astype(np.float64) - ref)) / np.max(np.abs(ref)))
                      for o in outs.values())
            if not err < 1e-3:
                failures.append(f"{name}: normwise error {err:.1e} >= 1e-3")
            if not np.array_equal(outs["poll"], outs["no poll"]):
                failures.append(f"{name}: results with and without the poll differ")
            iterations = args.threads * args.iters
            rows.append([name, f"{iterations:.1e}", bc.fmt_time(t["poll"]), bc.fmt_time(t["no poll"]),
                         f"{(t['poll'] / t['no poll'] - 1) * 100:+.1f}%",
                         f"{t['poll'] / iterations * 1e9:.2f} ns", f"{err:.1e}"])
    finally:
        code, _ = daemon.stop(keep=bool(failures))
    if code != 0:
        failures.append(f"weftd exited with {code}")
    bc.print_table(f"Loop cancellation poll on vs off (CPU, {args.threads} threads x {args.iters} "
                   f"iterations, median of launch + synchronize, {os.cpu_count()} CPUs, "
                   f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})",
                   ["kernel", "loop iterations", "poll", "no poll", "overhead", "per iteration",
                    "max err vs f64"], rows)
    if failures:
        print("\nFAILED:\n  " + "\n  ".join(failures))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
