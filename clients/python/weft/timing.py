"""CUDA activity timing (Warp's wp.timing_begin, wp.timing_end, wp.timing_print, TimingResult,
TIMING_*): weftd times the session's GPU operations of the kinds asked for with a pair of CUDA
events each on the session's stream, and the synchronize after timing_end brings the elapsed
times back (docs/cuda.md, "Activity timing"). CPU work is not timed, as in Warp.

The commands go in order with the session's other commands: what was issued between
timing_begin and timing_end is timed, however the client batched it. At most 65536 operations
per GPU are timed between timing_begin and timing_end; timing_end warns with the count of those
that ran untimed past it."""
from __future__ import annotations

import threading
import warnings

from . import _runtime
from .v1 import exec_pb2

__all__ = ["TIMING_ALL", "TIMING_GRAPH", "TIMING_KERNEL", "TIMING_KERNEL_BUILTIN", "TIMING_MEMCPY",
           "TIMING_MEMSET", "TimingResult", "timing_begin", "timing_end", "timing_print"]

TIMING_KERNEL = 1
"""Timing flag for user-defined kernel launches."""
TIMING_KERNEL_BUILTIN = 2
"""Timing flag for built-in kernel operations (strided copy and fill, geometry builds)."""
TIMING_MEMCPY = 4
"""Timing flag for memory copy operations."""
TIMING_MEMSET = 8
"""Timing flag for memory set operations."""
TIMING_GRAPH = 16
"""Timing flag for CUDA graph launches."""
TIMING_ALL = 0xFFFFFFFF
"""Timing flag to capture all CUDA activities."""


class TimingResult:
    """Timing result for a single activity."""

    def __init__(self, device, name, filter, elapsed):  # noqa: A002 - Warp's parameter name
        self.device = device
        """The device where the activity was recorded."""
        self.name: str = name
        """The activity name ("forward kernel NAME", "memcpy HtoD", "memset", "graph launch", ...)."""
        self.filter: int = filter
        """The type of activity (e.g. ``TIMING_KERNEL``)."""
        self.elapsed: float = elapsed
        """The elapsed time in milliseconds."""

    def __repr__(self) -> str:
        return f"TimingResult({self.device}, {self.name!r}, {self.filter}, {self.elapsed:.6f} ms)"


def _refuse_in_capture(what: str) -> None:
    rt = _runtime.current_runtime()
    if rt is not None and rt.captures and threading.get_ident() in rt.captures:
        raise RuntimeError(f"{what} cannot be called while a graph is being captured in this thread "
                           "(a graph launch is timed as one activity)")


def _check_filter(cuda_filter) -> int:
    if isinstance(cuda_filter, bool) or not isinstance(cuda_filter, int):
        raise TypeError(f"cuda_filter must be an integer of TIMING_* flags, got {type(cuda_filter).__name__}")
    if cuda_filter < 0 or cuda_filter > 0xFFFFFFFF:
        raise ValueError(f"cuda_filter must be a 32-bit set of TIMING_* flags, got {cuda_filter}")
    return cuda_filter


def timing_begin(cuda_filter: int = TIMING_ALL, synchronize: bool = True) -> None:
    """Begin detailed activity timing.

    Parameters:
        cuda_filter: Filter flags for CUDA activity timing, e.g. ``TIMING_KERNEL`` or ``TIMING_ALL``
        synchronize: Whether to synchronize all CUDA devices before timing starts
    """
    cuda_filter = _check_filter(cuda_filter)
    _refuse_in_capture("timing_begin")
    if synchronize:
        from .device import synchronize as sync_all  # noqa: PLC0415

        sync_all()
    rt = _runtime.get_runtime()
    rt.timing_collected = None
    rt.submit(exec_pb2.Command(timing=exec_pb2.TimingCommand(op=exec_pb2.TimingCommand.BEGIN,
                                                             filter=cuda_filter)))


def timing_end(synchronize: bool = True) -> list[TimingResult]:
    """End detailed activity timing.

    Parameters:
        synchronize: Whether to synchronize all CUDA devices before timing ends. weftd
            collects the elapsed times at a synchronize of the session, so timing_end always
            waits for the work issued before it; an error of that work is raised either way.

    Returns:
        A list of :class:`TimingResult` objects for all recorded activities.

    Raises:
        RuntimeError: If work issued before it failed. Timing ends and its results are discarded.
    """
    _refuse_in_capture("timing_end")
    from .device import get_device  # noqa: PLC0415

    rt = _runtime.get_runtime()
    rt.timing_collected = None
    rt.submit(exec_pb2.Command(timing=exec_pb2.TimingCommand(op=exec_pb2.TimingCommand.END)))
    rt.synchronize()   # an error here ends timing too: weftd discarded the records
    collected, rt.timing_collected = rt.timing_collected, None
    if collected is None:
        return []
    activities, dropped = collected
    if dropped:
        warnings.warn(f"timing_end: {dropped} GPU operation(s) ran untimed: weftd times at most 65536 "
                      "per GPU between timing_begin and timing_end", RuntimeWarning, stacklevel=2)
    devices = {}
    results = []
    for a in activities:
        device = devices.get(a.device)
        if device is None:
            device = devices[a.device] = get_device(a.device)
        results.append(TimingResult(device, a.name, a.filter, a.elapsed_ms))
    return results


def timing_print(results: list[TimingResult], indent: str = "") -> None:
    """Print timing results: the timeline, then totals per activity, then totals per device.

    Parameters:
        results: List of :class:`TimingResult` objects to print.
        indent: Optional indentation to prepend to all output lines.
    """
    if not results:
        print("No activity")
        return
    width = max(len("Activity"), *(len(r.name) for r in results)) + 1
    dashes = "-" * width
    by_device: dict[str, list] = {}
    by_name: dict[str, list] = {}
    print(f"{indent}CUDA timeline:")
    print(f"{indent}----------------+---------+{dashes}")
    print(f"{indent}Time            | Device  | Activity")
    print(f"{indent}----------------+---------+{dashes}")
    for r in results:
        alias = str(getattr(r.device, "alias", r.device))
        for table, key in ((by_device, alias), (by_name, r.name)):
            total = table.setdefault(key, [0, 0.0])
            total[0] += 1
            total[1] += r.elapsed
        print(f"{indent}{r.elapsed:12.6f} ms | {alias:7s} | {r.name}")
    for title, column, table in (("CUDA activity summary:", "Activity", by_name),
                                 ("CUDA device summary:", "Device", by_device)):
        print()
        print(f"{indent}{title}")
        print(f"{indent}----------------+---------+{dashes}")
        print(f"{indent}Total time      | Count   | {column}")
        print(f"{indent}----------------+---------+{dashes}")
        for key, (count, elapsed) in table.items():
            print(f"{indent}{elapsed:12.6f} ms | {count:7d} | {key}")
