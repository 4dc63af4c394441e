"""The pipelined submit path (weft._runtime.Runtime._pump): queued launches reach the daemon
before any sync point, so the device works while the client queues more (Warp's launches start
at once); one Submit at a time keeps them in order; a short step (a few launches, then a sync)
is still one fused round trip; a daemon's rejection of an asynchronous Submit surfaces at the next
sync. Runs on the CPU device of a local session (a CPU array's numpy() is a view of the memory
the daemon writes, so the test sees the launches run without synchronizing)."""
import os
import time

import numpy as np
import pytest

import weft as wp_module
from weft import _runtime


@wp_module.kernel
def pipe_add(data: wp_module.array(dtype=float), x: float):
    i = wp_module.tid()
    data[i] = data[i] + x


@pytest.fixture
def runtime(wp, monkeypatch):
    # Batches go out by count (PUMP_FIRST commands, then doubling), never early by age: on a
    # busy machine a few launches may take longer than PUMP_AFTER_S, and an early Submit would
    # change the batches these tests count.
    monkeypatch.setattr(_runtime, "PUMP_AFTER_S", 60.0)
    wp.synchronize()
    rt = _runtime.get_runtime()
    if not rt.local:
        pytest.skip("needs a local (Unix-socket) session: numpy() of a CPU array is a view there")
    saved = rt.pipelined
    rt.pipelined = True
    # These tests watch the gRPC stub; the fast lane (test_fast_lane.py) is off meanwhile.
    lane, rt.fast_lane = rt.fast_lane, None
    yield rt
    rt.pipelined = saved
    rt.fast_lane = lane
    wp.synchronize()


def test_queued_launches_run_before_a_sync(wp, runtime, wait_for):
    seed = int.from_bytes(os.urandom(4), "little")
    rng = np.random.default_rng(seed)
    values = rng.standard_normal(256).astype(np.float32)
    data = wp.array(values, dtype=float, device="cpu")
    view = data.numpy()   # synchronizes once; from here on a view of the daemon's memory
    steps = [float(x) for x in rng.uniform(0.5, 2.0, size=3 * _runtime.PUMP_FIRST)]
    for x in steps:
        wp.launch(pipe_add, dim=256, inputs=[data, x], device="cpu")
    expected = values.astype(np.float64) + sum(np.float64(np.float32(x)) for x in steps)
    # No sync point: the first PUMP_FIRST went out together (later ones may still be batched).
    assert wait_for(lambda: np.all(np.abs(view.astype(np.float64) - values) > 0.4), 20), \
        f"seed={seed}: no launch ran before a sync point"
    wp.synchronize()
    np.testing.assert_allclose(view.astype(np.float64), expected, rtol=1e-5, atol=1e-5,
                               err_msg=f"seed={seed}")


def test_order_kept_across_many_asynchronous_submits(wp, runtime):
    data = wp.zeros(64, dtype=float, device="cpu")
    wp.synchronize()
    sent = []
    original = runtime.exec_stub.Submit

    class _Counting:
        def __call__(self, request, *args, **kwargs):
            return original(request, *args, **kwargs)

        def future(self, request, *args, **kwargs):
            sent.append(len(request.commands))
            return original.future(request, *args, **kwargs)

    runtime.exec_stub.Submit = _Counting()
    try:
        total = 0.0
        for k in range(300):
            # x_k = k+1; each launch depends on the one before through `data`.
            wp.launch(pipe_add, dim=64, inputs=[data, float(k + 1)], device="cpu")
            total += k + 1
        got = data.numpy()
    finally:
        runtime.exec_stub.Submit = original
    np.testing.assert_array_equal(got, np.full(64, total, dtype=np.float32))
    assert sent, "no asynchronous Submit was sent"
    assert sent[0] == _runtime.PUMP_FIRST and all(n >= 2 for n in sent), sent


def test_a_short_step_then_sync_is_one_round_trip(wp, runtime):
    data = wp.zeros(8, dtype=float, device="cpu")
    wp.synchronize()
    calls = []
    original_submit, original_sync = runtime.exec_stub.Submit, runtime.exec_stub.Synchronize

    class _Logged:
        def __init__(self, name, method):
            self.name, self.method = name, method

        def __call__(self, request, *args, **kwargs):
            calls.append((self.name, getattr(request, "synchronize", None)))
            return self.method(request, *args, **kwargs)

        def future(self, request, *args, **kwargs):
            calls.append((self.name + ".future", None))
            return self.method.future(request, *args, **kwargs)

    runtime.exec_stub.Submit = _Logged("Submit", original_submit)
    runtime.exec_stub.Synchronize = _Logged("Synchronize", original_sync)
    try:
        for _ in range(3):
            wp.launch(pipe_add, dim=8, inputs=[data, 1.5], device="cpu")
        got = data.numpy()
    finally:
        runtime.exec_stub.Submit, runtime.exec_stub.Synchronize = original_submit, original_sync
    assert calls == [("Submit", True)], calls
    np.testing.assert_array_equal(got, 4.5)


def test_rejected_asynchronous_submit_raises_at_the_next_sync(wp, runtime):
    from weft.v1 import exec_pb2

    data = wp.zeros(4, dtype=float, device="cpu")
    wp.synchronize()
    bad = exec_pb2.Command()   # no command in it: the daemon refuses the whole batch
    with runtime._lock:
        runtime._batch_since = time.perf_counter()
        runtime._batch.append(_runtime.framed_command(bad))
    runtime._unsynchronized = True
    for _ in range(_runtime.PUMP_FIRST - 1):   # PUMP_FIRST queued: sent now, refused whole
        wp.launch(pipe_add, dim=4, inputs=[data, 1.0], device="cpu")
    with pytest.raises(wp.WeftError):
        wp.synchronize()
    wp.synchronize()   # taken: nothing more to report
    np.testing.assert_array_equal(data.numpy(), 0.0)   # nothing of the refused batch ran
    wp.launch(pipe_add, dim=4, inputs=[data, 2.0], device="cpu")
    wp.launch(pipe_add, dim=4, inputs=[data, 3.0], device="cpu")
    np.testing.assert_array_equal(data.numpy(), 5.0)


def test_framed_commands_are_the_submit_request_the_daemon_parses():
    """A batch travels as its commands' frames (Runtime.framed_command) and the request's
    flags, never as a SubmitRequest message: byte for byte the serialization of that message,
    for commands whose lengths take one, two and three varint bytes (127/128 and 16383/16384
    around the boundaries); the ordering commands weft.interop.cuda_order builds from bytes
    parse to the message they stand for, for values of every varint length."""
    import types

    from weft.interop import cuda_order
    from weft.v1 import exec_pb2, types_pb2

    rng = np.random.default_rng()
    commands = []
    for size in (0, 1, 100, 120, 121, 122, 123, 124, 125, 126, 127, 128, 129, 300, 16370,
                 16380, 16381, 16382, 16383, 16384, 16385, 70000):
        name = "".join(chr(c) for c in rng.integers(97, 123, size))
        commands.append(exec_pb2.Command(
            launch=exec_pb2.LaunchCommand(kernel=name, dim=[int(rng.integers(1, 1 << 30))]),
            origin=types_pb2.SourceLocation(file="f.py", line=int(rng.integers(1, 1 << 20)))))
    # the commands' length prefixes take one, two and three varint bytes
    assert {len(_runtime.varint(len(c.SerializeToString()))) for c in commands} == {1, 2, 3}
    frames = [_runtime.framed_command(c) for c in commands]
    for flags, expected in ((b"", exec_pb2.SubmitRequest(commands=commands)),
                            (_runtime._SUBMIT_SYNCHRONIZE,
                             exec_pb2.SubmitRequest(commands=commands, synchronize=True)),
                            (_runtime._SUBMIT_RUN, exec_pb2.SubmitRequest(commands=commands, run=True))):
        body = b"".join(frames) + flags
        assert body == expected.SerializeToString()
        assert exec_pb2.SubmitRequest.FromString(body) == expected
    for n in (0, 1, 127, 128, 16383, 16384, (1 << 63) + 5, (1 << 64) - 1):
        assert types_pb2.ArrayRef.FromString(b"\x08" + _runtime.varint(n)).handle == n

    fake = types.SimpleNamespace(_handle=(1 << 40) + 7,
                                 _ref=lambda: types_pb2.ArrayRef(handle=3, shape=[32]))
    order = cuda_order._ValueOrder(fake, 0xDEAD0000, 0)
    for op in (exec_pb2.CudaValueCommand.WAIT, exec_pb2.CudaValueCommand.WRITE):
        for index in (0, 1, 31):
            for value in (0, 1, 127, 128, int(rng.integers(1, 1 << 62)), (1 << 64) - 1):
                got = exec_pb2.SubmitRequest.FromString(order.command(op, index, value)).commands
                assert len(got) == 1
                assert got[0] == exec_pb2.Command(
                    cuda_value=exec_pb2.CudaValueCommand(
                        op=op, order=types_pb2.ArrayRef(handle=fake._handle), index=index,
                        value=value),
                    origin=types_pb2.SourceLocation())
                assert got[0].HasField("origin")   # set (empty): not the caller's line
