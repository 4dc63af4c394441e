"""weft._stream_ops (clients/python/native/stream_ops.c): an ordered launch's value commands and
stream memory operations in C. Its commands are the bytes the Python path builds, for counters
over the whole uint64 range and any slot; hostile calls (wrong types and counts, addresses 0,
values and flags out of range, an oversized template) raise and never call the driver. On a GPU:
writes and waits through the C path land (on the default stream with the device's context
current, on a stream of its own, and with no context current, where the C call declines and
the Python path pushes the context), and ordered Torch launches give Torch's results with the C
path on and off. Skipped where the module was not built (no Python development headers)."""
import random

import numpy as np
import pytest

import weft as wp

ops = pytest.importorskip("weft._stream_ops", reason="the client's C accelerators were not built")


class _FakeOrder:
    """What _ValueOrder reads of its order array: the wire reference and the handle."""

    def __init__(self, handle):
        self._handle = handle

    def _ref(self):
        from weft.v1 import types_pb2

        return types_pb2.ArrayRef(handle=self._handle)


def _python_command(order, op, index, value, monkeypatch):
    from weft.interop import cuda_order

    monkeypatch.setattr(cuda_order, "_NATIVE_COMMAND", None)
    return order.command(op, index, value)


def test_value_commands_are_the_python_paths_bytes(monkeypatch):
    from weft.interop import cuda_order
    from weft.v1 import exec_pb2

    rng = random.Random()
    ends = [0, 1, 127, 128, 16383, 16384, (1 << 32) - 1, 1 << 32, (1 << 63) - 1, 1 << 63, (1 << 64) - 1]
    for _ in range(300):
        handle = rng.choice([1, 127, 128, rng.randrange(1, 1 << 63), (1 << 64) - 1])
        order = cuda_order._ValueOrder(_FakeOrder(handle), 0x7000_0000_0000, 0)
        op = rng.choice([exec_pb2.CudaValueCommand.WRITE, exec_pb2.CudaValueCommand.WAIT])
        index = rng.randrange(0, cuda_order.SLOTS + 1)
        value = rng.choice(ends + [rng.randrange(0, 1 << 64)])
        inner = exec_pb2.CudaValueCommand(op=op, order=order.ref, index=index).SerializeToString()
        native = ops.value_command(inner, value)
        assert native == _python_command(order, op, index, value, monkeypatch)
        request = exec_pb2.SubmitRequest.FromString(native)
        got = request.commands[0].cuda_value
        assert (got.op, got.order.handle, got.index, got.value) == (op, handle, index, value)
        assert request.commands[0].HasField("origin")


@pytest.mark.parametrize("case", ["no args", "str template", "float value", "negative value",
                                  "value past 64 bits", "oversized template"])
def test_hostile_value_commands_raise(case):
    calls = {
        "no args": lambda: ops.value_command(),
        "str template": lambda: ops.value_command("abc", 1),
        "float value": lambda: ops.value_command(b"", 1.5),
        "negative value": lambda: ops.value_command(b"", -1),
        "value past 64 bits": lambda: ops.value_command(b"", 1 << 64),
        "oversized template": lambda: ops.value_command(b"x" * 5000, 1),
    }
    with pytest.raises((TypeError, ValueError, OverflowError)):
        calls[case]()


@pytest.mark.parametrize("case", ["six args", "function 0", "get_current 0", "str stream",
                                  "negative address", "flags past 32 bits"])
def test_hostile_stream_ops_raise_without_calling_the_driver(case):
    # Addresses that would crash if called: every case must be refused before any call.
    bad = 0x10
    calls = {
        "six args": lambda: ops.op(bad, bad, 0, 0, 0, 0),
        "function 0": lambda: ops.op(0, bad, 0, 0, 0, 0, 0),
        "get_current 0": lambda: ops.op(bad, 0, 0, 0, 0, 0, 0),
        "str stream": lambda: ops.op(bad, bad, 0, "0", 0, 0, 0),
        "negative address": lambda: ops.op(bad, bad, 0, 0, -8, 0, 0),
        "flags past 32 bits": lambda: ops.op(bad, bad, 0, 0, 0, 0, 1 << 32),
    }
    with pytest.raises((TypeError, ValueError, OverflowError)):
        calls[case]()


# ---- GPU

@pytest.fixture
def driver(cuda):
    from weft import _cuda_ipc

    if not _cuda_ipc.available():
        pytest.skip(f"no CUDA IPC in this client: {_cuda_ipc.reason()}")
    if not _cuda_ipc.stream_mem_ops(0):
        pytest.skip("cuda:0 has no 64-bit stream memory operations in this client")
    if _cuda_ipc._native_op(0) is None:
        pytest.skip("weft._stream_ops is turned off (WEFT_NATIVE_STREAM_OPS=0)")
    return _cuda_ipc


def _read_words(cuda_ipc, address, n):
    import ctypes

    words = (ctypes.c_uint64 * n)()
    cuda_ipc.synchronize(0)
    cuda_ipc.copy_to_host(0, ctypes.addressof(words), address, 8 * n)
    return list(words)


def test_writes_and_waits_land_through_the_c_path(wp, driver):
    import ctypes

    cuda_ipc = driver
    target = wp.zeros(4, dtype=wp.uint64, device="cuda:0")
    wp.synchronize()
    address = int(target.ptr)
    rng = random.Random()
    for stream in (0, cuda_ipc.proxy_stream(0)):     # the default stream, a stream of its own
        for slot in range(4):
            value = rng.randrange(1, 1 << 64)
            cuda_ipc.write_value(0, stream, address + 8 * slot, value)
            cuda_ipc.wait_value(0, stream, address + 8 * slot, value)     # GEQ: passes at once
            assert _read_words(cuda_ipc, address + 8 * slot, 1) == [value]
    # No context current: the C call declines (201) and the Python path pushes the context.
    current = ctypes.c_void_p()
    assert cuda_ipc._lib.cuCtxGetCurrent(ctypes.byref(current)) == 0
    assert cuda_ipc._lib.cuCtxSetCurrent(None) == 0
    try:
        native = cuda_ipc._native_op(0)
        assert native[0](native[1], native[3], native[4], 0, address, 5, 0) == cuda_ipc.CUDA_ERROR_INVALID_CONTEXT
        cuda_ipc.write_value(0, 0, address, 77)
        cuda_ipc.wait_value(0, 0, address, 77)
    finally:
        cuda_ipc._lib.cuCtxSetCurrent(current)
    assert _read_words(cuda_ipc, address, 1) == [77]


@wp.kernel
def scale_add(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@pytest.mark.parametrize("native", [True, False])
def test_ordered_torch_launches_with_and_without_the_c_path(wp, driver, tordered, torch, monkeypatch, native):
    from weft import _cuda_ipc
    from weft.interop import cuda_order

    if not native:
        monkeypatch.setattr(cuda_order, "_NATIVE_COMMAND", None)
        monkeypatch.setattr(_cuda_ipc, "_native_ops", {0: None})
    rng = np.random.default_rng()
    n = int(rng.integers(1 << 15, 1 << 17))
    x = rng.standard_normal(n) * 10.0 ** rng.uniform(-20, 20, n)
    y = rng.standard_normal(n) * 10.0 ** rng.uniform(-20, 20, n)
    tx = torch.tensor(x, dtype=torch.float32, device="cuda")
    ty = torch.tensor(y, dtype=torch.float32, device="cuda")
    expected = y.astype(np.float32).astype(np.float64)
    xs = x.astype(np.float32).astype(np.float64)
    torch.cuda._sleep(20_000_000)                 # Torch's stream is busy when weft launches
    for step in range(8):
        a = float(rng.uniform(-2, 2))
        ty.mul_(0.5)                              # Torch, then weft, then Torch ...
        expected = expected * 0.5
        wp.launch(scale_add, dim=n, inputs=[wp.from_torch(tx), wp.from_torch(ty), a], device=tordered)
        expected = np.float32(a) * xs + expected
    got = ty.cpu().numpy().astype(np.float64)
    scale = np.maximum(np.abs(expected), np.abs(xs) * 2.0 + 1e-30)
    assert np.max(np.abs(got - expected) / scale) < 1e-5
