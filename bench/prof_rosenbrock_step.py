"""Where one step of the Torch Rosenbrock autograd example goes on a GPU (bench_interop's
second table: from_torch of the points, wp.zeros, the launch, to_torch, from_torch of the
incoming gradient set as z.grad, the adjoint launch, to_torch of the gradient): cProfile of
the client, top functions by cumulative and own time, then each of the step's lines timed
alone with perf_counter (no profiler), median over the steps. Usage: WEFT_DAEMON=... python3
bench/prof_rosenbrock_step.py [--iters 500] [--lines]"""
from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))
sys.path.insert(0, str(HERE))

import bench_common as bc  # noqa: E402
from bench_interop import SOURCE, rosenbrock_step  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=500)
    ap.add_argument("--top", type=int, default=30)
    ap.add_argument("--lines", action="store_true",
                    help="also the self time of each line of the client and the step "
                         "(bench/line_profile.py), top --top lines")
    args = ap.parse_args()
    import torch

    with bc.WeftSession() as (wp, rt):
        mod = bc.load_kernels(SOURCE, "weft", "rosen_prof")
        n = 1500
        rng = np.random.default_rng(7)
        xy = torch.tensor(rng.uniform(-1.5, 1.5, size=(n, 2)), dtype=torch.float32,
                          device="cuda", requires_grad=True)

        def loop(iters):
            for _ in range(iters):
                rosenbrock_step(wp, mod, torch, xy, n, "cuda:0")
            wp.synchronize()
            torch.cuda.synchronize()

        loop(20)
        t0 = time.perf_counter()
        loop(args.iters)
        plain = (time.perf_counter() - t0) / args.iters
        prof = cProfile.Profile()
        prof.enable()
        loop(args.iters)
        prof.disable()
        out = io.StringIO()
        stats = pstats.Stats(prof, stream=out)
        stats.sort_stats("cumulative").print_stats(args.top)
        stats.sort_stats("tottime").print_stats(15)
        print(out.getvalue())
        print(f"per step without the profiler: {plain * 1e6:.1f} us")

        names = ["grad=None + from_torch(xy)", "wp.zeros", "launch", "to_torch(z)",
                 "ones_like + from_torch", "adjoint launch", "to_torch(grad)"]
        samples = {k: [] for k in names}

        def timed_steps(iters):
            clock = time.perf_counter
            for _ in range(iters):
                t = [clock()]
                xy.grad = None
                wxy = wp.from_torch(xy, dtype=wp.vec2, requires_grad=True)
                t.append(clock())
                z = wp.zeros(n, requires_grad=True, device="cuda:0")
                t.append(clock())
                wp.launch(mod.eval_rosenbrock, dim=n, inputs=[wxy], outputs=[z], device="cuda:0")
                t.append(clock())
                tz = wp.to_torch(z)
                t.append(clock())
                z.grad = wp.from_torch(torch.ones_like(tz))
                t.append(clock())
                wp.launch(mod.eval_rosenbrock, dim=n, inputs=[wxy], outputs=[z],
                          adj_inputs=[wxy.grad], adj_outputs=[z.grad], adjoint=True,
                          device="cuda:0")
                t.append(clock())
                wp.to_torch(wxy.grad)
                t.append(clock())
                for k, a, b in zip(names, t, t[1:]):
                    samples[k].append(b - a)
            wp.synchronize()
            torch.cuda.synchronize()

        timed_steps(args.iters)
        total = 0.0
        print(f"{'line of the step':<30} {'median us':>10} {'mean us':>10}")
        for k in names:
            v = sorted(samples[k])
            med = v[len(v) // 2]
            total += med
            print(f"{k:<30} {med * 1e6:>10.1f} {sum(v) / len(v) * 1e6:>10.1f}")
        print(f"{'sum of medians':<30} {total * 1e6:>10.1f}")

        if args.lines:
            from line_profile import LineProfile  # noqa: PLC0415

            client = HERE.parent / "clients" / "python" / "weft"
            with LineProfile([client, HERE / "bench_interop.py"]) as lp:
                loop(args.iters)
            print()
            print(lp.report(args.iters, args.top, strip=str(HERE.parent) + "/"))


if __name__ == "__main__":
    main()
