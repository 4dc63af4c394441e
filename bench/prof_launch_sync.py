"""Where a launch + synchronize goes, split between the client and weftd: each case runs in its
own client process (its own session and fast lane) against one weftd started with
WEFT_LANE_TRACE, so the daemon's per-frame phases (docs/cuda.md "Tracing the fast lane") come
back one line per case. Per case the client prints the median time of the `wp.launch` call, of
the `wp.synchronize` call and of the pair, and of the fast lane's send and receive per frame
(the rest of the synchronize is the client's Python); with --profile, cProfile's top entries.

Cases: empty and 3-array launches + sync on `cpu` and on `cuda:0` (when present); saxpy 1e7 on
`cuda:0`, 32 launches then one sync, pipelined and batched at the sync (the launch call alone).
Usage: python3 bench/prof_launch_sync.py [--calls 2000] [--profile]   (WEFT_DAEMON: the weftd)"""
from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
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
def three_args(a: wp.array(dtype=float), b: wp.array(dtype=float), c: wp.array(dtype=float)):
    pass

@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]
'''


def client(case: str, calls: int, profile: bool) -> None:
    import bench_common as bc  # noqa: PLC0415
    import weft as wp  # noqa: PLC0415
    from weft import _runtime  # noqa: PLC0415

    wp.init()
    mod = bc.load_kernels(SOURCE, "weft", "prof_ls")
    kind, dev = case.split("@")
    rt = _runtime.get_runtime()
    launch_t, sync_t, pair_t = [], [], []
    # the fast lane's send (the system call) and receive (the wait for the reply, polling
    # included), timed inside the synchronize: what is left of it is the client's Python
    lane_t = {"send": [], "receive": []}
    lane = rt.fast_lane
    if lane is not None:
        for name in ("_send", "_receive"):
            original = getattr(lane, name)

            def timed(*a, _original=original, _out=lane_t[name[1:]], **k):
                t = time.perf_counter()
                try:
                    return _original(*a, **k)
                finally:
                    _out.append(time.perf_counter() - t)
            setattr(lane, name, timed)
    if kind in ("empty", "three"):
        arrays = [wp.zeros(16, dtype=float, device=dev) for _ in range(3)]

        def launch():
            if kind == "empty":
                wp.launch(mod.empty_kernel, dim=1, device=dev)
            else:
                wp.launch(mod.three_args, dim=1, inputs=arrays, device=dev)

        def body():
            t0 = time.perf_counter()
            launch()
            t1 = time.perf_counter()
            wp.synchronize()
            t2 = time.perf_counter()
            launch_t.append(t1 - t0)
            sync_t.append(t2 - t1)
            pair_t.append(t2 - t0)
        rounds = calls
    else:   # saxpy-pipelined / saxpy-batched: 32 launches, one sync
        rt.pipelined = kind == "saxpy-pipelined"
        n = 10_000_000
        x = wp.zeros(n, dtype=float, device=dev)
        y = wp.zeros(n, dtype=float, device=dev)

        def body():
            t0 = time.perf_counter()
            for _ in range(32):
                t = time.perf_counter()
                wp.launch(mod.saxpy, dim=n, inputs=[x, y, 2.0], device=dev)
                launch_t.append(time.perf_counter() - t)
            t1 = time.perf_counter()
            wp.synchronize()
            t2 = time.perf_counter()
            sync_t.append(t2 - t1)
            pair_t.append((t2 - t0) / 32)
        rounds = max(10, calls // 100)
    for _ in range(min(50, rounds)):
        body()
    launch_t.clear(), sync_t.clear(), pair_t.clear()
    lane_t["send"].clear(), lane_t["receive"].clear()
    prof = cProfile.Profile() if profile else None
    if prof:
        prof.enable()
    for _ in range(rounds):
        body()
    if prof:
        prof.disable()
    med = lambda v: statistics.median(v) * 1e6  # noqa: E731
    what = "per launch (32 then a sync)" if kind.startswith("saxpy") else "launch+sync"
    print(f"{case:22s} launch call {med(launch_t):7.1f} us  sync call {med(sync_t):7.1f} us  "
          f"{what} {med(pair_t):7.1f} us", flush=True)
    if lane_t["send"] and lane_t["receive"]:
        print(f"{'':22s} of which lane send {med(lane_t['send']):5.1f} us, receive (the wait) "
              f"{med(lane_t['receive']):5.1f} us, per frame", flush=True)
    if prof:
        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(18)
        print("\n".join(s.getvalue().splitlines()[4:28]), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--case", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.case:
        client(args.case, args.calls, args.profile)
        return
    import bench_common as bc  # noqa: PLC0415

    trace = Path(tempfile.mkdtemp(prefix="weft-lane-trace-")) / "lane.txt"
    os.environ["WEFT_LANE_TRACE"] = str(trace)
    daemon = bc.BenchDaemon()
    env = dict(os.environ, WEFT_ADDRESS=daemon.address)
    try:
        probe = subprocess.run([sys.executable, "-c", "import weft; weft.init(); "
                                "print(any(d.is_cuda for d in weft.get_devices()))"],
                               env=env, capture_output=True, text=True, cwd=HERE)
        gpu = probe.stdout.strip().endswith("True")
        cases = ["empty@cpu", "three@cpu"]
        if gpu:
            cases += ["empty@cuda:0", "three@cuda:0", "saxpy-pipelined@cuda:0", "saxpy-batched@cuda:0"]
        for case in cases:
            cmd = [sys.executable, __file__, "--case", case, "--calls", str(args.calls)]
            if args.profile:
                cmd.append("--profile")
            subprocess.run(cmd, env=env, check=False)
    finally:
        daemon.stop()
    print("\nweftd, per fast-lane frame (medians; before = from the previous reply sent to this frame "
          "received: the client's time; serve = the engine's work, device_sync = waiting for the GPU):")
    print(trace.read_text() if trace.exists() else "(no trace written)")


if __name__ == "__main__":
    main()
