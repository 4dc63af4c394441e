"""The fused sync path: with commands pending, a sync point (numpy(), wp.synchronize()) is ONE
ExecService.Submit(synchronize=true) round trip whose response carries what Synchronize would
return. Checks that errors (kernel name and source line) and print output still arrive through
it, that a batch sent without sync (plain Submit) still works and syncs with Synchronize, that
a sync with nothing queued since the last one sends nothing, and the wire contract by hand."""
import inspect
import os

import numpy as np
import pytest

import weft as wp
from weft import _runtime


@wp.kernel
def fused_oob_write(data: wp.array(dtype=float), n: int):
    i = wp.tid()
    data[i + n] = 7.0


@wp.kernel
def fused_add(data: wp.array(dtype=float), x: float):
    i = wp.tid()
    data[i] = data[i] + x


@wp.kernel
def fused_say(data: wp.array(dtype=float)):
    i = wp.tid()
    wp.printf("fused-printf %d %.2f\n", i, data[i])


def _line(func, needle):
    lines, start = inspect.getsourcelines(func)
    return start + next(k for k, t in enumerate(lines) if needle in t)


class _CallLog:
    """Wraps the runtime's ExecService stub methods and records (method, request) per call."""

    def __init__(self, runtime):
        self.runtime = runtime
        self.calls = []
        self._saved = {}

    def __enter__(self):
        # The calls of the fused path only: batches wait for the sync point (no asynchronous
        # Submit while launches are queued; test_submit_pipeline.py checks that path).
        self._pipelined, self.runtime.pipelined = self.runtime.pipelined, False
        # The gRPC calls: the fast lane (test_fast_lane.py) is off while they are logged.
        self._lane, self.runtime.fast_lane = self.runtime.fast_lane, None
        for name in ("Submit", "Synchronize"):
            original = getattr(self.runtime.exec_stub, name)
            self._saved[name] = original

            def wrapped(request, *args, _name=name, _original=original, **kwargs):
                self.calls.append((_name, request))
                return _original(request, *args, **kwargs)

            setattr(self.runtime.exec_stub, name, wrapped)
        return self

    def __exit__(self, *exc):
        for name, original in self._saved.items():
            setattr(self.runtime.exec_stub, name, original)
        self.runtime.pipelined = self._pipelined
        self.runtime.fast_lane = self._lane

    def names(self):
        return [name for name, _ in self.calls]


@pytest.fixture
def rng(request):
    seed = int.from_bytes(os.urandom(4), "little")
    print(f"{request.node.nodeid}: seed={seed}")
    return np.random.default_rng(seed)


@pytest.fixture
def runtime(wp):
    wp.synchronize()
    return _runtime.get_runtime()


def test_launch_then_numpy_is_one_fused_round_trip(wp, runtime, rng):
    values = rng.standard_normal(64).astype(np.float32)
    data = wp.array(values, dtype=float)
    expected = values.astype(np.float64)
    wp.synchronize()
    with _CallLog(runtime) as log:
        for k in range(5):
            x = float(rng.standard_normal())
            wp.launch(fused_add, dim=64, inputs=[data, x])
            expected = expected + np.float32(x)
            got = data.numpy()
            np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)
        got_again = data.numpy()   # nothing queued since the last sync: no call at all
    assert log.names() == ["Submit"] * 5, log.names()
    assert all(request.synchronize and len(request.commands) == 1 for _, request in log.calls)
    np.testing.assert_array_equal(got_again, got)


def test_out_of_bounds_error_surfaces_at_numpy(wp, runtime):
    data = wp.zeros(8, dtype=float)
    neighbour = wp.full(8, 5.0, dtype=float)
    wp.synchronize()
    with _CallLog(runtime) as log:
        wp.launch(fused_oob_write, dim=8, inputs=[data, 4])
        with pytest.raises(wp.WeftError) as info:
            data.numpy()
    assert log.names() == ["Submit"] and log.calls[0][1].synchronize, log.names()
    message = str(info.value)
    assert "fused_oob_write" in message, message
    line = _line(fused_oob_write.func, "data[i + n]")
    assert f"test_sync_fused.py:{line}" in message, message
    # The error was taken by that sync: the session goes on, nothing was written out of bounds.
    np.testing.assert_array_equal(neighbour.numpy(), 5.0)
    wp.launch(fused_add, dim=8, inputs=[neighbour, 1.0])
    np.testing.assert_array_equal(neighbour.numpy(), 6.0)


def test_error_raised_once_then_later_batches_succeed(wp, runtime):
    data = wp.zeros(4, dtype=float)
    wp.launch(fused_oob_write, dim=4, inputs=[data, 2])
    wp.launch(fused_add, dim=4, inputs=[data, 1.0])   # skipped: after the first failure
    with pytest.raises(wp.WeftError):
        wp.synchronize()
    wp.synchronize()   # nothing pending, no new error
    before = data.numpy().copy()
    wp.launch(fused_add, dim=4, inputs=[data, 2.0])
    np.testing.assert_array_equal(data.numpy(), before + 2.0)


def test_print_output_arrives_through_fused_sync(wp, runtime, capfd):
    data = wp.array([0.5, -1.25, 3.0], dtype=float)
    wp.synchronize()
    capfd.readouterr()
    with _CallLog(runtime) as log:
        wp.launch(fused_say, dim=3, inputs=[data])
        data.numpy()
    assert log.names() == ["Submit"], log.names()
    out = capfd.readouterr().out
    for i, v in enumerate(["0.50", "-1.25", "3.00"]):
        assert f"fused-printf {i} {v}" in out, out


def test_batch_sent_without_sync_still_works(wp, runtime, capfd, rng):
    values = rng.standard_normal(32).astype(np.float32)
    data = wp.array(values, dtype=float)
    wp.synchronize()
    capfd.readouterr()
    with _CallLog(runtime) as log:
        for _ in range(3):
            wp.launch(fused_add, dim=32, inputs=[data, 0.5])
        wp.launch(fused_say, dim=2, inputs=[data])
        runtime.flush()                       # plain Submit, no sync
        got = data.numpy()                    # nothing pending: the plain Synchronize
    assert log.names() == ["Submit", "Synchronize"], log.names()
    assert not log.calls[0][1].synchronize and len(log.calls[0][1].commands) == 4
    np.testing.assert_allclose(got, values.astype(np.float64) + 1.5, rtol=1e-6, atol=1e-6)
    out = capfd.readouterr().out
    assert "fused-printf 0" in out and "fused-printf 1" in out, out
    # An error in a flushed (unsynchronized) batch still surfaces at the next data access.
    wp.launch(fused_oob_write, dim=32, inputs=[data, 1])
    runtime.flush()
    with pytest.raises(wp.WeftError) as info:
        data.numpy()
    assert "fused_oob_write" in str(info.value)


def test_wire_contract_by_hand(weftd):
    from weft.v1 import exec_pb2

    with weftd.raw_session("pytest fused sync") as raw:
        plain = raw.exec.Submit(exec_pb2.SubmitRequest(), metadata=raw.metadata, timeout=30)
        assert not plain.HasField("sync") and plain.queued == 0
        fused = raw.exec.Submit(exec_pb2.SubmitRequest(synchronize=True),
                                metadata=raw.metadata, timeout=30)
        assert fused.HasField("sync") and fused.queued == 0
        assert fused.sync.error == "" and fused.sync.output == ""
        # A bad handle fails at execution: reported in `sync`, and taken (the next sync is clean).
        bad = exec_pb2.Command(fill=exec_pb2.FillCommand(value=b"\0\0\0\0"))
        bad.fill.dst.handle = 987654321
        fused = raw.exec.Submit(exec_pb2.SubmitRequest(commands=[bad], synchronize=True),
                                metadata=raw.metadata, timeout=30)
        assert fused.queued == 1 and fused.sync.error, fused
        again = raw.exec.Synchronize(exec_pb2.SynchronizeRequest(), metadata=raw.metadata,
                                     timeout=30)
        assert again.error == "", again
