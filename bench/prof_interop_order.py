"""Profile of the cost of ordering a weft launch with Torch's stream across the process boundary
(docs/interop.md, "Ordering"): per-launch time of a launch on imported Torch memory and where it
goes (the client-side event calls, the Submit that returns once weftd queued the batch), the
daemon round trip for batches of each composition (empty, launch, WAIT, RECORD, all three), an
ordered launch against a launch + synchronize (the host ordering it replaces) and asynchronous
launches (no round trip). Needs a GPU, Torch on CUDA and CUDA IPC in the client; error: the
imported tensor's final values against a float64 count of the launches (exact). Table printed
last. Usage: WEFT_DAEMON=... python3 bench/prof_interop_order.py [--device cuda:0] [--n 300]"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--n", type=int, default=300)
    args = ap.parse_args()
    import torch

    import weft as wp
    from weft import _cuda_ipc, _runtime
    from weft.interop import cuda_order
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    ordinal = int(args.device.split(":")[1])

    @wp.kernel
    def inc(a: wp.array(dtype=float)):
        i = wp.tid()
        a[i] = a[i] + 1.0

    m = 1024
    t = torch.zeros(m, device=args.device)
    a = wp.from_torch(t)
    own = wp.zeros(m, device=args.device)
    wp.launch(inc, dim=m, inputs=[a], device=args.device)
    wp.launch(inc, dim=m, inputs=[own], device=args.device)
    wp.synchronize()
    torch.cuda.synchronize()
    launches = 1
    if not cuda_order.enabled(rt, {ordinal}):
        print(f"event ordering is off: {cuda_order.refused() or 'WEFT_CUDA_EVENTS=0 / no IPC'}")
    rows = []
    n = args.n

    # where an ordered launch's time goes
    acc: dict = {}

    def timed(owner, name):
        fn = getattr(owner, name)

        def wrapper(*a_, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a_, **k)
            finally:
                acc[name] = acc.get(name, 0.0) + time.perf_counter() - t0
        setattr(owner, name, wrapper)
        return fn

    saved = [(o, nm, timed(o, nm)) for o, nm in
             ((cuda_order, "before"), (cuda_order, "after"), (cuda_order, "framework_stream"),
              (_cuda_ipc, "record_event"), (_cuda_ipc, "wait_event"), (rt, "run"))]
    t0 = time.perf_counter()
    for _ in range(n):
        wp.launch(inc, dim=m, inputs=[a], device=args.device)
    rows.append(("ordered launch on imported Torch memory", (time.perf_counter() - t0) / n))
    launches += n
    for o, nm, fn in saved:
        if o is rt:
            del rt.run            # back to the method
        else:
            setattr(o, nm, fn)
    for name, v in sorted(acc.items(), key=lambda kv: -kv[1]):
        rows.append((f"  of which {name}", v / n))
    wp.synchronize()

    def event_cmd(op):
        ev = _cuda_ipc.next_event(ordinal)
        _cuda_ipc.record_event(ev, 0)
        return exec_pb2.Command(cuda_event=exec_pb2.CudaEventCommand(
            op=op, device=args.device, ipc_handle=ev.handle))

    def batch(name, make):
        rt.synchronize()
        t0 = time.perf_counter()
        for _ in range(n):
            make()
            rt.run()
        rows.append((name, (time.perf_counter() - t0) / n))
        rt.synchronize()

    W, R = exec_pb2.CudaEventCommand.WAIT, exec_pb2.CudaEventCommand.RECORD
    batch("Submit(run) of []", lambda: None)
    batch("Submit(run) of [launch]", lambda: wp.launch(inc, dim=m, inputs=[own], device=args.device))
    batch("Submit(run) of [WAIT]", lambda: rt.submit(event_cmd(W)))
    batch("Submit(run) of [RECORD]", lambda: rt.submit(event_cmd(R)))
    batch("Submit(run) of [WAIT, launch, RECORD]",
          lambda: (rt.submit(event_cmd(W)), wp.launch(inc, dim=m, inputs=[own], device=args.device),
                   rt.submit(event_cmd(R))))
    t0 = time.perf_counter()
    for _ in range(n):
        wp.launch(inc, dim=m, inputs=[own], device=args.device)
        rt.synchronize()
    rows.append(("launch + synchronize", (time.perf_counter() - t0) / n))
    t0 = time.perf_counter()
    for _ in range(n):
        wp.launch(inc, dim=m, inputs=[own], device=args.device)
    rt.synchronize()
    rows.append(("asynchronous launches, one synchronize", (time.perf_counter() - t0) / n))
    torch.cuda.synchronize()
    got = t.cpu().numpy().astype(np.float64)
    error = float(np.max(np.abs(got - float(launches))))
    print(f"\nordering profile, {args.device}, {n} calls each (us per call); "
          f"error of the imported tensor vs float64 launch count: {error:.1e}")
    for name, seconds in rows:
        print(f"  {name:44s} {seconds * 1e6:9.1f}")


if __name__ == "__main__":
    main()
