"""Allocation tracking (weft/memory_tracker.py: wp.ScopedMemoryTracker, wp.config.track_memory,
wp.print_memory_report) on cpu and cuda:0: nested and per-thread scopes, live counts falling when
arrays are released, peaks that do not fall, the caller's file:line, Warp's labels, the sort
orders and item limit, report_func, and the errors Warp gives (tracking off, a bad sort)."""
from __future__ import annotations

import io
import threading

import numpy as np
import pytest


@pytest.fixture
def tracker(wp):
    from weft import memory_tracker

    with memory_tracker._lock:
        memory_tracker._live.clear()
        memory_tracker._scope_totals.clear()
        memory_tracker._device_bytes.clear()
        memory_tracker._total_count = memory_tracker._total_bytes = 0
    return memory_tracker


def _live(tracker, device):
    with tracker._lock:
        return [r for r in tracker._live.values() if r.device.startswith(device)]


def test_scopes_live_counts_peaks_and_sites(wp, tracker, device):
    reports = []
    with wp.ScopedMemoryTracker("outer", report_func=reports.append):
        a = wp.zeros(32, dtype=wp.float32)                              # line of the site below
        site_line = test_scopes_live_counts_peaks_and_sites.__code__.co_firstlineno + 3
        with wp.ScopedMemoryTracker("inner", print=False):
            b = wp.array(np.arange(1000, dtype=np.float32))
            c = wp.empty((4, 8), dtype=wp.vec3)
        live_inside = len(_live(tracker, device))
        peak = tracker._device_bytes[device][1]
        del b
    assert live_inside == 3
    assert len(_live(tracker, device)) == 2
    assert tracker._device_bytes[device][1] == peak >= 4000 + 128 + 384   # peaks do not fall
    text = reports[0]
    assert "Allocation Tracking Report" in text and "Total allocations: 3" in text
    assert "Live allocations: 2" in text
    assert "outer/inner" in text and "array[float32, 32]" in text and "array[vec3f, 4x8]" in text
    assert f"test_memory_tracker.py:{site_line}" in text, text
    after = wp.zeros(8)                         # tracking ended with the scope: not recorded
    assert len(_live(tracker, device)) == 2
    out = io.StringIO()
    with wp.ScopedMemoryTracker("again", print=False) as t:
        t.report(file=out, sort="chronological", max_items=1)
    lines = out.getvalue().splitlines()
    assert "oldest first" in out.getvalue() and "... 1 more" in out.getvalue()
    assert "array[float32, 32]" in "\n".join(lines[-2:])          # a (oldest) before c
    del a, c, after


def test_global_tracking_threads_and_errors(wp, tracker, device):
    with pytest.raises(RuntimeError, match="not active"):
        wp.print_memory_report()
    saved = wp.config.track_memory
    wp.config.track_memory = True
    try:
        arrays = []

        def work(name):
            with wp.ScopedMemoryTracker(name, print=False):
                arrays.append(wp.zeros(64, dtype=wp.int32))
                with wp.ScopedMemoryTracker("inner", print=False):
                    arrays.append(wp.zeros(16, dtype=wp.float64))

        threads = [threading.Thread(target=work, args=(f"thread_{k}",)) for k in "ab"]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        top = wp.zeros(4)                       # outside any scope: "root"
        out = io.StringIO()
        wp.print_memory_report(file=out)
        text = out.getvalue()
        for scope in ("thread_a", "thread_b", "thread_a/inner", "thread_b/inner", "root"):
            assert f"  {scope} " in text, text
        with pytest.raises(ValueError, match="Invalid sort order"):
            wp.print_memory_report(sort="newest")
        del top, arrays
    finally:
        wp.config.track_memory = saved


def test_pinned_arrays_are_labelled(wp, tracker, device):
    if device != "cpu":
        pytest.skip("pinned memory is a CPU array's")
    reports = []
    with wp.ScopedMemoryTracker("pinned", report_func=reports.append):
        p = wp.zeros(256, dtype=wp.float32, pinned=True)
    assert "cpu (pinned)" in reports[0]
    del p
