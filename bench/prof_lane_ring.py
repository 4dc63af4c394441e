"""The fast lane's ring against its socket (docs/protocol.md "Ring"), same daemon, same run:
client processes with each transport alternate for --rounds rounds against one weftd, each
timing a launch + synchronize loop (an empty kernel, and saxpy on 3 arrays whose result is
checked against float64) on every device given, and within it the launch call and the
synchronize call. Transports: `socket` (WEFT_LANE_RING=0 in the
client), `ring` (WEFT_LANE_EAGER=0) and `ring+eager` (the default where weftd offers rings: the
first GPU launch after a sync point sent at once). Prints per transport and case the
median over rounds of the median per iteration, and the ratio.

Usage: python3 bench/prof_lane_ring.py [--devices cpu,cuda:0] [--calls 2000] [--rounds 4]
(WEFT_DAEMON: the weftd; WEFT_LANE_POLLERS / WEFT_LANE_RING=1 make a machine of fewer than 4
cores offer rings, as the tests do)."""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

CLIENT = '''
import statistics, sys, time
import numpy as np
import weft as wp
from weft import _runtime

@wp.kernel
def empty_kernel():
    pass

@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]

device, calls = sys.argv[1], int(sys.argv[2])
lane = _runtime.get_runtime().fast_lane
n = 4096
rng = np.random.default_rng()
x0 = rng.uniform(-1, 1, n).astype(np.float32)
y0 = rng.uniform(-1, 1, n).astype(np.float32)
x = wp.array(x0, dtype=float, device=device)
y = wp.array(y0, dtype=float, device=device)
for case in ("empty", "saxpy"):
    times, launches, syncs = [], [], []
    for i in range(calls + 50):
        t = time.perf_counter()
        if case == "empty":
            wp.launch(empty_kernel, dim=1, device=device)
        else:
            wp.launch(saxpy, dim=n, inputs=[x, y, 0.5], device=device)
        t1 = time.perf_counter()
        wp.synchronize()
        t2 = time.perf_counter()
        if i >= 50:
            times.append(t2 - t)
            launches.append(t1 - t)
            syncs.append(t2 - t1)
    print(case, statistics.median(times) * 1e6, statistics.median(launches) * 1e6,
          statistics.median(syncs) * 1e6)
ref = y0.astype(np.float64)
for _ in range(calls + 50):
    ref = np.float32(0.5) * x0.astype(np.float64) + ref
err = float(np.max(np.abs(y.numpy() - ref)) / np.max(np.abs(ref)))   # relative to the largest
print("error", err)
print("ring", lane is not None and lane.ring is not None,
      "wakes", lane.ring.wakes_sent if lane is not None and lane.ring is not None else 0)
'''

TRANSPORTS = {"socket": {"WEFT_LANE_RING": "0"},
              "ring": {"WEFT_LANE_RING": "1", "WEFT_LANE_EAGER": "0"},
              "ring+eager": {"WEFT_LANE_RING": "1", "WEFT_LANE_EAGER": "1"}}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--devices", default=None, help="default: cpu, and cuda:0 when present")
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=4)
    args = ap.parse_args()
    import bench_common as bc  # noqa: PLC0415

    daemon = bc.BenchDaemon()
    results: dict = {}
    try:
        tmp = Path(tempfile.mkdtemp(prefix="weft-lane-ring-"))
        script = tmp / "lane_ring_client.py"       # kernels need a source file
        script.write_text(textwrap.dedent(CLIENT))
        env0 = dict(os.environ, WEFT_ADDRESS=daemon.address,
                    PYTHONPATH=os.pathsep.join([str(HERE.parent / "clients" / "python"),
                                                os.environ.get("PYTHONPATH", "")]))
        devices = args.devices.split(",") if args.devices else None
        if devices is None:
            probe = subprocess.run([sys.executable, "-c", "import weft; weft.init(); "
                                    "print(any(d.is_cuda for d in weft.get_devices()))"],
                                   env=env0, capture_output=True, text=True, timeout=120)
            devices = ["cpu"] + (["cuda:0"] if probe.stdout.strip().endswith("True") else [])
        for r in range(args.rounds):
            for name, extra in TRANSPORTS.items():
                for device in devices:
                    out = subprocess.run([sys.executable, str(script), device, str(args.calls)],
                                         env=dict(env0, **extra), capture_output=True, text=True,
                                         timeout=600)
                    if out.returncode != 0:
                        print(out.stdout, out.stderr, file=sys.stderr)
                        raise SystemExit(f"{name} {device}: client failed")
                    lines = dict(line.split(" ", 1) for line in out.stdout.strip().splitlines())
                    for case in ("empty", "saxpy"):
                        total, launch, sync = (float(v) for v in lines[case].split())
                        results.setdefault((device, case, name), []).append(total)
                        results.setdefault((device, case + " launch", name), []).append(launch)
                        results.setdefault((device, case + " sync", name), []).append(sync)
                    results.setdefault((device, "error", name), []).append(float(lines["error"]))
                    results[(device, "ring", name)] = lines["ring"]
            print(f"round {r + 1}/{args.rounds} done", flush=True)
    finally:
        daemon.stop()
    print(f"\nlaunch + synchronize, median over {args.rounds} rounds of the median of {args.calls} (us)")
    print(f"| device | case | {' | '.join(TRANSPORTS)} | ratio socket / ring+eager | error vs float64 |")
    print("| --- | --- | " + " | ".join("---" for _ in TRANSPORTS) + " | --- | --- |")
    for device in devices:
        for case in ("empty", "empty launch", "empty sync", "saxpy", "saxpy launch", "saxpy sync"):
            med = {name: statistics.median(results[(device, case, name)]) for name in TRANSPORTS}
            err = max(max(results[(device, "error", name)]) for name in TRANSPORTS)
            print(f"| {device} | {case} | " + " | ".join(f"{med[n]:.1f}" for n in TRANSPORTS) +
                  f" | {med['socket'] / med['ring+eager']:.2f} | {err:.1e} |")
    for device in devices:
        print(device, "client used the ring:", {n: results[(device, 'ring', n)] for n in TRANSPORTS})


if __name__ == "__main__":
    main()
