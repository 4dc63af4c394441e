"""Where the time of a launch + synchronize goes, and what the pipelined submit buys.

Rows (median of many, one client, weft's own daemon on a Unix socket):
- the transport floor: a no-op RPC (SessionService.Stats) and Synchronize with nothing
  queued, wall time and this process's CPU time per call;
- empty launch + wp.synchronize() and 3-argument launch + sync, on `cpu` and on `cuda:0`
  (the difference between the two devices is the GPU's part: stream wait, error read-back),
  each through gRPC and through the fast lane (weft._fast_lane: Submit/Synchronize over a Unix
  SOCK_SEQPACKET socket; rows "fast lane"; absent when the daemon offers none);
- saxpy at 1e7 and 1e8 elements, R launches then one sync, with the early (pipelined)
  submit on and off (weft._runtime: WEFT_PIPELINE): time per launch, and the fixed cost of a
  round (intercept of time against R from R=4 and R=32); the same with bounds checks off (the
  daemon runs with --allow-unchecked; the module option bounds_checks=False), to show what the
  checks cost; warp-lang beside it when importable.
Error column: the saxpy result against a float64 reference (first 1e6 elements).
The table is printed last. Usage: python3 bench/bench_cuda_sync.py [--device cuda:0]
(WEFT_DAEMON: the weftd to start)."""
from __future__ import annotations

import argparse
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
def three_args(a: wp.array(dtype=float), b: wp.array(dtype=float), c: wp.array(dtype=float)):
    pass

@wp.kernel
def fill_random(x: wp.array(dtype=float), seed: int):
    i = wp.tid()
    state = wp.rand_init(seed, i)
    x[i] = wp.randf(state) - 0.5

@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]
'''


def per_call(fn, n: int):
    """(median wall seconds, mean process CPU seconds) per call of fn over n calls."""
    fn()
    walls = []
    c0 = time.process_time()
    for _ in range(n):
        t = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t)
    return statistics.median(walls), (time.process_time() - c0) / n


def round_time(lib, fn, reps: int, rounds: int = 5) -> float:
    best = None
    for _ in range(rounds):
        lib.synchronize()
        t = time.perf_counter()
        for _ in range(reps):
            fn()
        lib.synchronize()
        dt = time.perf_counter() - t
        best = dt if best is None else min(best, dt)
    return best


def saxpy_rows(lib, mod, dev, sizes, label, set_pipelined=None):
    rows = []
    for n in sizes:
        x = lib.empty(n, dtype=float, device=dev)
        y = lib.empty(n, dtype=float, device=dev)
        lib.launch(mod.fill_random, dim=n, inputs=[x, 1], device=dev)
        lib.launch(mod.fill_random, dim=n, inputs=[y, 2], device=dev)
        m = min(n, 1_000_000)
        x0 = x.numpy()[:m].astype(np.float64)
        y0 = y.numpy()[:m].astype(np.float64)
        lib.launch(mod.saxpy, dim=n, inputs=[x, y, 1.7], device=dev)
        got = y.numpy()[:m].astype(np.float64)
        ref = np.float64(np.float32(1.7)) * x0 + y0
        err = float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1e-3)))
        modes = [(None, label)] if set_pipelined is None else [(True, label + " pipelined"),
                                                               (False, label + " batched at sync")]
        for mode, name in modes:
            if set_pipelined is not None:
                set_pipelined(mode)

            def one():
                lib.launch(mod.saxpy, dim=n, inputs=[x, y, 1.7], device=dev)

            t4 = round_time(lib, one, 4)
            t32 = round_time(lib, one, 32, rounds=3)
            slope = (t32 - t4) / 28
            rows.append([f"saxpy {n:.0e}, {name}", bc.fmt_time(t32 / 32), bc.fmt_time(slope),
                         bc.fmt_time(t4 - 4 * slope), f"{12 * n / slope / 1e9:.0f} GB/s",
                         f"{err:.1e}"])
        if set_pipelined is not None:
            set_pipelined(True)
        del x, y
        lib.synchronize()
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--device", default="cuda:0")
    parser.add_argument("--sizes", default="1e7,1e8")
    parser.add_argument("--calls", type=int, default=400)
    args = parser.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    rows = []
    notes = []
    with bc.WeftSession(["--allow-unchecked"]) as (weft, rt):
        from weft.v1 import exec_pb2, session_pb2  # noqa: PLC0415

        mod = bc.load_kernels(SOURCE, "weft", "sync")
        devices = ["cpu"] + ([args.device] if args.device != "cpu" else [])
        if args.device != "cpu" and not weft.is_cuda_available():
            notes.append(f"no CUDA device in weftd: {args.device} rows left out")
            devices = ["cpu"]
        wall, cpu = per_call(lambda: rt.session_stub.Stats(session_pb2.StatsRequest(),
                                                            metadata=rt.metadata), args.calls)
        rows.append(["no-op RPC (Stats)", bc.fmt_time(wall), bc.fmt_time(cpu), "", "", ""])
        wall, cpu = per_call(lambda: rt.exec_stub.Synchronize(exec_pb2.SynchronizeRequest(),
                                                              metadata=rt.metadata), args.calls)
        rows.append(["Synchronize, nothing queued", bc.fmt_time(wall), bc.fmt_time(cpu), "", "", ""])
        lane = rt.fast_lane
        if lane is None:
            notes.append("no fast lane (WEFT_FAST_LANE=0, or the daemon offers none): its rows left out")
        else:
            wall, cpu = per_call(lambda: rt.synchronize(), args.calls)
            rows.append(["Synchronize, nothing queued, fast lane", bc.fmt_time(wall), bc.fmt_time(cpu), "", "", ""])
        transports = [("gRPC", None)] + ([("fast lane", lane)] if lane is not None else [])
        for dev in devices:
            a = weft.zeros(1, dtype=float, device=dev)
            b = weft.zeros(1, dtype=float, device=dev)
            c = weft.zeros(1, dtype=float, device=dev)
            for tname, tlane in transports:
                rt.fast_lane = tlane
                wall, cpu = per_call(lambda: (weft.launch(mod.empty_kernel, dim=1, inputs=[], device=dev),
                                              weft.synchronize()), args.calls)
                rows.append([f"empty launch + sync, {dev}, {tname}", bc.fmt_time(wall), bc.fmt_time(cpu), "", "", ""])
                wall, cpu = per_call(lambda: (weft.launch(mod.three_args, dim=1, inputs=[a, b, c], device=dev),
                                              weft.synchronize()), args.calls)
                rows.append([f"3-arg launch + sync, {dev}, {tname}", bc.fmt_time(wall), bc.fmt_time(cpu), "", "", ""])
            rt.fast_lane = lane
        if args.device != "cpu" and "cpu" not in devices[1:] and len(devices) > 1:

            def set_pipelined(on):
                rt.pipelined = on

            rows += saxpy_rows(weft, mod, args.device, sizes, "weft", set_pipelined)
            umod = bc.load_kernels(SOURCE, "weft", "sync_unchecked")
            weft.set_module_options({"bounds_checks": False}, module=umod)
            rows += saxpy_rows(weft, umod, args.device, sizes, "weft, bounds checks off")
            try:
                import warp  # noqa: PLC0415

                warp.config.quiet = True
                warp.init()
                wmod = bc.load_kernels(SOURCE, "warp", "sync")
                rows += saxpy_rows(warp, wmod, args.device, sizes, f"warp {warp.config.version}")
            except Exception as err:  # noqa: BLE001
                notes.append(f"warp-lang rows left out: {type(err).__name__}: {str(err)[:200]}")
    for note in notes:
        print(note)
    bc.print_table("launch + synchronize breakdown (median per call; saxpy: per launch from R=4 "
                   "and R=32 rounds)",
                   ["case", "wall (saxpy: per launch at R=32)", "client CPU (saxpy: slope)", "saxpy: fixed per round",
                    "rate", "err"], rows)


if __name__ == "__main__":
    main()
