"""wp.Stream and wp.Event for a client of weftd, as far as they make sense across the process
boundary (docs/cuda.md, "Streams and events in the client").

A CUDA stream is an object of one process's CUDA context. A weft client's GPU work runs in the
daemon, on the one stream the daemon gives the session per GPU; commands of a session run in
the order they were submitted. So every `wp.Stream` of a device names that same session
stream: `wait_event`/`wait_stream` are already satisfied (one ordered queue), and
`stream.synchronize()` waits for all of the session's work. `cuda_stream` is None: no handle of
the daemon's stream exists in this process.

Events mark a point in the session's command order. An event created with
`enable_timing=True` is a CUDA event of the daemon's (TimedEventCommand): `record_event` queues
its record on the session's stream without waiting, and `get_event_elapsed_time(start, end)`
asks weftd for the GPU time between the two records (cuEventElapsedTime), as Warp measures it.
An event without timing records without waiting; `synchronize_event` then waits for the
session's work.
"""
from __future__ import annotations

import itertools

from . import _runtime
from .device import get_device
from .graph import is_capturing, refuse_host_wait

__all__ = ["Stream", "Event", "get_stream", "set_stream", "ScopedStream", "synchronize_stream",
           "synchronize_event", "record_event", "wait_event", "wait_stream",
           "get_event_elapsed_time", "event_from_ipc_handle"]


def _cuda_device(device):
    device = get_device(device)
    if not device.is_cuda:
        raise RuntimeError(f"streams and events are CUDA objects; {device} has none (CPU work "
                           f"is ordered by synchronization)")
    return device


def _session_work_done(asker) -> bool:
    """Whether the session's queued work is done, for Stream.is_complete and Event.query. The
    client cannot see the daemon's stream without a round trip: work queued since the last
    synchronize answers False once per asking stream or event (it may well be running), and
    when that one asks again with nothing new queued, the answer waits for the work (a
    synchronize) and is True, so a loop that polls until completion ends."""
    rt = _runtime.get_runtime()
    if not (rt._batch or rt._unsynchronized):
        return True
    mark = (id(rt), rt.work_queued)
    if getattr(asker, "_unfinished_mark", None) == mark:
        rt.synchronize_if_needed()
        return True
    asker._unfinished_mark = mark
    return False


class Event:
    """A point in the session's command order on a device (Warp's wp.Event). With
    `interprocess=True` (or from wp.event_from_ipc_handle) it is a real CUDA interprocess event
    of this process that weftd opens by its handle: recording it queues a record on the
    session's stream in the daemon, waiting on it queues a wait there, and any process holding
    its handle (another client of the same or another session, a framework) can order with it."""

    def __init__(self, device=None, enable_timing=False, interprocess=False, _ipc=None):
        self.device = _cuda_device(device)
        self.enable_timing = bool(enable_timing)
        if interprocess and _ipc is None:
            if enable_timing:
                raise ValueError("The combination of 'enable_timing=True' and "
                                 "'interprocess=True' is not allowed.")
            _ipc = _new_interprocess_event(self.device)
        self._ipc = _ipc              # _cuda_ipc.IpcEvent of this process, or None
        self.is_ipc = _ipc is not None
        self._recorded = False
        # A timing event is weftd's, by this id, once recorded in the session of `_timing_rt`.
        self._timing_id = next(_timing_ids) if self.enable_timing else 0
        self._timing_rt = None

    def _record(self) -> None:
        rt = _runtime.get_runtime()
        if self._ipc is not None:
            self._refuse_in_capture("recorded")
            # Run, not just send: once this returns weftd has queued the record, so a process
            # told about it afterwards (a pipe, a join) waits for the right work.
            rt.submit(_ipc_event_command("RECORD", self.device, self._ipc))
            rt.run()
        elif self.enable_timing:
            rt.submit(_timed_event_command("RECORD", self.device, self._timing_id))
            self._timing_rt = rt
        else:
            rt.flush()
        self._recorded = True

    def _wait_on_session_stream(self) -> None:
        """The session's later work on the device waits (on the GPU) for the latest record."""
        self._refuse_in_capture("waited on")
        _runtime.get_runtime().submit(_ipc_event_command("WAIT", self.device, self._ipc))

    def _refuse_in_capture(self, what: str) -> None:
        """A weft graph records no event operations: an interprocess event used while this
        thread captures on its device would act at once, outside the graph's order."""
        if _runtime.get_runtime().captures and is_capturing(self.device):
            raise RuntimeError(f"an interprocess event cannot be {what} inside a graph capture on "
                               f"weft: use it before or after the graph's launch")

    def query(self) -> bool:
        """True when the work before the last record is done (always after a timed record)."""
        if self._ipc is not None:
            from . import _cuda_ipc  # noqa: PLC0415
            return _cuda_ipc.event_is_done(self._ipc)
        if not self._recorded:
            return True
        return _session_work_done(self)

    @property
    def is_complete(self) -> bool:
        """Warp's name for query(): True when the work before the last record is done (and
        for an event never recorded)."""
        return self.query()

    def synchronize(self) -> None:
        refuse_host_wait("event", self.device)
        if self._ipc is not None:
            from . import _cuda_ipc  # noqa: PLC0415
            # this session's own work (its errors surface here), then records by any process
            _runtime.get_runtime().synchronize_if_needed()
            _cuda_ipc.synchronize_event(self._ipc)
            return
        if self._recorded:
            _runtime.get_runtime().synchronize_if_needed()

    def ipc_handle(self) -> bytes:
        """The event's 64-byte CUDA IPC handle (wp.event_from_ipc_handle opens it in another
        process); an event made without interprocess=True has none: a warning and zeros, as
        Warp gives."""
        if self._ipc is None:
            from ._log import log_warning  # noqa: PLC0415
            log_warning("IPC event handle appears to be invalid. Was interprocess=True used?")
            return bytes(64)
        return self._ipc.handle

    @property
    def cuda_event(self):
        """The CUDA event of this process (interprocess events), else None: the session's
        order lives in the daemon."""
        return None if self._ipc is None else self._ipc.event.value

    def __del__(self):
        rt = getattr(self, "_timing_rt", None)
        if rt is not None:              # weftd forgets the event with the next batch
            try:
                rt.submit_from_finalizer(_timed_event_command("DESTROY", self.device, self._timing_id))
            except Exception:  # noqa: BLE001 (interpreter shutdown)
                pass
        ipc = getattr(self, "_ipc", None)
        if ipc is not None:
            try:
                from . import _cuda_ipc  # noqa: PLC0415
                _cuda_ipc.destroy_event(ipc)
            except Exception:  # noqa: BLE001 (interpreter shutdown)
                pass

    def __repr__(self):
        kind = " interprocess" if self._ipc is not None else ""
        return f"<weft{kind} Event on {self.device} timing={self.enable_timing}>"


_timing_ids = itertools.count(1)


def _timed_event_command(op: str, device, event_id: int):
    from .v1 import exec_pb2  # noqa: PLC0415

    return exec_pb2.Command(timed_event=exec_pb2.TimedEventCommand(
        op=getattr(exec_pb2.TimedEventCommand, op), event_id=event_id, device=device.alias))


def _ipc_requirements(device):
    """The session's runtime once weftd can use this process's interprocess events on
    `device`; a clear error where it cannot (a remote session, no CUDA driver here)."""
    from .interop import cuda_order  # noqa: PLC0415

    rt = _runtime.get_runtime()
    if not cuda_order.enabled(rt, {int(device.ordinal)}):
        why = cuda_order.refused() or ("the session is not local" if not rt.local else
                                       "CUDA IPC is not available in this process")
        raise RuntimeError(f"interprocess events on {device} need CUDA IPC between this process "
                           f"and weftd: {why}")
    return rt


def _new_interprocess_event(device):
    """A new interprocess event of this process, opened by weftd for this session and shared
    with the other sessions of the same principal (the clients a handle is passed to)."""
    from . import _cuda_ipc  # noqa: PLC0415

    rt = _ipc_requirements(device)
    ipc = _cuda_ipc.create_ipc_event(int(device.ordinal))
    try:
        rt.submit(_ipc_event_command("SHARE", device, ipc))
        rt.run()
    except BaseException:
        _cuda_ipc.destroy_event(ipc)
        raise
    return ipc


def _ipc_event_command(op: str, device, ipc):
    from .interop import cuda_order  # noqa: PLC0415

    pb = cuda_order._pb()
    return pb.Command(cuda_event=pb.CudaEventCommand(
        op=getattr(pb.CudaEventCommand, op), device=f"cuda:{device.ordinal}", ipc_handle=ipc.handle))


def event_from_ipc_handle(handle, device=None) -> Event:
    """The interprocess event whose handle another process took with Event.ipc_handle()."""
    from . import _cuda_ipc  # noqa: PLC0415

    device = _cuda_device(device)
    if not isinstance(handle, (bytes, bytearray, memoryview)):
        raise TypeError("event_from_ipc_handle expects the 64 bytes of Event.ipc_handle()")
    _ipc_requirements(device)
    return Event(device, _ipc=_cuda_ipc.open_ipc_event(int(device.ordinal), bytes(handle)))


class Stream:
    """The session's stream on a CUDA device in the daemon (Warp's wp.Stream), optionally
    bound to a CUDA stream of this process (`cuda_stream=` a handle, as Warp's external
    streams; wp.stream_from_torch): weft work on memory a framework holds, launched while
    the bound stream is current (wp.ScopedStream, wp.set_stream), is ordered with that stream
    by interprocess events (docs/interop.md, "Ordering")."""

    def __init__(self, device=None, priority=0, cuda_stream=None, **_kwargs):
        self.device = _cuda_device(device)
        if not isinstance(priority, int) or isinstance(priority, bool):
            raise TypeError(f"Stream priority must be an integer, got {type(priority).__name__}")
        # Warp's two levels: high (-1) and normal (0), other values clamped. The daemon runs
        # the session's commands on its one stream per device, so the level is kept, not used.
        self.priority = min(max(priority, -1), 0)
        self._torch_stream = None
        self._foreign = None if cuda_stream is None else int(cuda_stream)
        # streams weft names are blocking (as Warp's); a bound stream's flags are read on use
        self._is_blocking = True if self._foreign is None else None

    @property
    def is_blocking(self) -> bool:
        """Whether the stream synchronizes with the legacy default stream (Warp's streams
        do); for a bound stream of this process, read from the driver once."""
        if self._is_blocking is None:
            from . import _cuda_ipc  # noqa: PLC0415
            self._is_blocking = _cuda_ipc.stream_is_blocking(int(self.device.ordinal), self._foreign)
        return self._is_blocking

    @property
    def is_complete(self) -> bool:
        """True when the work queued on the stream so far is done (a bound stream: its own
        work too); see _session_work_done for what a weft client can know."""
        if self._foreign is not None:
            from . import _cuda_ipc  # noqa: PLC0415
            if not _cuda_ipc.stream_is_idle(int(self.device.ordinal), self._foreign):
                return False
        return _session_work_done(self)

    @property
    def cuda_stream(self):
        """The bound stream of this process; for the session's own stream, a stream of this
        process that weft makes wait for the session's queued work each time this is read
        (None where the session cannot order with events: CUDA IPC off, remote session)."""
        if self._foreign is not None:
            return self._foreign
        from . import _cuda_ipc  # noqa: PLC0415
        from .interop import cuda_order  # noqa: PLC0415

        rt = _runtime.get_runtime()
        ordinal = int(self.device.ordinal)
        if not cuda_order.enabled(rt, {ordinal}):
            return None
        proxy = _cuda_ipc.proxy_stream(ordinal)
        cuda_order.after(rt, (ordinal,), [proxy])
        return proxy

    @property
    def is_capturing(self) -> bool:
        """Whether this thread is capturing a graph on the stream's device."""
        return is_capturing(self.device)

    def record_event(self, event=None) -> Event:
        if event is None:
            event = Event(self.device)
        elif event.device != self.device:
            raise RuntimeError(f"event on {event.device} cannot be recorded on a stream of "
                               f"{self.device}")
        if event._ipc is not None and self._foreign is not None:
            from . import _cuda_ipc  # noqa: PLC0415
            _cuda_ipc.record_event(event._ipc, self._foreign)
            event._recorded = True
            return event
        event._record()
        return event

    def wait_event(self, event) -> None:
        """An interprocess event: later work on this stream waits for its latest record (made
        by any process). Any other event is satisfied already: the session's commands run in
        order on one stream per device; across devices the daemon orders copies itself."""
        if not isinstance(event, Event):
            raise TypeError("wait_event expects a wp.Event")
        if event._ipc is None:
            return
        if self._foreign is not None:
            from . import _cuda_ipc  # noqa: PLC0415
            _cuda_ipc.wait_event(self._foreign, event._ipc)
        else:
            event._wait_on_session_stream()

    def wait_stream(self, other, event=None) -> None:
        """Work queued on this stream after the call waits for `other`'s work so far. Between
        the session's stream and a bound stream of this process: an interprocess event (on
        the GPU; a host wait where events are not available)."""
        if not isinstance(other, Stream):
            raise TypeError("wait_stream expects a wp.Stream")
        if (self._foreign is None) == (other._foreign is None):
            if self._foreign is not None and self._foreign != other._foreign:
                from . import _cuda_ipc  # noqa: PLC0415
                _cuda_ipc.synchronize_stream(int(other.device.ordinal), other._foreign)
            return                       # one session stream: in order already
        from . import _cuda_ipc  # noqa: PLC0415
        from .interop import cuda_order  # noqa: PLC0415

        rt = _runtime.get_runtime()
        ordinal = int(self.device.ordinal)
        ordered = cuda_order.enabled(rt, {ordinal})
        if self._foreign is not None:     # a stream of this process waits for weft's work
            if ordered:
                cuda_order.after(rt, (ordinal,), [self._foreign])
            else:
                rt.synchronize()
        elif ordered:                     # the session's stream waits for a stream here
            cuda_order.before(rt, (ordinal,), other._foreign)
        else:
            _cuda_ipc.synchronize_stream(ordinal, other._foreign)

    def synchronize(self) -> None:
        refuse_host_wait("stream", self.device)
        if self._foreign is not None:
            from . import _cuda_ipc  # noqa: PLC0415
            _cuda_ipc.synchronize_stream(int(self.device.ordinal), self._foreign)
        _runtime.get_runtime().synchronize()

    def __eq__(self, other):
        return isinstance(other, Stream) and other.device == self.device and \
            other._foreign == self._foreign

    def __hash__(self):
        return hash(("weft-stream", self.device.alias, self._foreign))

    def __repr__(self):
        if self._foreign is not None:
            return f"<weft Stream on {self.device} bound to CUDA stream {self._foreign:#x}>"
        return f"<weft Stream of the session on {self.device}>"


def _bind(stream):
    """Makes `stream`'s bound stream (or none) the one weft orders with on its device;
    returns the previous binding."""
    from .interop import cuda_order  # noqa: PLC0415

    return cuda_order.set_scoped_stream(int(stream.device.ordinal), stream._foreign)


_current: dict = {}


def get_stream(device=None) -> Stream:
    device = _cuda_device(device)
    stream = _current.get(device.alias)
    if stream is None:
        stream = _current[device.alias] = Stream(device)
    return stream


def set_stream(stream, device=None, sync=False) -> None:
    if not isinstance(stream, Stream):
        raise TypeError("set_stream expects a wp.Stream")
    if sync:
        stream.synchronize()
    _current[stream.device.alias] = stream
    _bind(stream)


class ScopedStream:
    """with wp.ScopedStream(s): the current stream (and device) while inside."""

    def __init__(self, stream, sync_enter=True, sync_exit=False):
        self.stream = stream
        self.sync_exit = sync_exit
        self._device_scope = None
        self._saved = None
        self._saved_binding = None

    def __enter__(self):
        if self.stream is None:
            return None
        from .device import ScopedDevice  # noqa: PLC0415

        self._device_scope = ScopedDevice(self.stream.device)
        self._device_scope.__enter__()
        self._saved = _current.get(self.stream.device.alias)
        _current[self.stream.device.alias] = self.stream
        self._saved_binding = _bind(self.stream)
        return self.stream

    def __exit__(self, *exc):
        if self.stream is None:
            return
        if self.sync_exit:
            self.stream.synchronize()
        if self._saved is None:
            _current.pop(self.stream.device.alias, None)
        else:
            _current[self.stream.device.alias] = self._saved
        from .interop import cuda_order  # noqa: PLC0415
        cuda_order.set_scoped_stream(int(self.stream.device.ordinal), self._saved_binding)
        self._device_scope.__exit__(*exc)


def synchronize_stream(stream_or_device=None) -> None:
    if isinstance(stream_or_device, Stream):
        stream_or_device.synchronize()
        return
    device = get_device(stream_or_device)
    refuse_host_wait("stream", device)
    _runtime.get_runtime().synchronize()


def record_event(event=None, external=False) -> Event:
    """Records `event` (a new one when None) on the current stream. Inside a graph capture the
    record is part of the captured order (`external=True`, Warp's event between two graphs,
    needs nothing more: the session's graphs and commands run in order on one stream)."""
    device = event.device if event is not None else None
    stream = get_stream(device)
    if event is not None and event._ipc is not None:
        return stream.record_event(event)      # refused inside a capture (Event._record)
    if external or stream.is_capturing:
        if event is None:
            event = Event(stream.device)
        event._recorded = True
        return event
    return stream.record_event(event)


def wait_event(event, external=False) -> None:
    get_stream(event.device).wait_event(event)


def wait_stream(other_stream, event=None) -> None:
    get_stream(other_stream.device).wait_stream(other_stream, event)


def synchronize_event(event) -> None:
    event.synchronize()


def get_event_elapsed_time(start_event, end_event, synchronize=True) -> float:
    """Milliseconds of GPU time between the records of two timed events (weftd's CUDA events,
    cuEventElapsedTime). synchronize=True waits for the session's work first and raises its
    error; either way weftd waits for the end event's record to complete."""
    from .v1 import exec_pb2  # noqa: PLC0415

    for e in (start_event, end_event):
        if not e.enable_timing:
            raise RuntimeError("get_event_elapsed_time needs events created with "
                               "enable_timing=True")
        if e._timing_rt is None:
            raise RuntimeError("get_event_elapsed_time: the event was not recorded")
    if start_event.device != end_event.device:
        raise RuntimeError(f"get_event_elapsed_time: the events were recorded on two devices "
                           f"({start_event.device} and {end_event.device})")
    rt = _runtime.get_runtime()
    if start_event._timing_rt is not rt or end_event._timing_rt is not rt:
        raise RuntimeError("get_event_elapsed_time: an event was recorded in an earlier session "
                           "(the daemon's session ended since): record it again")
    if synchronize:
        rt.synchronize()
    else:
        rt.flush()
    response = rt.call(rt.exec_stub.EventElapsed, exec_pb2.EventElapsedRequest(
        device=start_event.device.alias, start_id=start_event._timing_id,
        end_id=end_event._timing_id))
    return response.elapsed_ms
