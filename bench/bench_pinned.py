"""Host <-> GPU copies from pageable and pinned CPU arrays (`wp.copy`, Warp's pinned=True),
weft beside warp-lang on the same GPU in the same run.

Rows: CPU -> GPU and GPU -> CPU, each from a pageable and from a pinned CPU array of --mb MiB
(float32, fresh random data). Columns: time per copy (best of --repeat, each copy followed by a
device synchronize), GB/s, whether the result is bit-exact, warp-lang's time and the ratio
warp/weft (above 1: weft is faster). weft's pinned arrays are slabs of their own that weftd
page-locks (cuMemHostRegister); its copies run in the daemon.
Usage: python3 bench/bench_pinned.py [--mb 256] [--repeat 5] (starts its own weftd)."""
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


def measure(lib, n: int, repeat: int, host: np.ndarray) -> dict:
    """{(direction, kind): (seconds, exact)} for one library."""
    out = {}
    dev = lib.zeros(n, dtype=float, device="cuda:0")
    for kind, pinned in (("pageable", False), ("pinned", True)):
        src = lib.array(host, dtype=float, device="cpu", pinned=pinned)
        dst = lib.zeros(n, dtype=float, device="cpu", pinned=pinned)
        for direction in ("cpu -> gpu", "gpu -> cpu"):
            a, b = (dev, src) if direction == "cpu -> gpu" else (dst, dev)
            lib.copy(a, b)
            lib.synchronize_device("cuda:0")
            best = None
            for _ in range(repeat):
                t = time.perf_counter()
                lib.copy(a, b)
                lib.synchronize_device("cuda:0")
                dt = time.perf_counter() - t
                best = dt if best is None else min(best, dt)
            check = dev if direction == "cpu -> gpu" else dst
            out[(direction, kind)] = (best, bool(np.array_equal(check.numpy(), host)))
        del src, dst
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--mb", type=int, default=256)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    n = args.mb * (1 << 20) // 4
    host = np.random.default_rng().standard_normal(n).astype(np.float32)
    with bc.WeftSession() as (wp, _rt):
        if not any(d.is_cuda and d.is_compute_supported for d in wp.get_cuda_devices()):
            raise SystemExit("weftd has no CUDA device: nothing to measure")
        mine = measure(wp, n, args.repeat, host)
        page_locked = wp.zeros(4, dtype=float, device="cpu", pinned=True)._info.page_locked
    theirs = {}
    try:
        import warp  # noqa: PLC0415

        warp.config.quiet = True
        warp.init()
        theirs = measure(warp, n, args.repeat, host)
    except Exception as err:  # noqa: BLE001
        print(f"(warp-lang not available: {err})")
    print(f"\nhost <-> GPU copies of {args.mb} MiB (weft pinned arrays page-locked: {page_locked})")
    head = ("case", "weft", "GB/s", "exact", "warp-lang", "GB/s", "ratio warp/weft")
    print("  ".join(f"{h:>18}" for h in head))
    for key, (t, exact) in mine.items():
        w = theirs.get(key)
        row = (f"{key[0]}, {key[1]}", f"{t * 1e3:.2f} ms", f"{n * 4 / t / 1e9:.1f}", str(exact),
               f"{w[0] * 1e3:.2f} ms" if w else "n/a", f"{n * 4 / w[0] / 1e9:.1f}" if w else "n/a",
               f"{w[0] / t:.2f}" if w else "n/a")
        print("  ".join(f"{c:>18}" for c in row))


if __name__ == "__main__":
    main()
