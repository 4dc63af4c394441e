"""Self time per source line of chosen files (sys.monitoring on Python 3.12+, sys.settrace
before it): each line of a
function whose file is chosen gets the time from its LINE event to the next event of that
frame, minus the time spent in chosen functions it called; calls into files not chosen (Torch,
NumPy, ctypes, the standard library) stay in the calling line. Files not chosen are switched
off at their first event (sys.monitoring.DISABLE), so they cost nothing afterwards. Each event
costs about a microsecond of its own, which lands in the next line's time: compare lines by
their time per call, not the total with the unprofiled run. Used by bench/prof_rosenbrock_step.py
(--lines)."""
from __future__ import annotations

import linecache
import sys
import time


_DISABLE = sys.monitoring.DISABLE if hasattr(sys, "monitoring") else object()


class LineProfile:
    TOOL = 3   # a tool id sys.monitoring leaves to users (0-5; 2 is cProfile's, 5 optimizers')

    def __init__(self, roots):
        self.roots = tuple(str(r) for r in roots)
        self.spent = {}     # (filename, line) -> [ns, count]
        self.stack = []     # [code, line, start ns] per chosen frame being run
        self.chosen = {}    # code -> bool

    def _is_chosen(self, code) -> bool:
        hit = self.chosen.get(code)
        if hit is None:
            hit = self.chosen[code] = code.co_filename.startswith(self.roots)
        return hit

    def _charge(self, top, now):
        key = (top[0].co_filename, top[1])
        slot = self.spent.get(key)
        if slot is None:
            self.spent[key] = [now - top[2], 1]
        else:
            slot[0] += now - top[2]
            slot[1] += 1

    def _start(self, code, offset):
        if not self._is_chosen(code):
            return _DISABLE
        now = time.perf_counter_ns()
        if self.stack:
            self._charge(self.stack[-1], now)
        self.stack.append([code, code.co_firstlineno, now])
        return None

    def _line(self, code, line):
        if not self._is_chosen(code):
            return _DISABLE
        now = time.perf_counter_ns()
        stack = self.stack
        while stack and stack[-1][0] is not code:
            stack.pop()                 # a frame left by an exception
        if not stack:
            stack.append([code, line, now])
            return None
        top = stack[-1]
        self._charge(top, now)
        top[1] = line
        top[2] = now
        return None

    def _end(self, code, offset, value=None):
        if not self._is_chosen(code):
            return _DISABLE
        now = time.perf_counter_ns()
        stack = self.stack
        while stack and stack[-1][0] is not code:
            stack.pop()
        if stack:
            self._charge(stack.pop(), now)
        if stack:
            stack[-1][2] = now
        return None

    def _trace(self, frame, event, arg):
        # sys.settrace (Python < 3.12): the same events; only chosen frames get a local tracer
        code = frame.f_code
        if event == "call":
            if self._start(code, 0) is not None:
                return None
            return self._trace
        if event == "line":
            self._line(code, frame.f_lineno)
        elif event == "return":
            self._end(code, 0)
        return self._trace

    def __enter__(self):
        if not hasattr(sys, "monitoring"):
            sys.settrace(self._trace)
            return self
        m = sys.monitoring
        m.use_tool_id(self.TOOL, "weft line profile")
        e = m.events
        m.register_callback(self.TOOL, e.PY_START, self._start)
        m.register_callback(self.TOOL, e.PY_RESUME, self._start)
        m.register_callback(self.TOOL, e.LINE, self._line)
        m.register_callback(self.TOOL, e.PY_RETURN, self._end)
        m.register_callback(self.TOOL, e.PY_YIELD, self._end)
        m.set_events(self.TOOL, e.PY_START | e.PY_RESUME | e.LINE | e.PY_RETURN | e.PY_YIELD)
        return self

    def __exit__(self, *exc):
        if not hasattr(sys, "monitoring"):
            sys.settrace(None)
            self.stack.clear()
            return
        m = sys.monitoring
        m.set_events(self.TOOL, 0)
        for ev in (m.events.PY_START, m.events.PY_RESUME, m.events.LINE, m.events.PY_RETURN,
                   m.events.PY_YIELD):
            m.register_callback(self.TOOL, ev, None)
        m.free_tool_id(self.TOOL)
        self.stack.clear()

    def report(self, per: int, top: int = 40, strip: str = "") -> str:
        """The `top` lines by self time, in microseconds per `per` (e.g. steps run)."""
        rows = sorted(self.spent.items(), key=lambda kv: -kv[1][0])[:top]
        total = sum(v[0] for v in self.spent.values())
        out = [f"self time of chosen lines: {total / per / 1e3:.1f} us per step "
               f"(events cost ~1 us each)",
               f"{'us/step':>8} {'calls/step':>10} {'us/call':>8}  where"]
        for (filename, line), (ns, count) in rows:
            text = linecache.getline(filename, line).strip()[:70]
            name = filename[len(strip):] if strip and filename.startswith(strip) else filename
            out.append(f"{ns / per / 1e3:>8.1f} {count / per:>10.1f} {ns / count / 1e3:>8.2f}  "
                       f"{name}:{line}  {text}")
        return "\n".join(out)
