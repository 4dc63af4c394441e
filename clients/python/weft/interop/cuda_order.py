"""Ordering on the GPU between this process's CUDA streams (Torch's current stream, CuPy's,
the stream of a `wp.ScopedStream(wp.stream_from_torch(s))`) and the daemon's session stream,
without host synchronization (docs/interop.md, "Ordering").

Two mechanisms, chosen per session and device (probed once):
- Stream memory operations (where both the daemon's and this process's driver and GPU support
  64-bit ones): counters in a small weft GPU array of the session (the order array), which
  this process sees through its CUDA IPC mapping. before(): the framework stream writes the
  next value of its slot (cuStreamWriteValue64) and the session's stream waits for it
  (CudaValueCommand WAIT); after(): the session's stream writes the next value of slot 0 after
  the launch (WRITE) and the framework stream waits for it (cuStreamWaitValue64 GEQ). The
  counters only grow, so nothing has to come back from the daemon: an ordered launch costs no
  round trip, only an asynchronous send.
- Interprocess CUDA events otherwise: before() records an event of this process on the
  framework stream and the session's stream waits for it (CudaEventCommand WAIT); after() has
  the daemon record an event (RECORD, in a Submit that returns once weftd queued it: one round
  trip) and the framework stream waits for it.

Where neither can be used (remote session, no CUDA driver here, a daemon that cannot open this
process's handles, WEFT_CUDA_EVENTS=0) `enabled()` is False and callers synchronize on the
host. WEFT_CUDA_VALUES=0 keeps events even where values would work.
"""
from __future__ import annotations

import ctypes
import os
import sys
import threading

from .. import _cuda_ipc
from .._runtime import varint as _varint

_state = threading.local()       # .foreign: {ordinal: stream handle} of a ScopedStream
_refused: dict = {}              # id(runtime) -> why weftd cannot use this process's events
_probed: set = set()             # (id(runtime), ordinal) that passed the probe
_enabled: set = set()            # (id(runtime), frozenset of ordinals) all probed (enabled())
_values: dict = {}               # (session id, ordinal) -> _ValueOrder, or None (events)
SLOTS = 31                       # framework streams ordered by values at once, per device
# (id(runtime), ordinal, stream) -> runtime.work_queued when that stream was last made to wait
# for everything queued: a later hand-out with nothing new queued needs no round trip
_ordered: dict = {}


def refused() -> str:
    """'' while weftd orders this process's streams with events, else why it cannot."""
    return next(iter(_refused.values()), "")


def set_scoped_stream(ordinal: int, handle):
    """Makes `handle` (a CUDA stream of this process) the framework stream of device `ordinal`
    for this thread (None: back to the default); returns the previous value."""
    foreign = getattr(_state, "foreign", None)
    if foreign is None:
        foreign = _state.foreign = {}
    previous = foreign.get(ordinal)
    if handle is None:
        foreign.pop(ordinal, None)
    else:
        foreign[ordinal] = int(handle)
    return previous


def framework_stream(ordinal: int) -> int:
    """The CUDA stream of this process that weft work on device `ordinal` is ordered with: the
    stream of the active wp.ScopedStream when it names one of this process, else Torch's
    current stream of that device (when Torch is in use), else the legacy default stream (0),
    which every blocking stream of the context (CuPy's default included) synchronizes with."""
    foreign = getattr(_state, "foreign", None)
    if foreign:
        handle = foreign.get(ordinal)
        if handle is not None:
            return handle
    global _raw_stream
    if _raw_stream is not None:                  # Torch's CUDA is initialized (it stays so)
        try:
            return int(_raw_stream(ordinal))
        except (RuntimeError, TypeError):
            pass
    torch = sys.modules.get("torch")
    if torch is not None:
        try:
            if torch.cuda.is_initialized():
                raw = getattr(torch._C, "_cuda_getCurrentRawStream", None)
                if raw is not None:              # ~1 us; current_stream() costs tens
                    _raw_stream = raw
                    return int(raw(ordinal))
                return int(torch.cuda.current_stream(ordinal).cuda_stream)
        except (RuntimeError, AttributeError, AssertionError):
            pass
    return 0


# Torch's current-stream function once Torch's CUDA is initialized (framework_stream): the
# check of that and the look-up cost more than the call.
_raw_stream = None


_EXEC_PB = None


def _pb():
    global _EXEC_PB
    if _EXEC_PB is None:
        from ..v1 import exec_pb2  # noqa: PLC0415

        _EXEC_PB = exec_pb2
    return _EXEC_PB


class _ValueOrder:
    """Ordering by stream memory operations for one session on one device: the order array
    (uint64, 1 + SLOTS elements; element 0 is written by the session's stream, element i > 0
    by framework stream i's), its address here, and the counters."""

    def __init__(self, order, address: int, ordinal: int):
        self.order = order
        # the handle alone names the whole array (offset 0, its own shape): a smaller message
        self.ref = type(order._ref())(handle=order._handle)
        self.address = address
        self.ordinal = ordinal
        self.done_value = 0          # element 0: the last value the session's stream will write
        self.slots: dict = {}        # framework stream handle -> element index (LRU order)
        self.values = [0] * (SLOTS + 1)
        self._templates: dict = {}   # (op, index) -> the CudaValueCommand less its value, serialized

    def slot(self, stream: int) -> int:
        index = self.slots.pop(stream, None)
        if index is None:
            if len(self.slots) < SLOTS:
                index = len(self.slots) + 1
            else:
                # Least recently used stream gives its element up; its writes already queued
                # must land before another stream's larger values (a counter never goes back).
                old_stream, index = next(iter(self.slots.items()))
                del self.slots[old_stream]
                _cuda_ipc.synchronize_stream(self.ordinal, old_stream)
        self.slots[stream] = index
        return index

    def command(self, op, index: int, value: int) -> bytes:
        """The Command {cuda_value: {op, order, index, value}, origin: {}} as
        Runtime.submit_framed takes it (one SubmitRequest.commands element), built from bytes
        kept per (op, index): a Python message per use cost more than the launch it orders.
        origin is set but empty: the client's file:line is for user commands, not these."""
        inner = self._templates.get((op, index))
        if inner is None:
            inner = self._templates[(op, index)] = _pb().CudaValueCommand(
                op=op, order=self.ref, index=index).SerializeToString()
        native = _NATIVE_COMMAND if _NATIVE_COMMAND is not False else _native_command()
        if native is not None:
            return native(inner, value)                       # the same bytes, in C
        inner += b"\x20" + _varint(value)                     # CudaValueCommand.value = 4
        cmd = b"\x3a" + _varint(len(inner)) + inner + b"\x7a\x00"   # cuda_value = 7, origin = 15
        return b"\x0a" + _varint(len(cmd)) + cmd              # SubmitRequest.commands = 1


_NATIVE_COMMAND = False     # weft._stream_ops.value_command; None: not built or turned off


def _native_command():
    global _NATIVE_COMMAND
    from .. import _native  # noqa: PLC0415

    module = _native.optional("_stream_ops", "WEFT_NATIVE_STREAM_OPS")
    _NATIVE_COMMAND = module.value_command if module is not None else None
    return _NATIVE_COMMAND


def _value_order(rt, ordinal):
    """The session's _ValueOrder on `ordinal`, or None where stream memory operations cannot
    order it (then events do); probed once per session and device."""
    key = (rt.session_id, ordinal)
    if key in _values:
        return _values[key]
    _values[key] = None
    pb = _pb()
    if os.environ.get("WEFT_CUDA_VALUES", "1") == "0" or not hasattr(pb, "CudaValueCommand") \
            or not _cuda_ipc.stream_mem_ops(ordinal):
        return None
    import weft  # noqa: PLC0415
    from ..errors import WeftError  # noqa: PLC0415

    try:
        order = weft.zeros(SLOTS + 1, dtype=weft.uint64, device=f"cuda:{ordinal}")
        address = order.ptr
        if not address:
            return None
        state = _ValueOrder(order, int(address), ordinal)
        # Probe: the daemon writes element 0, waits for it, and this process reads it back.
        rt.synchronize()
        rt.submit_framed(state.command(pb.CudaValueCommand.WRITE, 0, 1))
        rt.submit_framed(state.command(pb.CudaValueCommand.WAIT, 0, 1))
        rt.synchronize()
        word = ctypes.c_uint64()
        _cuda_ipc.copy_to_host(ordinal, ctypes.addressof(word), state.address, 8)
        if word.value != 1:
            return None
    except (WeftError, _cuda_ipc.CudaError):
        return None
    state.done_value = 1
    _values[key] = state
    return state


def uses_values(rt, ordinal) -> bool:
    """Whether launches of this session on `ordinal` are ordered by stream memory operations
    (no round trip) rather than events (tests, benchmarks)."""
    return enabled(rt, {ordinal}) and _values.get((rt.session_id, ordinal)) is not None


def _command(op, ordinal, event):
    pb = _pb()
    return pb.Command(cuda_event=pb.CudaEventCommand(op=op, device=f"cuda:{ordinal}",
                                                     ipc_handle=event.handle))


def enabled(rt, ordinals) -> bool:
    """Whether this session orders GPU work with the framework streams by events (probed once
    per device: weftd must open this process's event handles)."""
    key = id(rt)
    if type(ordinals) is frozenset and (key, ordinals) in _enabled:
        return True                      # these devices probed already for this runtime
    if ordinals and all((key, o) in _probed for o in ordinals):
        if type(ordinals) is frozenset:
            _enabled.add((key, ordinals))
        return True                      # probed already (WEFT_CUDA_EVENTS is read once)
    if not ordinals or not rt.local or os.environ.get("WEFT_CUDA_EVENTS", "1") == "0":
        return False
    if id(rt) in _refused or not _cuda_ipc.available():
        return False
    if not hasattr(_pb(), "CudaEventCommand"):
        return False
    for ordinal in ordinals:
        if (id(rt), ordinal) not in _probed and not _probe(rt, ordinal):
            return False
    return True


def _probe(rt, ordinal) -> bool:
    from ..errors import WeftError  # noqa: PLC0415

    pb = _pb()
    rt.synchronize()            # errors of earlier commands surface here, not in the probe
    try:
        event = _cuda_ipc.next_event(ordinal)
        _cuda_ipc.record_event(event, 0)
        rt.submit(_command(pb.CudaEventCommand.WAIT, ordinal, event))
        rt.submit(_command(pb.CudaEventCommand.RECORD, ordinal, event))
        rt.synchronize()
    except _cuda_ipc.CudaError as err:
        _refused[id(rt)] = f"this process cannot make interprocess events ({err})"
        return False
    except WeftError as err:
        _refused[id(rt)] = f"weftd cannot use this process's events ({err})"
        return False
    _probed.add((id(rt), ordinal))
    _value_order(rt, ordinal)
    return True


def before(rt, ordinals, stream=None) -> dict:
    """Queues, for each device: the session stream waits for the framework stream's work so
    far (`stream`: that stream of this process instead; an event recorded on it now).
    Returns {ordinal: the stream ordered}, which after() may take as `sources`."""
    pb = _pb()
    rt.pump_held += 1                 # WAIT, the launch and RECORD go out in one Submit (run)
    sources = {}
    for ordinal in ordinals:
        source = sources[ordinal] = framework_stream(ordinal) if stream is None else stream
        values = _values.get((rt.session_id, ordinal))
        if values is not None:
            with rt._lock:    # counter order is queue order (threads of one runtime)
                index = values.slot(source)
                values.values[index] += 1
                _cuda_ipc.write_value(ordinal, source, values.address + 8 * index,
                                      values.values[index])
                rt.submit_framed(values.command(pb.CudaValueCommand.WAIT, index, values.values[index]))
            continue
        event = _cuda_ipc.next_event(ordinal)
        _cuda_ipc.record_event(event, source)
        rt.submit(_command(pb.CudaEventCommand.WAIT, ordinal, event))
    return sources


def after(rt, ordinals, streams=None, sources=None) -> None:
    """Weft's work queued so far on each device is made to come before later work on the
    framework stream (`streams`: those streams instead, handles of this process; `sources`:
    {ordinal: stream} as before() returned it, the framework streams of a launch read once):
    one Submit that returns once weftd queued it, then GPU-side waits; no host wait for the
    GPU."""
    pb = _pb()
    events = []
    waits = []
    for ordinal in ordinals:
        values = _values.get((rt.session_id, ordinal))
        if values is not None:
            with rt._lock:    # counter order is queue order (threads of one runtime)
                values.done_value += 1
                rt.submit_framed(values.command(pb.CudaValueCommand.WRITE, 0, values.done_value))
                waits.append((ordinal, values, values.done_value))
            continue
        event = _cuda_ipc.next_event(ordinal)
        rt.submit(_command(pb.CudaEventCommand.RECORD, ordinal, event))
        events.append((ordinal, event))
    if events:
        rt.run()
    else:
        rt.send_now()                 # the WRITE must reach weftd without another weft call
    for ordinal, values, target in waits:
        for stream in _targets(ordinal, streams, sources):
            _cuda_ipc.wait_value(ordinal, stream, values.address, target)
            _ordered[(id(rt), ordinal, stream)] = rt.work_queued
    for ordinal, event in events:
        for stream in _targets(ordinal, streams, sources):
            _cuda_ipc.wait_event(stream, event)
            _ordered[(id(rt), ordinal, stream)] = rt.work_queued


def _targets(ordinal, streams, sources):
    if streams is not None:
        return streams
    if sources is not None and ordinal in sources:
        return (sources[ordinal],)
    return (framework_stream(ordinal),)


def ready(a, streams=None) -> bool:
    """Weft's queued work is ordered before later work on `streams` (default: the framework
    stream) of GPU array `a`'s device: by an event where this session can (True), else by
    finishing it on the host (False)."""
    rt = a._alloc.runtime
    if not (rt._unsynchronized or rt._batch or rt._deferred_error is not None):
        return True                      # nothing queued since the last synchronize
    ordinal = int(a.device.ordinal)
    targets = [framework_stream(ordinal)] if streams is None else streams
    if all(_ordered.get((id(rt), ordinal, s)) == rt.work_queued for s in targets):
        return True                      # these streams already wait for all queued work
    if enabled(rt, {ordinal}):
        after(rt, (ordinal,), streams)
        return True
    rt.synchronize_if_needed()
    return False


def gpu_ordinals(values) -> set:
    """The GPU ordinals of the weft arrays among `values`."""
    ordinals = set()
    for value in values:
        device = getattr(value, "device", None)
        if device is not None and getattr(device, "is_cuda", False):
            ordinals.add(int(device.ordinal))
    return ordinals


def shared_devices():
    """(GPU ordinals of the allocations frameworks hold, whether any of them is CPU memory)."""
    from . import memory  # noqa: PLC0415

    ordinals, cpu = set(), False
    for alloc in list(memory._shared):
        info = getattr(alloc, "info", None)
        device = getattr(info, "device", "") or ""
        if device.startswith("cuda"):
            ordinals.add(int(device.split(":")[1]) if ":" in device else 0)
        else:
            cpu = True
    return ordinals, cpu


def begin_for_frameworks(rt):
    """Before a tape's backward pass: the session's streams wait for the framework streams
    on the devices of shared GPU memory. Returns those ordinals when the pass is ordered by
    events (finish_for_frameworks then orders the framework streams after it), else None."""
    ordinals, cpu = shared_devices()
    if cpu or not ordinals or not enabled(rt, ordinals):
        for ordinal in ordinals:
            _cuda_ipc.synchronize(ordinal)
        return None
    before(rt, ordinals)
    return ordinals


def finish_for_frameworks(rt, ordinals) -> None:
    """After a tape's backward pass: framework streams ordered after it (events), or the pass
    finished on the host."""
    if ordinals:
        after(rt, ordinals)
    else:
        rt.synchronize()
