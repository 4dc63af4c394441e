"""The client's Python in one `wp.launch` call, with nothing sent: the batch is held (the
runtime's pump_held), so the time is the launch call's own work (argument packing, the
command, queueing). Per case (an empty kernel and a 3-array one, on `cpu` and on `cuda:0` when
weftd computes there): the median time per call over rounds of --calls launches, then
cProfile's top entries of one more round (--profile). Python's version and the machine's CPU
are printed first: the same client costs 3x more on a slower host.
Usage: python3 bench/prof_launch_call.py [--calls 3000] [--profile]   (WEFT_DAEMON: the weftd)"""
from __future__ import annotations

import argparse
import cProfile
import io
import platform
import pstats
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

from prof_launch_sync import SOURCE  # noqa: E402  (the same empty and 3-array kernels)


def cpu_model() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--calls", type=int, default=3000)
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args()
    import bench_common as bc  # noqa: PLC0415
    import weft as wp  # noqa: PLC0415
    from weft import _runtime  # noqa: PLC0415

    print(f"python {platform.python_version()} on {cpu_model()}")
    wp.init()
    mod = bc.load_kernels(SOURCE, "weft", "prof_lc")
    rt = _runtime.get_runtime()
    devices = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])
    for dev in devices:
        arrays = [wp.zeros(16, dtype=float, device=dev) for _ in range(3)]
        for name, kernel, inputs in (("empty", mod.empty_kernel, []), ("three", mod.three_args, arrays)):
            wp.launch(kernel, dim=1, inputs=inputs, device=dev)
            wp.synchronize()
            best = float("inf")
            for _ in range(5):
                rt.pump_held = 1          # nothing sent: the launch call alone
                t = time.perf_counter()
                for _ in range(args.calls):
                    wp.launch(kernel, dim=1, inputs=inputs, device=dev)
                best = min(best, (time.perf_counter() - t) / args.calls)
                rt.pump_held = 0
                wp.synchronize()
            print(f"{name}@{dev:8s} launch call {best * 1e6:6.2f} us (best of 5 rounds of {args.calls})",
                  flush=True)
            if args.profile:
                rt.pump_held = 1
                prof = cProfile.Profile()
                prof.enable()
                for _ in range(args.calls):
                    wp.launch(kernel, dim=1, inputs=inputs, device=dev)
                prof.disable()
                rt.pump_held = 0
                wp.synchronize()
                s = io.StringIO()
                pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(14)
                print("\n".join(s.getvalue().splitlines()[4:22]), flush=True)


if __name__ == "__main__":
    main()
