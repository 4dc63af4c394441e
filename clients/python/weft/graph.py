"""Graph capture for a weft client: wp.capture_begin / capture_end / capture_launch,
wp.ScopedCapture, wp.Graph, capture_pause / capture_resume, capture_if / capture_while and
capture_debug_dot_print, on CPU and CUDA devices alike (docs/graphs.md).

A client's device work reaches the daemon as commands that run in order (launches, copies,
fills, a tape's backward/zero/reset). While a thread captures on a device, the commands it
issues for that device are recorded instead of sent: nothing runs. capture_end sends each run
of recorded launches, copies and fills to the daemon once, as a graph of the session
(GraphCommand CREATE: on a GPU a CUDA graph captured on the session's stream, checked as the
commands would be; elsewhere a list the daemon replays), and `capture_launch` queues one small
LAUNCH per run (and the tape commands between runs). Launch arguments are fixed when captured,
as in a CUDA graph.

What is state rather than work is not recorded: array creation (a `zeros`/`full` made while
capturing also records a fill, so each replay starts from the value, as Warp's captured
memset does), a tape's begin/end, gradient replacement, framework stream ordering. A forward
launch captured while a tape records is also sent at once as a record-only launch, so the
tape holds it as Warp's tape does, and a captured `tape.backward()` replays its adjoints.

A graph keeps the daemon arrays it names: an array the program drops stays allocated until
the graph is gone (Warp asks the program to keep them alive; weft does it for it).

The wp.utils algorithms (sorts, scans, reductions into `out`, casts, run-length encoding) run
on the host in weft. Captured, one becomes a *host step* of the graph (HostStep): its arguments
are checked when captured, and capture_launch sends the graph's commands before it, runs it (it
waits for them as it reads its arrays) and goes on with the rest. capture_if / capture_while
inside a capture are host steps too: their branches are captured as graphs, and the condition
is read when the graph runs.
"""
from __future__ import annotations

import enum
import itertools
import threading

from . import _runtime
from .device import get_device

__all__ = ["CaptureMode", "Graph", "ScopedCapture", "capture_begin", "capture_end", "capture_launch",
           "capture_pause", "capture_resume", "capture_if", "capture_while",
           "capture_debug_dot_print", "is_conditional_graph_supported", "is_capturing"]


class CaptureMode(enum.IntEnum):
    """Warp's CUDA stream capture modes (capture_begin(capture_mode=...)). A weft client's
    capture records commands in this process and weftd captures them on the session's stream in
    RELAXED mode (other sessions' threads keep running), so every mode records the same; the
    value is checked."""

    GLOBAL = 0
    THREAD_LOCAL = 1
    RELAXED = 2


def _check_capture_mode(capture_mode) -> None:
    if capture_mode is None or isinstance(capture_mode, CaptureMode):
        return
    if isinstance(capture_mode, bool) or not isinstance(capture_mode, int) or \
            capture_mode not in CaptureMode._value2member_map_:
        raise ValueError(f"capture_mode must be a wp.CaptureMode (GLOBAL, THREAD_LOCAL, RELAXED), "
                         f"got {capture_mode!r}")


def _array_handles(message, out: set) -> None:
    """The daemon array handles an exec_pb2 message names (every ArrayRef in it)."""
    for field, value in message.ListFields():
        if field.message_type is None:
            continue
        repeated = getattr(field, "is_repeated", None)
        if repeated is None:                       # protobuf before 6: the field's label
            repeated = field.label == field.LABEL_REPEATED
        values = value if repeated else (value,)
        if field.message_type.name == "ArrayRef":
            out.update(ref.handle for ref in values if ref.handle)
        else:
            for item in values:
                _array_handles(item, out)


_graph_ids = itertools.count(1)
_GRAPH_KINDS = ("launch", "copy", "fill")


class HostStep:
    """Work a graph runs in this process at its place in the graph's order (a wp.utils
    algorithm captured with its arguments): `call()` runs it."""
    __slots__ = ("name", "call")

    def __init__(self, name: str, call):
        self.name = name
        self.call = call

    def __repr__(self):
        return f"<host step {self.name}>"


def record_host_step(name: str, call) -> None:
    """Records `call` as a host step of the graph this thread captures (a caller checked that
    it captures)."""
    capture = _capture_of_thread(_runtime.get_runtime())
    if capture is None or capture.paused:
        raise RuntimeError(f"{name}: no graph capture is active on this thread")
    capture.graph.commands.append(HostStep(name, call))


class Graph:
    """Commands captured on one device, replayed by wp.capture_launch (Warp's wp.Graph)."""

    def __init__(self, device, runtime):
        self.device = device
        self.commands: list = []     # as captured
        self._runtime = runtime
        # What capture_launch replays, in order: (commands, their bytes) blocks of LAUNCHes and
        # tape commands for the batch, and HostSteps between them.
        self._segments: list = []
        self._graph_ids: list = []   # the daemon graphs made from the runs of commands
        self._retained: list = []    # array handles kept for the recorded commands (per command)
        self._children: list = []    # graphs launched while this one was captured
        self.graph = self            # Warp exposes the native graph; here this object
        self.graph_exec = None

    def _seal(self) -> None:
        """Sends each run of launches/copies/fills to the daemon as a graph (CREATE)."""
        from .v1 import exec_pb2  # noqa: PLC0415

        run: list = []
        replay: list = []

        def close_run():
            if not run:
                return
            graph_id = next(_graph_ids)
            create = exec_pb2.GraphCommand(op=exec_pb2.GraphCommand.CREATE, graph_id=graph_id,
                                           device=self.device.alias, commands=run)
            self._runtime.submit(exec_pb2.Command(graph=create, origin=run[0].origin))
            self._graph_ids.append(graph_id)
            replay.append(exec_pb2.Command(
                graph=exec_pb2.GraphCommand(op=exec_pb2.GraphCommand.LAUNCH, graph_id=graph_id),
                origin=run[0].origin))
            run.clear()

        def close_block():
            if replay:
                frames = [_runtime.framed_command(cmd) for cmd in replay]
                self._segments.append((list(replay), frames, sum(len(f) for f in frames)))
                replay.clear()

        for cmd in self.commands:
            if isinstance(cmd, HostStep):
                close_run()
                close_block()
                self._segments.append(cmd)
            elif cmd.WhichOneof("kind") in _GRAPH_KINDS:
                run.append(cmd)
            else:
                close_run()
                replay.append(cmd)
        close_run()
        close_block()

    @property
    def is_loaded(self) -> bool:
        return False

    def __len__(self) -> int:
        return len(self.commands)

    def __del__(self):
        try:
            rt = self._runtime
            if rt.closed:
                return
            if self._graph_ids:
                from .v1 import exec_pb2  # noqa: PLC0415
                for graph_id in self._graph_ids:
                    rt.submit_from_finalizer(exec_pb2.Command(graph=exec_pb2.GraphCommand(
                        op=exec_pb2.GraphCommand.DESTROY, graph_id=graph_id)))
            if self._retained:
                rt.release_handles(self._retained)
        except Exception:  # noqa: BLE001 - finalizer: never raise
            pass

    def __repr__(self):
        return f"<weft Graph on {self.device}: {len(self.commands)} commands>"


class _Capture:
    """The recording of one thread on one device (installed in Runtime.captures)."""

    def __init__(self, graph):
        self.graph = graph
        self.paused = False

    def take(self, cmd) -> bool:
        """Records `cmd` into the graph (True), or lets it go out now (False)."""
        if self.paused:
            return False
        kind = cmd.WhichOneof("kind")
        if kind == "launch":
            launch = cmd.launch
            if launch.record_only:
                return False
            if launch.device != self.graph.device.alias and \
                    get_device(launch.device) != self.graph.device:
                return False               # work on another device runs now, as in Warp
            if not launch.adjoint:
                self._record_on_tape(cmd)
        elif kind == "tape":
            from .v1 import exec_pb2  # noqa: PLC0415
            ops = exec_pb2.TapeCommand
            if cmd.tape.op not in (ops.BACKWARD, ops.ZERO, ops.RESET):
                return False               # begin/end/free: the tape's state, not work
        elif kind == "graph":
            from .v1 import exec_pb2  # noqa: PLC0415
            if cmd.graph.op != exec_pb2.GraphCommand.LAUNCH:
                return False               # a graph made or destroyed: the session's state
        elif kind == "geometry":
            pass                           # a build or refit: sent again at each replay
        elif kind not in ("copy", "fill"):
            return False                   # gradient replacement, framework stream ordering
        self.graph.commands.append(cmd)
        # Kept from now: an array made and dropped while capturing stays for the graph.
        handles: set = set()
        _array_handles(cmd, handles)
        if handles:
            self.graph._runtime.retain_handles(handles)
            self.graph._retained.extend(handles)
        return True

    def _record_on_tape(self, cmd) -> None:
        from ._kernel import tape as tape_mod  # noqa: PLC0415

        tape = tape_mod.active_tape()
        if tape is None or tape._mode != "daemon":
            return
        record = type(cmd)()
        record.CopyFrom(cmd)
        record.launch.record_only = True
        self.graph._runtime.submit(record)   # passes take(): record_only


def _capture_of_thread(rt):
    return rt.captures.get(threading.get_ident())


def is_capturing(device=None) -> bool:
    """Whether this thread is capturing a graph on `device` (any device when None); not while
    the capture is paused."""
    rt = _runtime.get_runtime()
    capture = _capture_of_thread(rt)
    if capture is None or capture.paused:
        return False
    return device is None or get_device(device) == capture.graph.device


def refuse_host_wait(what: str, device=None) -> None:
    """Warp's error for a host wait (`what`: "device", "stream", "event") while this thread
    captures a graph on `device` (on any device when None)."""
    if _runtime.get_runtime().captures and is_capturing(device):
        where = f" {device}" if device is not None else ""
        raise RuntimeError(f"Cannot synchronize {what}{where} while graph capture is active")


def capture_begin(device=None, stream=None, force_module_load=None, external=False,
                  apic=False, capture_mode=None):
    """Starts recording this thread's commands for `device` (or `stream`'s device)."""
    _check_capture_mode(capture_mode)
    if external:
        raise RuntimeError("external graph capture is not available to weft clients: the "
                           "daemon runs the work, not a CUDA stream of this process")
    if stream is not None:
        device = stream.device
    device = get_device(device)
    rt = _runtime.get_runtime()
    if _capture_of_thread(rt) is not None:
        raise RuntimeError("Graph capture already in progress")
    rt.captures[threading.get_ident()] = _Capture(Graph(device, rt))


def capture_end(device=None, stream=None) -> Graph:
    """Ends this thread's capture and returns the graph."""
    rt = _runtime.get_runtime()
    capture = _capture_of_thread(rt)
    if capture is None:
        raise RuntimeError("Graph capture is not active on this stream")
    if stream is not None:
        device = stream.device
    if device is not None and get_device(device) != capture.graph.device:
        raise RuntimeError(f"Graph capture is active on {capture.graph.device}, not on "
                           f"{get_device(device)}")
    del rt.captures[threading.get_ident()]
    capture.graph._seal()
    return capture.graph


def capture_pause(device=None, stream=None) -> Graph:
    """Lets this thread's commands run at once until capture_resume."""
    rt = _runtime.get_runtime()
    capture = _capture_of_thread(rt)
    if capture is None:
        raise RuntimeError("Graph capture is not active on this stream")
    capture.paused = True
    return capture.graph


def capture_resume(graph=None, device=None, stream=None) -> None:
    rt = _runtime.get_runtime()
    capture = _capture_of_thread(rt)
    if capture is None or (graph is not None and graph is not capture.graph):
        raise RuntimeError("capture_resume: the graph's capture is not paused on this thread")
    capture.paused = False


def capture_launch(graph: Graph, stream=None) -> None:
    """Queues the graph's commands (one block of the batch; see Runtime.submit_recorded)."""
    if not isinstance(graph, Graph):
        raise TypeError(f"capture_launch expects a wp.Graph, got {type(graph).__name__}")
    if stream is not None and stream.device != graph.device:
        raise RuntimeError(f"Cannot launch graph from device {graph.device} on stream from "
                           f"device {stream.device}")
    rt = _runtime.get_runtime()
    if graph._runtime is not rt:
        raise RuntimeError("this graph was captured by another weft session")
    outer = _capture_of_thread(rt)
    capturing = outer is not None and not outer.paused
    if capturing:
        outer.graph._children.append(graph)   # its daemon graphs live as long as the outer one
    for segment in graph._segments:
        if not isinstance(segment, HostStep):
            rt.submit_recorded(*segment)
        elif capturing:
            outer.graph.commands.append(segment)   # a step of the graph being captured
        else:
            segment.call()                         # waits for the commands sent before it


def is_conditional_graph_supported() -> bool:
    """True: capture_if / capture_while work inside a capture. A weft graph has no device-side
    branches: the condition is read on the host when the graph runs (a host step, see the
    module's docstring), after the work queued before it."""
    return True


def _condition_value(condition) -> bool:
    _condition_type_check(condition)
    return bool(condition.numpy().reshape(-1)[0])


def _run_branch(branch, stream, kwargs) -> None:
    if isinstance(branch, Graph):
        capture_launch(branch, stream=stream)
    elif callable(branch):
        branch(**kwargs)
    else:
        raise RuntimeError("branch must be a callable or a wp.Graph")


def _captured_branch(outer, branch, kwargs):
    """A branch of a conditional captured inside `outer`'s capture: a graph as given, or a
    callable's work captured into a graph of its own now (as Warp captures the body into the
    conditional node's child graph). The outer graph keeps it."""
    if branch is None:
        return None
    if isinstance(branch, Graph):
        sub = branch
    elif callable(branch):
        rt = outer.graph._runtime
        key = threading.get_ident()
        sub = Graph(outer.graph.device, rt)
        rt.captures[key] = _Capture(sub)
        try:
            branch(**kwargs)
        finally:
            rt.captures[key] = outer
        sub._seal()
    else:
        raise RuntimeError("branch must be a callable or a wp.Graph")
    outer.graph._children.append(sub)
    return sub


def capture_if(condition, on_true=None, on_false=None, stream=None, **kwargs) -> None:
    """Runs on_true or on_false (callables or graphs) by condition[0] (Warp's capture_if).
    Inside a capture the branches are captured as graphs and the choice is a host step of the
    graph: made each time the graph runs, after the work before it."""
    if on_true is None and on_false is None:
        return
    outer = _capture_of_thread(_runtime.get_runtime())
    if outer is not None and not outer.paused:
        _condition_type_check(condition)
        true_graph = _captured_branch(outer, on_true, kwargs)
        false_graph = _captured_branch(outer, on_false, kwargs)

        def choose():
            graph = true_graph if _condition_value(condition) else false_graph
            if graph is not None:
                capture_launch(graph, stream=stream)

        outer.graph.commands.append(HostStep("capture_if", choose))
        return
    branch = on_true if _condition_value(condition) else on_false
    if branch is not None:
        _run_branch(branch, stream, kwargs)


def capture_while(condition, while_body, stream=None, **kwargs) -> None:
    """Runs while_body (a callable or graph) as long as condition[0] is nonzero. Inside a
    capture the body is captured as a graph and the loop is a host step of the graph."""
    outer = _capture_of_thread(_runtime.get_runtime())
    if outer is not None and not outer.paused:
        _condition_type_check(condition)
        body = _captured_branch(outer, while_body, kwargs)

        def loop():
            while _condition_value(condition):
                capture_launch(body, stream=stream)

        outer.graph.commands.append(HostStep("capture_while", loop))
        return
    while _condition_value(condition):
        _run_branch(while_body, stream, kwargs)


def _condition_type_check(condition) -> None:
    from .array import array  # noqa: PLC0415
    from .types import int32  # noqa: PLC0415

    if not isinstance(condition, array) or condition.dtype is not int32:
        raise TypeError("Condition must be a Warp array of int32 with a single element")


def capture_debug_dot_print(graph: Graph, path: str, verbose: bool = True) -> None:
    """Writes the graph's commands, in order, as a DOT file (one node per command)."""
    if not isinstance(graph, Graph):
        raise TypeError(f"capture_debug_dot_print expects a wp.Graph, got "
                        f"{type(graph).__name__}")
    lines = ["digraph weft_graph {", "  rankdir=TB;", "  node [shape=box];"]
    for i, cmd in enumerate(graph.commands):
        if isinstance(cmd, HostStep):
            lines.append(f'  n{i} [label="host step {cmd.name}"];')
            if i:
                lines.append(f"  n{i - 1} -> n{i};")
            continue
        kind = cmd.WhichOneof("kind")
        if kind == "launch":
            label = f"{'adjoint ' if cmd.launch.adjoint else ''}launch {cmd.launch.kernel}"
            if verbose:
                label += f"\\ndim {list(cmd.launch.dim)}"
        else:
            label = kind
            if kind == "tape":
                from .v1 import exec_pb2  # noqa: PLC0415
                label += " " + exec_pb2.TapeCommand.Op.Name(cmd.tape.op).lower()
        if verbose and cmd.origin.file:
            label += f"\\n{cmd.origin.file}:{cmd.origin.line}"
        label = label.replace('"', "'")
        lines.append(f'  n{i} [label="{label}"];')
        if i:
            lines.append(f"  n{i - 1} -> n{i};")
    lines.append("}")
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")


class ScopedCapture:
    """`with wp.ScopedCapture() as capture:` records; `capture.graph` after the block."""

    def __init__(self, device=None, stream=None, force_module_load=None, external=False,
                 apic=False, capture_mode=None):
        self.device = device
        self.stream = stream
        self.force_module_load = force_module_load
        self.external = external
        self.capture_mode = capture_mode
        self.active = False
        self.graph = None

    def __enter__(self):
        capture_begin(device=self.device, stream=self.stream, external=self.external,
                      capture_mode=self.capture_mode)
        self.active = True
        return self

    def __exit__(self, exc_type, exc, tb):
        if self.active:
            try:
                self.graph = capture_end(device=self.device, stream=self.stream)
            except Exception:
                if exc_type is None:
                    raise
            finally:
                self.active = False
        return False
