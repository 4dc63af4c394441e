"""What opening a session costs, ordinary and isolated: a weftd of this build started twice on a
temporary socket, once plain and once with --isolate-sessions, and ten SessionService.Open calls
timed on each (for an isolated session the Open that starts a session host, then the Open in
that host, as the client does). Prints the median and the fastest in milliseconds.
Usage: python3 bench/prof_session_open.py [--weftd build/bin/weftd] [--opens 10]"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import grpc  # noqa: E402

from weft import _runtime  # noqa: E402
from weft.v1 import session_pb2  # noqa: E402


def open_times(weftd: str, flags: list, opens: int) -> list:
    workdir = tempfile.mkdtemp(prefix="weft-open-")
    sock = f"{workdir}/weftd.sock"
    daemon = subprocess.Popen([weftd, "--listen", f"unix:{sock}", "--cache-dir", f"{workdir}/cache", *flags],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 30
        while not os.path.exists(sock):
            if time.monotonic() > deadline or daemon.poll() is not None:
                raise RuntimeError(f"weftd did not start ({' '.join(flags)})")
            time.sleep(0.05)
        times = []
        for _ in range(opens):
            channel = grpc.insecure_channel(f"unix:{sock}")
            start = time.perf_counter()
            reply = _runtime.SessionServiceStub(channel).Open(
                session_pb2.OpenSessionRequest(client_name="prof_session_open"), timeout=90)
            if reply.session_host:
                host = grpc.insecure_channel("unix:" + reply.session_host)
                _runtime.SessionServiceStub(host).Open(
                    session_pb2.OpenSessionRequest(client_name="prof_session_open"), timeout=90)
                host.close()
            times.append(time.perf_counter() - start)
            channel.close()
            time.sleep(0.2)
        return times
    finally:
        daemon.terminate()
        daemon.wait()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--weftd", default=str(HERE.parent / "build" / "bin" / "weftd"))
    ap.add_argument("--opens", type=int, default=10)
    args = ap.parse_args()
    for label, flags in (("ordinary", []),
                         ("isolated (a session host started)",
                          ["--isolate-sessions", "--max-session-hosts", str(args.opens + 2),
                           "--attach-timeout", "2"])):
        t = open_times(args.weftd, flags, args.opens)
        print(f"{label:36s} Open: median {statistics.median(t) * 1e3:7.1f} ms, "
              f"fastest {min(t) * 1e3:7.1f} ms ({args.opens} opens)", flush=True)


if __name__ == "__main__":
    main()
