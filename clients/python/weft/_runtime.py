"""The process's connection to weftd: finding (or starting) the daemon, the session (Open, and
Attach held open from a daemon thread so the daemon reaps the session when this process dies),
the command batch (submit/flush/synchronize), unary calls with errors turned into WeftError,
deferred frees, and the cache of mapped shared-memory slabs.

Internal interface used by weft.array and weft._kernel (keep these names):
  get_runtime() -> Runtime with .session_stub .array_stub .exec_stub .module_stub .device_stub,
  .metadata, .submit(cmd), .flush(), .synchronize(), .local, .call(stub_method, request).
"""
from __future__ import annotations

import atexit
import collections
import ctypes
import fcntl
import mmap
import os
import shutil
import subprocess
import sys
import threading
import time
import weakref
from pathlib import Path

import grpc

from . import _create_ahead, _fast_lane
from .errors import WeftError, error_from_rpc

MAX_MESSAGE_BYTES = 64 << 20
BATCH_MAX_COMMANDS = 1000
BATCH_MAX_BYTES = 16 << 20
PENDING_FREE_LIMIT = 4096
LANE_IN_FLIGHT = 16     # asynchronous fast-lane Submits sent before the oldest reply is read
PUMP_FIRST = 8         # commands queued before the first early Submit after a sync point
PUMP_AFTER_S = 0.002   # or: two commands, the oldest queued this long ago (gRPC)
PUMP_AFTER_LANE_S = 40e-6   # the same through the fast lane (an early Submit costs a send)


def framed_command(cmd) -> bytes:
    """exec_pb2.Command `cmd` serialized as one element of SubmitRequest.commands (field 1,
    length-delimited): a Submit's body is the concatenation of its commands' frames (and the
    request's flags), so a batch is serialized once per command, when it is queued, and never
    copied into a SubmitRequest message (upb deep-copies every command it is given)."""
    data = cmd.SerializeToString()
    return b"\x0a" + varint(len(data)) + data


def varint(n: int) -> bytes:
    """The protobuf base-128 varint of unsigned `n`."""
    if n < 0x80:
        return bytes((n,))
    out = bytearray()
    while n >= 0x80:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


_SUBMIT_SYNCHRONIZE = b"\x10\x01"     # SubmitRequest.synchronize = true (field 2, varint)
_SUBMIT_RUN = b"\x18\x01"             # SubmitRequest.run = true (field 3, varint)
_SYNCHRONIZE_BYTES = b""              # SynchronizeRequest() serialized (no fields)
# A GPU launch of at least this many threads goes out at once when no Submit is in flight
# (Runtime.submit's `start`): its kernel runs longer than a frame costs, so holding it to fuse
# with a synchronize only delays the device (saxpy 1e8: ~60 us per round of five launches).
# WEFT_START_GPU_THREADS=0 turns it off.
START_GPU_THREADS = int(os.environ.get("WEFT_START_GPU_THREADS", str(1 << 20))) or (1 << 62)
# The first GPU launch after a sync point goes out at once, as a quiet Submit record of the
# lane's ring, when weftd polls the ring (Runtime.submit_eager): weftd launches it while this
# process prepares its synchronize (docs/protocol.md "Ring"). WEFT_LANE_EAGER=0 turns it off.
LANE_EAGER = os.environ.get("WEFT_LANE_EAGER", "1") != "0"
DAEMON_START_TIMEOUT_S = 30.0
RPC_TIMEOUT_S = None  # unary calls wait as long as the daemon needs (compiles can be slow)
ATTACH_CONFIRM_S = 30.0   # how long a new session waits for the daemon to claim its Attach stream

_PACKAGE_DIR = Path(__file__).resolve().parent
_REPO_DIR = _PACKAGE_DIR.parents[1].parent  # clients/python/weft -> repo root


_PB2_NAMES = ("types_pb2", "array_pb2", "device_pb2", "exec_pb2", "module_pb2", "session_pb2")


def _generate_stubs() -> None:
    """Generates weft/v1/*_pb2.py from <repo>/proto with grpc_tools (when it is installed), in
    a child process: grpc_tools carries a protobuf library of its own, which must not share a
    process with another extension's (Paddle's aborts the process when both are loaded)."""
    import importlib.util

    proto_dir = _REPO_DIR / "proto"
    if importlib.util.find_spec("grpc_tools") is None:
        raise ImportError("weft.v1 message modules are missing: run `make proto-py` in the "
                          "weft repository (needs grpcio-tools)")
    out_dir = _PACKAGE_DIR.parent
    (_PACKAGE_DIR / "v1").mkdir(exist_ok=True)
    protos = sorted(str(p) for p in (proto_dir / "weft" / "v1").glob("*.proto"))
    args = [sys.executable, "-m", "grpc_tools.protoc", f"-I{proto_dir}", f"--python_out={out_dir}",
            f"--grpc_python_out={out_dir}"] + protos
    if not protos or subprocess.run(args, capture_output=True, timeout=300).returncode != 0:
        raise ImportError(f"generating weft.v1 from {proto_dir} failed")
    (_PACKAGE_DIR / "v1" / "__init__.py").touch()


def _import_pb2_modules() -> dict:
    """The generated message modules (weft.v1.*_pb2). Generated on the fly when missing; a
    protobuf runtime older than the generator (same wire format) is accepted with its version
    check relaxed, so stubs generated on one machine run on another."""
    import importlib

    def load():
        return {name: importlib.import_module(f"weft.v1.{name}") for name in _PB2_NAMES}

    try:
        return load()
    except ModuleNotFoundError:
        _generate_stubs()
        return load()
    except Exception as err:  # noqa: BLE001 - protobuf VersionError and friends
        from google.protobuf import runtime_version

        if not isinstance(err, getattr(runtime_version, "VersionError", ())):
            raise
        for name in _PB2_NAMES:
            sys.modules.pop(f"weft.v1.{name}", None)
        original = runtime_version.ValidateProtobufRuntimeVersion
        runtime_version.ValidateProtobufRuntimeVersion = lambda *args, **kwargs: None
        try:
            return load()
        finally:
            runtime_version.ValidateProtobufRuntimeVersion = original


def _make_stub_class(service):
    """A gRPC client stub class for a service descriptor (what *_pb2_grpc.py would hold,
    built here so the client does not depend on the grpcio version that generated them)."""
    from google.protobuf import message_factory

    def message_class(descriptor):
        return message_factory.GetMessageClass(descriptor)

    methods = [(m.name, f"/{service.full_name}/{m.name}", m.client_streaming,
                m.server_streaming, message_class(m.input_type), message_class(m.output_type))
               for m in service.methods]

    def __init__(self, channel):
        for name, path, client_streaming, server_streaming, request, response in methods:
            factory = {(False, False): channel.unary_unary, (False, True): channel.unary_stream,
                       (True, False): channel.stream_unary,
                       (True, True): channel.stream_stream}[(client_streaming, server_streaming)]
            setattr(self, name, factory(path, request_serializer=request.SerializeToString,
                                        response_deserializer=response.FromString))

    return type(f"{service.name}Stub", (), {"__init__": __init__,
                                           "__doc__": f"Client stub of {service.full_name}."})


_pb2 = _import_pb2_modules()
types_pb2 = _pb2["types_pb2"]
array_pb2 = _pb2["array_pb2"]
device_pb2 = _pb2["device_pb2"]
exec_pb2 = _pb2["exec_pb2"]
module_pb2 = _pb2["module_pb2"]
session_pb2 = _pb2["session_pb2"]
SessionServiceStub = _make_stub_class(session_pb2.DESCRIPTOR.services_by_name["SessionService"])
ArrayServiceStub = _make_stub_class(array_pb2.DESCRIPTOR.services_by_name["ArrayService"])
ExecServiceStub = _make_stub_class(exec_pb2.DESCRIPTOR.services_by_name["ExecService"])
ModuleServiceStub = _make_stub_class(module_pb2.DESCRIPTOR.services_by_name["ModuleService"])
DeviceServiceStub = _make_stub_class(device_pb2.DESCRIPTOR.services_by_name["DeviceService"])

_CODE_NAMES = {code.value[0]: code.name for code in grpc.StatusCode}
# Submit(synchronize=true) (flush + Synchronize in one round trip), when the generated message
# modules are recent enough to have the field (`make proto-py` regenerates them).
_FUSED_SYNC = "synchronize" in exec_pb2.SubmitRequest.DESCRIPTOR.fields_by_name
# Batches go out as soon as no Submit is in flight (Runtime._pump); WEFT_PIPELINE=0 keeps them
# until the next synchronize (or a full batch).
_PIPELINED = os.environ.get("WEFT_PIPELINE", "1") != "0"


# ------------------------------------------------------------------------------------------
# Finding the daemon


def default_socket_path() -> Path:
    """$XDG_RUNTIME_DIR/weft/weftd.sock, else /tmp/weft-$UID/weftd.sock (weftd's default)."""
    runtime_dir = os.environ.get("XDG_RUNTIME_DIR")
    if runtime_dir:
        return Path(runtime_dir) / "weft" / "weftd.sock"
    return Path(f"/tmp/weft-{os.getuid()}") / "weftd.sock"


def normalize_address(address: str) -> str:
    """A gRPC target for WEFT_ADDRESS: unix:/path stays, tcp:host:port -> host:port."""
    address = address.strip()
    if address.startswith("tcp:"):
        return address[len("tcp:"):]
    if address.startswith("/"):
        return "unix:" + address
    return address


def _channel_ready(target: str, timeout_s: float) -> bool:
    channel = grpc.insecure_channel(target)
    try:
        grpc.channel_ready_future(channel).result(timeout=timeout_s)
        return True
    except grpc.FutureTimeoutError:
        return False
    finally:
        channel.close()


def find_daemon_binary() -> str | None:
    """WEFT_DAEMON, else `weftd` on PATH, else <repo>/build/bin/weftd next to the package."""
    explicit = os.environ.get("WEFT_DAEMON")
    if explicit:
        return explicit
    on_path = shutil.which("weftd")
    if on_path:
        return on_path
    beside = _REPO_DIR / "build" / "bin" / "weftd"
    return str(beside) if beside.exists() else None


def module_cache_dir() -> Path | None:
    """The disk module cache an autostarted weftd keeps (as Warp's kernel cache, so a second run
    compiles nothing): wp.config.kernel_cache_dir, else $WEFT_CACHE_DIR, else
    $XDG_CACHE_HOME/weft/modules (~/.cache/weft/modules); None (memory only) when
    wp.config.cache_kernels is False."""
    from . import config  # noqa: PLC0415 - config is a leaf module

    if not config.cache_kernels:
        return None
    chosen = config.kernel_cache_dir or os.environ.get("WEFT_CACHE_DIR")
    if chosen:
        return Path(chosen).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "weft" / "modules"


def _start_local_daemon(socket_path: Path) -> None:
    """Starts weftd in the background on `socket_path` (with the disk module cache of
    module_cache_dir()) and waits until it answers."""
    target = f"unix:{socket_path}"
    socket_path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    lock_path = socket_path.parent / "weftd.start.lock"
    with open(lock_path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one starter at a time; the others then find it
        if socket_path.exists() and _channel_ready(target, 1.0):
            return
        binary = find_daemon_binary()
        if binary is None:
            raise WeftError(f"no weftd answers at {socket_path} and no weftd binary was found: "
                            "set WEFT_ADDRESS to a running daemon, or WEFT_DAEMON to the weftd "
                            "binary, or put weftd on PATH", "UNAVAILABLE")
        if not os.access(binary, os.X_OK):
            raise WeftError(f"no weftd answers at {socket_path} and the weftd binary {binary} "
                            "does not exist or is not executable (WEFT_DAEMON / PATH)",
                            "UNAVAILABLE")
        log_path = socket_path.parent / "weftd.log"
        argv = [binary, "--listen", target]
        cache_dir = module_cache_dir()
        if cache_dir is not None:
            cache_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
            argv += ["--cache-dir", str(cache_dir)]
        with open(log_path, "ab") as log:
            proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL,
                                    stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True, close_fds=True)
        deadline = time.monotonic() + DAEMON_START_TIMEOUT_S
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                tail = log_path.read_text(errors="replace")[-2000:]
                raise WeftError(f"weftd ({binary}) exited with {proc.returncode} at start; "
                                f"log {log_path}:\n{tail}", "UNAVAILABLE")
            if socket_path.exists() and _channel_ready(target, 0.5):
                return
            time.sleep(0.05)
        raise WeftError(f"weftd ({binary}) did not answer at {socket_path} within "
                        f"{DAEMON_START_TIMEOUT_S:.0f} s; log {log_path}", "UNAVAILABLE")


def _unchecked_requested() -> bool:
    """The session is opened unchecked (its kernels may turn bounds checks off) when
    WEFT_UNCHECKED=1, or when a module option already turns them off as it opens."""
    if os.environ.get("WEFT_UNCHECKED", "").lower() in ("1", "true", "yes"):
        return True
    from ._kernel import module as module_mod  # noqa: PLC0415

    return module_mod.unchecked_requested()


def resolve_address() -> str:
    """The gRPC target to use: WEFT_ADDRESS, else the default socket (starting weftd there)."""
    address = os.environ.get("WEFT_ADDRESS")
    if address:
        return normalize_address(address)
    socket_path = default_socket_path()
    target = f"unix:{socket_path}"
    if socket_path.exists() and _channel_ready(target, 2.0):
        return target
    _start_local_daemon(socket_path)
    return target


# ------------------------------------------------------------------------------------------
# Where user code called us (the origin of commands, for asynchronous error messages)


def caller_location():
    """types_pb2.SourceLocation of the innermost frame outside the weft package."""
    frame = sys._getframe(1)
    package = str(_PACKAGE_DIR)
    while frame is not None:
        filename = frame.f_code.co_filename
        if not filename.startswith(package):
            return types_pb2.SourceLocation(file=filename, line=frame.f_lineno)
        frame = frame.f_back
    return types_pb2.SourceLocation()


def format_location(location) -> str | None:
    if location is None or not location.file:
        return None
    return f"{location.file}:{location.line}" if location.line else location.file


def _report_sync(response, deferred) -> None:
    """What a SynchronizeResponse brings back: kernel print output to stdout, then the error
    held back from an earlier asynchronous call, then the session's error."""
    if response.output:
        sys.stdout.write(response.output)
        sys.stdout.flush()
    if deferred is not None:
        raise deferred
    if response.error:
        raise WeftError(response.error, _CODE_NAMES.get(response.error_code),
                        format_location(response.error_origin))


# ------------------------------------------------------------------------------------------
# The session


class _SlabMapping:
    """One mapped slab. Held by the allocations and NumPy views that use it; unmapped when the
    last of them goes away (the daemon unlinks empty slabs, so keeping them mapped would pin
    their memory)."""

    __slots__ = ("mm", "address", "size", "_anchor", "__weakref__")

    def __init__(self, name: str, size: int):
        path = "/dev/shm/" + name.lstrip("/")
        fd = os.open(path, os.O_RDWR)
        try:
            self.mm = mmap.mmap(fd, size, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE)
        finally:
            os.close(fd)
        self._anchor = ctypes.c_char.from_buffer(self.mm)
        self.address = ctypes.addressof(self._anchor)
        self.size = size


class Runtime:
    """One session with one weftd, for the life of this process."""

    def __init__(self, address: str | None = None, token: str | None = None):
        self.address = address or resolve_address()
        self.token = token if token is not None else (os.environ.get("WEFT_TOKEN") or None)
        self.pid = os.getpid()
        unchecked = self.unchecked = _unchecked_requested()
        daemon_address = self.address
        opened = self._open(unchecked)
        # An unchecked session (every session of a weftd started with --isolate-sessions) runs
        # in a weftd process of its own (a session host), and under --device-hosts a checked
        # session runs in the process of its device (a device host): the daemon started it and
        # names its socket; the session is opened there. A device host that ended just then
        # (its GPU lost to a fault) is not listening any more: the daemon is asked again and
        # starts a new one.
        self.hosted = bool(getattr(opened, "session_host", ""))
        self.host_device = getattr(opened, "session_device", "") if self.hosted else ""
        for attempt in range(3):
            if not self.hosted:
                break
            self.channel.close()
            self.address = "unix:" + opened.session_host
            try:
                opened = self._open(unchecked)
                break
            except WeftError as err:
                if err.code != "UNAVAILABLE" or not self.host_device or attempt == 2:
                    raise
            time.sleep(0.2)
            self.address = daemon_address
            opened = self._open(unchecked)
            self.hosted = bool(getattr(opened, "session_host", ""))
            self.host_device = getattr(opened, "session_device", "") if self.hosted else ""
        self.session_id = opened.session_id
        self.daemon_version = opened.daemon_version
        self.daemon_pid = opened.daemon_pid
        self.local = bool(opened.local) and self.address.startswith("unix:")
        self.metadata = self._base_metadata + (("weft-session", self.session_id),)
        self.fast_lane = self._open_fast_lane(opened)
        # ArrayService.Create/Free/Describe over the lane too (WEFT_FAST_LANE_ARRAYS=0: through
        # gRPC, as before the lane carried them; bench/bench_interop.py compares the two).
        self.lane_arrays = os.environ.get("WEFT_FAST_LANE_ARRAYS", "1") != "0"

        self._lock = threading.RLock()
        self._batch: list = []
        self._batch_bytes = 0
        self._pending_frees: collections.deque = collections.deque()
        # Commands that finalizers queued (geometry frees, tape frees, graph destroys): a
        # finalizer may run inside any allocation of this thread, even while the lock is held
        # and a deque is being walked, so it only appends here, without the lock; the next
        # batch takes them, after the commands queued before them.
        self._finalizer_commands: collections.deque = collections.deque()
        self._free_calls: list = []
        self._deferred_error: WeftError | None = None
        # Asynchronous Submits in flight, oldest first: one gRPC future, or up to
        # LANE_IN_FLIGHT fast-lane replies (the lane keeps frames in order), see _pump/send_now.
        self._inflight: collections.deque = collections.deque()
        # Frames the lane does not answer (quiet Submits: only failures; unanswered Frees:
        # never) sent since it last answered a request: a gRPC call waits for the lane's
        # answer to an empty Submit first (order_grpc, _fence_quiet). `_quiet_sends` counts
        # the quiet Submits between polls for their failures.
        self._quiet_unfenced = False
        self._quiet_sends = 0
        self.eager_sends = 0               # launches sent at once by submit_eager
        self.pipelined = _PIPELINED
        # Commands (and GPU array creations) queued so far: weft.interop.cuda_order knows
        # from it whether a framework stream already waits for everything queued.
        self.work_queued = 0
        # > 0 while an ordered launch is being queued (WAIT, launch, RECORD go in one Submit).
        self.pump_held = 0
        self._pump_at = PUMP_FIRST
        self._pump_after = PUMP_AFTER_LANE_S
        self._batch_since = 0.0   # when the oldest command of the batch was queued
        self._slabs = weakref.WeakValueDictionary()   # name -> _SlabMapping in use
        self._devices = None
        self._device_listing = None
        self._unsynchronized = False   # commands were queued since the last Synchronize
        self.gpu_work = False          # GPU launches were queued since the last synchronize
        self.create_ahead = _create_ahead.CreateAhead(self)   # small arrays created ahead
        # Graph capture (weft/graph.py): thread id -> the capture recording that thread's
        # commands; handles that captured graphs name, and those freed while a graph held them.
        self.captures: dict = {}
        # (activities, dropped) of the synchronize after a TimingCommand END (weft.timing).
        self.timing_collected = None
        self._graph_handles: collections.Counter = collections.Counter()
        self._graph_freed: set = set()
        self.closed = False
        self.gone_reported = False   # the end of this session's host process was raised once
        self.attach_lost = False
        self.attach_message = ""

        self._closing = threading.Event()
        self._attach_answered = threading.Event()   # the daemon's first event, or the stream's end
        self._attach_call = self.session_stub.Attach(self._attach_requests(),
                                                     metadata=self.metadata)
        self._attach_thread = threading.Thread(target=self._attach_loop, name="weft-attach",
                                               daemon=True)
        self._attach_thread.start()
        # The session is returned once the daemon holds its Attach stream: a process killed
        # right after connecting is then reaped at once, not after the unattached timeout.
        if not self._attach_answered.wait(ATTACH_CONFIRM_S) or not self.attach_message:
            reason = ("did not confirm the session's stream within "
                      f"{ATTACH_CONFIRM_S:g} s" if not self._attach_answered.is_set()
                      else "ended the session's stream before claiming it")
            self.close()
            raise WeftError(f"SessionService.Attach: the daemon at {self.address} {reason}")

    def _open(self, unchecked: bool):
        """A channel and stubs for self.address, and SessionService.Open on it."""
        options = [("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
                   ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES)]
        self.channel = grpc.insecure_channel(self.address, options=options)
        self.session_stub = SessionServiceStub(self.channel)
        self.array_stub = ArrayServiceStub(self.channel)
        self.exec_stub = ExecServiceStub(self.channel)
        self.module_stub = ModuleServiceStub(self.channel)
        self.device_stub = DeviceServiceStub(self.channel)
        self._base_metadata = (("authorization", f"Bearer {self.token}"),) if self.token else ()
        self.metadata = self._base_metadata
        request = session_pb2.OpenSessionRequest(
            client_name=f"python {sys.version.split()[0]} pid {self.pid}", client_pid=self.pid)
        if unchecked and "unchecked" in request.DESCRIPTOR.fields_by_name:
            request.unchecked = True
        # The device this session works on, for a daemon that runs each device's sessions in a
        # process of their own (--device-hosts); empty: the daemon's first GPU, else the CPU.
        device = os.environ.get("WEFT_SESSION_DEVICE", "")
        if device and "device" in request.DESCRIPTOR.fields_by_name:
            request.device = device
        try:
            # an Open may wait for a session host to start (an unchecked session, or any under
            # --isolate-sessions; CUDA initialisation)
            return self.session_stub.Open(request, metadata=self._base_metadata, timeout=90)
        except grpc.RpcError as err:
            self.channel.close()
            raise error_from_rpc(err) from None

    def _end_if_over(self, response) -> None:
        """A session host whose GPU a kernel fault took says the session is over: forget it
        (its arrays are gone), so that the next weft call opens a new session."""
        if getattr(response, "session_ended", False):
            self.abandon()

    def abandon(self) -> None:
        """Drops a session that can no longer work, without flushing or synchronizing."""
        if self.closed:
            return
        self._batch.clear()
        self._inflight.clear()
        self._end_session(close_timeout=5)

    def _end_session(self, close_timeout: float) -> None:
        """Marks the session closed, closes the fast lane, sends SessionService.Close (errors
        ignored: the daemon may be gone), ends the Attach stream and closes the channel."""
        self.closed = True
        self._pending_frees.clear()
        if self.fast_lane is not None:
            self.fast_lane.close()
        try:
            self.session_stub.Close(session_pb2.CloseSessionRequest(session_id=self.session_id),
                                    metadata=self.metadata, timeout=close_timeout)
        except grpc.RpcError:
            pass
        self._closing.set()
        try:
            self._attach_call.cancel()
        except Exception:  # noqa: BLE001
            pass
        self.channel.close()

    def _open_fast_lane(self, opened):
        """The fast lane (_fast_lane.py) when the daemon offers one to this local client and
        WEFT_FAST_LANE is not 0; None (gRPC only) otherwise or when it cannot be opened."""
        path = getattr(opened, "fast_lane_path", "")
        if not (path and self.local and _fast_lane.enabled() and hasattr(session_pb2, "FastLaneHello")):
            return None
        try:
            return _fast_lane.FastLane.connect(path, self.session_id, opened.fast_lane_secret,
                                               session_pb2.FastLaneHello)
        except (WeftError, OSError):
            return None

    def _exec(self, method: str, request, gpu_wait: bool = False):
        """ExecService.Submit / Synchronize: through the fast lane when it is open and the
        request fits a frame, else through gRPC. Same responses and errors either way.
        `request`: the message, or its serialized body (for Submit framed_command frames and
        flags). `gpu_wait`: the reply waits for GPU work (the lane polls for it longer)."""
        lane = self.fast_lane
        body = request if isinstance(request, bytes) else None
        if lane is not None and (lane.fits_bytes(len(body)) if body is not None
                                 else lane.fits(request)):
            spin = _fast_lane.SPIN_GPU_S if gpu_wait and _fast_lane.SPIN_GPU_S > 0 else None
            try:
                if method == "Submit":
                    return lane.call(_fast_lane.SUBMIT, request, exec_pb2.SubmitResponse, spin)
                return lane.call(_fast_lane.SYNCHRONIZE, request, exec_pb2.SynchronizeResponse, spin)
            except WeftError as err:
                self._raise_if_host_gone(err)
                raise
        if body is not None:
            message = exec_pb2.SubmitRequest if method == "Submit" else exec_pb2.SynchronizeRequest
            request = message.FromString(body)
        return self.call(getattr(self.exec_stub, method), request)   # fenced by order_grpc

    def _raise_if_host_gone(self, err: WeftError) -> None:
        """In a session host (an unchecked or isolated session's own process), a lost connection
        means the process ended (an unchecked kernel, or a fault, crashed it): the session is
        over. Raises that."""
        if not self.hosted or err.code != "UNAVAILABLE" or self.closed:
            return
        raise self.host_gone_error() from None

    def host_gone_error(self) -> WeftError:
        """Ends this session, whose process (a session or device host) ended, and returns the
        error that says so."""
        pid = self.daemon_pid
        self.gone_reported = True
        self.abandon()
        if self.host_device:
            cause = (f"a fault or crash ended the process of the sessions of {self.host_device} "
                     "(weftd runs each device's sessions in a process of their own: "
                     "--device-hosts), and every session of that device with it")
        elif self.unchecked:
            cause = "most likely an unchecked kernel crashed it"
        else:
            cause = ("a fault or crash in this session ended it (weftd runs each session in a "
                     "process of its own: --isolate-sessions)")
        kind = "device host" if self.host_device else "session host"
        return WeftError(f"the process of this session ({kind} pid {pid}) ended, {cause}: "
                         "the session and its arrays are gone (the daemon and its other sessions "
                         "were not touched); the next weft call opens a new session", "ABORTED")

    _LANE_ARRAY_METHODS = {"Create": (_fast_lane.ARRAY_CREATE, array_pb2.CreateArrayResponse),
                           "Free": (_fast_lane.ARRAY_FREE, array_pb2.FreeArrayResponse),
                           "Describe": (_fast_lane.ARRAY_DESCRIBE, array_pb2.DescribeArrayResponse),
                           "ImportCuda": (_fast_lane.ARRAY_IMPORT_CUDA, array_pb2.ImportCudaResponse)}

    def _lane_free(self):
        """The fast lane when it is open, once no asynchronous Submit's reply is outstanding on
        it (they are collected first); else None (caller holds the lock)."""
        lane = self.fast_lane
        if lane is None or lane.broken:
            return None
        self._collect_done()
        if any(isinstance(call, _fast_lane.PendingReply) for call in self._inflight):
            # Submits of ordered launches (send_now) still on the lane: their replies come as
            # soon as weftd has admitted them, sooner than a gRPC call would
            self._collect_inflight()
        return None if lane.broken else lane

    def array_call(self, method: str, request):
        """ArrayService.Create / Free / Describe / ImportCuda: through the fast lane when it is free and the
        request fits a frame (a round trip without gRPC: wp.zeros in a loop), else through
        gRPC. Same responses and errors either way."""
        return self._lane_or_grpc(self._LANE_ARRAY_METHODS[method],
                                  lambda: getattr(self.array_stub, method), request)

    def geometry_call(self, stub_method, request):
        """GeometryService.Call (create, build, refit, rebuild, free of geometry objects) the
        same way: through the fast lane when it is free (a per-step mesh.refit() costs no gRPC
        round trip), else `stub_method`."""
        from .v1 import geometry_pb2  # noqa: PLC0415

        return self._lane_or_grpc((_fast_lane.GEOMETRY_CALL, geometry_pb2.GeometryResponse),
                                  lambda: stub_method, request)

    def _lane_or_grpc(self, lane_entry, grpc_method, request):
        if self.lane_arrays and self.fast_lane is not None and self.fast_lane.fits(request):
            lane_method, response_type = lane_entry
            with self._lock:
                lane = self._lane_free()
                if lane is not None:
                    try:
                        return lane.call(lane_method, request, response_type)
                    except WeftError:
                        # An error that ended the lane is about the lane, not the request (the
                        # connection broke, or a daemon that serves fewer methods on its lane):
                        # gRPC serves the call or says what is wrong. Else it is the answer.
                        if not lane.broken:
                            raise
        return self.call(grpc_method(), request)

    # -- Attach: held open until this process ends
    def _attach_requests(self):
        yield session_pb2.AttachRequest(session_id=self.session_id)
        self._closing.wait()

    def _attach_loop(self):
        try:
            for event in self._attach_call:
                self.attach_message = event.message   # "attached #<label>"
                self._attach_answered.set()
        except grpc.RpcError:
            pass
        self._attach_answered.set()
        if not self._closing.is_set():
            self.attach_lost = True

    # -- unary calls
    def call(self, stub_method, request, timeout=RPC_TIMEOUT_S):
        """A unary call with the session metadata (after order_grpc); grpc errors become
        WeftError."""
        self.order_grpc()
        try:
            return stub_method(request, metadata=self.metadata, timeout=timeout)
        except grpc.RpcError as err:
            error = error_from_rpc(err)
            self._raise_if_host_gone(error)
            raise error from None

    def order_grpc(self) -> None:
        """Before a gRPC call: after frames the lane does not answer (quiet Submits, unanswered
        Frees), waits until weftd served them (_fence_quiet), since gRPC and the lane are not
        ordered with each other."""
        if self._quiet_unfenced:
            with self._lock:
                self._collect_inflight()
                self._fence_quiet()

    # -- command batch
    def submit(self, cmd, start: bool = False) -> None:
        """Appends an exec_pb2.Command to the batch (origin = caller's file:line if unset).
        When no Submit is in flight the batch goes out at once, without waiting for the reply
        (see _pump): the daemon starts on it while this process queues more. `start`: send it
        now if nothing is in flight (a large GPU launch, START_GPU_THREADS)."""
        if not cmd.HasField("origin"):
            cmd.origin.CopyFrom(caller_location())
        if self.captures:
            capture = self.captures.get(threading.get_ident())
            if capture is not None and capture.take(cmd):
                return
        self._queue_frame(framed_command(cmd), start)

    def submit_framed(self, frame: bytes, start: bool = False) -> None:
        """submit() of a command already framed (as framed_command frames it) with its origin
        set: launches and the ordering commands of weft.interop.cuda_order, built as bytes.
        Under a graph capture of this thread it is parsed and goes through submit()."""
        if self.captures and threading.get_ident() in self.captures:
            self.submit(exec_pb2.SubmitRequest.FromString(frame).commands[0], start)
            return
        self._queue_frame(frame, start)

    def submit_eager(self, frame: bytes) -> bool:
        """Sends a GPU launch's framed command at once as a quiet Submit when it is the first
        command since the last sync point and the lane's ring finds weftd polling (a record in
        memory, no system call); False when it is not sent (the caller queues it)."""
        lane = self.fast_lane
        if lane is None or self._unsynchronized or lane.ring is None or not lane.quiet or \
                lane.broken or self._batch or self._inflight or self._finalizer_commands or \
                self.pump_held or self._deferred_error is not None or self.captures:
            return False
        with self._lock:
            if self._unsynchronized or self._batch or self._inflight or not lane.ring.daemon_polls():
                return False
            self._unsynchronized = True
            self.work_queued += 1
            self.eager_sends += 1
            try:
                lane.send_quiet(frame)
                self._quiet_sends += 1
                self._quiet_unfenced = True
            except WeftError as err:
                self._deferred_error = err
            return True

    def _queue_frame(self, frame: bytes, start: bool) -> None:
        with self._lock:
            self._unsynchronized = True
            self.work_queued += 1
            if not self._batch:
                self._batch_since = time.perf_counter()
            if self._finalizer_commands:
                self._queue_finalizer_commands()
            self._batch.append(frame)
            self._batch_bytes += len(frame)
            full = len(self._batch) >= BATCH_MAX_COMMANDS or self._batch_bytes >= BATCH_MAX_BYTES
            if not full:
                self._pump(start)
        if full:
            self.flush()

    def submit_recorded(self, commands, frames, nbytes: int) -> None:
        """Queues recorded commands (a captured graph: origins set, checked when captured) as
        one block of the batch; a block larger than a batch goes out in batch-sized Submits.
        `frames`: the commands as framed_command made them, `nbytes` their total length."""
        if self.captures and threading.get_ident() in self.captures:
            for cmd in commands:        # a graph launched while capturing: part of the new one
                self.submit(cmd)
            return
        for start in range(0, len(frames), BATCH_MAX_COMMANDS):
            chunk = frames[start:start + BATCH_MAX_COMMANDS]
            if len(self._batch) + len(chunk) > BATCH_MAX_COMMANDS or \
                    self._batch_bytes + nbytes > BATCH_MAX_BYTES:
                self.flush()
            with self._lock:
                self._unsynchronized = True
                self.work_queued += len(chunk)
                if not self._batch:
                    self._batch_since = time.perf_counter()
                self._batch.extend(chunk)
                self._batch_bytes += nbytes if len(chunk) == len(frames) else \
                    sum(len(frame) for frame in chunk)
                self._pump()

    def retain_handles(self, handles) -> None:
        """Keeps the daemon arrays `handles` while a captured graph names them."""
        with self._lock:
            self._graph_handles.update(handles)

    def release_handles(self, handles) -> None:
        """A graph is gone: frees the arrays that were released while it held them."""
        with self._lock:
            for handle in handles:
                self._graph_handles[handle] -= 1
                if self._graph_handles[handle] <= 0:
                    del self._graph_handles[handle]
                    if handle in self._graph_freed:
                        self._graph_freed.discard(handle)
                        self._pending_frees.append(handle)

    def _pump(self, start: bool = False) -> None:
        """Sends the batch as an asynchronous Submit when no Submit is in flight and the batch
        holds at least `_pump_at` commands, or two commands the oldest of which was queued
        PUMP_AFTER_S ago (through the fast lane `_pump_after`: PUMP_AFTER_LANE_S after a sync
        point, doubling with each early Submit up to PUMP_AFTER_S; sending costs a few
        microseconds there, so a loop of launches starts the device after ~40 us instead of
        after PUMP_FIRST launches, a long loop still goes out in few frames, and a launch or
        two followed by a sync stays one fused Submit) (caller holds the lock). Without this a
        batch waited for the next synchronize, and the device idled while the client queued
        launches (Warp's launches start at once). At most one Submit is in flight, so the
        daemon receives batches in order (send_now, for ordered GPU launches, may add fast-lane
        Submits behind it: the lane keeps frames in order); while one is on its way, commands
        accumulate. Through a lane that takes quiet Submits (answered only when they fail)
        nothing stays in flight: the lane serves its frames in order, and the count and age
        thresholds alone space the sends. `_pump_at` starts at PUMP_FIRST after each sync
        point and doubles with each asynchronous Submit, so a long run of launches costs only
        a few extra round trips, while a short step (a few launches, then a sync) stays one
        fused Submit: an early Submit there would add a round trip. A failed asynchronous
        Submit (nothing of it was queued) is raised by the next synchronize, and nothing more
        is sent once the client knows of it. `start` (a large GPU launch was queued): sent now
        whatever the count and age, when nothing is in flight."""
        if not self.pipelined or self._deferred_error is not None or self.pump_held:
            return
        if self._inflight:
            self._collect_done()
            if self._inflight or self._deferred_error is not None:
                return
        n = len(self._batch)
        if n < self._pump_at and not start:
            if n < 2:
                return
            lane = self.fast_lane
            after = self._pump_after if lane is not None and not lane.broken else PUMP_AFTER_S
            if time.perf_counter() - self._batch_since < after:
                return
        self._pump_at = min(2 * self._pump_at, BATCH_MAX_COMMANDS)
        self._pump_after = min(2 * self._pump_after, PUMP_AFTER_S)
        self._send_batch()

    def send_now(self) -> None:
        """Sends the batch at once as an asynchronous Submit (after collecting the one in
        flight), without waiting for its reply: a framework stream made to wait on the GPU for
        a command of it (weft.interop.cuda_order) is then released without another weft call.
        A failed earlier Submit is raised here (by a synchronize, which also sends the batch)."""
        with self._lock:
            self.pump_held = 0
            if not self._batch:
                return
            if len(self._inflight) >= LANE_IN_FLIGHT:
                self._collect_done()       # replies are read in bulk, not one per send
            # A gRPC Submit is only ever in flight alone (_send_batch collects everything
            # before sending one): the head tells whether all in flight went over the lane.
            lane_ok = self.fast_lane is not None and not self.fast_lane.broken and \
                len(self._inflight) < LANE_IN_FLIGHT and \
                (not self._inflight or isinstance(self._inflight[0], _fast_lane.PendingReply))
            if not lane_ok:
                self._collect_inflight()
            if self.pipelined and self._deferred_error is None:
                self._send_batch()
            if self._batch or self._deferred_error is not None:
                self.synchronize()

    def _send_batch(self) -> None:
        """The batch as an asynchronous Submit (caller holds the lock; nothing in flight, or
        only fast-lane Submits when this one goes over the lane too: the lane keeps order)."""
        body, self._batch, self._batch_bytes = b"".join(self._batch), [], 0
        lane = self.fast_lane
        if lane is not None and lane.quiet and not self._inflight and lane.fits_bytes(len(body)):
            try:   # answered only if it fails: nothing to collect
                self._quiet_sends += 1
                if self._quiet_sends >= LANE_IN_FLIGHT:
                    self._quiet_sends = 0
                    lane.poll_quiet()       # failures drained: the daemon never blocks on them
                    self._take_quiet()
                lane.send_quiet(body)
                self._quiet_unfenced = True
            except WeftError as err:
                self._deferred_error = err
            return
        if lane is not None and not lane.broken and lane.fits_bytes(len(body)):
            try:   # sent without waiting; the reply is collected like the grpc future's
                self._inflight.append(lane.send(_fast_lane.SUBMIT, body, exec_pb2.SubmitResponse))
            except WeftError as err:
                self._deferred_error = err
            return
        self._collect_inflight()           # gRPC and the lane are not ordered with each other
        self._fence_quiet()
        self._inflight.append(self.exec_stub.Submit.future(
            exec_pb2.SubmitRequest.FromString(body), metadata=self.metadata))

    def _collect_inflight(self) -> None:
        """Waits for the asynchronous Submit in flight, if any (caller holds the lock); its
        error becomes the deferred error."""
        while self._inflight:
            self._collect_one(self._inflight.popleft())

    def _fence_quiet(self) -> None:
        """After quiet Submits, before a gRPC call that must come after them: an empty Submit
        through the lane, answered once weftd has served every frame before it (the lane
        serves its frames in order); their failures are taken on the way (caller holds the
        lock)."""
        if not self._quiet_unfenced:
            return
        self._quiet_unfenced = False
        lane = self.fast_lane
        if lane is None or lane.broken:
            return
        try:
            lane.call(_fast_lane.SUBMIT, b"", exec_pb2.SubmitResponse)
        except WeftError as err:
            if self._deferred_error is None:
                self._deferred_error = err
        self._take_quiet()

    def _take_quiet(self) -> None:
        """The first failure of a quiet Submit the lane read becomes the deferred error."""
        lane = self.fast_lane
        if lane is not None and lane.quiet_error is not None:
            err = lane.take_quiet_error()
            if self._deferred_error is None:
                self._deferred_error = err

    def _collect_done(self) -> None:
        """Collects the asynchronous Submits at the head of the queue whose replies are in."""
        while self._inflight and self._inflight[0].done():
            self._collect_one(self._inflight.popleft())

    def _collect_one(self, call) -> None:
        try:
            if type(call) is _fast_lane.PendingReply:
                if call.ahead is not None:     # a creation ahead: never the session's error
                    call.ahead.collected(call)
                    return
                call.check()           # only its error matters: not parsed
            else:
                call.result()
        except grpc.RpcError as err:
            if self._deferred_error is None:
                self._deferred_error = error_from_rpc(err)
                self._raise_if_host_gone(self._deferred_error)
        except WeftError as err:   # a fast-lane Submit's error
            if self._deferred_error is None:
                self._deferred_error = err
                self._raise_if_host_gone(err)

    def flush(self) -> None:
        """Sends the batched commands (ExecService.Submit), then the deferred frees."""
        with self._lock:
            self._collect_inflight()
            if self._finalizer_commands:
                self._queue_finalizer_commands()
            batch, self._batch, self._batch_bytes = self._batch, [], 0
            if batch:
                self._exec("Submit", b"".join(batch))
            self._drain_frees()

    def synchronize(self) -> None:
        """Flushes, waits for every command, prints kernel output, raises the first error.
        With commands pending this is ONE round trip: Submit(synchronize=true) queues them and
        returns what Synchronize would; with none pending, a plain Synchronize."""
        with self._lock:
            self._collect_inflight()
            self._pump_at = PUMP_FIRST
            self._pump_after = PUMP_AFTER_LANE_S
            self.pump_held = 0
            if self._finalizer_commands:
                self._queue_finalizer_commands()
            batch, self._batch, self._batch_bytes = self._batch, [], 0
            gpu, self.gpu_work = self.gpu_work, False
            if batch and _FUSED_SYNC:
                batch.append(_SUBMIT_SYNCHRONIZE)
                response = self._exec("Submit", b"".join(batch), gpu)
                if not response.HasField("sync"):
                    # A daemon from before the fused path ignores `synchronize`.
                    response = self._exec("Synchronize", exec_pb2.SynchronizeRequest(), gpu)
                else:
                    response = response.sync
            else:
                if batch:   # message modules generated before SubmitRequest.synchronize
                    self.call(self.exec_stub.Submit, exec_pb2.SubmitRequest.FromString(b"".join(batch)))
                response = self._exec("Synchronize", _SYNCHRONIZE_BYTES, gpu)
            self._unsynchronized = False
            self._quiet_unfenced = False       # the lane answered after every quiet Submit
            self._drain_frees()
            self._take_quiet()
            deferred, self._deferred_error = self._deferred_error, None
            self._end_if_over(response)
            self._note_timing(response)
        _report_sync(response, deferred)

    def _note_timing(self, response) -> None:
        """Keeps the timed GPU operations a synchronize brought back (weft.timing.timing_end)."""
        if response.timing_ended:
            self.timing_collected = (list(response.timing), response.timing_dropped)

    def run(self) -> None:
        """Sends the batched commands and returns once weftd has run them (GPU work queued on
        the session's streams, not finished): one round trip, no wait for the GPU. An error
        of the session is raised here (the daemon then synchronized)."""
        with self._lock:
            self._collect_inflight()
            batch, self._batch, self._batch_bytes = self._batch, [], 0
            self.pump_held = 0
            batch.append(_SUBMIT_RUN)
            response = self._exec("Submit", b"".join(batch))
            self._take_quiet()
            deferred, self._deferred_error = self._deferred_error, None
            if not response.HasField("sync"):
                self._drain_frees()
                if deferred is not None:
                    raise deferred
                return
            self._pump_at = PUMP_FIRST
            self._pump_after = PUMP_AFTER_LANE_S
            self._drain_frees()
            self._unsynchronized = False
            response = response.sync
            self._end_if_over(response)
            self._note_timing(response)
        _report_sync(response, deferred)

    def synchronize_if_needed(self) -> None:
        """synchronize() when commands were queued since the last one (data access)."""
        if self._unsynchronized or self._batch or self._deferred_error is not None:
            self.synchronize()

    # -- frees (deferred: never an RPC from a finalizer, never before queued commands are sent)
    def free_later(self, handle: int) -> None:
        if self.closed:
            return
        if self._graph_handles:
            with self._lock:
                if handle in self._graph_handles:   # a captured graph still names it
                    self._graph_freed.add(handle)
                    return
        self._pending_frees.append(handle)

    def free_geometry_later(self, object_id: int) -> None:
        """A geometry object the client released (its finalizer: no lock, no RPC here): freed
        by a command of the next batch, after the commands queued before it."""
        from .v1 import geometry_pb2  # noqa: PLC0415

        self.submit_from_finalizer(exec_pb2.Command(geometry=geometry_pb2.GeometryRequest(
            op=geometry_pb2.GeometryRequest.Op.FREE, id=object_id)))

    def submit_from_finalizer(self, cmd) -> None:
        """submit() for a finalizer: no lock, no RPC, no walk of the batch or of the Submits
        in flight (the finalizer may have interrupted one); the next batch takes `cmd`."""
        if not self.closed:
            self._finalizer_commands.append(cmd)

    def _queue_finalizer_commands(self) -> None:
        # Caller holds the lock; straight into the batch, never into a graph being captured.
        while self._finalizer_commands:
            frame = framed_command(self._finalizer_commands.popleft())
            self._batch.append(frame)
            self._batch_bytes += len(frame)

    def drain_frees(self) -> None:
        """Frees what finalizers released, if no command that may use them is unsent."""
        with self._lock:
            self._collect_done()
            if self._batch or self._inflight:
                # Commands that may use them are not in the daemon yet.
                if len(self._pending_frees) < PENDING_FREE_LIMIT:
                    return
                self.flush()
                return
            self._drain_frees()

    def _drain_frees(self) -> None:
        # Through the fast lane, pipelined (a few microseconds each); else asynchronous gRPC
        # calls: the caller does not wait for the round trips. Errors (already gone: session
        # closed, daemon restarted) are ignored; there is nothing left to free.
        if self._free_calls:
            self._free_calls = [call for call in self._free_calls if not call.done()]
        lane = self._lane_free() if self._pending_frees and self.lane_arrays else None
        if lane is not None and lane.unanswered_free:
            # Popped one by one (a finalizer may append to the deque while this runs), sent in
            # frames nothing answers: the lane serves them in order after what came before, and
            # a later gRPC call is fenced behind them (_fence_quiet).
            handles = []
            while self._pending_frees:
                handles.append(self._pending_frees.popleft())
            try:
                for start in range(0, len(handles), _fast_lane.FREE_HANDLES_PER_FRAME):
                    lane.send_unanswered_free(array_pb2.FreeArrayRequest(
                        handles=handles[start:start + _fast_lane.FREE_HANDLES_PER_FRAME]
                    ).SerializeToString())
                self._quiet_unfenced = True
                return
            except _fast_lane.FastLaneError:
                self._pending_frees.extend(handles)   # gRPC below (a free of a freed handle fails harmlessly)
        elif lane is not None:
            # Popped one by one: a finalizer may append to the deque while this runs.
            requests = []
            while self._pending_frees:
                requests.append(array_pb2.FreeArrayRequest(handle=self._pending_frees.popleft()))
            try:
                lane.call_many(_fast_lane.ARRAY_FREE, requests)
                return
            except _fast_lane.FastLaneError:
                self._pending_frees.extend(r.handle for r in requests)   # gRPC below
        if self._pending_frees and self._quiet_unfenced:
            # gRPC is not ordered with the lane: a free sent now could reach weftd before a
            # quiet Submit still unread in the lane that uses the array (its command would then
            # find the handle gone). The fence returns once weftd served everything sent so far.
            self._collect_inflight()
            self._fence_quiet()
        while self._pending_frees:
            handle = self._pending_frees.popleft()
            self._free_calls.append(self.array_stub.Free.future(
                array_pb2.FreeArrayRequest(handle=handle), metadata=self.metadata, timeout=30))

    # -- devices
    def device_listing(self):
        """The daemon's ListDevicesResponse (devices and CUDA toolchain), asked once."""
        if self._device_listing is None:
            self._device_listing = self.call(self.device_stub.List, device_pb2.ListDevicesRequest())
        return self._device_listing

    def devices(self):
        if self._devices is None:
            self._devices = list(self.device_listing().devices)
        return self._devices

    # -- shared memory (local sessions)
    def map_slab(self, name: str, size: int) -> _SlabMapping:
        """The mapping of slab `name`: mapped once and shared while anything holds it."""
        mapping = self._slabs.get(name)
        if mapping is None or mapping.size < size:
            with self._lock:
                mapping = self._slabs.get(name)
                if mapping is None or mapping.size < size:
                    mapping = _SlabMapping(name, size)
                    self._slabs[name] = mapping
        return mapping

    # -- end of session
    def close(self) -> None:
        """Flushes, synchronizes (errors reported on stderr), closes the session."""
        if self.closed:
            return
        try:
            with self._lock:
                self.flush()
                self._fence_quiet()     # frees flush() sent unanswered come before the end
                response = self.exec_stub.Synchronize(exec_pb2.SynchronizeRequest(),
                                                      metadata=self.metadata, timeout=30)
            if response.output:
                sys.stdout.write(response.output)
                sys.stdout.flush()
            if response.error:
                sys.stderr.write("weft: error in a command not synchronized before exit: "
                                 f"{response.error}\n")
        except Exception as err:  # noqa: BLE001 - exiting; report and go on
            if not self.attach_lost:
                sys.stderr.write(f"weft: while closing the session: {err}\n")
        self._end_session(close_timeout=10)


_runtime: Runtime | None = None
_runtime_lock = threading.Lock()
_every_runtime: list = []


def _usable(rt) -> bool:
    """rt is this process's open session; a session host that went away (its process ended:
    a crash of an unchecked kernel) ends its session."""
    if rt is None or rt.pid != os.getpid() or rt.closed:
        return False
    if rt.hosted and rt.attach_lost:
        rt.abandon()
        return False
    return True


# This process's id, kept current across fork: os.getpid() is a system call (glibc no longer
# caches it), and get_runtime runs in every launch.
_pid = os.getpid()


def _forked() -> None:
    global _pid
    _pid = os.getpid()


os.register_at_fork(after_in_child=_forked)


def get_runtime() -> Runtime:
    """The process's Runtime, connecting (and opening a session) on first use, and again after
    the session ended."""
    global _runtime
    rt = _runtime
    if rt is not None and not rt.closed and not rt.attach_lost and rt.pid == _pid:
        return rt   # the common case, as cheap as a launch needs it
    if _usable(rt):
        return rt
    if rt is not None and rt.hosted and rt.attach_lost and not rt.gone_reported and rt.pid == _pid:
        # Its process ended between calls: this call gets the error (the arrays it names are
        # gone), the next one a new session.
        raise rt.host_gone_error()
    with _runtime_lock:
        rt = _runtime
        if not _usable(rt):
            rt = Runtime()
            _runtime = rt
            _every_runtime.append(rt)   # alive for good: caches keyed by id(runtime) stay apart
    return rt


def is_initialized() -> bool:
    return _usable(_runtime)


def current_runtime() -> Runtime | None:
    """The live Runtime of this process, or None (never connects)."""
    rt = _runtime
    return rt if _usable(rt) else None


def shutdown() -> None:
    """Closes this process's session (also run at exit)."""
    global _runtime
    rt = _runtime
    if rt is not None and rt.pid == os.getpid():
        rt.close()
    _runtime = None


atexit.register(shutdown)
