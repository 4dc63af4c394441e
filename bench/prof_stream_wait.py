"""How weftd's wait for a GPU stream at a synchronize affects rounds of launches: the same
client work against two daemons, one per wait mode (WEFT_STREAM_WAIT=poll: poll, then 100 us
sleeps; default: poll for WEFT_STREAM_SPIN_US, then block until a host function queued on the
stream signals; engine/device/cuda_device.cpp WaitStream).

Per mode and size: saxpy, R launches then one synchronize (R as bench/bench_cuda.py picks it:
5 at 1e8), best of 5 rounds, time per launch; the same round's slope between R and 4R (the
kernel's own time) and the intercept (per-round cost outside the kernels); an empty launch +
synchronize each. Then the daemons' fast-lane traces (WEFT_LANE_TRACE: stream_wait medians and
how many frames blocked) and how long this machine's 100 us sleep really takes.
Usage (GPU machine, WEFT_DAEMON set): python3 bench/prof_stream_wait.py [--sizes 1e6,1e7,1e8]"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

SOURCE = '''
@wp.kernel
def empty_kernel():
    pass

@wp.kernel
def init_random(x: wp.array(dtype=float), seed: int, scale: float):
    i = wp.tid()
    state = wp.rand_init(seed, i)
    x[i] = (wp.randf(state) - 0.5) * scale

@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]
'''


def reps_for(n: int) -> int:
    return max(5, min(200, int(2e9 // (n * 12))))


def client(sizes: list[int]) -> None:
    import numpy as np  # noqa: PLC0415

    import bench_common as bc  # noqa: PLC0415
    import weft as wp  # noqa: PLC0415

    wp.init()
    mod = bc.load_kernels(SOURCE, "weft", "prof_sw")
    dev = "cuda:0"

    def round_time(fn, reps: int) -> float:
        wp.synchronize()
        t = time.perf_counter()
        for _ in range(reps):
            fn()
        wp.synchronize()
        return time.perf_counter() - t

    for n in sizes:
        x = wp.empty(n, dtype=float, device=dev)
        y = wp.empty(n, dtype=float, device=dev)
        wp.launch(mod.init_random, dim=n, inputs=[x, 1, 4.0], device=dev)
        wp.launch(mod.init_random, dim=n, inputs=[y, 2, 4.0], device=dev)
        m = min(n, 1_000_000)
        x0 = x[:m].numpy().astype(np.float64)
        y0 = y[:m].numpy().astype(np.float64)
        wp.launch(mod.saxpy, dim=n, inputs=[x, y, 1.7], device=dev)
        ref = 1.7 * x0 + y0
        got = y[:m].numpy().astype(np.float64)
        err = float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1e-3)))

        def saxpy():
            wp.launch(mod.saxpy, dim=n, inputs=[x, y, 1.7], device=dev)
        r = reps_for(n)
        short = min(round_time(saxpy, r) for _ in range(5))
        long = min(round_time(saxpy, 4 * r) for _ in range(5))
        slope = (long - short) / (3 * r)
        intercept = short - slope * r
        print(f"ROW saxpy {n:.0e} R={r}: {short / r * 1e6:.1f} us per launch; slope {slope * 1e6:.1f} us, "
              f"per-round cost {intercept * 1e6:.1f} us; rel. error {err:.1e}", flush=True)
        del x, y

    def empty_sync():
        wp.launch(mod.empty_kernel, dim=1, device=dev)
        wp.synchronize()
    empty_sync()
    t = statistics.median(round_time(empty_sync, 200) / 200 for _ in range(5))
    print(f"ROW empty launch + sync each: {t * 1e6:.1f} us", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="1e6,1e7,1e8")
    ap.add_argument("--client", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    if args.client:
        client(sizes)
        return
    import bench_common as bc  # noqa: PLC0415

    rows: dict = {}
    traces = {}
    for mode in ("poll", "signal"):
        trace = Path(tempfile.mkdtemp(prefix="weft-stream-wait-")) / "lane.txt"
        os.environ["WEFT_LANE_TRACE"] = str(trace)
        if mode == "poll":
            os.environ["WEFT_STREAM_WAIT"] = "poll"
        else:
            os.environ.pop("WEFT_STREAM_WAIT", None)
        daemon = bc.BenchDaemon()
        env = dict(os.environ, WEFT_ADDRESS=daemon.address)
        try:
            out = subprocess.run([sys.executable, __file__, "--client", "--sizes", args.sizes],
                                 env=env, capture_output=True, text=True, cwd=HERE, timeout=400)
            print(f"[{mode}] " + out.stdout + out.stderr[-2000:], flush=True)
            rows[mode] = [line[4:] for line in out.stdout.splitlines() if line.startswith("ROW ")]
        finally:
            daemon.stop()
        traces[mode] = trace.read_text() if trace.exists() else "(no trace written)"
    sleeps = []
    for _ in range(200):
        t = time.perf_counter()
        time.sleep(100e-6)
        sleeps.append(time.perf_counter() - t)
    print("\nweftd's fast-lane frames per mode (medians):")
    for mode, text in traces.items():
        print(f"[{mode}]\n{text}")
    print(f"a 100 us sleep here takes {statistics.median(sleeps) * 1e6:.0f} us (median of 200; "
          f"max {max(sleeps) * 1e6:.0f} us)")
    print("\n| case | WEFT_STREAM_WAIT=poll | signalled wait (default) |\n| --- | --- | --- |")
    for a, b in zip(rows.get("poll", []), rows.get("signal", [])):
        name, _, va = a.partition(":")
        _, _, vb = b.partition(":")
        print(f"| {name} | {va.strip()} | {vb.strip()} |")


if __name__ == "__main__":
    main()
