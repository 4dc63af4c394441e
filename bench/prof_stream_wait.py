"""How weftd's wait for a GPU stream at a synchronize affects rounds of launches: the same
client work against four daemons, one per wait mode (WEFT_STREAM_WAIT=poll: poll, then 100 us
sleeps; WEFT_STREAM_SPIN_US=1000: poll for 1 ms, then block until a host function queued on the
stream signals; default: the same after 20 ms of polling; engine/device/cuda_device.cpp
WaitStream), and
the default with the client holding large GPU launches for a batch (WEFT_START_GPU_THREADS=0).

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

from bench_cuda import SOURCE, reps_for, saxpy_inputs  # noqa: E402  (its kernels and rounds)


def client(sizes: list[int]) -> None:
    import bench_common as bc  # noqa: PLC0415
    import weft as wp  # noqa: PLC0415

    wp.init()
    mod = bc.load_kernels(SOURCE, "weft", "prof_sw")
    dev = "cuda:0"

    calls: dict = {}

    def round_time(fn, reps: int) -> float:
        wp.synchronize()
        t = time.perf_counter()
        for _ in range(reps):
            fn()
        t1 = time.perf_counter()
        wp.synchronize()
        t2 = time.perf_counter()
        calls.setdefault(reps, []).append(((t1 - t) / reps, t2 - t1))
        return t2 - t

    for n in sizes:
        x, y, _, _, err = saxpy_inputs(wp, mod, n, dev, 1.7)

        def saxpy():
            wp.launch(mod.saxpy, dim=n, inputs=[x, y, 1.7], device=dev)
        r = reps_for(n)
        short = min(round_time(saxpy, r) for _ in range(5))
        long = min(round_time(saxpy, 4 * r) for _ in range(5))
        slope = (long - short) / (3 * r)
        intercept = short - slope * r
        print(f"ROW saxpy {n:.0e} R={r}: {short / r * 1e6:.1f} us per launch; slope {slope * 1e6:.1f} us, "
              f"per-round cost {intercept * 1e6:.1f} us; rel. error {err:.1e}", flush=True)
        for reps in (r, 4 * r):
            launch_s, sync_s = min(calls[reps], key=lambda c: c[0] * reps + c[1])
            print(f"  {n:.0e} R={reps}: wp.launch {launch_s * 1e6:.1f} us each, then wp.synchronize "
                  f"{sync_s * 1e6:.1f} us", flush=True)
        calls.clear()
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
    # (name, daemon environment, client environment)
    modes = [("poll", {"WEFT_STREAM_WAIT": "poll"}, {}),
             ("signal", {"WEFT_STREAM_SPIN_US": "1000"}, {}),
             ("spin 20 ms", {}, {}),
             ("held", {}, {"WEFT_START_GPU_THREADS": "0"})]
    for mode, daemon_env, client_env in modes:
        trace = Path(tempfile.mkdtemp(prefix="weft-stream-wait-")) / "lane.txt"
        os.environ["WEFT_LANE_TRACE"] = str(trace)
        for key in ("WEFT_STREAM_WAIT", "WEFT_STREAM_SPIN_US", "WEFT_START_GPU_THREADS"):
            os.environ.pop(key, None)
        os.environ.update(daemon_env)
        daemon = bc.BenchDaemon()
        env = dict(os.environ, WEFT_ADDRESS=daemon.address, **client_env)
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
    print("\n| case | WEFT_STREAM_WAIT=poll | WEFT_STREAM_SPIN_US=1000 (signalled after 1 ms) | default (polls 20 ms) | "
          "default, client holds large launches (WEFT_START_GPU_THREADS=0) |\n| --- | --- | --- | --- | --- |")
    for a, b, c, d in zip(*(rows.get(m[0], []) for m in modes)):
        cells = [x.partition(":")[2].strip() for x in (a, b, c, d)]
        print(f"| {a.partition(':')[0]} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
