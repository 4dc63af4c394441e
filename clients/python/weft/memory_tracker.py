"""Allocation tracking (Warp's wp.config.track_memory, wp.ScopedMemoryTracker,
wp.print_memory_report): while tracking is on, every array this process has weftd allocate is
recorded with its bytes, device, a label ("array[float32, 32]"), the scope path of the
ScopedMemoryTrackers around it ("simulation/collision", per thread) and the first call site
outside weft; it leaves the live set when the process releases it. Totals, per-device peaks and
per-scope counts are kept for the report.

What Warp also counts and weft does not: allocations inside the native library (BVH, mesh and
hash grid buffers, labelled "(native:...)" by Warp). Those live in weftd, which accounts them per
session (SessionService.Stats, docs/operations.md). Tracking costs nothing while off: an array's
creation checks one flag."""
from __future__ import annotations

import itertools
import os
import sys
import threading
import weakref

from . import config

__all__ = ["ScopedMemoryTracker", "print_memory_report"]

_lock = threading.Lock()
_scoped = 0                      # ScopedMemoryTrackers that turned tracking on
_scopes = threading.local()      # .stack: this thread's scope names
_sequence = itertools.count()
_live: dict = {}                 # sequence -> _Record
_total_count = 0
_total_bytes = 0
_scope_totals: dict = {}         # scope path -> [count, bytes]
_device_bytes: dict = {}         # device -> [live bytes, peak bytes]
_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


class _Record:
    __slots__ = ("sequence", "nbytes", "device", "label", "scope", "site")

    def __init__(self, sequence, nbytes, device, label, scope, site):
        self.sequence, self.nbytes, self.device = sequence, nbytes, device
        self.label, self.scope, self.site = label, scope, site


def active() -> bool:
    return _scoped > 0 or bool(getattr(config, "track_memory", False))


def _call_site() -> str:
    frame = sys._getframe(2)
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE_DIR):
        frame = frame.f_back
    if frame is None:
        return "(unknown)"
    return f"{frame.f_code.co_filename}:{frame.f_lineno} ({frame.f_code.co_name})"


def note_allocated(alloc, info, dtype_name: str, shape, pinned: bool = False) -> None:
    """Records a new allocation of this process (called only while active())."""
    global _total_count, _total_bytes
    nbytes = int(info.byte_size)
    device = info.device + (" (pinned)" if pinned else "")
    label = f"array[{dtype_name}, {'x'.join(str(int(s)) for s in shape) or '0'}]"
    scope = "/".join(getattr(_scopes, "stack", None) or ["root"])
    site = _call_site()
    with _lock:
        sequence = next(_sequence)
        _live[sequence] = _Record(sequence, nbytes, device, label, scope, site)
        _total_count += 1
        _total_bytes += nbytes
        totals = _scope_totals.setdefault(scope, [0, 0])
        totals[0] += 1
        totals[1] += nbytes
        current = _device_bytes.setdefault(device, [0, 0])
        current[0] += nbytes
        current[1] = max(current[1], current[0])
    weakref.finalize(alloc, _freed, sequence)


def _freed(sequence: int) -> None:
    with _lock:
        record = _live.pop(sequence, None)
        if record is not None:
            _device_bytes[record.device][0] -= record.nbytes


def _report_text(sort: str, max_items: int) -> str:
    if sort not in ("size", "chronological"):
        raise ValueError(f"Invalid sort order {sort!r}; expected 'size' or 'chronological'")
    with _lock:
        live = list(_live.values())
        scopes = {k: list(v) for k, v in _scope_totals.items()}
        devices = {k: list(v) for k, v in _device_bytes.items()}
        total_count, total_bytes = _total_count, _total_bytes
    live_bytes = sum(r.nbytes for r in live)
    lines = ["Allocation Tracking Report", "=" * 26,
             f"Total allocations: {total_count} ({_human(total_bytes)})",
             f"Live allocations: {len(live)} ({_human(live_bytes)})", "", "Per device (live / peak):"]
    for device, (current, peak) in sorted(devices.items()):
        lines.append(f"  {device:<16} {_human(current):>12} / {_human(peak)}")
    lines += ["", "Per scope (allocations, bytes):"]
    for scope, (count, nbytes) in sorted(scopes.items()):
        lines.append(f"  {scope:<32} {count:>8} {_human(nbytes):>12}")
    ordered = sorted(live, key=(lambda r: -r.nbytes) if sort == "size" else (lambda r: r.sequence))
    lines += ["", f"Live allocations ({'largest first' if sort == 'size' else 'oldest first'}, "
                  f"at most {max_items}):"]
    for r in ordered[:max_items]:
        lines.append(f"  {_human(r.nbytes):>12}  {r.device:<16} {r.label:<28} [{r.scope}] {r.site}")
    if len(ordered) > max_items:
        lines.append(f"  ... {len(ordered) - max_items} more")
    return "\n".join(lines) + "\n"


def _human(nbytes: int) -> str:
    for unit, size in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if nbytes >= size:
            return f"{nbytes / size:.2f} {unit}"
    return f"{nbytes} B"


def print_memory_report(file=None, sort="size", max_items=10) -> None:
    """Prints the tracked allocations (wp.config.track_memory = True, or inside a
    ScopedMemoryTracker): totals, per device live and peak bytes, per scope, and the live
    allocations by size (sort="size") or age (sort="chronological"), at most max_items.
    RuntimeError when tracking is not on; ValueError for another sort."""
    if sort not in ("size", "chronological"):
        raise ValueError(f"Invalid sort order {sort!r}; expected 'size' or 'chronological'")
    if not active():
        raise RuntimeError("Allocation tracking is not active. Set wp.config.track_memory = True "
                           "before calling wp.init(), or use wp.ScopedMemoryTracker as a context manager.")
    (file or sys.stdout).write(_report_text(sort, max_items))


class ScopedMemoryTracker:
    """`with wp.ScopedMemoryTracker("name"):` tracks the allocations made inside it (scope path
    "outer/name" when nested, per thread) and prints the report when it ends (`print=False`: no
    report; `report_func(text)`: the report goes there instead of stdout); `report()` prints it
    again later."""

    def __init__(self, name: str = "root", active: bool = True, print: bool = True,  # noqa: A002
                 report_func=None):
        self.name = name
        self.active = active
        self.print = print
        self.report_func = report_func

    def __enter__(self):
        global _scoped
        if self.active:
            stack = getattr(_scopes, "stack", None)
            if stack is None:
                stack = _scopes.stack = []
            stack.append(self.name)
            with _lock:
                _scoped += 1
        return self

    def __exit__(self, exc_type, exc_value, traceback):
        global _scoped
        if not self.active:
            return
        _scopes.stack.pop()
        try:
            if self.print:
                self.report()
        finally:
            with _lock:
                _scoped -= 1

    def report(self, file=None, sort="size", max_items=10) -> None:
        text = _report_text(sort, max_items)
        if self.report_func is not None and file is None:
            self.report_func(text)
        else:
            (file or sys.stdout).write(text)
