"""Does where x and y sit change the saxpy kernel's time? saxpy (y = a*x + y) at n elements
with x and y as separate arrays, then as two slices of one allocation whose starts are n + pad
elements apart (pad 0, 64 B, 4 KiB, 1 MiB + 4 KiB, 2 MiB), under weft and warp-lang in the same
run: per-launch time as the slope between rounds of 4 and 32 launches (one sync each), and the
distance between the two device pointers. Usage: python3 bench/prof_saxpy_placement.py
[--n 1e7]   (GPU machine; WEFT_DAEMON and warp-lang on PYTHONPATH)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import bench_common as bc  # noqa: E402
import bench_cuda  # noqa: E402
import bench_cuda_sync  # noqa: E402

# The kernels of bench/bench_cuda.py (saxpy, integrate), so both measure the same code.
SOURCE = bench_cuda.SOURCE


def slope(lib, fn) -> float:
    """Seconds per launch: the slope between rounds of 4 and 32 launches (bench_cuda_sync's)."""
    fn()
    return (bench_cuda_sync.round_time(lib, fn, 32, rounds=3) - bench_cuda_sync.round_time(lib, fn, 4)) / 28


def cases(lib, n: int):
    mod = bc.load_kernels(SOURCE, lib.__name__, "placement")
    dev = "cuda:0"
    rng = np.random.default_rng()
    out = []
    x = lib.array(rng.standard_normal(n).astype(np.float32), dtype=float, device=dev)
    y = lib.array(rng.standard_normal(n).astype(np.float32), dtype=float, device=dev)
    t = slope(lib, lambda: lib.launch(mod.saxpy, dim=n, inputs=[x, y, 2.0], device=dev))
    out.append(("separate arrays", y.ptr - x.ptr, t))
    del x, y
    for pad_bytes in (0, 64, 4096, (1 << 20) + 4096, 2 << 20):
        pad = pad_bytes // 4
        big = lib.array(rng.standard_normal(2 * n + pad).astype(np.float32), dtype=float, device=dev)
        x, y = big[0:n], big[n + pad:2 * n + pad]
        t = slope(lib, lambda: lib.launch(mod.saxpy, dim=n, inputs=[x, y, 2.0], device=dev))
        out.append((f"one allocation, pad {pad_bytes} B", y.ptr - x.ptr, t))
        del x, y, big
    lib.synchronize()
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=float, default=1e7)
    args = ap.parse_args()
    n = int(args.n)
    results = {}
    with bc.WeftSession() as (weft, _rt):
        results["weft"] = cases(weft, n)
    warp = bc.import_warp()
    if warp is not None:
        results["warp"] = cases(warp, n)
    print(f"\nsaxpy n={n}: per-launch slope (us), y.ptr - x.ptr (bytes)")
    for i, (name, _d, _t) in enumerate(results["weft"]):
        row = f"  {name:34s}"
        for lib in ("weft", "warp"):
            if lib in results:
                _n, d, t = results[lib][i]
                row += f"  {lib} {t * 1e6:8.1f} us ({12 * n / t / 1e9:6.0f} GB/s) dist {d}"
        print(row)


if __name__ == "__main__":
    main()
