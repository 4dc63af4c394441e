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


@wp_module.struct
class FrameStruct:
    scale: float
    count: int


@wp_module.kernel
def frame_probe(data: wp_module.array(dtype=float), s: float, n: int, v: wp_module.vec3,
                st: FrameStruct):
    i = wp_module.tid()
    wp_module.atomic_add(data, i % 64, s * st.scale + float(n + st.count) + v[1])


def test_launch_commands_assembled_from_bytes_are_the_commands_protobuf_builds(wp):
    """wp.launch assembles a launch's command from bytes cached per kernel, argument and call
    site (weft/_kernel/launch.py): parsed, it is the command the message path builds (taken
    when max_blocks is set on the CPU) but for max_blocks, for dimensions whose varints take 1
    to 6 bytes, negative and changing scalars, vectors, structs and NumPy arrays (the packer's
    path), and the launches compute what they should; the daemon refuses a launch of 2^80
    threads (6-byte varints) naming its dimensions and the limit, as before."""
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    wp.synchronize()
    frames = []
    queue = rt._queue_frame

    def spy(frame, start):
        frames.append(frame)
        return queue(frame, start)

    rng = np.random.default_rng()
    cases = []
    # eighths and small integers: the large launches' float32 sums stay exact; a large n only
    # where few threads add it up
    for dims in ((64,), (3, 5), (2, 2, 2, 2), (1, 1, 1, 64), (20_000,), (2_100_000,)):
        large = int(np.prod(dims)) > 1000
        for n in (0, -1, 7) if large else (0, -1, 7, int(rng.integers(-(1 << 30), 1 << 30))):
            s = float(rng.integers(-8, 9)) / 8
            v = wp.vec3(*(rng.integers(-8, 9, 3) / 8.0))
            st = FrameStruct()
            st.scale, st.count = float(rng.choice([1.0, 1.5])), int(rng.integers(-5, 5))
            cases.append((dims, [wp.zeros(64, dtype=float, device="cpu"), s, n, v, st]))
    cases.append(((64,), [np.ones(64, np.float32), 1.0, 2, (1.0, 2.0, 3.0), FrameStruct()]))
    rt._queue_frame = spy
    try:
        for dims, inputs in cases:
            wp.launch(frame_probe, dim=dims, inputs=inputs, device="cpu")
            wp.launch(frame_probe, dim=dims, inputs=inputs, device="cpu", max_blocks=1)
        wp.synchronize()
        with pytest.raises(Exception, match=r"dim \(1099511627776, 1099511627776\) has .* threads, "
                                            r"more than the limit"):
            wp.launch(frame_probe, dim=(1 << 40, 1 << 40), inputs=cases[0][1], device="cpu")
            wp.synchronize()
    finally:
        rt._queue_frame = queue
    launches = [c for f in frames for c in exec_pb2.SubmitRequest.FromString(f).commands
                if c.HasField("launch")]
    assert len(launches) == 2 * len(cases) + 1
    assert list(launches[-1].launch.dim) == [1 << 40, 1 << 40]
    assert launches[-1].launch.module_id == launches[0].launch.module_id
    for k, (dims, inputs) in enumerate(cases):
        from_bytes, from_message = launches[2 * k], launches[2 * k + 1]
        assert from_message.launch.max_blocks == 1 and from_bytes.launch.max_blocks == 0
        from_message.launch.max_blocks = 0
        assert from_message.origin.line == from_bytes.origin.line + 1   # the next line
        from_message.origin.line = from_bytes.origin.line
        if isinstance(inputs[0], np.ndarray):   # each launch copies it to a new array
            assert from_bytes.launch.args[0].array.handle != from_message.launch.args[0].array.handle
            from_message.launch.args[0].array.handle = from_bytes.launch.args[0].array.handle
        assert from_bytes == from_message
        assert list(from_bytes.launch.dim) == list(dims)
        assert from_bytes.origin.file == __file__ and from_bytes.origin.line > 0
        if not isinstance(inputs[0], np.ndarray):
            threads = int(np.prod(dims))
            data, s, n, v, st = inputs
            inc = np.float32(s) * np.float32(st.scale) + np.float32(n + st.count) + np.float32(v[1])
            host = np.zeros(64, dtype=np.float64)
            first = np.arange(dims[0]) % 64          # i = wp.tid(), the first coordinate
            np.add.at(host, first, 2 * (threads // dims[0]) * np.float64(inc))
            np.testing.assert_allclose(data.numpy(), host, rtol=1e-5, atol=0)   # <= 128 float32 sums
