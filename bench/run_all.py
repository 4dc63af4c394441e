"""Runs every weft benchmark (compile, launch overhead, kernels, foundation, bounds checks,
lazy adjoint, the loops' cancellation poll, 64 concurrent clients, tiles, marching cubes) and prints their tables.
Arguments are passed to every benchmark.
`make bench` installs warp-lang first so each table has a warp-lang ratio column."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHES = ["bench_compile.py", "bench_launch.py", "bench_kernels.py", "bench_foundation.py",
           "bench_bounds_checks.py", "bench_lazy_adjoint.py", "bench_interop.py",
           "bench_cancel_poll.py", "bench_many_clients.py", "bench_tiles.py", "bench_iso_surface.py"]


def main() -> int:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), str(HERE.parent / "clients" / "python")] +
                                        ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    failed = []
    for name in BENCHES:
        print(f"\n=== {name} ===", flush=True)
        proc = subprocess.run([sys.executable, str(HERE / name)] + sys.argv[1:], env=env)
        if proc.returncode != 0:
            failed.append(name)
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
