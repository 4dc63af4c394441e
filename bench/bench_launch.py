"""Launch overhead, weft beside warp-lang on the same device in the same run.

Rows (per launch; N launches per timing, median of repeats):
- empty kernel, N launches then one synchronize (batched);
- a 4-argument kernel (array of vec3, vec3, float, float: the step of Warp's particle
  examples) batched the same way;
- the same kernel in steps of 24 launches then a synchronize (an eager simulation frame);
- empty kernel, launch + synchronize each time (one round trip per launch).
Columns: wall time, this process's CPU time, weftd's CPU time (all its threads, from
/proc/<pid>/task/*/schedstat; on a machine with few cores the two processes compete), the part
of it weftd's executors spent running the commands (StatsResponse.command_run_seconds; the
rest is receiving, parsing and admitting them, and waking threads), warp-lang's wall time and
the ratio warp/weft (above 1: weft is faster).
Error column: a counter kernel launched N times the same way must count exactly N; the
4-argument kernel's array after all its launches is compared with a float64 NumPy reference
(max |error| / max |v|).
Usage: python3 bench/bench_launch.py [--device cpu|cuda:0] [-n 2000] [--repeat 3]
(the bench starts its own weftd: WEFT_DAEMON or build/bin/weftd)."""
from __future__ import annotations

import argparse
import os
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
def empty_kernel(a: wp.array(dtype=float)):
    pass

@wp.kernel
def count(c: wp.array(dtype=int)):
    wp.atomic_add(c, 0, 1)

@wp.kernel
def forces(v: wp.array(dtype=wp.vec3), g: wp.vec3, damping: float, dt: float):
    i = wp.tid()
    v[i] = (v[i] + g * dt) * (1.0 - damping * dt)
'''
STEP = 24                       # launches per eager step
PARTICLES = 1000
G, DAMPING, DT = (0.0, -9.8, 0.0), 0.1, 1e-3


def _cpu_seconds(pid) -> float:
    """CPU seconds of this process (pid 0) or of every thread of process `pid` (from
    /proc/<pid>/task/*/schedstat: nanoseconds, not clock ticks)."""
    if not pid:
        return time.process_time()
    total = 0
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{task}/schedstat") as f:
                total += int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            pass                      # a thread that ended meanwhile
    return total * 1e-9


def _executor_seconds(rt):
    """weftd's command_run_seconds (StatsResponse), or None for a daemon without it."""
    if rt is None:
        return None
    from weft.v1 import session_pb2  # noqa: PLC0415

    stats = rt.call(rt.session_stub.Stats, session_pb2.StatsRequest())
    return stats.command_run_seconds if hasattr(stats, "command_run_seconds") else None


def _measure(fn, launches, repeat, daemon_pid, rt):
    """(wall, client CPU, daemon CPU, daemon executor time) per launch of fn(), which makes
    `launches`; the daemon columns are None for warp-lang."""
    wall = bc.median_time(fn, repeat=repeat) / launches
    c0 = time.process_time()
    d0 = _cpu_seconds(daemon_pid) if daemon_pid else None
    e0 = _executor_seconds(rt)
    fn()
    client = (time.process_time() - c0) / launches
    daemon = (_cpu_seconds(daemon_pid) - d0) / launches if daemon_pid else None
    e1 = _executor_seconds(rt)
    executor = (e1 - e0) / launches if e0 is not None and e1 is not None else None
    return wall, client, daemon, executor


def run_library(wp, mod, device, n, repeat, daemon_pid=None, rt=None):
    """{row: (wall, client CPU, daemon CPU)} and {row: error text} for one library."""
    a = wp.zeros(1, dtype=float, device=device)
    rng = np.random.default_rng(11)
    v0 = rng.standard_normal((PARTICLES, 3)).astype(np.float32)
    v = wp.array(v0, dtype=wp.vec3, device=device)
    g = wp.vec3(*G)
    launched = [0]

    def empty_batched():
        for _ in range(n):
            wp.launch(mod.empty_kernel, dim=1, inputs=[a], device=device)
        wp.synchronize()

    def forces_batched():
        for _ in range(n):
            wp.launch(mod.forces, PARTICLES, inputs=[v, g, DAMPING, DT], device=device)
        wp.synchronize()
        launched[0] += n

    def forces_steps():
        for _ in range(n // STEP):
            for _ in range(STEP):
                wp.launch(mod.forces, PARTICLES, inputs=[v, g, DAMPING, DT], device=device)
            wp.synchronize()
        launched[0] += n // STEP * STEP

    def empty_synchronous():
        for _ in range(n // 10):
            wp.launch(mod.empty_kernel, dim=1, inputs=[a], device=device)
            wp.synchronize()

    wp.launch(mod.empty_kernel, dim=1, inputs=[a], device=device)
    wp.launch(mod.forces, PARTICLES, inputs=[v, g, DAMPING, DT], device=device)
    wp.synchronize()
    launched[0] += 1
    times = {
        "empty kernel, batched": _measure(empty_batched, n, repeat, daemon_pid, rt),
        "4-arg kernel, batched": _measure(forces_batched, n, repeat, daemon_pid, rt),
        f"4-arg kernel, steps of {STEP} + sync": _measure(forces_steps, n // STEP * STEP,
                                                         repeat, daemon_pid, rt),
        "empty kernel, launch + sync each": _measure(empty_synchronous, n // 10, repeat,
                                                     daemon_pid, rt),
    }
    c = wp.zeros(1, dtype=int, device=device)
    for _ in range(n):
        wp.launch(mod.count, dim=1, inputs=[c], device=device)
    counted = int(c.numpy()[0])
    ref = v0.astype(np.float64)
    gd = np.array(G, dtype=np.float64)
    for _ in range(launched[0]):
        ref = (ref + gd * DT) * (1.0 - DAMPING * DT)
    got = v.numpy().astype(np.float64)
    rel = float(np.max(np.abs(got - ref)) / np.max(np.abs(ref)))
    errors = {"empty kernel, batched": f"count {counted - n:+d}",
              "4-arg kernel, batched": f"{rel:.1e}"}
    return times, errors


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("-n", type=int, default=2000, help="launches per timing")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    session = bc.WeftSession()
    with session as (weft, rt):
        mod = bc.load_kernels(SOURCE, "weft", "launch")
        weft_times, weft_errors = run_library(weft, mod, args.device, args.n, args.repeat,
                                              session.daemon.proc.pid, rt)

    warp = bc.import_warp()
    warp_times = {}
    if warp is not None:
        wmod = bc.load_kernels(SOURCE, "warp", "launch")
        warp_times, _ = run_library(warp, wmod, args.device, args.n, args.repeat)

    rows = []
    for name, (wall, client, daemon, executor) in weft_times.items():
        ref = warp_times.get(name)
        rows.append([name, bc.fmt_time(wall), bc.fmt_time(client), bc.fmt_time(daemon),
                     bc.fmt_time(executor),
                     f"{1 / wall:,.0f}/s", weft_errors.get(name, ""),
                     bc.fmt_time(ref[0] if ref else None), bc.fmt_ratio(wall, ref[0] if ref else None)])
    bc.print_table(f"launch overhead, {args.device}, N={args.n} (per launch)",
                   ["case", "weft", "client CPU", "weftd CPU", "weftd executor", "launches",
                    "error",
                    "warp-lang", "ratio warp/weft"], rows)


if __name__ == "__main__":
    main()
