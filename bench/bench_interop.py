"""Torch interop overhead (Warp's benchmark_interop_torch pattern): each iteration converts
five Torch tensors and launches one kernel on them, in three modes: wp.from_torch (default),
wp.from_torch(..., return_ctype=True), and the tensors passed to wp.launch directly. weft and
warp-lang run the same kernel on the same device in the same process (--device cpu, the
default, or cuda:N with CUDA tensors). Time is per iteration (median of repeats, weft's and
warp-lang's runs taken in turn, so that a machine whose speed drifts moves both alike). Error: after the timed iterations the accumulated output is compared with a
float64 NumPy reference (max relative error). Ratio = warp time / weft time.

A second table times one step of the documentation's Rosenbrock torch.autograd.Function
(wp.from_torch of the points, wp.zeros for the output, the launch, to_torch, from_torch of the
incoming gradient set as z.grad, the adjoint launch, to_torch of the points' gradient); error:
the last step's gradient against the float64 analytic gradient at the same points.

weft notes (docs/interop.md): from_torch of a CPU tensor moves its storage into a weft slab on
the first call, so later conversions are zero-copy look-ups; a CUDA tensor is imported by CUDA
IPC on the first conversion (one round trip) and remembered on the tensor, so later conversions
and direct launch arguments cost no round trip. A launch that touches memory Torch holds is
ordered with Torch's stream on the GPU (docs/interop.md, "Ordering"): by stream memory
operations where both drivers support them (no round trip: the launch is sent without waiting),
else by interprocess events (one round trip: the Submit that returns once weftd queued the launch
and recorded the event). On a GPU the table adds the direct-tensor mode ordered by events in the
same run; WEFT_CUDA_EVENTS=0 measures the host synchronization instead."""
from __future__ import annotations

import argparse

import numpy as np

import bench_common as bc

SOURCE = '''
@wp.kernel
def inc5(a: wp.array(dtype=float), b: wp.array(dtype=float), c: wp.array(dtype=float),
         d: wp.array(dtype=float), e: wp.array(dtype=float)):
    i = wp.tid()
    e[i] = e[i] + a[i] + b[i] + c[i] + d[i]


@wp.func
def rosenbrock(x: float, y: float):
    return (1.0 - x) ** 2.0 + 100.0 * (y - x**2.0) ** 2.0


@wp.kernel
def eval_rosenbrock(xs: wp.array(dtype=wp.vec2), z: wp.array(dtype=float)):
    i = wp.tid()
    x = xs[i]
    z[i] = rosenbrock(x[0], x[1])
'''
MODES = ["from_torch", "from_torch(return_ctype=True)", "direct tensors"]


def prepare(wp, mod, torch, mode, n, iters, seed, device="cpu"):
    """(body, error): body() runs `iters` iterations of `mode` and waits for them; error() is
    the max relative error of the accumulated output against float64 after every body()
    run so far (body() runs once here: compile, first conversions)."""
    rng = np.random.default_rng(seed)
    inputs = [rng.standard_normal(n).astype(np.float32) for _ in range(4)]
    tdev = "cpu" if device == "cpu" else device
    ts = [torch.tensor(x, device=tdev) for x in inputs] + \
        [torch.zeros(n, dtype=torch.float32, device=tdev)]
    done = [0]

    def body():
        for _ in range(iters):
            if mode == "direct tensors":
                args = ts
            else:
                ctype = mode != "from_torch"
                args = [wp.from_torch(t, return_ctype=ctype) for t in ts]
            wp.launch(mod.inc5, dim=n, inputs=args, device=device)
        wp.synchronize()
        if device != "cpu":
            torch.cuda.synchronize()
        done[0] += iters

    def error():
        reference = done[0] * sum(x.astype(np.float64) for x in inputs)
        got = ts[4].cpu().numpy().astype(np.float64)
        return float(np.max(np.abs(got - reference) / np.maximum(np.abs(reference), 1.0)))

    body()                                   # warm-up: compile, first conversions
    return body, error


def run(wp, mod, torch, mode, n, iters, repeat, seed, device="cpu"):
    """(seconds per iteration, error) of `mode` alone."""
    body, error = prepare(wp, mod, torch, mode, n, iters, seed, device)
    seconds = bc.median_time(body, repeat=repeat) / iters
    return seconds, error()


def rosenbrock_step(wp, mod, torch, xy, n, device):
    """One step of the documentation's Rosenbrock torch.autograd.Function on points `xy` (a
    Torch tensor that requires grad): the forward launch, then the adjoint one for an incoming
    gradient of ones; returns the points' gradient as a Torch tensor."""
    xy.grad = None   # the optimizer's zero_grad()
    wxy = wp.from_torch(xy, dtype=wp.vec2, requires_grad=True)
    z = wp.zeros(n, requires_grad=True, device=device)
    wp.launch(mod.eval_rosenbrock, dim=n, inputs=[wxy], outputs=[z], device=device)
    tz = wp.to_torch(z)
    z.grad = wp.from_torch(torch.ones_like(tz))
    wp.launch(mod.eval_rosenbrock, dim=n, inputs=[wxy], outputs=[z], adj_inputs=[wxy.grad],
              adj_outputs=[z.grad], adjoint=True, device=device)
    return wp.to_torch(wxy.grad)


def prepare_rosenbrock(wp, mod, torch, n, iters, seed, device="cpu"):
    """(body, error) of the Rosenbrock step as prepare() gives them: body() runs `iters`
    steps; error() compares the last step's gradient with the float64 analytic one."""
    rng = np.random.default_rng(seed)
    tdev = "cpu" if device == "cpu" else device
    xy = torch.tensor(rng.uniform(-1.5, 1.5, size=(n, 2)), dtype=torch.float32, device=tdev,
                      requires_grad=True)
    last = [None]

    def body():
        for _ in range(iters):
            last[0] = rosenbrock_step(wp, mod, torch, xy, n, device)
        wp.synchronize()
        if device != "cpu":
            torch.cuda.synchronize()

    def error():
        p = xy.detach().cpu().numpy().astype(np.float64)
        x, y = p[:, 0], p[:, 1]
        ref = np.stack([-2.0 * (1.0 - x) - 400.0 * x * (y - x * x), 200.0 * (y - x * x)], axis=1)
        got = last[0].cpu().numpy().astype(np.float64)
        return float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1.0)))

    body()
    return body, error


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--iters", type=int, default=200)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--device", default="cpu", help="cpu or cuda:N (CUDA tensors)")
    args, _ = parser.parse_known_args()
    try:
        import torch
    except ImportError as err:
        print(f"torch is not installed ({err}): nothing to measure")
        return 0
    with bc.WeftSession() as (weft, _rt):
        weft_mod = bc.load_kernels(SOURCE, "weft", "interop")
        warp = bc.import_warp()
        warp_mod = bc.load_kernels(SOURCE, "warp", "interop") if warp is not None else None
        rows = []
        for i, mode in enumerate(MODES):
            # weft and warp-lang timed in turn, one run of each per round (interleaved_medians)
            bodies, errors = {}, {}
            for name, lib, mod in (("weft", weft, weft_mod), ("warp", warp, warp_mod)):
                if lib is not None:
                    bodies[name], errors[name] = prepare(lib, mod, torch, mode, args.n, args.iters,
                                                         100 + i, args.device)
            medians = bc.interleaved_medians(bodies, args.repeat)
            ws, we = medians["weft"] / args.iters, errors["weft"]()
            if warp is not None:
                ps, pe = medians["warp"] / args.iters, errors["warp"]()
            else:
                ps = pe = None
            rows.append([mode, bc.fmt_time(ws), f"{we:.1e}", bc.fmt_time(ps),
                         "n/a" if pe is None else f"{pe:.1e}", bc.fmt_ratio(ws, ps)])
        if args.device != "cpu":
            from weft.interop import cuda_order

            ordinal = int(args.device.split(":")[1]) if ":" in args.device else 0
            key = (_rt.session_id, ordinal)
            mechanism = "stream memory operations" if cuda_order.uses_values(_rt, ordinal) else \
                ("events" if cuda_order.enabled(_rt, {ordinal}) else "host synchronization")
            print(f"weft orders launches with Torch's stream by: {mechanism}")
            if cuda_order.uses_values(_rt, ordinal):
                saved, cuda_order._values[key] = cuda_order._values[key], None
                es, ee = run(weft, weft_mod, torch, "direct tensors", args.n, args.iters,
                             args.repeat, 102, args.device)
                cuda_order._values[key] = saved
                rows.append(["direct tensors (weft ordered by events)", bc.fmt_time(es), f"{ee:.1e}",
                             rows[-1][3], rows[-1][4], bc.fmt_ratio(es, ps)])
        bc.print_table(f"Torch interop, {args.device}: 5 conversions + 1 launch per iteration "
                       f"(n={args.n}, {args.iters} iterations x {args.repeat})",
                       ["mode", "weft", "weft err", "warp-lang", "warp err", "ratio"], rows)
        # weft, warp-lang, and weft with ArrayService calls through gRPC
        # (WEFT_FAST_LANE_ARRAYS=0: what the fast lane's array calls save), timed in turn
        bodies, errors = {}, {}
        bodies["weft"], errors["weft"] = prepare_rosenbrock(weft, weft_mod, torch, 1500, args.iters,
                                                            7, args.device)
        if warp is not None:
            bodies["warp"], errors["warp"] = prepare_rosenbrock(warp, warp_mod, torch, 1500,
                                                                args.iters, 7, args.device)
        grpc_body, errors["grpc"] = prepare_rosenbrock(weft, weft_mod, torch, 1500, args.iters, 7,
                                                       args.device)

        def over_grpc():
            lane_arrays, _rt.lane_arrays = _rt.lane_arrays, False
            try:
                grpc_body()
            finally:
                _rt.lane_arrays = lane_arrays

        bodies["grpc"] = over_grpc
        medians = bc.interleaved_medians(bodies, args.repeat)
        ws, we = medians["weft"] / args.iters, errors["weft"]()
        gs, ge = medians["grpc"] / args.iters, errors["grpc"]()
        ps = pe = None
        if warp is not None:
            ps, pe = medians["warp"] / args.iters, errors["warp"]()
        if args.device != "cpu":
            from weft import _cuda_ipc

            print(f"weft CUDA IPC: {_cuda_ipc.reason() or 'on'}; imports opened by weftd "
                  f"are cached per session")
        bc.print_table(f"Torch Rosenbrock autograd step, {args.device} (1500 points, "
                       f"{args.iters} iterations x {args.repeat})",
                       ["step", "weft", "weft err", "warp-lang", "warp err", "ratio"],
                       [["zeros + 2 launches + 4 conversions", bc.fmt_time(ws), f"{we:.1e}",
                         bc.fmt_time(ps), "n/a" if pe is None else f"{pe:.1e}", bc.fmt_ratio(ws, ps)],
                        ["the same, array calls over gRPC", bc.fmt_time(gs), f"{ge:.1e}",
                         bc.fmt_time(ps), "n/a" if pe is None else f"{pe:.1e}", bc.fmt_ratio(gs, ps)]])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
