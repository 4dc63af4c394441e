"""CUDA activity timing (wp.timing_begin / timing_end) in weft next to warp-lang on the same GPU
in the same run.

Rows (each for weft and Warp, the same kernel source, cuda:0):
- empty launch, batched (N launches, one synchronize), with timing off and with TIMING_ALL on:
  the cost of timing per launch (weft records two CUDA events per launch on the session's
  stream; Warp records its own per-activity events);
- saxpy at 1e7 elements: the kernel time the timing results report (median of R launches) and
  the host's time per launch for R launches between two synchronizes (the GPU-bound rate);
- saxpy at 1e7 between timed events (wp.Event(enable_timing=True)): R iterations of record,
  launch, record, then the R elapsed times read: the host's time per iteration (weft records
  without waiting) and the median event time against the activity timing's kernel time;
- error: saxpy's result against a float64 reference (max relative error), and whether each
  library returned exactly one result per timed launch.
The table is printed last. Usage: python3 bench/bench_activity_timing.py [--launches 2000]
[--repeat 5] (WEFT_DAEMON: the weftd to start; warp-lang imported from PYTHONPATH).
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
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import bench_common as bc  # noqa: E402

SOURCE = '''
@wp.kernel
def empty_kernel():
    pass

@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]
'''


def launches(lib, mod, n: int, timed: bool) -> tuple[float, int]:
    """Seconds per launch of n empty launches and one synchronize; the results' count."""
    lib.launch(mod.empty_kernel, dim=1, device="cuda:0")
    lib.synchronize()
    if timed:
        lib.timing_begin(lib.TIMING_ALL)
    t = time.perf_counter()
    for _ in range(n):
        lib.launch(mod.empty_kernel, dim=1, device="cuda:0")
    count = len(lib.timing_end()) if timed else 0
    if not timed:
        lib.synchronize()
    return (time.perf_counter() - t) / n, count


def saxpy_rows(lib, mod, n: int, repeat: int, x0: np.ndarray, y0: np.ndarray):
    x = lib.array(x0, dtype=float, device="cuda:0")
    y = lib.array(y0, dtype=float, device="cuda:0")
    lib.launch(mod.saxpy, dim=n, inputs=[x, y, 2.0], device="cuda:0")   # warm (load)
    lib.synchronize()
    lib.timing_begin(lib.TIMING_KERNEL)
    t = time.perf_counter()
    for _ in range(repeat):
        lib.launch(mod.saxpy, dim=n, inputs=[x, y, 2.0], device="cuda:0")
    results = lib.timing_end()
    host = (time.perf_counter() - t) / repeat
    kernel_ms = statistics.median(r.elapsed for r in results) if results else None
    ref = y0.astype(np.float64) + (repeat + 1) * 2.0 * x0.astype(np.float64)
    got = y.numpy().astype(np.float64)
    # Relative to the terms' magnitude: where y and a*x cancel, float32 keeps only that much.
    scale = np.abs(y0.astype(np.float64)) + (repeat + 1) * 2.0 * np.abs(x0.astype(np.float64))
    err = float(np.max(np.abs(got - ref) / np.maximum(scale, 1e-30)))
    return kernel_ms / 1e3 if kernel_ms is not None else None, host, err, len(results) == repeat


def event_rows(lib, mod, n: int, repeat: int, x0: np.ndarray, y0: np.ndarray):
    """Host seconds per iteration of record / launch / record, and the median event time (s)."""
    x = lib.array(x0, dtype=float, device="cuda:0")
    y = lib.array(y0, dtype=float, device="cuda:0")
    lib.launch(mod.saxpy, dim=n, inputs=[x, y, 2.0], device="cuda:0")
    lib.synchronize()
    pairs = [(lib.Event("cuda:0", enable_timing=True), lib.Event("cuda:0", enable_timing=True))
             for _ in range(repeat)]
    t = time.perf_counter()
    for start, end in pairs:
        lib.record_event(start)
        lib.launch(mod.saxpy, dim=n, inputs=[x, y, 2.0], device="cuda:0")
        lib.record_event(end)
    host = (time.perf_counter() - t) / repeat
    elapsed = [lib.get_event_elapsed_time(start, end) for start, end in pairs]
    return host, statistics.median(elapsed) / 1e3


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--launches", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--size", type=float, default=1e7)
    args = parser.parse_args()
    n = int(args.size)
    rng = np.random.default_rng(int.from_bytes(os.urandom(4), "little"))
    # Hard inputs: magnitudes over 12 decades, mixed signs.
    x0 = (rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 6, n)).astype(np.float32)
    y0 = (rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 6, n)).astype(np.float32)

    daemon = bc.BenchDaemon()
    os.environ["WEFT_ADDRESS"] = daemon.address
    notes, results = [], {}
    try:
        import weft  # noqa: PLC0415

        weft.init()
        if not weft.is_cuda_available():
            raise SystemExit("weftd has no CUDA device: nothing to time")
        libs = [("weft", weft)]
        warp = bc.import_warp()
        if warp is not None:
            libs.append(("warp", warp))
            notes.append(f"warp-lang {warp.config.version}")
        for name, lib in libs:
            mod = bc.load_kernels(SOURCE, lib.__name__, "timing")
            r = results[name] = {}
            off = [launches(lib, mod, args.launches, False)[0] for _ in range(args.repeat)]
            on = [launches(lib, mod, args.launches, True) for _ in range(args.repeat)]
            r["off"] = statistics.median(off)
            r["on"] = statistics.median(t for t, _ in on)
            r["count_ok"] = all(c == args.launches for _, c in on)
            r["kernel"], r["host"], r["err"], r["saxpy_count_ok"] = saxpy_rows(lib, mod, n, 20, x0, y0)
            r["event_host"], r["event_time"] = event_rows(lib, mod, n, 20, x0, y0)
            print(f"{name}: done", flush=True)
    finally:
        daemon.stop()

    def row(label, key):
        a = results.get("weft", {}).get(key)
        b = results.get("warp", {}).get(key)
        return [label, bc.fmt_time(a), bc.fmt_time(b), bc.fmt_ratio(a, b)]

    rows = [row(f"empty launch batched x{args.launches}, timing off", "off"),
            row(f"empty launch batched x{args.launches}, TIMING_ALL on", "on"),
            row(f"saxpy {n:.0e}: kernel time from timing_end (median of 20)", "kernel"),
            row(f"saxpy {n:.0e}: host time per launch, 20 between syncs", "host"),
            row(f"saxpy {n:.0e} between timed events: host time per iteration (x20)", "event_host"),
            row(f"saxpy {n:.0e} between timed events: event time (median of 20)", "event_time")]
    for name in results:
        r = results[name]
        notes.append(f"{name}: timing cost per launch {(r['on'] - r['off']) * 1e6:.2f} us; one result per "
                     f"launch: {r['count_ok'] and r['saxpy_count_ok']}; saxpy max error vs float64 (relative to |y| + |sum of a*x|) "
                     f"{r['err']:.1e}")
    for note in notes:
        print(note)
    bc.print_table("CUDA activity timing on cuda:0 (ratio = Warp time / weft time; >= 1.0: weft as fast "
                   "or faster)", ["case", "weft", "warp-lang", "ratio"], rows)


if __name__ == "__main__":
    main()
