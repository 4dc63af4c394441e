"""Ordering across the process boundary with interprocess CUDA events (ExecService
CudaEventCommand, weft.interop.cuda_order; docs/interop.md, "Ordering"): Torch work queued
before a weft launch on imported memory is seen by it and Torch work queued after sees its
writes, without the launch waiting for the GPU on the host; wp.stream_from_torch /
wp.ScopedStream order with a Torch side stream, `__dlpack__(stream=...)`,
`__cuda_array_interface__["stream"]` and wp.stream_to_torch hand out streams that wait for
weft's work. Hostile requests (a handle of the wrong size, an unknown op, forged handle bytes,
a handle another session uses, a CPU device) get clear errors and the daemon keeps serving.
The CPU-side validation runs everywhere; the GPU tests skip with the reason without a GPU,
Torch on CUDA or CUDA IPC in the client."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def add_one(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] + 1.0


@wp.kernel
def slow_fill(x: wp.array(dtype=float), value: float, spins: int):
    i = wp.tid()
    acc = float(0.0)
    for k in range(spins):               # keeps the GPU busy so that ordering matters
        acc = acc + wp.sin(float(k)) * 1.0e-30
    x[i] = value + acc * 0.0


def _event_command(op, handle, device="cuda:0"):
    from weft.v1 import exec_pb2

    return exec_pb2.Command(cuda_event=exec_pb2.CudaEventCommand(op=op, device=device,
                                                                 ipc_handle=handle))


def _submit(wp, commands, run=False):
    from weft import _runtime
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    rt.synchronize()
    return rt.call(rt.exec_stub.Submit, exec_pb2.SubmitRequest(commands=commands, run=run))


def _still_serving(wp):
    a = wp.zeros(8, dtype=float, device="cpu")
    wp.launch(add_one, dim=8, inputs=[a], device="cpu")
    np.testing.assert_array_equal(a.numpy(), np.ones(8, dtype=np.float32))


# ---- CPU-side validation (every machine)

def test_event_handle_of_the_wrong_size_is_refused_at_submit(wp):
    from weft.v1 import exec_pb2

    with pytest.raises(Exception, match="event handle has 64 bytes, got 63"):
        _submit(wp, [_event_command(exec_pb2.CudaEventCommand.WAIT, b"\x01" * 63)])
    with pytest.raises(Exception, match="event handle has 64 bytes, got 0"):
        _submit(wp, [_event_command(exec_pb2.CudaEventCommand.RECORD, b"")])
    _still_serving(wp)


def test_unknown_event_op_is_refused_at_submit(wp):
    with pytest.raises(Exception, match="unknown cuda_event op 7"):
        _submit(wp, [_event_command(7, b"\x02" * 64)])
    _still_serving(wp)


def test_event_on_the_cpu_is_a_clear_error_and_run_reports_it(wp):
    from weft import _runtime
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    rt.synchronize()
    rt.submit(_event_command(exec_pb2.CudaEventCommand.WAIT, b"\x03" * 64, device="cpu"))
    with pytest.raises(Exception, match="'cpu' is not a GPU"):
        rt.run()                     # Submit(run=true) returns the session's error
    _still_serving(wp)


def test_run_returns_after_the_daemon_ran_the_batch(wp):
    from weft import _runtime

    rt = _runtime.get_runtime()
    a = wp.zeros(1000, dtype=float, device="cpu")
    view = a.numpy()                 # a view of the slab: reading it never synchronizes
    for _ in range(3):
        wp.launch(add_one, dim=1000, inputs=[a], device="cpu")
    rt.run()
    # CPU launches run on the executor: done once run() returned, without a synchronize
    assert rt._unsynchronized
    np.testing.assert_array_equal(view, np.full(1000, 3.0, dtype=np.float32))


def test_streams_are_cuda_objects(wp, torch):
    with pytest.raises(RuntimeError, match="CUDA objects"):
        wp.stream_from_torch("cpu")
    with pytest.raises(RuntimeError, match="CUDA objects"):
        wp.stream_to_torch("cpu")


# ---- GPU

SPINS = 20000


def test_torch_work_before_a_launch_is_seen_without_a_host_wait(wp, tordered, torch):
    n = 1 << 16
    t = torch.zeros(n, device="cuda")
    a = wp.from_torch(t)
    wp.launch(add_one, dim=n, inputs=[a], device=tordered)      # imports, probes, warms up
    torch.cuda.synchronize()
    torch.cuda._sleep(200_000_000)                           # ~0.1 s of GPU time on Torch's stream
    t.fill_(41.0)                                            # queued behind it
    wp.launch(add_one, dim=n, inputs=[a], device=tordered)
    busy = not torch.cuda.current_stream().query()
    result = t.cpu().numpy()                                 # Torch's stream: after the launch
    np.testing.assert_array_equal(result, np.full(n, 42.0, dtype=np.float32))
    assert busy, "wp.launch waited on the host for Torch's stream"


def test_launch_writes_are_seen_by_torch_work_queued_after(wp, tordered, torch):
    n = 1 << 15
    t = torch.zeros(n, device="cuda")
    a = wp.from_torch(t)
    for value in (3.0, 7.0):
        wp.launch(slow_fill, dim=n, inputs=[a, value, SPINS], device=tordered)
        s = (t * 2.0).sum().item()                           # Torch reads at once
        assert s == pytest.approx(2.0 * value * n)


def test_scoped_stream_from_a_torch_side_stream(wp, tordered, torch):
    n = 1 << 15
    side = torch.cuda.Stream()
    t = torch.zeros(n, device="cuda")
    torch.cuda.synchronize()
    a = wp.from_torch(t)
    ws = wp.stream_from_torch(side)
    assert ws.cuda_stream == side.cuda_stream and wp.stream_to_torch(ws) is side
    with torch.cuda.stream(side):
        torch.cuda._sleep(100_000_000)
        t.fill_(5.0)
        with wp.ScopedStream(ws):
            wp.launch(add_one, dim=n, inputs=[a], device=tordered)
        u = t * 10.0                                         # on the side stream, after weft
    side.synchronize()
    np.testing.assert_array_equal(u.cpu().numpy(), np.full(n, 60.0, dtype=np.float32))


def test_dlpack_stream_and_cuda_array_interface_stream(wp, tordered, torch, rng):
    from weft import _cuda_ipc

    n = 4096
    a = wp.zeros(n, dtype=float, device=tordered)
    wp.launch(slow_fill, dim=n, inputs=[a, 2.5, SPINS], device=tordered)
    side = torch.cuda.Stream()
    with torch.cuda.stream(side):
        t = torch.utils.dlpack.from_dlpack(a)            # __dlpack__(stream=side)
        total = t.sum()
    side.synchronize()
    assert total.item() == pytest.approx(2.5 * n)
    wp.launch(slow_fill, dim=n, inputs=[a, 4.0, SPINS], device=tordered)
    cai = a.__cuda_array_interface__
    assert cai["stream"] == _cuda_ipc.proxy_stream(0) and cai["stream"] not in (0, None)
    proxy = torch.cuda.ExternalStream(cai["stream"])
    with torch.cuda.stream(proxy):
        total = torch.as_tensor(a, device="cuda").sum()
    proxy.synchronize()
    assert total.item() == pytest.approx(4.0 * n)


def test_stream_to_torch_of_the_session_stream(wp, tordered, torch):
    n = 4096
    a = wp.zeros(n, dtype=float, device=tordered)
    t = wp.to_torch(a)
    wp.launch(slow_fill, dim=n, inputs=[a, 1.5, SPINS], device=tordered)
    ts = wp.stream_to_torch(wp.get_stream(tordered))
    with torch.cuda.stream(ts):
        total = t.sum()
    ts.synchronize()
    assert total.item() == pytest.approx(1.5 * n)


def test_forged_event_handle_is_a_clear_error(wp, tordered, rng):
    from weft import _runtime
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    rt.synchronize()
    forged = bytes(rng.integers(0, 256, 64, dtype=np.uint8))
    rt.submit(_event_command(exec_pb2.CudaEventCommand.WAIT, forged))
    with pytest.raises(Exception, match="could not be opened on cuda:0"):
        rt.run()
    a = wp.zeros(16, dtype=float, device=tordered)             # the session and daemon go on
    wp.launch(add_one, dim=16, inputs=[a], device=tordered)
    np.testing.assert_array_equal(a.numpy(), np.ones(16, dtype=np.float32))


CHILD = """
import sys, torch, weft as wp
from weft import _cuda_ipc, _runtime
from weft.interop import cuda_order
t = torch.zeros(16, device="cuda")
rt = _runtime.get_runtime()
assert cuda_order.enabled(rt, {0}), cuda_order.refused()
from weft.v1 import exec_pb2
event = _cuda_ipc.next_event(0)
_cuda_ipc.record_event(event, 0)      # this session opens its events (as the event path does)
rt.submit(cuda_order._command(exec_pb2.CudaEventCommand.WAIT, 0, event))
rt.synchronize()
print(" ".join(e.handle.hex() for e in _cuda_ipc._events[0]), flush=True)
sys.stdin.readline()
"""


def test_an_event_another_session_uses_is_refused(wp, tordered, spawn_client):
    from weft import _runtime
    from weft.v1 import exec_pb2

    child = spawn_client(CHILD)
    line = child.stdout.readline().split()
    assert line, child.stderr.read()
    try:
        rt = _runtime.get_runtime()
        rt.synchronize()
        for handle in line:                  # the child's pool: the ones it opened are refused
            rt.submit(_event_command(exec_pb2.CudaEventCommand.RECORD, bytes.fromhex(handle)))
        with pytest.raises(Exception, match="used by another session"):
            rt.run()
    finally:
        child.stdin.write("\n")
        child.stdin.flush()
        child.wait(timeout=60)
    _still_serving(wp)
