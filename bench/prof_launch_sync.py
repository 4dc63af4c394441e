"""Where a launch + synchronize goes in the client: an empty kernel launched and synchronized
N times, first timed bare, then under cProfile (the time spent waiting for the daemon's reply
shows as the socket's recv). Usage: WEFT_DAEMON=... python3 bench/prof_launch_sync.py
[--device cuda:0] [-n 3000] [--top 25]"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import weft as wp  # noqa: E402 - kernel annotations name it at module scope


@wp.kernel
def empty_kernel(a: wp.array(dtype=float)):
    pass


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cpu")
    ap.add_argument("-n", type=int, default=3000)
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args()
    a = wp.zeros(4, dtype=float, device=args.device)

    def loop(n):
        for _ in range(n):
            wp.launch(empty_kernel, dim=1, inputs=[a], device=args.device)
            wp.synchronize_device(args.device)

    loop(300)
    t = time.perf_counter()
    loop(args.n)
    print(f"launch + synchronize, {args.device}: {(time.perf_counter() - t) / args.n * 1e6:.1f} us per iteration")
    pr = cProfile.Profile()
    pr.enable()
    loop(args.n)
    pr.disable()
    pstats.Stats(pr).sort_stats("tottime").print_stats(args.top)


if __name__ == "__main__":
    main()
