"""Shared pytest fixtures of the weft Python client: real weftd daemons and child clients.

Fixtures (any test under clients/python/tests/, kernels/ included, may use them):
  weftd      session: a weftd on a Unix socket in a temp dir with a temp --cache-dir; sets
             WEFT_ADDRESS for this process and its children; stopped with SIGTERM at the end,
             checking that it exited and left no /dev/shm/weft-<pid>-* files.
  wp         session: the `weft` module, initialised against `weftd`.
  tcp_weftd  session: a second weftd listening on TCP 127.0.0.1 with a token file
             (`.address`, `.token`); this process does not connect to it by default.
  start_weftd function: start_weftd(extra_args) starts a weftd of the test's own with more
             flags (limits, --config); stopped and checked at the end of the test.
  run_client function: run_client(code, env=None, timeout=60, check=True) runs a Python
             snippet in a child process (connected to `weftd` unless env overrides
             WEFT_ADDRESS) and returns the CompletedProcess; check=True asserts exit 0.
  spawn_client function: like run_client but returns the Popen (stdin/stdout pipes, text);
             processes still alive at the end of the test are killed.
  client_env function: client_env(overrides) -> environment dict for a child client.
  daemon_path function: the weftd binary.
  needs_nvrtc function: skips the test when this weftd was built without NVRTC.
  wait_for   function: wait_for(predicate, timeout_s, period_s=0.05) -> the predicate's first
             truthy value, or its last value when the time is up.
Daemon objects also give .stats() (SessionService.Stats), .shm_files(), .threads(),
.thread_names(), .cpu_seconds(), .open_fds() and .raw_session() (bare gRPC stubs with a
session of their own, for hand-made requests: .attach(), .create_array(), .read_array()).
The daemon binary is $WEFT_DAEMON, else <repo>/build/bin/weftd; tests are skipped with a
clear reason when it does not exist.
"""
from __future__ import annotations

import glob
import os
import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest

# JAX on a GPU takes 75% of its memory when its backend starts; test processes side by side (the
# GPU machine runs the suite in shards) and weftd share the GPU, so JAX allocates as it goes.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")

REPO_ROOT = Path(__file__).resolve().parents[3]
CLIENT_DIR = REPO_ROOT / "clients" / "python"
DAEMON_START_TIMEOUT_S = 30.0
DAEMON_STOP_TIMEOUT_S = 15.0


def daemon_binary() -> Path:
    """The weftd the tests run: $WEFT_DAEMON, else <repo>/build/bin/weftd."""
    return Path(os.environ.get("WEFT_DAEMON", REPO_ROOT / "build" / "bin" / "weftd"))


_HAS_NVRTC: dict = {}


def daemon_has_nvrtc() -> bool:
    """Whether this weftd was built with NVRTC (it links libnvrtc)."""
    binary = str(daemon_binary())
    if binary not in _HAS_NVRTC:
        try:
            out = subprocess.run(["ldd", binary], capture_output=True, text=True, timeout=30).stdout
        except (OSError, subprocess.SubprocessError):
            out = ""
        _HAS_NVRTC[binary] = "libnvrtc" in out
    return _HAS_NVRTC[binary]


def verify_cuda_flags() -> list:
    """["--verify-cuda", "--verify-cuda-archs", "75,90"] when this weftd was built with NVRTC:
    every kernel the tests compile is then also compiled by NVRTC for sm_75 and sm_90 (CI's
    check that every test kernel compiles for the GPU), on machines without one too; a kernel
    NVRTC rejects fails its test. WEFT_TEST_VERIFY_CUDA=0 turns it off;
    WEFT_TEST_VERIFY_CUDA_ARCHS chooses the architectures."""
    if os.environ.get("WEFT_TEST_VERIFY_CUDA", "1") == "0" or not daemon_has_nvrtc():
        return []
    return ["--verify-cuda", "--verify-cuda-archs", os.environ.get("WEFT_TEST_VERIFY_CUDA_ARCHS", "75,90")]


def wait_until(predicate, timeout_s: float, period_s: float = 0.05):
    """Calls `predicate` until it returns a truthy value (returned) or `timeout_s` passes (its
    last value is returned)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(period_s)
    return predicate()


def _free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _channel_ready(target: str, timeout_s: float) -> bool:
    import grpc

    channel = grpc.insecure_channel(target)
    try:
        grpc.channel_ready_future(channel).result(timeout=timeout_s)
        return True
    except grpc.FutureTimeoutError:
        return False
    finally:
        channel.close()


class Daemon:
    """One weftd process started by the tests, with its address, logs and shm checks.
    `extra_args` are more weftd flags (a test's own daemon with its own settings)."""

    def __init__(self, workdir: Path, tcp: bool = False, extra_args: tuple = (),
                 also_tcp: bool = False):
        """tcp: listen on TCP only; also_tcp: listen on the Unix socket (.address) and on TCP
        (.tcp_target, token in .token); extra_args: more weftd flags (limits)."""
        self.workdir = workdir
        self.cache_dir = workdir / "cache"
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = workdir / "weftd.log"
        self.token: str | None = None
        args = [str(daemon_binary())]
        if tcp:
            self.port = _free_tcp_port()
            self.token = secrets.token_hex(16)
            self.token_file = workdir / "token"
            self.token_file.write_text(self.token + "\n")
            os.chmod(self.token_file, 0o600)
            self.address = f"127.0.0.1:{self.port}"
            self.grpc_target = self.address
            args += ["--listen", f"tcp:{self.address}", "--token-file", str(self.token_file)]
        else:
            self.socket_path = workdir / "weftd.sock"
            self.address = f"unix:{self.socket_path}"
            self.grpc_target = self.address
            args += ["--listen", self.address]
            if also_tcp:
                self.port = _free_tcp_port()
                self.token = secrets.token_hex(16)
                self.token_file = workdir / "token"
                self.token_file.write_text(self.token + "\n")
                os.chmod(self.token_file, 0o600)
                self.tcp_target = f"127.0.0.1:{self.port}"
                args += ["--listen", f"tcp:{self.tcp_target}", "--token-file", str(self.token_file)]
        args += ["--cache-dir", str(self.cache_dir), "--log-level", "info"] + verify_cuda_flags()
        if "--compile-time-limit" not in extra_args:
            # Compile times measure the machine, not weft: a 2-core CI machine under load took
            # over the daemon's default 30 s for some test modules. The limit itself is tested
            # by daemons of their own (test_security_compile.py).
            args += ["--compile-time-limit", os.environ.get("WEFT_TEST_COMPILE_TIME_LIMIT", "120")]
        args += list(extra_args)   # e.g. limits a test sets on its own daemon
        self.args = args
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(args, stdout=self._log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL)
        self.pid = self.proc.pid
        self._wait_ready()

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def _wait_ready(self) -> None:
        deadline = time.monotonic() + DAEMON_START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"weftd exited with {self.proc.returncode} at start "
                                   f"({' '.join(self.args)}):\n{self.log()}")
            if _channel_ready(self.grpc_target, 0.5):
                return
        self.proc.kill()
        raise RuntimeError(f"weftd did not answer at {self.address} within "
                           f"{DAEMON_START_TIMEOUT_S} s:\n{self.log()}")

    def shm_files(self) -> list[str]:
        """The shared-memory slab files this daemon owns right now (/dev/shm/weft-<pid>-*)."""
        return sorted(glob.glob(f"/dev/shm/weft-{self.pid}-*"))

    def metadata(self, session_id: str | None = None) -> tuple:
        md = []
        if self.token is not None:
            md.append(("authorization", f"Bearer {self.token}"))
        if session_id is not None:
            md.append(("weft-session", session_id))
        return tuple(md)

    def stats(self):
        """SessionService.Stats through a short-lived session of its own (StatsResponse)."""
        from weft.v1 import session_pb2

        with self.raw_session("pytest stats") as raw:
            return raw.session.Stats(session_pb2.StatsRequest(), metadata=raw.metadata,
                                     timeout=10)

    def raw_session(self, name: str = "pytest raw", target: str | None = None):
        """A context manager: a session opened with bare gRPC stubs (RawSession), over
        `target` (default: the daemon's own address)."""
        return RawSession(self, name, target)

    def threads(self) -> int:
        """The daemon's thread count (/proc/<pid>/status)."""
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("Threads:"):
                return int(line.split()[1])
        raise AssertionError("no Threads: line")

    def thread_names(self) -> list[str]:
        """The names (comm) of the daemon's threads, sorted: weftd's own are "weftd"."""
        names = []
        for tid in os.listdir(f"/proc/{self.pid}/task"):
            try:
                names.append(Path(f"/proc/{self.pid}/task/{tid}/comm").read_text().strip())
            except OSError:
                pass   # the thread ended meanwhile
        return sorted(names)

    def cpu_seconds(self) -> float:
        """User + system CPU time the daemon has used so far (/proc/<pid>/stat)."""
        fields = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def open_fds(self) -> int:
        """How many file descriptors the daemon has open."""
        return len(os.listdir(f"/proc/{self.pid}/fd"))

    def stop(self) -> int:
        """SIGTERM, wait, and return the exit code (kills it if it does not exit in time)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=DAEMON_STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                self._log.close()
                raise AssertionError(f"weftd did not exit within {DAEMON_STOP_TIMEOUT_S} s "
                                     f"of SIGTERM:\n{self.log()}")
        self._log.close()
        return self.proc.returncode


class RawSession:
    """Bare gRPC access to a daemon for tests that craft requests by hand: `.session`,
    `.arrays`, `.exec`, `.devices`, `.modules` stubs; `.metadata` carries session and token;
    `.session_id`, `.opened` (OpenSessionResponse). Closes the session on exit."""

    def __init__(self, daemon: Daemon, name: str, target: str | None = None):
        import grpc
        from weft import _runtime
        from weft.v1 import session_pb2

        options = [("grpc.max_send_message_length", 64 << 20),
                   ("grpc.max_receive_message_length", 64 << 20)]
        self.channel = grpc.insecure_channel(target or daemon.grpc_target, options=options)
        self.session = _runtime.SessionServiceStub(self.channel)
        self.arrays = _runtime.ArrayServiceStub(self.channel)
        self.exec = _runtime.ExecServiceStub(self.channel)
        self.devices = _runtime.DeviceServiceStub(self.channel)
        self.modules = _runtime.ModuleServiceStub(self.channel)
        request = session_pb2.OpenSessionRequest(client_name=name, client_pid=os.getpid())
        self.opened = self.session.Open(request, metadata=daemon.metadata(), timeout=60)
        if self.opened.session_host and not self.opened.session_id:
            # A daemon that runs sessions in hosts (--device-hosts, --isolate-sessions) names
            # the host's socket: the session is opened there, as the clients do.
            self.channel.close()
            self.channel = grpc.insecure_channel("unix:" + self.opened.session_host, options=options)
            self.session = _runtime.SessionServiceStub(self.channel)
            self.arrays = _runtime.ArrayServiceStub(self.channel)
            self.exec = _runtime.ExecServiceStub(self.channel)
            self.devices = _runtime.DeviceServiceStub(self.channel)
            self.modules = _runtime.ModuleServiceStub(self.channel)
            self.opened = self.session.Open(request, metadata=daemon.metadata(), timeout=60)
        self.session_id = self.opened.session_id
        self.metadata = daemon.metadata(self.session_id)
        self._session_pb2 = session_pb2

    def attach(self, session_id: str | None = None, metadata: tuple | None = None):
        """Opens an Attach stream for `session_id` (default: this session) with `metadata`
        (default: this session's); returns (call, first event or the RpcError, release), where
        release() ends the stream (the daemon then reaps the session it claimed)."""
        import grpc
        import threading

        done = threading.Event()
        session_id = self.session_id if session_id is None else session_id

        def requests():
            yield self._session_pb2.AttachRequest(session_id=session_id)
            done.wait()

        call = self.session.Attach(requests(), metadata=self.metadata if metadata is None else metadata)
        try:
            first = next(call)
        except grpc.RpcError as error:
            first = error
        return call, first, done.set

    def create_array(self, values):
        """A new array of the session holding `values` (a 1-D float32 numpy array); its ArrayInfo."""
        from weft.v1 import array_pb2, types_pb2

        return self.arrays.Create(array_pb2.CreateArrayRequest(
            dtype=types_pb2.DType(scalar=types_pb2.FLOAT32, type_name="float32"),
            shape=[values.size], device="cpu", init=array_pb2.CreateArrayRequest.DATA,
            value=values.tobytes()), metadata=self.metadata, timeout=10).info

    def read_array(self, handle: int):
        """The contents of float32 array `handle` of the session, as a numpy array."""
        import numpy as np
        from weft.v1 import array_pb2

        chunks = self.arrays.Read(array_pb2.ReadArrayRequest(handle=handle), metadata=self.metadata,
                                  timeout=10)
        return np.frombuffer(b"".join(c.data for c in chunks), np.float32)

    def close(self):
        """Closes the session (a session already closed or reaped is fine) and the channel."""
        import grpc

        if getattr(self, "_closed", False):
            return
        self._closed = True
        try:
            self.session.Close(self._session_pb2.CloseSessionRequest(session_id=self.session_id),
                               metadata=self.metadata, timeout=10)
        except grpc.RpcError as error:
            if error.code() != grpc.StatusCode.FAILED_PRECONDITION:
                raise
        finally:
            self.channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _require_daemon() -> None:
    if not daemon_binary().exists():
        pytest.skip(f"weftd not built: {daemon_binary()} (set WEFT_DAEMON or run make build)")


def _stop_and_check(daemon: Daemon) -> None:
    code = daemon.stop()
    leftovers = daemon.shm_files()
    assert code == 0, f"weftd exited with {code} after SIGTERM:\n{daemon.log()[-4000:]}"
    assert not leftovers, f"weftd left shared-memory files after SIGTERM: {leftovers}"


@pytest.fixture(scope="session")
def weftd():
    """A weftd on a Unix socket; WEFT_ADDRESS points at it for this process and children."""
    _require_daemon()
    workdir = Path(tempfile.mkdtemp(prefix="weft-test-"))
    # WEFT_TEST_DAEMON_ARGS: more flags for this shared daemon, e.g. --device-hosts (the tests'
    # sessions then run in the processes of their devices; docs/testing.md).
    daemon = Daemon(workdir, extra_args=tuple(os.environ.get("WEFT_TEST_DAEMON_ARGS", "").split()))
    old_address = os.environ.get("WEFT_ADDRESS")
    old_token = os.environ.pop("WEFT_TOKEN", None)
    os.environ["WEFT_ADDRESS"] = daemon.address
    try:
        yield daemon
    finally:
        # Close this process's session first so the daemon stops with no client attached.
        runtime_module = sys.modules.get("weft._runtime")
        if runtime_module is not None and hasattr(runtime_module, "shutdown"):
            try:
                runtime_module.shutdown()
            except Exception:  # noqa: BLE001 - shutting down; the daemon checks follow
                pass
        if old_address is None:
            os.environ.pop("WEFT_ADDRESS", None)
        else:
            os.environ["WEFT_ADDRESS"] = old_address
        if old_token is not None:
            os.environ["WEFT_TOKEN"] = old_token
        _stop_and_check(daemon)


@pytest.fixture(scope="session")
def wp(weftd):
    """The weft module, initialised against the session's Unix-socket daemon."""
    import weft

    weft.init()
    return weft


@pytest.fixture(scope="session")
def tcp_weftd():
    """A weftd on TCP 127.0.0.1:<free port> requiring a token (`.address`, `.token`)."""
    _require_daemon()
    workdir = Path(tempfile.mkdtemp(prefix="weft-test-tcp-"))
    daemon = Daemon(workdir, tcp=True)
    try:
        yield daemon
    finally:
        _stop_and_check(daemon)


@pytest.fixture
def needs_nvrtc():
    """Skips the test (with the reason) when this weftd was built without NVRTC."""
    if not daemon_has_nvrtc():
        pytest.skip("this weftd was built without NVRTC (no CUDA compiles)")


@pytest.fixture
def start_weftd():
    """start_weftd(extra_args, also_tcp=False) -> a Daemon of the test's own, started with more
    weftd flags (limits, a --config file), also on TCP with a token when also_tcp; stopped and
    checked like `weftd` when the test ends."""
    _require_daemon()
    started = []

    def start(extra_args=(), also_tcp: bool = False):
        workdir = Path(tempfile.mkdtemp(prefix="weft-test-own-"))
        started.append(Daemon(workdir, extra_args=tuple(extra_args), also_tcp=also_tcp))
        return started[-1]

    try:
        yield start
    finally:
        for daemon in started:
            _stop_and_check(daemon)


def _child_env(env: dict | None) -> dict:
    child = dict(os.environ)
    child["PYTHONPATH"] = os.pathsep.join(
        [str(CLIENT_DIR)] + ([child["PYTHONPATH"]] if child.get("PYTHONPATH") else []))
    child["PYTHONUNBUFFERED"] = "1"
    if env:
        for key, value in env.items():
            if value is None:
                child.pop(key, None)
            else:
                child[key] = str(value)
    return child


@pytest.fixture
def client_env():
    """client_env(overrides) -> the environment of a child client: this process's (with
    WEFT_ADDRESS), the client package on PYTHONPATH, and `overrides` (None removes a key).
    Test modules cannot import conftest by name (tests/kernels has its own conftest)."""
    return _child_env


@pytest.fixture
def wait_for():
    """wait_for(predicate, timeout_s, period_s=0.05): polls until the predicate holds."""
    return wait_until


@pytest.fixture
def daemon_path():
    """The weftd binary the tests run."""
    return daemon_binary()


@pytest.fixture
def run_client(weftd):
    """run_client(code, env=None, timeout=60, check=True) -> CompletedProcess of a child."""

    def run(code: str, env: dict | None = None, timeout: float = 60, check: bool = True):
        proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)],
                              env=_child_env(env), capture_output=True, text=True,
                              timeout=timeout)
        if check:
            assert proc.returncode == 0, (f"child client failed ({proc.returncode}):\n"
                                          f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}")
        return proc

    return run


@pytest.fixture
def spawn_client(weftd):
    """spawn_client(code, env=None) -> Popen with text stdin/stdout/stderr pipes."""
    children: list[subprocess.Popen] = []

    def spawn(code: str, env: dict | None = None) -> subprocess.Popen:
        proc = subprocess.Popen([sys.executable, "-c", textwrap.dedent(code)],
                                env=_child_env(env), stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                bufsize=1)
        children.append(proc)
        return proc

    yield spawn
    for proc in children:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        for stream in (proc.stdin, proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()

