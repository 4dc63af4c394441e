"""Graph capture against eager launches, weft beside warp-lang in the same run.

One simulation step is SUBSTEPS substeps of three particle kernels (gravity + damping on the
velocities, integration of the positions, a spring pull toward the origin): 3 * SUBSTEPS
launches, as in Warp's examples, which capture a frame with wp.ScopedCapture and replay it
with wp.capture_launch. Rows per size and library:
- eager: the launches of one step, then wp.synchronize();
- graph: capture_launch of the captured step, then wp.synchronize();
- graph x R: R capture_launch calls, one synchronize (time per step).
Error: positions after all the timed steps of the graph rows against a float64 NumPy
reference that ran the same number of steps (max |error| / max |x|).
The table is printed last. Usage: python3 bench/bench_graph.py [--device cuda:0]
[--sizes 1e4,1e6] [--substeps 8] (WEFT_DAEMON: the weftd to start)."""
from __future__ import annotations

import argparse
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
def forces(v: wp.array(dtype=wp.vec3), g: wp.vec3, damping: float, dt: float):
    i = wp.tid()
    v[i] = (v[i] + g * dt) * (1.0 - damping * dt)

@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), dt: float):
    i = wp.tid()
    x[i] = x[i] + v[i] * dt

@wp.kernel
def spring(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), k: float, dt: float):
    i = wp.tid()
    v[i] = v[i] - x[i] * (k * dt)
'''

G = (0.0, -9.8, 0.0)
DAMPING, K, DT = 0.1, 2.0, 1e-3


def reference_steps(x, v, steps, substeps):
    x = x.astype(np.float64)
    v = v.astype(np.float64)
    g = np.array(G)
    for _ in range(steps * substeps):
        v = (v + g * DT) * (1.0 - DAMPING * DT)
        x = x + v * DT
        v = v - x * (K * DT)
    return x


def run_library(wp, mod, device, n, substeps, x0, v0, replays, rounds):
    """Times of (eager step, graph step, graph step pipelined) and the positions' error."""
    x = wp.array(x0, dtype=wp.vec3, device=device)
    v = wp.array(v0, dtype=wp.vec3, device=device)
    g = wp.vec3(*G)

    def step():
        for _ in range(substeps):
            wp.launch(mod.forces, n, inputs=[v, g, DAMPING, DT], device=device)
            wp.launch(mod.integrate, n, inputs=[x, v, DT], device=device)
            wp.launch(mod.spring, n, inputs=[x, v, K, DT], device=device)

    step()
    wp.synchronize()
    steps = 1

    def eager():
        step()
        wp.synchronize()

    t_eager = bc.median_time(eager, repeat=rounds)
    steps += rounds
    with wp.ScopedCapture(device=device) as capture:
        step()
    graph = capture.graph

    def one_graph():
        wp.capture_launch(graph)
        wp.synchronize()

    one_graph()
    steps += 1
    t_graph = bc.median_time(one_graph, repeat=rounds)
    steps += rounds

    def many():
        for _ in range(replays):
            wp.capture_launch(graph)
        wp.synchronize()

    t_many = bc.median_time(many, repeat=3) / replays
    steps += 3 * replays
    ref = reference_steps(x0, v0, steps, substeps)
    err = float(np.abs(x.numpy().astype(np.float64) - ref).max() / np.abs(ref).max())
    return t_eager, t_graph, t_many, err


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--device", default="cuda:0")
    parser.add_argument("--sizes", default="1e4,1e6")
    parser.add_argument("--substeps", type=int, default=8)
    parser.add_argument("--replays", type=int, default=50)
    parser.add_argument("--rounds", type=int, default=30)
    args = parser.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    rng = np.random.default_rng()
    rows, notes = [], []
    with bc.WeftSession() as (weft, _rt):
        device = args.device
        if device != "cpu" and not weft.is_cuda_available():
            notes.append(f"no CUDA device in weftd: running on cpu instead of {device}")
            device = "cpu"
        wmod = bc.load_kernels(SOURCE, "weft", "graph")
        warp = bc.import_warp()
        pmod = bc.load_kernels(SOURCE, "warp", "graph") if warp is not None else None
        if warp is not None and device != "cpu" and not warp.is_cuda_available():
            notes.append("warp-lang sees no CUDA device: its columns show n/a")
            warp = None
        for n in sizes:
            x0 = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
            v0 = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
            t0 = time.perf_counter()
            ours = run_library(weft, wmod, device, n, args.substeps, x0, v0, args.replays,
                               args.rounds)
            theirs = (run_library(warp, pmod, device, n, args.substeps, x0, v0, args.replays,
                                  args.rounds) if warp is not None else (None,) * 4)
            print(f"  n={n:.0e} measured in {time.perf_counter() - t0:.1f} s", flush=True)
            launches = 3 * args.substeps
            for label, i in (("eager + sync", 0), ("graph + sync", 1),
                             (f"graph x{args.replays}, one sync", 2)):
                rows.append([f"{n:.0e}", label, bc.fmt_time(ours[i]),
                             bc.fmt_time(ours[i] / launches), bc.fmt_time(theirs[i]),
                             bc.fmt_ratio(ours[i], theirs[i]),
                             f"{ours[3]:.1e}" if i else "",
                             f"{theirs[3]:.1e}" if i and theirs[3] is not None else ""])
    for note in notes:
        print("note:", note)
    bc.print_table(f"one step = {3 * args.substeps} launches ({args.substeps} substeps x 3 "
                   f"kernels) on {device}; median time per step; ratio = warp / weft "
                   f"(> 1: weft faster); error = max |x - x_float64| / max |x_float64|",
                   ["n", "mode", "weft", "weft/launch", "warp", "ratio", "weft err",
                    "warp err"], rows)


if __name__ == "__main__":
    main()
