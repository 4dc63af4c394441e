"""Interprocess events between weft clients (wp.Event(interprocess=True), Event.ipc_handle,
wp.event_from_ipc_handle; docs/cuda-client.md): a real CUDA interprocess event of the creating
process that weftd opens and shares with the other sessions of the same principal (the
CudaEventCommand SHARE op), so that one client's launches wait on the GPU for another client's
work. Hostile use (an op the daemon does not know, SHARE on the CPU, a handle nobody shared)
gets clear errors and the daemon keeps serving. The CPU-side checks run everywhere; the GPU
tests skip with the reason without a GPU or CUDA IPC in the client."""
from pathlib import Path

import numpy as np
import pytest

import weft as wp

SPINS = 400_000                     # ~tens of ms of GPU time per thread: ordering matters


@wp.kernel
def slow_fill(x: wp.array(dtype=float), value: float, spins: int):
    i = wp.tid()
    acc = float(0.0)
    for k in range(spins):
        acc = acc + wp.sin(float(k)) * 1.0e-30
    x[i] = value + acc * 0.0


@wp.kernel
def copy_plus_one(src: wp.array(dtype=float), dst: wp.array(dtype=float)):
    i = wp.tid()
    dst[i] = src[i] + 1.0


def _event_command(op, handle, device):
    from weft.v1 import exec_pb2

    return exec_pb2.Command(cuda_event=exec_pb2.CudaEventCommand(op=op, device=device,
                                                                 ipc_handle=handle))


@pytest.fixture
def ipc_gpu(wp):
    """cuda:0 where this client and weftd can use interprocess events, else skipped."""
    if not any(d.is_cuda and d.is_compute_supported for d in wp.get_cuda_devices()):
        pytest.skip("weftd has no CUDA device it can run kernels on")
    from weft import _runtime
    from weft.interop import cuda_order

    if not cuda_order.enabled(_runtime.get_runtime(), {0}):
        pytest.skip(f"interprocess events are off here: {cuda_order.refused()}")
    return wp.get_cuda_device(0)


# ---- every machine

def test_share_on_the_cpu_is_a_clear_error(wp):
    from weft import _runtime
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    rt.synchronize()
    rt.submit(_event_command(exec_pb2.CudaEventCommand.SHARE, b"\x05" * 64, "cpu"))
    with pytest.raises(Exception, match="'cpu' is not a GPU"):
        rt.run()
    a = wp.full(4, 2.0, dtype=float, device="cpu")         # the session keeps working
    np.testing.assert_array_equal(a.numpy(), np.full(4, 2.0, dtype=np.float32))


def test_share_with_a_short_handle_is_refused_at_submit(wp):
    from weft import _runtime
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    rt.synchronize()
    with pytest.raises(Exception, match="event handle has 64 bytes, got 16"):
        rt.call(rt.exec_stub.Submit, exec_pb2.SubmitRequest(commands=[
            _event_command(exec_pb2.CudaEventCommand.SHARE, b"\x05" * 16, "cuda:0")]))


def test_interprocess_events_are_cuda_objects(wp):
    with pytest.raises(RuntimeError, match="CUDA objects"):
        wp.Event("cpu", interprocess=True)
    with pytest.raises(RuntimeError, match="CUDA objects"):
        wp.event_from_ipc_handle(b"\x00" * 64, device="cpu")


# ---- GPU

def test_an_interprocess_event_has_a_handle(ipc_gpu):
    e = wp.Event(ipc_gpu, interprocess=True)
    handle = e.ipc_handle()
    assert isinstance(handle, bytes) and len(handle) == 64 and handle != bytes(64)
    assert e.is_ipc and e.cuda_event
    assert e.query()                                        # never recorded: complete
    with pytest.raises(ValueError, match="enable_timing=True' and 'interprocess=True"):
        wp.Event(ipc_gpu, enable_timing=True, interprocess=True)
    with pytest.raises(ValueError, match="64 bytes"):
        wp.event_from_ipc_handle(handle[:32], device=ipc_gpu)


def test_an_event_without_interprocess_warns_and_has_no_handle(ipc_gpu, capsys):
    handle = wp.Event(ipc_gpu).ipc_handle()
    assert handle == bytes(64)
    assert "Warp UserWarning: IPC event handle appears to be invalid" in capsys.readouterr().err


def test_record_and_wait_in_one_session(ipc_gpu):
    n = 1024
    a = wp.zeros(n, dtype=float, device=ipc_gpu)
    b = wp.zeros(n, dtype=float, device=ipc_gpu)
    e = wp.Event(ipc_gpu, interprocess=True)
    wp.launch(slow_fill, dim=n, inputs=[a, 3.0, SPINS // 8], device=ipc_gpu)
    wp.record_event(e)
    wp.wait_event(e)
    wp.launch(copy_plus_one, dim=n, inputs=[a, b], device=ipc_gpu)
    wp.synchronize_event(e)
    assert e.query()
    np.testing.assert_array_equal(b.numpy(), np.full(n, 4.0, dtype=np.float32))
    with wp.ScopedCapture(ipc_gpu) as capture:        # a graph records no event operations
        with pytest.raises(RuntimeError, match="cannot be recorded inside a graph capture"):
            wp.record_event(e)
        with pytest.raises(RuntimeError, match="cannot be recorded inside a graph capture"):
            wp.get_stream(ipc_gpu).record_event(e)
        with pytest.raises(RuntimeError, match="cannot be waited on inside a graph capture"):
            wp.wait_event(e)
    assert len(capture.graph) == 0


CHILD = """
import sys, weft as wp
sys.path.insert(0, {test_dir!r})
from test_ipc_events import slow_fill     # this file's kernel (weft reads kernels' source files)
token, handle, n, spins = sys.stdin.readline().split()
a = wp.from_ipc_handle(bytes.fromhex(token), dtype=float, shape=(int(n),), device="cuda:0")
e = wp.event_from_ipc_handle(bytes.fromhex(handle), device="cuda:0")
wp.launch(slow_fill, dim=int(n), inputs=[a, 5.0, int(spins)], device="cuda:0")
wp.get_stream("cuda:0").record_event(e)
print("recorded", flush=True)        # no synchronize: the fill is still running
sys.stdin.readline()
wp.synchronize()
"""


def test_a_shared_event_orders_two_clients(ipc_gpu, spawn_client):
    n = 4096
    a = wp.zeros(n, dtype=float, device=ipc_gpu)
    b = wp.zeros(n, dtype=float, device=ipc_gpu)
    e = wp.Event(ipc_gpu, interprocess=True)
    token = a.ipc_handle()
    wp.synchronize()
    child = spawn_client(CHILD.format(test_dir=str(Path(__file__).resolve().parent)))
    try:
        child.stdin.write(f"{token.hex()} {e.ipc_handle().hex()} {n} {SPINS}\n")
        child.stdin.flush()
        line = child.stdout.readline()
        assert line.strip() == "recorded", child.stderr.read()
        busy = not e.query()            # the child's fill is still running on the GPU
        wp.get_stream(ipc_gpu).wait_event(e)                 # the session's stream waits
        wp.launch(copy_plus_one, dim=n, inputs=[a, b], device=ipc_gpu)
        np.testing.assert_array_equal(b.numpy(), np.full(n, 6.0, dtype=np.float32))
        assert busy, "the child's fill was done before the wait: nothing was ordered"
        e.synchronize()                 # a host wait on another process's record
        np.testing.assert_array_equal(a.numpy(), np.full(n, 5.0, dtype=np.float32))
    finally:
        if child.poll() is None:
            child.stdin.write("\n")
            child.stdin.flush()
    assert child.wait(timeout=120) == 0, child.stderr.read()


NOT_SHARED = """
import sys, weft as wp
from weft.interop import cuda_order
from weft import _runtime
handle = bytes.fromhex(sys.stdin.readline().strip())
e = wp.event_from_ipc_handle(handle, device="cuda:0")
try:
    wp.record_event(e)
    print("recorded")
except Exception as err:
    print("refused:", str(err).splitlines()[0])
wp.launch_ok = True
a = wp.full(8, 1.0, dtype=float, device="cuda:0")
print("serving", float(a.numpy().sum()), flush=True)
"""


def test_an_event_the_owner_did_not_share_is_refused(ipc_gpu, spawn_client):
    from weft import _cuda_ipc, _runtime
    from weft.interop import cuda_order
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    pooled = _cuda_ipc.next_event(0)        # the ordering pool's event: this session's own
    _cuda_ipc.record_event(pooled, 0)
    rt.submit(cuda_order._command(exec_pb2.CudaEventCommand.WAIT, 0, pooled))
    rt.synchronize()
    child = spawn_client(NOT_SHARED)
    out, err = child.communicate(pooled.handle.hex() + "\n", timeout=120)
    assert "refused:" in out and "used by another session" in out, out + err
    assert "serving 8.0" in out, out + err


def test_a_remote_session_cannot_use_event_handles(tcp_weftd, run_client):
    """A TCP session has no process on weftd's machine: every CudaEventCommand it sends (any
    op, any device, a handle it guessed) is refused, and the session goes on."""
    out = run_client("""
        import numpy as np
        import weft as wp
        from weft import _runtime
        from weft.v1 import exec_pb2
        wp.init()
        rt = _runtime.get_runtime()
        assert not rt.local
        ops = exec_pb2.CudaEventCommand
        for op in (ops.WAIT, ops.RECORD, ops.SHARE):
            for device in ("cuda:0", "cpu"):
                rt.submit(exec_pb2.Command(cuda_event=ops(op=op, device=device,
                                                          ipc_handle=bytes(range(64)))))
                try:
                    rt.run()
                except Exception as err:
                    assert "for local sessions" in str(err), str(err)
                else:
                    raise AssertionError("a remote session's cuda_event was accepted")
        a = wp.full(4, 3.0, dtype=float, device="cpu")
        assert np.array_equal(a.numpy(), np.full(4, 3.0, dtype=np.float32))
        print("OK")
    """, env={"WEFT_ADDRESS": tcp_weftd.address, "WEFT_TOKEN": tcp_weftd.token}, timeout=180)
    assert out.stdout.strip().endswith("OK"), out.stdout
