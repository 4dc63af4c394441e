"""Foundation benchmark of weft (no kernels): session open/close, array create/free, numpy()
zero-copy mapping, fill + numpy round trips, and bulk transfer over TCP (chunked gRPC streams,
with a token) against the Unix socket (shared memory through numpy()), each next to warp-lang on
the CPU where the same operation exists there.

It starts its own weftd ($WEFT_DAEMON, else <repo>/build/bin/weftd, else
<repo>/build-B1/bin/weftd) listening on a temp Unix socket and on a TCP port of 127.0.0.1 with a
token file, times every operation N times after warmup runs (median and p90), checks every
measured result (read-back equals the written random data, fills hold the value, sizes and
handles are right), prints one table and writes it as markdown to out/bench/foundation.md.
Exit status 1 when any check failed or the daemon did not stop cleanly.

    .venv/bin/python bench/bench_foundation.py [--repeat N] [--warmup W] [--out PATH]
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "clients" / "python"))
sys.path.insert(0, str(REPO_ROOT / "bench"))
import bench_common as bc  # noqa: E402

KIB = 1 << 10
MIB = 1 << 20
GIB = 1 << 30
TRANSFER_BYTES = 256 * MIB
NUMPY_BYTES = 1 * GIB


# ------------------------------------------------------------------------------------------
# The daemon


# ------------------------------------------------------------------------------------------
# Timing


@dataclass
class Measure:
    """The timed runs of one operation (warmup excluded) and whether every check passed."""

    times: list = field(default_factory=list)
    ok: bool = True
    failures: list = field(default_factory=list)

    def median(self):
        return statistics.median(self.times) if self.times else None

    def p90(self):
        return float(np.percentile(self.times, 90)) if self.times else None


def measure(body, check, repeat: int, warmup: int, setup=None) -> Measure:
    """Runs setup() (untimed), body(state) (timed), check(state, result) (untimed) for
    warmup + repeat runs; keeps the times of the last `repeat`. A check returns True or a
    string saying what is wrong; an exception in body/check is a failure too."""
    result = Measure()
    for run in range(warmup + repeat):
        state = setup() if setup is not None else None
        try:
            start = time.perf_counter()
            out = body(state)
            elapsed = time.perf_counter() - start
            verdict = check(state, out)
        except Exception as err:  # noqa: BLE001 - reported in the ok column
            result.ok = False
            result.failures.append(f"run {run}: {type(err).__name__}: {err}")
            continue
        if verdict is not True:
            result.ok = False
            result.failures.append(f"run {run}: {verdict}")
        if run >= warmup:
            result.times.append(elapsed)
        del out, state
    return result


@dataclass
class Row:
    operation: str
    weft: Measure
    nbytes: int = 0              # bytes moved per run, for the throughput column
    warp: Measure | None = None  # the same operation under warp-lang on the CPU


def fmt_time(seconds) -> str:
    if seconds is None:
        return "n/a"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.1f} us"
    if seconds < 1:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"


def fmt_throughput(nbytes: int, seconds) -> str:
    if not nbytes or not seconds:
        return ""
    return f"{nbytes / MIB / seconds:,.0f} MiB/s"


def table_rows(rows: list[Row]) -> list[list[str]]:
    out = []
    for row in rows:
        weft_median = row.weft.median()
        warp_median = row.warp.median() if row.warp is not None else None
        ratio = (f"{warp_median / weft_median:.2f}x" if warp_median and weft_median else "n/a")
        ok = row.weft.ok and (row.warp is None or row.warp.ok)
        out.append([row.operation, fmt_time(weft_median), fmt_time(row.weft.p90()),
                    fmt_throughput(row.nbytes, weft_median), fmt_time(warp_median), ratio,
                    "ok" if ok else "FAIL"])
    return out


HEADER = ["operation", "median", "p90", "throughput", "warp", "ratio", "ok"]
LEGEND = ("median/p90: weft wall time per operation over the timed runs (warmup excluded); "
          "throughput from the median; warp: warp-lang's median for the same operation on its "
          "CPU device (n/a where warp has no counterpart or is not installed); ratio = warp "
          "median / weft median (> 1: weft is faster); ok: every run's result was checked.")


def print_table(rows: list[list[str]]) -> None:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(HEADER)]
    print("  ".join(h.ljust(w) if i == 0 else h.rjust(w)
                    for i, (h, w) in enumerate(zip(HEADER, widths))))
    print("  ".join("-" * w for w in widths))
    for r in rows:
        print("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                        for i, (c, w) in enumerate(zip(r, widths))))


def markdown_table(rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(HEADER) + " |",
             "|" + "|".join(["---"] + ["---:"] * (len(HEADER) - 2) + [":---:"]) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------
# warp-lang


def import_warp():
    """warp-lang initialised on the CPU, or None (with the reason) when it is missing."""
    try:
        import warp  # noqa: PLC0415
    except Exception as err:  # noqa: BLE001
        print(f"(warp-lang not importable: {err}; the warp column shows n/a)")
        return None
    warp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="warp-cache-")
    warp.config.quiet = True
    warp.init()
    return warp


# ------------------------------------------------------------------------------------------
# The measurements


def _equal(expected: np.ndarray, got: np.ndarray) -> bool | str:
    if got.shape != expected.shape or got.dtype != expected.dtype:
        return f"got {got.dtype}{got.shape}, expected {expected.dtype}{expected.shape}"
    if not np.array_equal(got, expected):
        bad = int(np.count_nonzero(got != expected))
        return f"{bad} of {expected.size} elements differ from the written data"
    return True


def _all_equal(values: np.ndarray, value, shape, dtype) -> bool | str:
    if values.shape != tuple(shape) or values.dtype != np.dtype(dtype):
        return f"got {values.dtype}{values.shape}, expected {np.dtype(dtype)}{tuple(shape)}"
    bad = int(np.count_nonzero(values != value))
    return True if bad == 0 else f"{bad} of {values.size} elements are not {value}"


class RandomWords:
    """Fresh random uint32 data per run without paying a full RNG pass each time."""

    def __init__(self, count: int, seed: int = 12345):
        self.rng = np.random.default_rng(seed)
        self.base = self.rng.integers(0, 2**32, size=count, dtype=np.uint32)
        self.buffer = np.empty_like(self.base)

    def next(self) -> np.ndarray:
        np.bitwise_xor(self.base, np.uint32(self.rng.integers(1, 2**32)), out=self.buffer)
        return self.buffer


def session_rows(wp, unix_address, tcp_target, token, repeat, warmup) -> list[Row]:
    from weft import _runtime

    def open_close(address, tok):
        def body(_):
            rt = _runtime.Runtime(address, tok)
            facts = (rt.session_id, rt.local, rt.daemon_pid)
            rt.close()
            return facts + (rt.closed,)
        return body

    def check_local(expected_local):
        def check(_, facts):
            session_id, local, pid, closed = facts
            if not session_id or not pid or not closed:
                return f"session {session_id!r} daemon pid {pid} closed {closed}"
            return True if local == expected_local else f"local={local}"
        return check

    unix = measure(open_close(unix_address, None), check_local(True), repeat, warmup)
    tcp = measure(open_close(tcp_target, token), check_local(False), repeat, warmup)
    return [Row("session open+close (unix)", unix), Row("session open+close (tcp+token)", tcp)]


def create_free_rows(wp, warp, repeat, warmup) -> list[Row]:
    """Create (zero-filled) + Free as two blocking RPCs, against warp.zeros + del."""
    from weft import _runtime
    from weft.array import _dtype_proto

    rt = _runtime.get_runtime()
    ap = _runtime.array_pb2
    rows = []
    for nbytes, label in ((KIB, "1 KiB"), (MIB, "1 MiB")):
        request = ap.CreateArrayRequest(dtype=_dtype_proto(wp.uint8), shape=[nbytes],
                                        device="cpu", init=ap.CreateArrayRequest.ZEROS)

        def body(_):
            info = rt.call(rt.array_stub.Create, request).info
            rt.call(rt.array_stub.Free, ap.FreeArrayRequest(handle=info.handle))
            return info

        def check(_, info):
            if not info.handle or info.byte_size != nbytes or not info.shm_name:
                return f"handle {info.handle} byte_size {info.byte_size} shm {info.shm_name!r}"
            return True

        weft_m = measure(body, check, repeat, warmup)
        # the frees really happened: describing a freed handle fails
        last = rt.call(rt.array_stub.Create, request).info
        rt.call(rt.array_stub.Free, ap.FreeArrayRequest(handle=last.handle))
        try:
            rt.call(rt.array_stub.Describe, ap.DescribeArrayRequest(handle=last.handle))
            weft_m.ok = False
            weft_m.failures.append("a freed handle still describes")
        except Exception:  # noqa: BLE001 - expected: NOT_FOUND
            pass
        warp_m = None
        if warp is not None:
            warp_m = measure(lambda _: warp.zeros(nbytes, dtype=warp.uint8, device="cpu").shape,
                             lambda _, shape: True if shape == (nbytes,) else f"shape {shape}",
                             repeat, warmup)
        rows.append(Row(f"array create+free {label} (cpu)", weft_m, 0, warp_m))
    return rows


def numpy_rows(wp, warp, repeat, warmup) -> list[Row]:
    """1 GiB CPU arrays: zeros (create), first numpy() (maps the slab), repeated numpy()."""
    count = NUMPY_BYTES // 4
    rows = []

    def zeros_check(_, a):
        return True if (a.shape == (count,)) else f"shape {a.shape}"

    weft_zeros = measure(lambda _: wp.zeros(count, dtype=wp.float32, device="cpu"), zeros_check,
                         max(3, repeat // 4), 1)
    warp_zeros = None
    if warp is not None:
        warp_zeros = measure(lambda _: warp.zeros(count, dtype=warp.float32, device="cpu"),
                             zeros_check, max(3, repeat // 4), 1)
    rows.append(Row("zeros 1 GiB (cpu, create)", weft_zeros, NUMPY_BYTES, warp_zeros))

    def check_zero_view(a, view):
        # touches every page: outside the timed call, so page faults are not counted
        return _all_equal(view, 0.0, (count,), np.float32)

    def check_view_meta(a, view):
        if view.shape != (count,) or view.dtype != np.float32:
            return f"got {view.dtype}{view.shape}"
        return True if float(view[count // 2]) == 0.0 else "view not zero"

    def check_shared(a, view):
        # writes through the view reach the daemon: a daemon-side copy sees them
        view[4096] = 7.0
        b = wp.empty(1, dtype=wp.float32, device="cpu")
        wp.copy(b, a, src_offset=4096, count=1)
        got = float(b.numpy()[0])
        view[4096] = 0.0
        return True if got == 7.0 else f"daemon-side copy saw {got}, expected 7.0"

    weft_first = measure(lambda a: a.numpy(), check_zero_view, max(3, repeat // 4), 1,
                         setup=lambda: wp.zeros(count, dtype=wp.float32, device="cpu"))
    warp_first = None
    if warp is not None:
        warp_first = measure(lambda a: a.numpy(), check_zero_view, max(3, repeat // 4), 1,
                             setup=lambda: warp.zeros(count, dtype=warp.float32, device="cpu"))
    rows.append(Row("numpy() 1 GiB, first call (maps)", weft_first, 0, warp_first))

    held = wp.zeros(count, dtype=wp.float32, device="cpu")
    first_view = held.numpy()
    shared = check_shared(held, first_view)
    weft_again = measure(lambda a: a.numpy(), check_view_meta, repeat, warmup,
                         setup=lambda: held)
    if shared is not True:
        weft_again.ok = False
        weft_again.failures.append(str(shared))
    # every repeated view is the same memory as the first one
    again = held.numpy()
    if again.__array_interface__["data"][0] != first_view.__array_interface__["data"][0]:
        weft_again.ok = False
        weft_again.failures.append("repeated numpy() calls gave different memory")
    del again, first_view, held
    warp_again = None
    if warp is not None:
        warp_held = warp.zeros(count, dtype=warp.float32, device="cpu")
        warp_held.numpy()
        warp_again = measure(lambda a: a.numpy(), check_view_meta, repeat, warmup,
                             setup=lambda: warp_held)
        del warp_held
    rows.append(Row("numpy() 1 GiB, repeated call", weft_again, 0, warp_again))
    return rows


def fill_rows(wp, warp, repeat, warmup) -> list[Row]:
    """a.fill_(v) then a.numpy(): one batch flush + Synchronize + view (weft)."""
    rng = np.random.default_rng(7)
    rows = []
    for nbytes, label, runs in ((MIB, "1 MiB", repeat), (256 * MIB, "256 MiB",
                                                         max(3, repeat // 4))):
        count = nbytes // 4
        values = iter(rng.random(10 * (runs + warmup) + 10, dtype=np.float32) + 1.0)

        def run_on(lib, arr):
            def setup():
                return arr, float(next(values))

            def body(state):
                a, v = state
                a.fill_(v)
                return a.numpy()

            def check(state, view):
                return _all_equal(view, np.float32(state[1]), (count,), np.float32)
            return measure(body, check, runs, warmup, setup=setup)

        weft_m = run_on(wp, wp.zeros(count, dtype=wp.float32, device="cpu"))
        warp_m = None
        if warp is not None:
            warp_m = run_on(warp, warp.zeros(count, dtype=warp.float32, device="cpu"))
        rows.append(Row(f"fill_ + numpy() {label} (1 sync)", weft_m, nbytes, warp_m))
    return rows


def unix_transfer_rows(wp, warp, data: RandomWords, repeat, warmup) -> list[Row]:
    """256 MiB through numpy() zero-copy views over the Unix socket's shared memory."""
    count = TRANSFER_BYTES // 4
    runs = max(3, repeat // 4)
    rows = []

    def write_read(lib, arr, daemon_check):
        state = {}

        def setup():
            state["host"] = data.next()
            return arr

        def write(a):
            np.copyto(a.numpy(), state["host"])
            return a

        def check_write(a, _):
            verdict = _equal(state["host"], a.numpy())
            if verdict is True and daemon_check is not None:
                verdict = daemon_check(a, state["host"])
            return verdict

        def setup_read():
            np.copyto(arr.numpy(), data.next())
            state["host"] = data.buffer
            return arr

        def read(a):
            return a.numpy().copy()

        written = measure(write, check_write, runs, warmup, setup=setup)
        read_back = measure(read, lambda a, got: _equal(state["host"], got), runs, warmup,
                            setup=setup_read)
        return written, read_back

    def daemon_sees(a, host):
        # the daemon reads what was written through the view: a daemon-side copy of a
        # sampled range, brought back, equals the host data there
        b = wp.empty(1024, dtype=wp.uint32, device="cpu")
        offset = int(data.rng.integers(0, count - 1024))
        wp.copy(b, a, src_offset=offset, count=1024)
        return _equal(host[offset:offset + 1024], b.numpy())

    weft_w, weft_r = write_read(wp, wp.empty(count, dtype=wp.uint32, device="cpu"), daemon_sees)
    warp_w = warp_r = None
    if warp is not None:
        warp_w, warp_r = write_read(warp, warp.empty(count, dtype=warp.uint32, device="cpu"), None)
    rows.append(Row("write 256 MiB, unix numpy() view", weft_w, TRANSFER_BYTES, warp_w))
    rows.append(Row("read 256 MiB, unix numpy() copy", weft_r, TRANSFER_BYTES, warp_r))
    return rows


def tcp_transfer_rows(wp, data: RandomWords, repeat, warmup) -> list[Row]:
    """256 MiB written with assign() (Write stream, 4 MiB chunks) and read with numpy()
    (Read stream) over TCP with the token; read-back compared with the written data."""
    from weft import _runtime

    count = TRANSFER_BYTES // 4
    runs = max(3, repeat // 4)
    a = wp.empty(count, dtype=wp.uint32, device="cpu")
    rt = a._alloc.runtime
    problems = []
    if rt.local or not rt.address.startswith("127.0.0.1:") or not rt.token:
        problems.append(f"not a TCP+token session: address {rt.address} local {rt.local}")
    state = {}

    def setup():
        state["host"] = data.next()
        return a

    def setup_read():
        state["host"] = data.next()
        a.assign(state["host"])
        return a

    # each timed write is checked by reading it back (untimed), each timed read by comparing
    # with the fresh data written (untimed) before it
    written = measure(lambda arr: arr.assign(state["host"]),
                      lambda arr, _: _equal(state["host"], arr.numpy()), runs, warmup,
                      setup=setup)
    read_back = measure(lambda arr: arr.numpy(), lambda arr, got: _equal(state["host"], got),
                        runs, warmup, setup=setup_read)
    if problems:
        written.ok = False
        written.failures += problems
    del a
    _runtime.get_runtime().synchronize()
    return [Row("write 256 MiB, tcp chunked (token)", written, TRANSFER_BYTES),
            Row("read 256 MiB, tcp chunked (token)", read_back, TRANSFER_BYTES)]


# ------------------------------------------------------------------------------------------


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=20,
                        help="timed runs of the small operations (big ones: max(3, N/4))")
    parser.add_argument("--warmup", type=int, default=2, help="untimed runs before timing")
    parser.add_argument("--out", default=str(REPO_ROOT / "out" / "bench" / "foundation.md"))
    args, _unknown = parser.parse_known_args()   # run_all.py may pass other benches' flags

    binary = bc.daemon_binary()
    if not binary.exists():
        print(f"weftd not built: {binary} (set WEFT_DAEMON or build weftd)")
        return 1
    warp = import_warp()
    daemon = bc.BenchDaemon(tcp=True, binary=binary)
    print(f"weftd {binary} pid {daemon.proc.pid} on {daemon.address} and "
          f"tcp:{daemon.tcp_target}; repeat {args.repeat}, warmup {args.warmup}")
    os.environ.pop("WEFT_TOKEN", None)
    os.environ["WEFT_ADDRESS"] = daemon.address

    rows: list[Row] = []
    daemon_ok = True
    try:
        import weft as wp
        from weft import _runtime

        wp.init()
        data = RandomWords(TRANSFER_BYTES // 4)
        steps = [
            lambda: session_rows(wp, daemon.address, daemon.tcp_target, daemon.token,
                                 args.repeat, args.warmup),
            lambda: create_free_rows(wp, warp, args.repeat, args.warmup),
            lambda: numpy_rows(wp, warp, args.repeat, args.warmup),
            lambda: fill_rows(wp, warp, args.repeat, args.warmup),
            lambda: unix_transfer_rows(wp, warp, data, args.repeat, args.warmup),
        ]
        for step in steps:
            rows += step()
            print(f"  ... {rows[-1].operation}", flush=True)
        # the same process, now a session over TCP with the token
        wp.synchronize()
        _runtime.shutdown()
        os.environ["WEFT_ADDRESS"] = f"tcp:{daemon.tcp_target}"
        os.environ["WEFT_TOKEN"] = daemon.token
        rows += tcp_transfer_rows(wp, data, args.repeat, args.warmup)
        _runtime.shutdown()
    finally:
        code, leftovers = daemon.stop(keep=True)
        if code != 0 or leftovers:
            daemon_ok = False
            print(f"weftd stop: exit {code}, leftover shm {leftovers}\n{daemon.log()}")
        else:
            shutil.rmtree(daemon.workdir, ignore_errors=True)   # kept (with the log) on failure

    cells = table_rows(rows)
    print()
    print_table(cells)
    print(LEGEND)
    failures = [(row.operation, f) for row in rows
                for m in (row.weft, row.warp) if m is not None for f in m.failures]
    for op, failure in failures:
        print(f"FAIL {op}: {failure}")

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    warp_version = getattr(warp, "__version__", "n/a") if warp is not None else "not installed"
    out.write_text(
        "# weft foundation benchmark\n\n"
        f"`bench/bench_foundation.py`, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
        f"weftd `{binary}`; warp-lang {warp_version}; {os.cpu_count()} CPU cores; "
        f"repeat {args.repeat} (big transfers max(3, N/4)), warmup {args.warmup}.\n\n"
        + markdown_table(cells) + "\n\n" + LEGEND + "\n"
        + "".join(f"\n- FAIL {op}: {failure}" for op, failure in failures)
        + ("\n" if failures else ""))
    print(f"\nwrote {out}")
    all_ok = daemon_ok and not failures and all(
        row.weft.ok and (row.warp is None or row.warp.ok) for row in rows)
    return 0 if all_ok else 1


if __name__ == "__main__":
    sys.exit(main())
