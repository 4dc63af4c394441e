"""What a quiet Submit (docs/protocol.md, "Fast lane": answered only when it fails) saves where
each launch goes out as its own frame, as an ordered launch on framework memory does: launches
each followed by Runtime.send_now, in child clients of one weftd with WEFT_QUIET_SUBMIT=0 and 1
alternating (rounds), median per launch; and plain batched launches for comparison. After each
child's loop the array is checked against a float64 reference (every launch added its value).
Usage: python3 bench/prof_quiet_submit.py [--device cpu|cuda:0] [--launches 3000] [--rounds 3]
(WEFT_DAEMON: the weftd)"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

CHILD = r'''
import sys, time
import numpy as np
sys.path.insert(0, {client!r})
import weft as wp
from weft import _runtime

@wp.kernel
def add(a: wp.array(dtype=float), b: wp.array(dtype=float), c: wp.array(dtype=float), x: float):
    i = wp.tid()
    c[i] = c[i] + a[i] * b[i] + x

device, launches, mode = {device!r}, {launches}, {mode!r}
rng = np.random.default_rng()
a0 = rng.uniform(0.5, 1.5, 64).astype(np.float32)
b0 = rng.uniform(0.5, 1.5, 64).astype(np.float32)
a = wp.array(a0, dtype=float, device=device)
b = wp.array(b0, dtype=float, device=device)
c = wp.zeros(64, dtype=float, device=device)
rt = _runtime.get_runtime()
for _ in range(50):
    wp.launch(add, dim=64, inputs=[a, b, c, 0.25], device=device)
wp.synchronize()
t0 = time.perf_counter()
for _ in range(launches):
    wp.launch(add, dim=64, inputs=[a, b, c, 0.25], device=device)
    if mode == "send each":
        rt.send_now()
wp.synchronize()
per = (time.perf_counter() - t0) / launches
ref = (launches + 50) * (a0.astype(np.float64) * b0.astype(np.float64) + 0.25)
err = float(np.max(np.abs(c.numpy() - ref) / ref))
print(f"{{per * 1e6:.3f}} {{err:.2e}} {{int(rt.fast_lane is not None and rt.fast_lane.quiet)}}")
'''


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--launches", type=int, default=3000)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    sys.path.insert(0, str(HERE))
    import bench_common as bc

    import tempfile

    daemon = bc.BenchDaemon()
    workdir = Path(tempfile.mkdtemp(prefix="weft-quiet-"))
    try:
        results: dict = {}
        for _ in range(args.rounds):
            for mode in ("send each", "batched"):
                for quiet in ("0", "1"):
                    code = CHILD.format(client=str(HERE.parent / "clients" / "python"),
                                        device=args.device, launches=args.launches, mode=mode)
                    script = workdir / "child.py"     # kernels need their source in a file
                    script.write_text(code)
                    env = dict(os.environ, WEFT_ADDRESS=daemon.address, WEFT_QUIET_SUBMIT=quiet)
                    proc = subprocess.run([sys.executable, str(script)], env=env,
                                          capture_output=True, text=True, timeout=600)
                    if proc.returncode != 0:
                        raise SystemExit(f"child client failed:\n{proc.stdout}\n{proc.stderr}")
                    out = proc.stdout.split()
                    per, err, used = float(out[0]), float(out[1]), out[2] == "1"
                    results.setdefault((mode, quiet), []).append((per, err, used))
        rows = []
        for mode in ("send each", "batched"):
            off = statistics.median(r[0] for r in results[(mode, "0")])
            on = statistics.median(r[0] for r in results[(mode, "1")])
            err = max(r[1] for key in ((mode, "0"), (mode, "1")) for r in results[key])
            used = all(r[2] for r in results[(mode, "1")])
            rows.append([f"launch, {mode}", f"{off:.2f} us", f"{on:.2f} us" + ("" if used else " (not offered)"),
                         f"{1e6 / on / 1e3:.1f} k/s", f"{off / on:.2f}x", f"{err:.1e}"])
        bc.print_table(f"Quiet Submits, {args.device}: 3-array launch, median of {args.rounds} child "
                       f"clients x {args.launches} launches",
                       ["case", "plain Submit", "quiet Submit", "launches/s (quiet)", "plain / quiet",
                        "err vs float64"], rows)
    finally:
        daemon.stop()
        import shutil

        shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    main()
