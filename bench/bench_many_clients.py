"""Many clients at once: C client processes (default 64) each make L launches (default 10,000)
of a small kernel against one weftd, synchronizing every S launches (default 100) and timing
each synchronize (the round trip that runs the batch and waits for it). Prints a table: clients,
launches, errors, wall time, launches per second, p50/p99/max sync latency.
Error column: every launch adds 1 to a counter array of the client (wp.atomic_add over 64
threads); a client whose counters do not read exactly L at the end, or any exception, counts
as an error.

The clients are forked from one process that imported the client package once (no gRPC channel
exists before the fork), so they start in seconds. The daemon: $WEFT_DAEMON, else
<repo>/build/bin/weftd; it listens on a temp Unix socket and is stopped at the end.

    .venv/bin/python bench/bench_many_clients.py [--clients 64] [--launches 10000] [--sync-every 100]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO_ROOT / "clients" / "python"))

import bench_common as bc  # noqa: E402

CLIENT = """
import json, os, sys, time
import numpy as np
import weft as wp

@wp.kernel
def bump(counter: wp.array(dtype=int)):
    i = wp.tid()
    wp.atomic_add(counter, i, 1)

def client(launches, sync_every, out_fd):
    result = {"latencies": [], "errors": 0, "message": ""}
    try:
        wp.init()
        wp.set_device("cpu")
        counter = wp.zeros(64, dtype=int)
        wp.synchronize()
        for n in range(1, launches + 1):
            wp.launch(bump, dim=64, inputs=[counter])
            if n % sync_every == 0 or n == launches:
                t = time.perf_counter()
                wp.synchronize()
                result["latencies"].append(time.perf_counter() - t)
        got = counter.numpy()
        if not (got == launches).all():
            result["errors"] += 1
            result["message"] = f"counters {got.min()}..{got.max()}, expected {launches}"
    except Exception as e:  # noqa: BLE001 - an error is a measurement here
        result["errors"] += 1
        result["message"] = repr(e)[:300]
    os.write(out_fd, (json.dumps(result) + "\\n").encode())

clients, launches, sync_every = (int(a) for a in sys.argv[1:4])
read_fd, write_fd = os.pipe()
pids = []
for _ in range(clients):
    pid = os.fork()
    if pid == 0:
        os.close(read_fd)
        try:
            client(launches, sync_every, write_fd)
        finally:
            os._exit(0)
    pids.append(pid)
os.close(write_fd)
with os.fdopen(read_fd) as lines:
    for line in lines:
        sys.stdout.write(line)
for pid in pids:
    os.waitpid(pid, 0)
"""


def percentile(values, q):
    values = sorted(values)
    if not values:
        return None
    k = min(len(values) - 1, max(0, round(q / 100 * (len(values) - 1))))
    return values[k]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--clients", type=int, default=64)
    ap.add_argument("--launches", type=int, default=10000)
    ap.add_argument("--sync-every", type=int, default=100)
    args = ap.parse_args()

    daemon = bc.BenchDaemon()
    try:
        env = dict(os.environ, WEFT_ADDRESS=daemon.address,
                   PYTHONPATH=os.pathsep.join([str(REPO_ROOT / "clients" / "python")] +
                                              ([os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else [])))
        start = time.perf_counter()
        script = daemon.workdir / "many_clients.py"   # kernels must be defined in a file
        script.write_text(textwrap.dedent(CLIENT))
        proc = subprocess.run([sys.executable, str(script), str(args.clients),
                               str(args.launches), str(args.sync_every)],
                              env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
        results = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
        code, leftovers = daemon.stop()
    except BaseException:
        daemon.stop(keep=True)
        raise
    errors = sum(r["errors"] for r in results) + (args.clients - len(results))
    latencies = [x for r in results for x in r["latencies"]]
    total = args.clients * args.launches
    bc.print_table(
        f"{args.clients} clients x {args.launches} launches (sync every {args.sync_every}), one weftd",
        ["clients", "launches", "errors", "wall", "launches/s", "syncs", "p50 sync", "p99 sync", "max sync"],
        [[args.clients, total, errors, bc.fmt_time(wall), f"{total / wall:,.0f}", len(latencies),
          bc.fmt_time(percentile(latencies, 50)), bc.fmt_time(percentile(latencies, 99)),
          bc.fmt_time(max(latencies) if latencies else None)]])
    for r in results:
        if r["errors"]:
            print("  client error:", r["message"])
    if len(results) < args.clients:
        print(f"  {args.clients - len(results)} client(s) reported nothing; stderr:\n{proc.stderr[-2000:]}")
    print(f"  daemon exit code {code}, shared-memory files left: {len(leftovers)}")
    return 0 if errors == 0 and code == 0 and not leftovers else 1


if __name__ == "__main__":
    sys.exit(main())
