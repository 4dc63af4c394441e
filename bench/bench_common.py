"""Shared helpers of the weft benchmarks: loading the same kernel source under weft and under
warp-lang (a generated module per library), timing, and printing tables."""
from __future__ import annotations

import importlib.util
import os
import statistics
import sys
import tempfile
import textwrap
import time
from pathlib import Path

_GEN_DIR = Path(tempfile.mkdtemp(prefix="weft-bench-"))


def load_kernels(source: str, library: str, tag: str):
    """Imports `source` (kernel code using `wp.`) with `import <library> as wp` as a module
    written to a temp file (kernels need a file); returns the module."""
    name = f"bench_{tag}_{library.replace('-', '_')}"
    path = _GEN_DIR / f"{name}.py"
    path.write_text(f"import {library} as wp\n\n" + textwrap.dedent(source))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def import_warp():
    """warp-lang initialised for the CPU, or None (with the reason printed) when missing."""
    try:
        import warp  # noqa: PLC0415
    except Exception as err:  # noqa: BLE001
        print(f"(warp-lang not available: {err}; its columns show n/a)")
        return None
    cache = os.environ.get("WEFT_BENCH_WARP_CACHE") or tempfile.mkdtemp(prefix="warp-cache-")
    warp.config.kernel_cache_dir = cache
    warp.config.quiet = True
    warp.init()
    return warp


def median_time(fn, repeat: int = 5, min_time: float = 0.0) -> float:
    """Median wall time of fn() over `repeat` runs (seconds)."""
    times = []
    start = time.perf_counter()
    while len(times) < repeat or time.perf_counter() - start < min_time:
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
        if len(times) > 1000:
            break
    return statistics.median(times)


def fmt_time(seconds) -> str:
    if seconds is None:
        return "n/a"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.1f} us"
    if seconds < 1:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"


def fmt_ratio(weft_s, warp_s) -> str:
    if weft_s is None or warp_s is None or weft_s == 0:
        return "n/a"
    return f"{warp_s / weft_s:.2f}x"


def print_table(title: str, header: list, rows: list) -> None:
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(header)]
    print(f"\n{title}")
    print("  " + "  ".join(str(h).rjust(w) for h, w in zip(header, widths)))
    print("  " + "  ".join("-" * w for w in widths))
    for r in rows:
        print("  " + "  ".join(str(c).rjust(w) for c, w in zip(r, widths)))
