"""What the Torch calls of the Rosenbrock step cost by themselves on a GPU, alone and inside
a weft session's step loop: torch.zeros_like / ones_like of a (n, 2) float32 CUDA tensor,
torch.utils.dlpack.from_dlpack of a capsule of Torch's own tensor and of a weft array. Median
over the calls, in microseconds. Usage: WEFT_DAEMON=... python3 bench/prof_torch_ops.py [--n 1500]"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))
sys.path.insert(0, str(HERE))

import bench_common as bc  # noqa: E402
from bench_interop import SOURCE, rosenbrock_step  # noqa: E402


def timed(fn, reps=2000):
    clock = time.perf_counter
    out = []
    for _ in range(reps):
        t0 = clock()
        fn()
        out.append(clock() - t0)
    return statistics.median(out) * 1e6


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=1500)
    args = ap.parse_args()
    import torch

    n = args.n
    xy = torch.rand(n, 2, device="cuda", requires_grad=True)
    rows = []

    def torch_alone(tag):
        def zeros():
            with torch.no_grad():
                xy.grad = None
                xy.grad = torch.zeros_like(xy)
        rows.append((tag, "grad = zeros_like(xy)", timed(zeros)))
        rows.append((tag, "ones_like(xy)", timed(lambda: torch.ones_like(xy))))
        rows.append((tag, "from_dlpack(torch tensor capsule)",
                     timed(lambda: torch.utils.dlpack.from_dlpack(torch.utils.dlpack.to_dlpack(xy.detach())))))
        torch.cuda.synchronize()

    torch_alone("torch only")
    with bc.WeftSession() as (wp, rt):
        mod = bc.load_kernels(SOURCE, "weft", "torch_ops")
        for _ in range(50):
            rosenbrock_step(wp, mod, torch, xy, n, "cuda:0")
        wp.synchronize()
        torch_alone("after weft steps")
        a = wp.zeros(n, dtype=wp.vec2, device="cuda:0")
        wp.synchronize()
        rows.append(("weft", "to_torch(a) (no grad)", timed(lambda: wp.to_torch(a))))
        rows.append(("weft", "from_dlpack(a.__dlpack__())",
                     timed(lambda: torch.utils.dlpack.from_dlpack(a.__dlpack__()))))
        t = torch.rand(n, 2, device="cuda")
        rows.append(("weft", "from_torch(t) of a converted tensor", timed(lambda: wp.from_torch(t, dtype=wp.vec2))))
        rows.append(("weft", "from_torch(ones_like(xy)) (new tensor)",
                     timed(lambda: wp.from_torch(torch.ones_like(xy), dtype=wp.vec2))))
        rows.append(("weft", "wp.zeros(n, requires_grad=True)",
                     timed(lambda: wp.zeros(n, requires_grad=True, device="cuda:0"))))
        rows.append(("weft", "wp.zeros(n)", timed(lambda: wp.zeros(n, device="cuda:0"))))
        rows.append(("weft", "rosenbrock_step", timed(lambda: rosenbrock_step(wp, mod, torch, xy, n, "cuda:0"), 500)))
        wp.synchronize()
        torch.cuda.synchronize()
    print(f"{'when':<18} {'call':<42} {'median us':>10}")
    for tag, what, us in rows:
        print(f"{tag:<18} {what:<42} {us:>10.1f}")


if __name__ == "__main__":
    main()
