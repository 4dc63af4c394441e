"""Where the time of an ordered launch on Torch GPU memory goes, in the client (cProfile of
bench_interop's loop: five from_torch conversions (--mode ctype: return_ctype=True) + one
launch per iteration), with the time
spent waiting for the daemon's replies split out. Needs a GPU, Torch on CUDA and CUDA IPC in
the client. Usage: WEFT_DAEMON=... python3 bench/prof_interop_launch.py [--iters 2000]"""
from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))
sys.path.insert(0, str(HERE))

import bench_common as bc  # noqa: E402
from bench_interop import SOURCE  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=2000)
    ap.add_argument("--mode", default="from_torch", choices=["from_torch", "ctype", "direct"])
    ap.add_argument("--top", type=int, default=30)
    args = ap.parse_args()
    import torch

    with bc.WeftSession() as (wp, rt):
        mod = bc.load_kernels(SOURCE, "weft", "interop_prof")
        n = 1024
        ts = [torch.randn(n, device="cuda") for _ in range(4)] + [torch.zeros(n, device="cuda")]

        def loop(iters):
            for _ in range(iters):
                a = ts if args.mode == "direct" else [wp.from_torch(t, return_ctype=args.mode == "ctype")
                                                      for t in ts]
                wp.launch(mod.inc5, dim=n, inputs=a, device="cuda:0")

        loop(50)
        wp.synchronize()
        torch.cuda.synchronize()
        t0 = time.perf_counter()
        loop(args.iters)
        wp.synchronize()
        torch.cuda.synchronize()
        plain = (time.perf_counter() - t0) / args.iters
        prof = cProfile.Profile()
        prof.enable()
        loop(args.iters)
        wp.synchronize()
        torch.cuda.synchronize()
        prof.disable()
        out = io.StringIO()
        stats = pstats.Stats(prof, stream=out)
        stats.sort_stats("tottime").print_stats(args.top)
        stats.sort_stats("cumulative").print_stats(args.top)
        print(out.getvalue())
        print(f"per iteration without the profiler: {plain * 1e6:.1f} us ({args.mode})")


if __name__ == "__main__":
    main()
