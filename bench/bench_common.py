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


def device_and_quick() -> tuple[str, bool]:
    """`--device NAME` (default cpu) and `--quick` from the command line."""
    device = sys.argv[sys.argv.index("--device") + 1] if "--device" in sys.argv else "cpu"
    return device, "--quick" in sys.argv


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


def interleaved_medians(bodies: dict, repeat: int = 5) -> dict:
    """{name: median wall time of bodies[name]() (seconds)}, the bodies timed in turn, one run
    of each per round (weft, Warp, weft, Warp, ...): a machine whose speed drifts during the
    run (the lent GPU hosts move by up to 2x within a minute) moves both alike, so their ratio
    holds where two separate medians would not."""
    times = {name: [] for name in bodies}
    for _ in range(repeat):
        for name, fn in bodies.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    return {name: statistics.median(v) for name, v in times.items()}


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


# ------------------------------------------------------------------------------------------
# A weftd of the benchmark's own

REPO_ROOT = Path(__file__).resolve().parent.parent
DAEMON_START_TIMEOUT_S = 30.0


def daemon_binary() -> Path:
    """$WEFT_DAEMON, else <repo>/build/bin/weftd, else the newest <repo>/build-*/bin/weftd."""
    explicit = os.environ.get("WEFT_DAEMON")
    if explicit:
        return Path(explicit)
    default = REPO_ROOT / "build" / "bin" / "weftd"
    if default.exists():
        return default
    others = sorted(REPO_ROOT.glob("build-*/bin/weftd"), key=lambda p: p.stat().st_mtime)
    if others:
        return others[-1]
    raise SystemExit("no weftd found: set WEFT_DAEMON or run `make build`")


def _channel_ready(target: str, timeout_s: float) -> bool:
    import grpc  # noqa: PLC0415

    channel = grpc.insecure_channel(target)
    try:
        grpc.channel_ready_future(channel).result(timeout=timeout_s)
        return True
    except grpc.FutureTimeoutError:
        return False
    finally:
        channel.close()


class BenchDaemon:
    """One weftd on a temp Unix socket (`address`) with an empty --cache-dir and `log_level`;
    with tcp=True also on TCP 127.0.0.1:<free port> (`tcp_target`) behind a token (`token`)."""

    def __init__(self, extra_args=(), tcp: bool = False, binary: Path | None = None,
                 log_level: str = "warn"):
        import secrets  # noqa: PLC0415
        import socket  # noqa: PLC0415
        import subprocess  # noqa: PLC0415

        self.binary = binary or daemon_binary()
        self.workdir = Path(tempfile.mkdtemp(prefix="weft-bench-daemon-"))
        self.address = f"unix:{self.workdir / 'weftd.sock'}"
        self.tcp_target = self.token = None
        self.log_path = self.workdir / "weftd.log"
        args = [str(self.binary), "--listen", self.address, "--cache-dir",
                str(self.workdir / "cache"), "--log-level", log_level, *extra_args]
        if tcp:
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
                s.bind(("127.0.0.1", 0))
                self.tcp_target = f"127.0.0.1:{s.getsockname()[1]}"
            self.token = secrets.token_hex(16)
            token_file = self.workdir / "token"
            token_file.write_text(self.token + "\n")
            os.chmod(token_file, 0o600)
            args += ["--listen", f"tcp:{self.tcp_target}", "--token-file", str(token_file)]
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(args, stdout=self._log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL)
        targets = [self.address] + ([self.tcp_target] if tcp else [])
        deadline = time.monotonic() + DAEMON_START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"weftd exited with {self.proc.returncode} at start:\n"
                                   f"{self.log()}")
            if all(_channel_ready(t, 0.5) for t in targets):
                return
        self.proc.kill()
        raise RuntimeError(f"weftd did not answer within {DAEMON_START_TIMEOUT_S} s:\n{self.log()}")

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-4000:]
        except OSError:
            return ""

    def stop(self, keep: bool = False) -> tuple[int, list[str]]:
        """SIGTERM and wait; returns (exit code, leftover /dev/shm/weft-<pid>-* files). The
        workdir (with the log) is removed unless `keep`."""
        import glob  # noqa: PLC0415
        import shutil  # noqa: PLC0415
        import signal  # noqa: PLC0415
        import subprocess  # noqa: PLC0415

        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        if not keep:
            shutil.rmtree(self.workdir, ignore_errors=True)
        return self.proc.returncode, sorted(glob.glob(f"/dev/shm/weft-{self.proc.pid}-*"))


class WeftSession:
    """`with WeftSession(extra_args) as (weft, rt):` — the setup client benchmarks share: a
    BenchDaemon (`daemon`), WEFT_ADDRESS pointing at it, `weft` imported and initialised, and
    the session's runtime (weft._runtime); on exit the session is closed (weft._runtime.shutdown
    where the client has it) and the daemon stopped."""

    def __init__(self, extra_args=(), **daemon_kwargs):
        self.daemon = BenchDaemon(extra_args, **daemon_kwargs)
        os.environ["WEFT_ADDRESS"] = self.daemon.address
        if "--allow-unchecked" in extra_args:   # the session's kernels may turn checks off
            os.environ["WEFT_UNCHECKED"] = "1"

    def __enter__(self):
        try:
            import weft  # noqa: PLC0415
            from weft import _runtime  # noqa: PLC0415

            weft.init()
            return weft, _runtime.get_runtime()
        except BaseException:
            self.daemon.stop()
            raise

    def __exit__(self, *exc):
        try:
            import weft._runtime as runtime  # noqa: PLC0415

            shutdown = getattr(runtime, "shutdown", None)
            if shutdown is not None:
                shutdown()
        finally:
            self.daemon.stop()
        return False
