"""Compile time against kernel size: kernels of N statements in a few shapes (a scalar chain, a
chain of vec3 statements, N if/else blocks, N small loops), compiled for the CPU by one weftd
(--compile-time-limit 0: no limit, so that the full time shows). Columns: the daemon's whole
compile (compile_ms: parsing, type checking, code generation, clang -O2, loading), clang's share
(the daemon's debug log), their difference (weft's own pipeline), the size of the generated C++,
and warp-lang's cold compile of the same kernel (n/a when warp-lang is not installed).
The kernels compute nothing worth checking against float64; this benchmark only times compiles.

    .venv/bin/python bench/bench_compile_size.py [--shapes chain,vec,branch,loop] [--sizes 100,200,300]
"""
from __future__ import annotations

import argparse
import re
import sys
import time
import uuid
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import bench_common as bc  # noqa: E402


def body(shape: str, n: int) -> str:
    lines = []
    if shape == "chain":      # each statement uses the one before
        lines.append("a0 = x[i]")
        lines += [f"a{k} = a{k - 1} * {1.0 + k * 1e-3:.4f} + wp.sin(a{k - 1})" for k in range(1, n)]
        lines.append(f"y[i] = a{n - 1}")
    elif shape == "vec":      # vec3 temporaries
        lines.append("v0 = wp.vec3(x[i], x[i] * 2.0, 1.0)")
        lines += [f"v{k} = wp.cross(v{k - 1}, wp.vec3(1.0, {k}.0, 2.0)) * 0.5 + v{k - 1}" for k in range(1, n)]
        lines.append(f"y[i] = wp.length(v{n - 1})")
    elif shape == "branch":
        lines.append("a = x[i]")
        lines += [f"if a > {k * 0.01:.3f}:\n        a = a * 0.99 + {k}.0\n    else:\n        a = a + 1.0"
                  for k in range(n)]
        lines.append("y[i] = a")
    elif shape == "loop":
        lines.append("a = x[i]")
        lines += [f"for j in range(3):\n        a = a * 0.5 + float(j) * {k}.0" for k in range(n)]
        lines.append("y[i] = a")
    else:
        raise SystemExit(f"unknown shape {shape}")
    return "\n    ".join(lines)


def source(shape: str, n: int) -> str:
    return f'''
SALT = {uuid.uuid4().int % 10**9}

@wp.kernel
def k_{shape}_{n}(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    {body(shape, n)}
'''


CLANG_LINE = re.compile(r"cpu jit: (\S+) \((\d+) bytes of C\+\+\) in (?:a child process|process): ([0-9.]+) ms")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shapes", default="chain,vec,branch,loop")
    ap.add_argument("--sizes", default="100,200,300")
    args = ap.parse_args()
    daemon = bc.BenchDaemon(["--compile-time-limit", "0"], log_level="debug")
    rows = []
    warp = None
    try:
        import os
        os.environ["WEFT_ADDRESS"] = daemon.address
        import weft as wp
        wp.init()
        warp = bc.import_warp()
        for shape in args.shapes.split(","):
            for n in (int(s) for s in args.sizes.split(",")):
                text = source(shape, n)
                mod = bc.load_kernels(text, "weft", f"size_{shape}_{n}")
                start = time.perf_counter()
                report = wp.load_module(mod, device="cpu")
                wall = time.perf_counter() - start
                clang = [m for m in CLANG_LINE.finditer(daemon.log_path.read_text(errors="replace"))]
                clang_ms, cpp_bytes = (float(clang[-1].group(3)), int(clang[-1].group(2))) if clang else (None, None)
                warp_s = None
                if warp is not None:
                    wmod = bc.load_kernels(text, "warp", f"size_{shape}_{n}")
                    start = time.perf_counter()
                    warp.load_module(wmod, device="cpu")
                    warp_s = time.perf_counter() - start
                rows.append([shape, n, bc.fmt_time(report.compile_ms / 1e3),
                             bc.fmt_time(clang_ms / 1e3 if clang_ms is not None else None),
                             bc.fmt_time((report.compile_ms - clang_ms) / 1e3 if clang_ms is not None else None),
                             f"{cpp_bytes / 1e3:,.0f} kB" if cpp_bytes else "n/a", bc.fmt_time(wall),
                             bc.fmt_time(warp_s), bc.fmt_ratio(wall, warp_s)])
                print("  ", *rows[-1], flush=True)
    finally:
        daemon.stop()
    bc.print_table("module compile time vs kernel size, CPU, one kernel (cold: nothing cached)",
                   ["shape", "statements", "daemon compile", "clang -O2", "weft pipeline", "generated C++",
                    "client wall", "warp-lang", "ratio warp/weft"], rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
