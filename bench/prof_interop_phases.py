"""Where an ordered launch on Torch GPU memory spends its time in the client, phase by phase,
without cProfile's distortion: the loop of bench_interop (five conversions + one launch per
iteration, or the tensors passed directly; mode "rosenbrock": one step of the Torch Rosenbrock
autograd example, as bench_interop's second table) runs once plain and once with perf_counter timers
wrapped around the client's steps (each timer's time is inclusive of what it calls; a
timer costs ~0.3 us, so the instrumented total is a little higher). Then the primitive costs
alone: a stream write through ctypes, a Command copy, a fast-lane send.

Needs a GPU, Torch on CUDA and CUDA IPC in the client.
Usage: WEFT_DAEMON=... python3 bench/prof_interop_phases.py [--iters 2000]"""
from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
# --client DIR: another copy of the Python client (a folder holding weft/), for A/B runs
_CLIENT = sys.argv[sys.argv.index("--client") + 1] if "--client" in sys.argv else \
    str(HERE.parent / "clients" / "python")
sys.path.insert(0, _CLIENT)
sys.path.insert(0, str(HERE))

import bench_common as bc  # noqa: E402
from bench_interop import SOURCE, rosenbrock_step  # noqa: E402

_totals: dict = defaultdict(float)
_calls: dict = defaultdict(int)


def _wrap(owner, name, label):
    original = getattr(owner, name)
    perf = time.perf_counter

    def timed(*args, **kwargs):
        t0 = perf()
        try:
            return original(*args, **kwargs)
        finally:
            _totals[label] += perf() - t0
            _calls[label] += 1

    setattr(owner, name, timed)
    return lambda: setattr(owner, name, original)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=2000)
    ap.add_argument("--client", help="a folder holding another weft client package (A/B)")
    ap.add_argument("--modes", default="direct,ctype,from_torch,weft arrays,launch+sync",
                    help="comma-separated modes to run")
    ap.add_argument("--plain", action="store_true", help="only the plain timings (no timers)")
    args = ap.parse_args()
    import torch

    with bc.WeftSession() as (wp, rt):
        import weft._cuda_ipc as cuda_ipc
        import weft._fast_lane as fast_lane
        import weft._runtime as runtime_mod
        import weft.interop.cuda_order as cuda_order
        import weft.interop.memory as interop_memory
        import weft.interop.torch as interop_torch
        import weft.interop.cuda_import as cuda_import
        import weft.interop.external as external
        import weft.interop.dlpack as interop_dlpack
        import weft._dlpack as dlpack_producer
        import torch.utils.dlpack as torch_dlpack
        array_mod = sys.modules["weft.array"]

        launch_mod = sys.modules["weft._kernel.launch"]   # weft._kernel.launch is also a function

        mod = bc.load_kernels(SOURCE, "weft", "interop_phases")
        n = 1024
        ts = [torch.randn(n, device="cuda") for _ in range(4)] + [torch.zeros(n, device="cuda")]
        weft_arrays = [wp.array(t.cpu().numpy(), device="cuda:0") for t in ts]

        rn = 1500
        xy = torch.rand((rn, 2), device="cuda", requires_grad=True)

        def loop(mode, iters):
            for _ in range(iters):
                if mode == "rosenbrock":
                    rosenbrock_step(wp, mod, torch, xy, rn, "cuda:0")
                    continue
                if mode == "direct":
                    a = ts
                elif mode in ("weft arrays", "launch+sync"):
                    a = weft_arrays
                else:
                    a = [wp.from_torch(t, return_ctype=mode == "ctype") for t in ts]
                wp.launch(mod.inc5, dim=n, inputs=a, device="cuda:0")
                if mode == "launch+sync":
                    wp.synchronize()

        def timed(mode):
            loop(mode, 50)
            wp.synchronize()
            torch.cuda.synchronize()
            best = None
            for _ in range(3):
                t0 = time.perf_counter()
                loop(mode, args.iters)
                wp.synchronize()
                torch.cuda.synchronize()
                dt = (time.perf_counter() - t0) / args.iters
                best = dt if best is None else min(best, dt)
            return best

        modes = [m.strip() for m in args.modes.split(",") if m.strip()]
        plain = {m: timed(m) for m in modes}
        if args.plain:
            print(f"client: {wp.__file__} WEFT_QUIET_SUBMIT={os.environ.get('WEFT_QUIET_SUBMIT', '1')}")
            for m in modes:
                print(f"  {m:<12} {plain[m] * 1e6:8.1f} us")
            return

        targets = [
            (launch_mod, "_pack_fast", "launch: _pack_fast"),
            (launch_mod, "_order_framework_gpu", "launch: order before (all)"),
            (launch_mod, "caller_origin", "launch: caller_origin"),
            (launch_mod, "_launch_plan", "launch: _launch_plan"),
            (launch_mod, "_launch_device", "launch: _launch_device"),
            (interop_memory, "touches_shared", "launch: touches_shared"),
            (cuda_order, "before", "order: before"),
            (cuda_order, "after", "order: after (all)"),
            (cuda_order, "framework_stream", "order: framework_stream"),
            (cuda_order, "enabled", "order: enabled"),
            (cuda_order._ValueOrder, "command", "order: command()"),
            (cuda_ipc, "write_value", "cuda: write_value"),
            (cuda_ipc, "wait_value", "cuda: wait_value"),
            (runtime_mod.Runtime, "submit", "rt.submit"),
            (runtime_mod.Runtime, "send_now", "rt.send_now"),
            (runtime_mod.Runtime, "_send_batch", "rt._send_batch"),
            (runtime_mod.Runtime, "_collect_done", "rt._collect_done"),
            (fast_lane.FastLane, "_send", "lane._send (syscall)"),
            (fast_lane.PendingReply, "result", "lane reply.result"),
            (fast_lane.PendingReply, "done", "lane reply.done (select)"),
            (interop_torch, "from_torch", "from_torch"),
            (runtime_mod.Runtime, "synchronize", "rt.synchronize"),
            (runtime_mod.Runtime, "_exec", "rt._exec"),
            (runtime_mod.Runtime, "_drain_frees", "rt._drain_frees"),
            (runtime_mod, "_report_sync", "_report_sync"),
            (fast_lane.FastLane, "_receive", "lane._receive"),
            (fast_lane.FastLane, "_poll", "lane._poll (waiting)"),
            (fast_lane.FastLane, "call", "lane.call (round trip)"),
            (fast_lane.FastLane, "call_many", "lane.call_many"),
            (interop_torch, "to_torch", "to_torch"),
            (cuda_import, "import_torch", "import: import_torch"),
            (cuda_import, "import_memory", "import: import_memory"),
            (cuda_import, "_fresh", "import: _fresh"),
            (external, "find_cuda_in_place", "import: find_cuda_in_place"),
            (cuda_ipc, "export_allocation", "cuda: export_allocation"),
            (interop_dlpack, "_export_cuda", "dlpack: _export_cuda"),
            (cuda_order, "ready", "order: ready"),
            (runtime_mod.Runtime, "synchronize_if_needed", "rt.synchronize_if_needed"),
            (dlpack_producer, "to_capsule", "dlpack: to_capsule"),
            (torch_dlpack, "from_dlpack", "torch from_dlpack"),
            (array_mod, "_create", "array: _create"),
            (array_mod, "zeros", "wp.zeros"),
            (array_mod.array, "_adopt", "array: _adopt"),
            (array_mod.array, "_set_daemon_grad", "array: _set_daemon_grad"),
            (interop_memory, "grad_view", "memory: grad_view"),
            (runtime_mod.Runtime, "array_call", "rt.array_call"),
            (runtime_mod.Runtime, "drain_frees", "rt.drain_frees"),
        ]
        restore = [_wrap(o, name, label) for o, name, label in targets]
        array_call = runtime_mod.Runtime.array_call

        def counted_array_call(self, method, request):   # which round trips, per iteration
            _calls[f"rt.array_call {method}"] += 1
            return array_call(self, method, request)

        runtime_mod.Runtime.array_call = counted_array_call
        restore.append(lambda: setattr(runtime_mod.Runtime, "array_call", array_call))
        wp.from_torch = interop_torch.from_torch
        wp.to_torch = interop_torch.to_torch
        wp.zeros = array_mod.zeros
        rows = []
        try:
            for mode in modes:
                _totals.clear()
                _calls.clear()
                loop(mode, 50)
                wp.synchronize()
                torch.cuda.synchronize()
                _totals.clear()
                _calls.clear()
                t0 = time.perf_counter()
                loop(mode, args.iters)
                wp.synchronize()
                torch.cuda.synchronize()
                total = (time.perf_counter() - t0) / args.iters
                rows.append((mode, total, dict(_totals), dict(_calls)))
        finally:
            for r in restore:
                r()
            wp.from_torch = interop_torch.from_torch
            wp.to_torch = interop_torch.to_torch
            wp.zeros = array_mod.zeros

        # primitives
        order = cuda_order._values.get((rt.session_id, 0))
        prims = []
        if order is not None:
            k = 20000
            t0 = time.perf_counter()
            for i in range(k):
                cuda_ipc.write_value(0, 0, order.address + 8 * 31, i)
            prims.append(("write_value on stream 0", (time.perf_counter() - t0) / k))
            s = torch.cuda.Stream()
            raw = int(s.cuda_stream)
            t0 = time.perf_counter()
            for i in range(k):
                cuda_ipc.write_value(0, raw, order.address + 8 * 31, i)
            prims.append(("write_value on a stream of its own", (time.perf_counter() - t0) / k))
            torch.cuda.synchronize()
            pb = cuda_order._pb()
            t0 = time.perf_counter()
            for i in range(k):
                order.command(pb.CudaValueCommand.WAIT, 1, i)
            prims.append(("ValueOrder.command()", (time.perf_counter() - t0) / k))
            t0 = time.perf_counter()
            for i in range(k):
                cuda_order.framework_stream(0)
            prims.append(("framework_stream(0)", (time.perf_counter() - t0) / k))
            t0 = time.perf_counter()
            for i in range(k):
                launch_mod.caller_origin()
            prims.append(("caller_origin()", (time.perf_counter() - t0) / k))
            t0 = time.perf_counter()
            for i in range(k):
                time.perf_counter()
            prims.append(("time.perf_counter()", (time.perf_counter() - t0) / k))
            t0 = time.perf_counter()
            for i in range(k):
                os.getpid()
            prims.append(("os.getpid()", (time.perf_counter() - t0) / k))
            code = loop.__code__
            t0 = time.perf_counter()
            for i in range(k):
                hash(code)
            prims.append(("hash(code of the loop)", (time.perf_counter() - t0) / k))
            frame = sys._getframe(0)
            t0 = time.perf_counter()
            for i in range(k):
                frame.f_lineno
            prims.append(("frame.f_lineno (main)", (time.perf_counter() - t0) / k))
        print(f"\nclient: {wp.__file__}")
        print(f"per iteration, best of 3 x {args.iters}, n={n} (weft only):")
        for m in modes:
            print(f"  {m:<12} {plain[m] * 1e6:8.1f} us")
        for mode, total, totals, calls in rows:
            print(f"\n{mode}: instrumented {total * 1e6:.1f} us per iteration (plain "
                  f"{plain[mode] * 1e6:.1f}); per iteration, inclusive:")
            for label, _ in sorted(totals.items(), key=lambda kv: -kv[1]):
                print(f"  {label:<30} {totals[label] / args.iters * 1e6:8.2f} us   "
                      f"{calls[label] / args.iters:5.2f} calls")
            for label in sorted(k for k in calls if k not in totals):
                print(f"  {label:<30} {'':>8}      {calls[label] / args.iters:5.2f} calls")
        print("\nprimitives:")
        for label, dt in prims:
            print(f"  {label:<36} {dt * 1e6:8.2f} us")


if __name__ == "__main__":
    main()
