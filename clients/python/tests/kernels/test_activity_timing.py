"""CUDA activity timing (wp.timing_begin / timing_end / timing_print, ScopedTimer(cuda_filter=...),
weft.timing; docs/cuda.md "Activity timing"), on cpu and cuda:0: the API as Warp's (flag values,
TimingResult, the printed tables); on the CPU nothing is timed (as in Warp); on a GPU kernels
(forward and backward), copies, fills and graph launches are timed with Warp's names, a filter
selects, the times are consistent with the host's clock, an error ends timing and discards its
records, the per-GPU limit drops (and reports) the operations past it. Timing events
(wp.Event(enable_timing=True)) are weftd's CUDA events: recording does not wait, the time between
two records matches the activity timing of the kernel between them, dropped events are released.
Hostile input: an unknown op, a filter that is not a 32-bit integer, timing inside a graph
capture, ids the session never recorded."""
from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

KERNELS = """
@wp.kernel
def scale(a: wp.array(dtype=float), b: wp.array(dtype=float), k: float):
    i = wp.tid()
    b[i] = a[i] * k

@wp.kernel
def spin(a: wp.array(dtype=float), n: int):
    i = wp.tid()
    x = a[i]
    for j in range(n):
        x = x * 0.999999 + 1.0e-7
    a[i] = x

@wp.kernel
def read_at(a: wp.array(dtype=float), at: int):
    i = wp.tid()
    a[i] = a[at]
"""


@pytest.fixture
def kernels(kernel_module):
    return kernel_module(KERNELS)


def test_api_matches_warps(wp, capsys):
    assert (wp.TIMING_KERNEL, wp.TIMING_KERNEL_BUILTIN, wp.TIMING_MEMCPY, wp.TIMING_MEMSET,
            wp.TIMING_GRAPH, wp.TIMING_ALL) == (1, 2, 4, 8, 16, 0xFFFFFFFF)
    cpu = wp.get_device("cpu")
    results = [wp.TimingResult(cpu, "forward kernel k", wp.TIMING_KERNEL, 0.25),
               wp.TimingResult(cpu, "memcpy HtoD", wp.TIMING_MEMCPY, 0.5),
               wp.TimingResult(cpu, "forward kernel k", wp.TIMING_KERNEL, 0.75)]
    wp.timing_print([])
    wp.timing_print(results, indent="  ")
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "No activity"
    assert out[1] == "  CUDA timeline:"
    assert "  " + f"{0.25:12.6f} ms | cpu     | forward kernel k" in out
    # Totals per activity (2 kernels, 1.0 ms) and per device (3, 1.5 ms).
    assert f"  {1.0:12.6f} ms | {2:7d} | forward kernel k" in out
    assert f"  {1.5:12.6f} ms | {3:7d} | cpu" in out
    for bad in (1.5, "1", True):
        with pytest.raises(TypeError, match="cuda_filter must be an integer"):
            wp.timing_begin(bad)
    for bad in (-1, 1 << 32):
        with pytest.raises(ValueError, match="32-bit"):
            wp.timing_begin(bad)


def test_an_unknown_op_is_an_error_and_the_session_serves(wp, kernels, device, rng):
    from weft import _runtime
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    rt.submit(exec_pb2.Command(timing=exec_pb2.TimingCommand(op=5)))
    with pytest.raises(Exception, match="unknown timing op 5"):
        wp.synchronize()
    a = wp.array(rng.standard_normal(64).astype(np.float32))
    b = wp.zeros_like(a)
    wp.launch(kernels.scale, dim=64, inputs=[a, b, 2.0])
    np.testing.assert_allclose(b.numpy(), a.numpy().astype(np.float64) * 2.0, rtol=1e-6)


def test_operations_are_timed_on_a_gpu_and_not_on_the_cpu(wp, kernels, device, rng):
    n = 1 << 16
    x = rng.standard_normal(n).astype(np.float32)
    a = wp.array(x, requires_grad=True)
    b = wp.zeros(n, dtype=float, requires_grad=True)
    c = wp.empty(n, dtype=float)
    wp.synchronize()
    t0 = time.perf_counter()
    wp.timing_begin(wp.TIMING_ALL)
    tape = wp.Tape()
    with tape:
        wp.launch(kernels.scale, dim=n, inputs=[a, b, 3.0])
    b.grad.fill_(1.0)
    tape.backward()
    wp.copy(c, b)
    c.zero_()
    results = wp.timing_end()
    wall_ms = (time.perf_counter() - t0) * 1e3
    np.testing.assert_allclose(a.grad.numpy(), np.full(n, 3.0), rtol=0)
    if device == "cpu":
        assert results == []
        return
    names = [r.name for r in results]
    kinds = {r.name: r.filter for r in results}
    forward = [nm for nm in names if nm.startswith("forward kernel ") and "scale" in nm]
    backward = [nm for nm in names if nm.startswith("backward kernel ") and "scale" in nm]
    assert forward and backward, names
    assert names.index(forward[0]) < names.index(backward[0]), names
    assert "memcpy DtoD" in names and "memset" in names, names
    assert kinds[forward[0]] == wp.TIMING_KERNEL and kinds["memcpy DtoD"] == wp.TIMING_MEMCPY
    assert kinds["memset"] == wp.TIMING_MEMSET
    for r in results:
        assert r.device == wp.get_device(device)
        assert 0.0 <= r.elapsed <= wall_ms, (r, wall_ms)
    assert sum(r.elapsed for r in results) <= wall_ms


def test_a_filter_selects_and_times_follow_the_work(wp, kernels, device, rng):
    n = 1 << 14
    a = wp.array(rng.standard_normal(n).astype(np.float32))
    b = wp.empty_like(a)
    wp.timing_begin(wp.TIMING_KERNEL)
    wp.launch(kernels.spin, dim=n, inputs=[a, 1])
    wp.launch(kernels.spin, dim=n, inputs=[a, 20000])
    wp.copy(b, a)                      # not a kernel: not timed
    results = wp.timing_end()
    if device == "cpu":
        assert results == []
        return
    assert [r.filter for r in results] == [wp.TIMING_KERNEL] * 2, results
    short, long = (r.elapsed for r in results)
    assert long > 10 * short, results   # 20000 iterations against 1

    wp.timing_begin(wp.TIMING_MEMCPY | wp.TIMING_MEMSET)
    wp.launch(kernels.spin, dim=n, inputs=[a, 1])
    wp.copy(b, a)
    b.fill_(0.0)
    c = wp.array(np.arange(n, dtype=np.float32), device="cpu")
    wp.copy(b, c)                      # an upload through weftd: memcpy HtoD
    results = wp.timing_end()
    np.testing.assert_array_equal(b.numpy(), np.arange(n, dtype=np.float32))
    names = [r.name for r in results]
    assert names == ["memcpy DtoD", "memset", "memcpy HtoD"], names
    assert [r.filter for r in results] == [wp.TIMING_MEMCPY, wp.TIMING_MEMSET, wp.TIMING_MEMCPY]


def test_an_error_ends_timing_and_discards_its_records(wp, kernels, device, rng):
    a = wp.array(rng.standard_normal(16).astype(np.float32))
    wp.timing_begin()
    wp.launch(kernels.scale, dim=16, inputs=[a, a, 2.0])
    wp.launch(kernels.read_at, dim=16, inputs=[a, 1000])   # out of bounds
    with pytest.raises(Exception, match="out of bounds|out of range") as err:
        wp.timing_end()
    assert "test_activity_timing.py" in str(err.value) or "read_at" in str(err.value)
    assert wp.timing_end() == []       # ended: nothing more comes back
    wp.timing_begin()                  # and timing works again
    wp.launch(kernels.scale, dim=16, inputs=[a, a, 1.0])
    results = wp.timing_end()
    if device != "cpu":
        assert len(results) == 1 and "scale" in results[0].name, results


def test_scoped_timer_cuda_filter(wp, device, capsys):
    src = wp.ones(16, dtype=wp.float32)
    dst = wp.zeros_like(src)
    with wp.ScopedTimer("copy", print=False, synchronize=True, cuda_filter=wp.TIMING_MEMCPY) as timer:
        wp.copy(dst, src)
    np.testing.assert_array_equal(dst.numpy(), np.ones(16, np.float32))
    if device == "cpu":
        assert timer.timing_results == []
    else:
        assert len(timer.timing_results) == 1
        result = timer.timing_results[0]
        assert result.device == wp.get_device(device)
        assert result.name == "memcpy DtoD" and result.filter == wp.TIMING_MEMCPY
        assert result.elapsed >= 0.0
    with wp.ScopedTimer("printed", cuda_filter=wp.TIMING_ALL):
        wp.copy(dst, src)
    out = capsys.readouterr().out
    assert "printed took" in out
    assert ("CUDA timeline:" in out and "memcpy DtoD" in out) == (device != "cpu"), out


def test_graph_launches_are_one_activity_and_capture_refuses_timing(wp, kernels, device, rng):
    if device == "cpu":
        pytest.skip("graph capture is a CUDA feature")
    a = wp.array(rng.standard_normal(256).astype(np.float32))
    b = wp.empty_like(a)
    with wp.ScopedCapture() as capture:
        wp.launch(kernels.scale, dim=256, inputs=[a, b, 2.0])
        with pytest.raises(RuntimeError, match="graph is being captured"):
            wp.timing_begin(synchronize=False)
    wp.timing_begin()
    wp.capture_launch(capture.graph)
    results = wp.timing_end()
    np.testing.assert_allclose(b.numpy(), a.numpy().astype(np.float64) * 2.0, rtol=1e-6)
    assert [r.name for r in results] == ["graph launch"], results
    assert results[0].filter == wp.TIMING_GRAPH


def test_past_the_limit_operations_run_untimed_and_are_counted(wp, device):
    if device == "cpu":
        pytest.skip("only GPU operations are timed")
    limit, extra = 65536, 37
    src = wp.ones(4, dtype=wp.float32)
    dst = wp.zeros_like(src)
    wp.timing_begin(wp.TIMING_MEMCPY)
    for _ in range(limit + extra):
        wp.copy(dst, src)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        results = wp.timing_end()
    assert len(results) == limit
    assert any(f"{extra} GPU operation(s) ran untimed" in str(w.message) for w in caught), caught
    np.testing.assert_array_equal(dst.numpy(), np.ones(4, np.float32))


def test_timed_events_are_gpu_events_and_recording_does_not_wait(wp, kernels, device, rng):
    """wp.Event(enable_timing=True) is weftd's CUDA event: recording it queues a record (no wait
    for the work before it), and the time between two records is the GPU's, matching the
    activity timing of the kernel between them."""
    if device == "cpu":
        with pytest.raises(RuntimeError, match="CUDA objects"):
            wp.Event(device, enable_timing=True)
        return
    n = 1 << 14
    a = wp.array(rng.standard_normal(n).astype(np.float32))
    start, end = wp.Event(enable_timing=True), wp.Event(enable_timing=True)
    wp.launch(kernels.spin, dim=n, inputs=[a, 10])      # loaded before timing
    wp.synchronize()
    wp.timing_begin(wp.TIMING_KERNEL)
    wp.record_event(start)
    wp.launch(kernels.spin, dim=n, inputs=[a, 400000])
    t = time.perf_counter()
    wp.record_event(end)
    record_s = time.perf_counter() - t
    results = wp.timing_end()
    elapsed = wp.get_event_elapsed_time(start, end)
    assert len(results) == 1, results
    kernel = results[0].elapsed
    assert kernel > 1.0, results                          # long enough to tell a wait from none
    assert record_s * 1e3 < kernel / 2, (record_s, kernel)
    assert 0.9 * kernel <= elapsed <= kernel + 1.0, (elapsed, kernel)
    assert wp.get_event_elapsed_time(end, end) == 0.0
    assert start.query() and end.query()


def test_timed_events_errors_and_release(wp, kernels, device, rng):
    if device == "cpu":
        pytest.skip("events are CUDA objects")
    recorded, never = wp.Event(enable_timing=True), wp.Event(enable_timing=True)
    plain = wp.Event()
    wp.record_event(recorded)
    wp.record_event(plain)
    with pytest.raises(RuntimeError, match="not recorded"):
        wp.get_event_elapsed_time(recorded, never)
    with pytest.raises(RuntimeError, match="enable_timing"):
        wp.get_event_elapsed_time(recorded, plain)
    # Events dropped are released in weftd (a session holds at most 4096): 5000 made, recorded
    # and dropped one after another leave the session working.
    a = wp.array(rng.standard_normal(64).astype(np.float32))
    for _ in range(5000):
        e = wp.Event(enable_timing=True)
        wp.record_event(e)
    del e
    b = wp.zeros_like(a)
    wp.launch(kernels.scale, dim=64, inputs=[a, b, 2.0])
    np.testing.assert_allclose(b.numpy(), a.numpy().astype(np.float64) * 2.0, rtol=1e-6)
    # A forged request: ids this session never recorded are NOT_FOUND, not another session's.
    from weft import _runtime
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    with pytest.raises(Exception, match="never recorded"):
        rt.call(rt.exec_stub.EventElapsed, exec_pb2.EventElapsedRequest(
            device=device, start_id=recorded._timing_id, end_id=(1 << 63) + 5))
