"""Profile of one step of the demo (clients/python/examples/demo.py: integrate + collide +
synchronize, 200,000 particles): time of each launch call, of the synchronize, of the whole
step, with the early (pipelined) submit on and off, with the loops' cancel poll on and off
(module option cancel_poll; the bench's weftd runs with --allow-unchecked), and the same
kernels timed on the device side by 50 launches between two syncs. The table is printed last.
Usage: python3 bench/prof_demo_step.py [--device cuda:0] [--steps 100]"""
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
GRAVITY = wp.constant(wp.vec3(0.0, -9.81, 0.0))
BOX = wp.constant(2.0)
RESTITUTION = wp.constant(0.7)
DRAG = wp.constant(0.02)

@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), dt: float):
    tid = wp.tid()
    v1 = v[tid] + GRAVITY * dt
    x[tid] = x[tid] + v1 * dt
    v[tid] = v1

@wp.kernel
def collide(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), dt: float):
    tid = wp.tid()
    p = x[tid]
    u = v[tid] * (1.0 - DRAG * dt)
    if p[1] < 0.0:
        p = wp.vec3(p[0], -p[1] * RESTITUTION, p[2])
        u = wp.vec3(u[0] * 0.9, wp.abs(u[1]) * RESTITUTION, u[2] * 0.9)
    for axis in range(3):
        if axis != 1:
            if p[axis] > BOX:
                p[axis] = BOX - (p[axis] - BOX) * RESTITUTION
                u[axis] = -wp.abs(u[axis]) * RESTITUTION
            if p[axis] < -BOX:
                p[axis] = -BOX + (-BOX - p[axis]) * RESTITUTION
                u[axis] = wp.abs(u[axis]) * RESTITUTION
    x[tid] = p
    v[tid] = u
'''


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--device", default="cuda:0")
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("-n", type=int, default=200_000)
    args = parser.parse_args()
    rows = []
    with bc.WeftSession(("--allow-unchecked",)) as (wp, rt):
        dev = args.device if (args.device == "cpu" or wp.is_cuda_available()) else "cpu"
        n = args.n
        rng = np.random.default_rng(7)
        x = wp.array(rng.uniform(-1, 1, (n, 3)).astype(np.float32), dtype=wp.vec3, device=dev)
        v = wp.array(rng.uniform(-1, 1, (n, 3)).astype(np.float32), dtype=wp.vec3, device=dev)
        for poll in (True, False):
            mod = bc.load_kernels(SOURCE, "weft", f"demo_{int(poll)}")
            mod.wp.set_module_options({"cancel_poll": poll}, module=mod)
            wp.launch(mod.integrate, dim=n, inputs=[x, v, 0.01], device=dev)
            wp.launch(mod.collide, dim=n, inputs=[x, v, 0.01], device=dev)
            wp.synchronize()
            for pipelined in (True, False):
                rt.pipelined = pipelined
                l1, l2, sy, step = [], [], [], []
                for _ in range(args.steps):
                    t0 = time.perf_counter()
                    wp.launch(mod.integrate, dim=n, inputs=[x, v, 0.01], device=dev)
                    t1 = time.perf_counter()
                    wp.launch(mod.collide, dim=n, inputs=[x, v, 0.01], device=dev)
                    t2 = time.perf_counter()
                    wp.synchronize()
                    t3 = time.perf_counter()
                    l1.append(t1 - t0)
                    l2.append(t2 - t1)
                    sy.append(t3 - t2)
                    step.append(t3 - t0)
                rt.pipelined = True
                med = statistics.median
                rows.append([f"{dev} step, poll {'on' if poll else 'off'}, "
                             f"{'pipelined' if pipelined else 'batched at sync'}",
                             bc.fmt_time(med(l1)), bc.fmt_time(med(l2)), bc.fmt_time(med(sy)),
                             bc.fmt_time(med(step)), f"{n / med(step) / 1e6:.1f} M/s"])
            for name, k in (("integrate", mod.integrate), ("collide", mod.collide)):
                wp.synchronize()
                t = time.perf_counter()
                for _ in range(50):
                    wp.launch(k, dim=n, inputs=[x, v, 0.01], device=dev)
                wp.synchronize()
                per = (time.perf_counter() - t) / 50
                rows.append([f"{dev} {name} x50 / 50, poll {'on' if poll else 'off'}", "", "", "",
                             bc.fmt_time(per), ""])
    bc.print_table(f"demo step profile ({args.n} particles, median of {args.steps} steps)",
                   ["case", "launch 1", "launch 2", "synchronize", "step", "particles/s"], rows)


if __name__ == "__main__":
    main()
