"""Inclusive time of the client functions inside interop calls on a GPU (each wrapped in a
perf_counter timer, which adds about half a microsecond per call and roughly doubles the
totals): each line of the Torch Rosenbrock step (bench_interop.rosenbrock_step) with the
functions it ran, then wp.zeros, from_torch of a new tensor (the step's ones_like) and
to_torch of an array with and without a gradient alone. Medians per call.
Usage: WEFT_DAEMON=... python3 bench/prof_call_parts.py [--n 1500] [--reps 1500]"""
from __future__ import annotations

import argparse
import collections
import functools
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))
sys.path.insert(0, str(HERE))

import bench_common as bc  # noqa: E402
from bench_interop import SOURCE, rosenbrock_step  # noqa: E402

WRAPPED = {
    "weft.interop.torch": ["_from_torch", "_cuda_tensor_over", "to_torch"],
    "weft.interop.cuda_import": ["import_torch", "import_memory", "_fresh"],
    "weft.interop.external": ["resolve_parts", "find_cuda_in_place", "_span"],
    "weft.interop.dlpack": ["export", "_export_cuda"],
    "weft.interop.cuda_order": ["ready", "before", "after"],
    "weft.interop.memory": ["note_range", "mark_shared", "grad_view"],
    "weft._dlpack": ["to_capsule", "_layout"],
    "weft._cuda_ipc": ["export_allocation", "available", "write_value", "wait_value"],
    "weft._kernel.launch": ["launch", "_order_framework_gpu", "pack_arguments", "_array_arg",
                            "_pack_fast"],
    "weft.array": ["_new_array", "zeros"],
}
METHODS = {
    ("weft.array", "array"): ["_from_info", "_adopt", "_init_new", "_set_daemon_grad", "_make_view"],
    ("weft._runtime", "Runtime"): ["array_call", "synchronize_if_needed", "drain_frees",
                                   "submit", "submit_framed", "send_now", "free_later",
                                   "_collect_done", "flush"],
    ("weft._fast_lane", "FastLane"): ["_send", "_receive", "call"],
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=1500)
    ap.add_argument("--reps", type=int, default=1500)
    args = ap.parse_args()
    import importlib

    import torch

    spent = collections.defaultdict(list)   # name -> [seconds] within the current call
    current = {}

    def wrap(name, fn):
        clock = time.perf_counter

        @functools.wraps(fn)
        def timed(*a, **k):
            t0 = clock()
            try:
                return fn(*a, **k)
            finally:
                current[name] = current.get(name, 0.0) + clock() - t0
                current[name + " #"] = current.get(name + " #", 0) + 1
        return timed

    with bc.WeftSession() as (wp, rt):
        for mod_name, names in WRAPPED.items():
            m = importlib.import_module(mod_name)
            for n in names:
                fn = getattr(m, n, None)
                if callable(fn):
                    setattr(m, n, wrap(f"{mod_name.split('.')[-1]}.{n}", fn))
        for (mod_name, cls), names in METHODS.items():
            c = getattr(importlib.import_module(mod_name), cls)
            for n in names:
                raw = c.__dict__.get(n)
                if isinstance(raw, classmethod):
                    setattr(c, n, classmethod(wrap(f"{cls}.{n}", raw.__func__)))
                elif callable(raw):
                    setattr(c, n, wrap(f"{cls}.{n}", raw))
        mod = bc.load_kernels(SOURCE, "weft", "call_parts")
        n = args.n
        xy = torch.rand(n, 2, device="cuda", requires_grad=True)
        for _ in range(30):
            rosenbrock_step(wp, mod, torch, xy, n, "cuda:0")
        wp.synchronize()
        z = wp.zeros(n, requires_grad=True, device="cuda:0")
        plain = wp.zeros(n, device="cuda:0")
        cases = {
            "wp.zeros(n)": lambda: wp.zeros(n, device="cuda:0"),
            "wp.zeros(n, requires_grad=True)": lambda: wp.zeros(n, requires_grad=True, device="cuda:0"),
            "from_torch(new tensor)": None,
            "to_torch(a)": lambda: wp.to_torch(plain),
            "to_torch(a with grad)": lambda: wp.to_torch(z),
        }
        clock = time.perf_counter

        # the Rosenbrock step's lines (bench_interop.rosenbrock_step), each timed with its parts
        lines = ["from_torch(xy, requires_grad)", "wp.zeros(requires_grad)", "launch",
                 "to_torch(z)", "z.grad = from_torch(ones_like)", "adjoint launch",
                 "to_torch(wxy.grad)", "end of step (frees)"]
        per_line = {k: collections.defaultdict(list) for k in lines}
        line_totals = {k: [] for k in lines}

        def mark(k, t0):
            t1 = clock()
            line_totals[k].append(t1 - t0)
            for name, v in current.items():
                per_line[k][name].append(v)
            current.clear()
            return clock()

        def step():
            current.clear()
            t0 = clock()
            xy.grad = None
            wxy = wp.from_torch(xy, dtype=wp.vec2, requires_grad=True)
            t0 = mark(lines[0], t0)
            z = wp.zeros(n, requires_grad=True, device="cuda:0")
            t0 = mark(lines[1], t0)
            wp.launch(mod.eval_rosenbrock, dim=n, inputs=[wxy], outputs=[z], device="cuda:0")
            t0 = mark(lines[2], t0)
            tz = wp.to_torch(z)
            t0 = mark(lines[3], t0)
            z.grad = wp.from_torch(torch.ones_like(tz))
            t0 = mark(lines[4], t0)
            wp.launch(mod.eval_rosenbrock, dim=n, inputs=[wxy], outputs=[z], adj_inputs=[wxy.grad],
                      adj_outputs=[z.grad], adjoint=True, device="cuda:0")
            t0 = mark(lines[5], t0)
            g = wp.to_torch(wxy.grad)
            t0 = mark(lines[6], t0)
            del wxy, z, tz, g
            mark(lines[7], t0)

        for _ in range(args.reps):
            step()
        wp.synchronize()
        print(f"Rosenbrock step, line by line: median {sum(statistics.median(v) for v in line_totals.values()) * 1e6:.1f} us summed")
        for k in lines:
            print(f"\n{k}: median {statistics.median(line_totals[k]) * 1e6:.1f} us")
            counts = per_line[k]
            rows = [(name, statistics.median(v + [0.0] * (args.reps - len(v))), len(v) / args.reps)
                    for name, v in counts.items() if not name.endswith(" #")]
            for name, v, share in sorted(rows, key=lambda r: -r[1])[:12]:
                calls = counts.get(name + " #", [0])
                print(f"  {v * 1e6:8.1f} us  x{statistics.median(calls):<4g} in {share:4.0%} of steps  {name}")

        for case, fn in cases.items():
            per = collections.defaultdict(list)
            totals = []
            for _ in range(args.reps):
                if fn is None:
                    t = torch.ones_like(xy)
                    current.clear()
                    t0 = clock()
                    wp.from_torch(t, dtype=wp.vec2)
                else:
                    current.clear()
                    t0 = clock()
                    fn()
                totals.append(clock() - t0)
                for k, v in current.items():
                    per[k].append(v)
            wp.synchronize()
            print(f"\n{case}: median {statistics.median(totals) * 1e6:.1f} us per call")
            rows = [(k, statistics.median(v)) for k, v in per.items() if not k.endswith(" #")]
            for k, v in sorted(rows, key=lambda kv: -kv[1]):
                count = statistics.median(per[k + " #"])
                print(f"  {v * 1e6:8.1f} us  x{count:<4g} {k}")


if __name__ == "__main__":
    main()
