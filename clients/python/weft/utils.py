"""wp.utils: the Python-scope helpers of Warp that weft supports (ScopedTimer)."""
from __future__ import annotations

import time

__all__ = ["ScopedTimer"]


class ScopedTimer:
    """`with wp.ScopedTimer("name"):` prints the block's wall time in ms (Warp's helper).
    synchronize=True waits for the daemon's commands before reading the clock."""

    indent = -1
    enabled = True

    def __init__(self, name, active=True, print=True, detailed=False, dict=None,
                 use_nvtx=False, color="rapids", synchronize=False, cuda_filter=0,
                 report_func=None, skip_tape=False):
        self.name = name
        self.active = active and self.enabled
        self.print = print
        self.dict = dict
        self.synchronize = synchronize
        self.report_func = report_func
        self.elapsed = 0.0
        self.timing_results = []
        if self.dict is not None and name not in self.dict:
            self.dict[name] = []

    def _sync(self):
        if self.synchronize:
            from .device import synchronize

            synchronize()

    def __enter__(self):
        if self.active:
            self._sync()
            ScopedTimer.indent += 1
            self.start = time.perf_counter_ns()
        return self

    def __exit__(self, exc_type, exc_value, traceback):
        if not self.active:
            return
        self._sync()
        self.elapsed = (time.perf_counter_ns() - self.start) / 1e6
        if self.dict is not None:
            self.dict[self.name].append(self.elapsed)
        if self.report_func is not None:
            self.report_func([], "  " * ScopedTimer.indent)
        if self.print:
            print(f"{'  ' * ScopedTimer.indent}{self.name} took {self.elapsed:.2f} ms")
        ScopedTimer.indent -= 1
