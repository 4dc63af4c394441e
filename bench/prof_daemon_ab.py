"""Two daemon settings against each other on one GPU, interleaved finely enough that the lent
machines' drift (up to 2x within a minute) falls on both: two weftd started at once, one with
--env-a, the other with --env-b (daemon environment variables, e.g. WEFT_LANE_ADAPTIVE_SPIN=0
and =1), then --rounds rounds, each running one client process against A and one against B
(in turn, A first in odd rounds). Each client runs --steps steps of a case after a warm-up and
prints its median step time; the table gives every round and the median over rounds.
--args-a / --args-b add weftd flags (e.g. --args-b=--device-hosts: B's sessions run in the
process of their device).
Cases: rosenbrock (bench_interop's Torch Rosenbrock step), zeros (wp.zeros(n) on cuda:0),
new_tensor (wp.from_torch of a tensor made anew each step), launch_sync / launch3_sync (an
empty / three-array kernel launched on cuda:0, then wp.synchronize()).
Usage: python3 bench/prof_daemon_ab.py --env-a WEFT_LANE_ADAPTIVE_SPIN=0 --env-b
WEFT_LANE_ADAPTIVE_SPIN=1 [--cases rosenbrock,zeros] [--rounds 6] [--steps 400]"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

CLIENT = r'''
import statistics, sys, time
sys.path.insert(0, {bench!r}); sys.path.insert(0, {client!r})
import numpy as np, torch
import weft as wp
import bench_common as bc
from bench_interop import SOURCE, rosenbrock_step
wp.init()
mod = bc.load_kernels(SOURCE, "weft", "daemon_ab")
n = 1500
xy = torch.tensor(np.random.default_rng(3).uniform(-1.5, 1.5, (n, 2)), dtype=torch.float32,
                  device="cuda", requires_grad=True)
case = {case!r}
if case == "rosenbrock":
    step = lambda: rosenbrock_step(wp, mod, torch, xy, n, "cuda:0")
elif case in ("launch_sync", "launch3_sync"):
    from bench_cuda import SOURCE as CUDA_SOURCE
    kmod = bc.load_kernels(CUDA_SOURCE, "weft", "daemon_ab_launch")
    bufs = [wp.zeros(1, dtype=float, device="cuda:0") for _ in range(3)]
    if case == "launch_sync":
        def step():
            wp.launch(kmod.empty_kernel, dim=1, inputs=[], device="cuda:0")
            wp.synchronize()
    else:
        def step():
            wp.launch(kmod.three_args, dim=1, inputs=bufs, device="cuda:0")
            wp.synchronize()
elif case == "zeros":
    step = lambda: wp.zeros(n, device="cuda:0")
else:
    step = lambda: wp.from_torch(torch.ones_like(xy), dtype=wp.vec2)
clock = time.perf_counter
for _ in range(50):
    step()
wp.synchronize()
times = []
for _ in range({steps}):
    t0 = clock()
    step()
    times.append(clock() - t0)
wp.synchronize()
torch.cuda.synchronize()
print("median_us", statistics.median(times) * 1e6)
'''


def run_client(address: str, case: str, steps: int) -> float:
    code = CLIENT.format(bench=str(HERE), client=str(HERE.parent / "clients" / "python"),
                         case=case, steps=steps)
    env = dict(os.environ, WEFT_ADDRESS=address)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=300)
    for line in out.stdout.splitlines():
        if line.startswith("median_us"):
            return float(line.split()[1])
    raise RuntimeError(f"client failed:\n{out.stdout[-2000:]}\n{out.stderr[-3000:]}")


def main() -> None:
    import bench_common as bc  # noqa: PLC0415

    ap = argparse.ArgumentParser()
    ap.add_argument("--env-a", action="append", default=[], help="NAME=VALUE for daemon A")
    ap.add_argument("--env-b", action="append", default=[], help="NAME=VALUE for daemon B")
    ap.add_argument("--args-a", default="", help="more weftd flags for daemon A, space separated")
    ap.add_argument("--args-b", default="", help="more weftd flags for daemon B (e.g. --device-hosts)")
    ap.add_argument("--cases", default="rosenbrock,zeros,new_tensor")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--steps", type=int, default=400)
    args = ap.parse_args()

    def start(pairs, flags):
        saved = dict(os.environ)
        os.environ.update(dict(p.split("=", 1) for p in pairs))
        try:
            return bc.BenchDaemon(extra_args=tuple(flags.split()))
        finally:
            os.environ.clear()
            os.environ.update(saved)

    daemons = {"A": start(args.env_a, args.args_a), "B": start(args.env_b, args.args_b)}
    try:
        print(f"A: {' '.join(args.env_a + args.args_a.split()) or '(default)'}   "
              f"B: {' '.join(args.env_b + args.args_b.split()) or '(default)'}")
        for case in args.cases.split(","):
            got = {"A": [], "B": []}
            for r in range(args.rounds):
                order = ("A", "B") if r % 2 == 0 else ("B", "A")
                for name in order:
                    got[name].append(run_client(daemons[name].address, case, args.steps))
                print(f"  {case:<12} round {r + 1}: A {got['A'][-1]:8.1f} us   B {got['B'][-1]:8.1f} us",
                      flush=True)
            a, b = statistics.median(got["A"]), statistics.median(got["B"])
            wins = sum(1 for x, y in zip(got["A"], got["B"]) if y < x)
            print(f"{case:<12} median A {a:8.1f} us   B {b:8.1f} us   A/B {a / b:5.2f}   "
                  f"B faster in {wins} of {args.rounds} rounds")
    finally:
        for d in daemons.values():
            d.stop()


if __name__ == "__main__":
    main()
