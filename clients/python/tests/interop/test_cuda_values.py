"""Ordering by stream memory operations (ExecService CudaValueCommand, weft.interop.cuda_order;
docs/interop.md, "Ordering by stream memory operations"): where both processes' drivers
support 64-bit stream memory operations, a launch on memory a framework holds is ordered with
the framework's stream by counters in a session GPU array, with no round trip to the daemon;
more framework streams than counter slots still order correctly; hostile commands (an order
array on the CPU, of the wrong type, an index past its end, an unknown handle or op) get clear
errors, and a client that dies while the daemon's stream waits for it leaves the daemon
serving (the wait is released when its session is reaped). The CPU-side validation runs
everywhere; the GPU tests skip with the reason without a GPU, Torch on CUDA, CUDA IPC in the
client or stream memory operations."""
import os
import signal

import numpy as np
import pytest

import weft as wp


@wp.kernel
def add_one(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] + 1.0


def _value_command(op, ref, index, value):
    from weft.v1 import exec_pb2

    return exec_pb2.Command(cuda_value=exec_pb2.CudaValueCommand(op=op, order=ref, index=index,
                                                                 value=value))


def _run(commands):
    from weft import _runtime

    rt = _runtime.get_runtime()
    rt.synchronize()
    for c in commands:
        rt.submit(c)
    rt.run()


def _still_serving(wp, device="cpu"):
    a = wp.zeros(8, dtype=float, device=device)
    wp.launch(add_one, dim=8, inputs=[a], device=device)
    np.testing.assert_array_equal(a.numpy(), np.ones(8, dtype=np.float32))


# ---- validation (every machine)

@pytest.mark.parametrize("case", ["cpu order array", "float elements", "2-D", "index past the end",
                                  "unknown handle"])
def test_bad_order_arrays_are_clear_errors(wp, case):
    from weft.v1 import exec_pb2, types_pb2

    WAIT = exec_pb2.CudaValueCommand.WAIT
    order = wp.zeros(4, dtype=wp.uint64, device="cpu")
    floats = wp.zeros(4, dtype=float, device="cpu")
    matrix = wp.zeros((2, 2), dtype=wp.uint64, device="cpu")
    if case == "cpu order array":
        command, want = _value_command(WAIT, order._ref(), 1, 5), "not a GPU"
    elif case == "float elements":
        command, want = _value_command(WAIT, floats._ref(), 0, 1), \
            "8-byte elements"
    elif case == "2-D":
        command, want = _value_command(WAIT, matrix._ref(), 0, 1), "must be 1-D"
    elif case == "index past the end":
        command, want = _value_command(WAIT, order._ref(), 4, 1), "index 4 is out of range"
    else:
        command, want = _value_command(WAIT, types_pb2.ArrayRef(handle=987654321), 0, 1), \
            "unknown array handle 987654321"
    with pytest.raises(Exception, match=want):
        _run([command])
    _still_serving(wp)


def test_unknown_value_op_is_refused_at_submit(wp):
    from weft import _runtime
    from weft.v1 import exec_pb2

    order = wp.zeros(4, dtype=wp.uint64, device="cpu")
    rt = _runtime.get_runtime()
    rt.synchronize()
    with pytest.raises(Exception, match="unknown cuda_value op 9"):
        rt.call(rt.exec_stub.Submit, exec_pb2.SubmitRequest(
            commands=[_value_command(9, order._ref(), 0, 1)], run=True))
    _still_serving(wp)


# ---- GPU

@pytest.fixture
def tvalues(tordered):
    """tordered, ordering by stream memory operations (else skipped with the reason)."""
    from weft import _cuda_ipc, _runtime
    from weft.interop import cuda_order

    if not _cuda_ipc.stream_mem_ops(0):
        pytest.skip("cuda:0 has no 64-bit stream memory operations in this client")
    assert cuda_order.uses_values(_runtime.get_runtime(), 0), \
        "both sides support stream memory operations, yet the session orders by events"
    return tordered


def test_ordered_launches_make_no_round_trip(wp, tvalues, torch, monkeypatch):
    from weft import _runtime

    n = 1 << 16
    t = torch.zeros(n, device="cuda")
    a = wp.from_torch(t)
    wp.launch(add_one, dim=n, inputs=[a], device=tvalues)     # imports and warms up
    torch.cuda.synchronize()
    rt = _runtime.get_runtime()
    calls = []
    real_exec, real_run = rt._exec, rt.run
    monkeypatch.setattr(rt, "_exec", lambda *args: calls.append(args[0]) or real_exec(*args))
    monkeypatch.setattr(rt, "run", lambda: calls.append("run") or real_run())
    expected = np.ones(n, dtype=np.float64)
    torch.cuda._sleep(50_000_000)                             # Torch's stream is busy
    for step in range(20):
        t.mul_(2.0)                                           # Torch, then weft, then Torch ...
        wp.launch(add_one, dim=n, inputs=[a], device=tvalues)
        expected = expected * 2.0 + 1.0
    result = t.cpu().numpy()                                  # Torch's stream: after the launches
    assert calls == [], f"ordered launches waited for the daemon: {calls}"
    np.testing.assert_array_equal(result, expected.astype(np.float32))


def test_more_framework_streams_than_slots(wp, tvalues, torch):
    from weft.interop import cuda_order

    count = cuda_order.SLOTS + 9
    n = 4096
    streams = [torch.cuda.Stream() for _ in range(count)]
    tensors = [torch.zeros(n, device="cuda") for _ in range(count)]
    torch.cuda.synchronize()
    outs = []
    for round_ in range(2):
        outs = []
        for i, (s, t) in enumerate(zip(streams, tensors)):
            with torch.cuda.stream(s):
                torch.cuda._sleep(1_000_000)
                t.fill_(float(i + round_))
                with wp.ScopedStream(wp.stream_from_torch(s)):
                    wp.launch(add_one, dim=n, inputs=[wp.from_torch(t)], device=tvalues)
                outs.append(t * 2.0)                          # on s, after weft's launch
    torch.cuda.synchronize()
    for i, u in enumerate(outs):
        np.testing.assert_array_equal(u.cpu().numpy(), np.full(n, 2.0 * (i + 2), dtype=np.float32))


def test_threads_ordering_on_one_stream(wp, tvalues, torch):
    """Four threads launch on tensors of the same Torch stream at once: the counter writes only
    grow on the stream (each queued under the runtime's lock with its count), so no launch waits
    forever and each sees the Torch work queued before it."""
    import threading

    n = 4096
    rounds = 40
    tensors = [torch.zeros(n, device="cuda") for _ in range(4)]
    arrays = [wp.from_torch(t) for t in tensors]
    torch.cuda.synchronize()
    errors = []

    def work(k):
        try:
            for _ in range(rounds):
                tensors[k].mul_(2.0)
                wp.launch(add_one, dim=n, inputs=[arrays[k]], device=tvalues)
        except Exception as exc:  # noqa: BLE001 - reported below
            errors.append(exc)
    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(60)
    assert not any(th.is_alive() for th in threads) and not errors, errors
    done = threading.Event()
    results = []

    def read():
        results.extend(t.cpu().numpy() for t in tensors)
        done.set()
    threading.Thread(target=read, daemon=True).start()
    assert done.wait(60), "a framework stream waited forever"
    expected = 0.0
    for _ in range(rounds):
        expected = expected * 2.0 + 1.0
    for r in results:
        np.testing.assert_array_equal(r, np.full(n, expected, dtype=np.float32))


def test_a_launch_that_fails_after_ordering_leaves_nothing_waiting(wp, tvalues, torch, monkeypatch):
    """A launch that fails after its ordering was queued (here: the Submit raises) leaves the
    daemon's wait with the framework stream's write it needs: the next synchronize returns, and
    the session and the stream go on."""
    import threading

    from weft import _runtime

    n = 4096
    t = torch.zeros(n, device="cuda")
    a = wp.from_torch(t)
    wp.launch(add_one, dim=n, inputs=[a], device=tvalues)
    torch.cuda.synchronize()
    from weft.v1 import exec_pb2

    rt = _runtime.get_runtime()
    real_submit, real_framed = rt.submit, rt.submit_framed

    def failing(cmd, start=False):
        if cmd.HasField("launch"):
            raise RuntimeError("injected failure")
        return real_submit(cmd, start)

    def failing_framed(frame, start=False):     # launches are queued as bytes
        if exec_pb2.SubmitRequest.FromString(frame).commands[0].HasField("launch"):
            raise RuntimeError("injected failure")
        return real_framed(frame, start)
    monkeypatch.setattr(rt, "submit", failing)
    monkeypatch.setattr(rt, "submit_framed", failing_framed)
    with pytest.raises(RuntimeError, match="injected"):
        wp.launch(add_one, dim=n, inputs=[a], device=tvalues)
    monkeypatch.setattr(rt, "submit", real_submit)
    monkeypatch.setattr(rt, "submit_framed", real_framed)
    done = threading.Event()
    threading.Thread(target=lambda: (wp.synchronize(), done.set()), daemon=True).start()
    assert done.wait(30), "the session's stream waits for a write that was never queued"
    wp.launch(add_one, dim=n, inputs=[a], device=tvalues)
    np.testing.assert_array_equal(t.cpu().numpy(), np.full(n, 2.0, dtype=np.float32))


DYING = """
import os, sys, torch, weft as wp
from weft import _runtime
from weft.interop import cuda_order
from weft.v1 import exec_pb2
rt = _runtime.get_runtime()
assert cuda_order.enabled(rt, {0}) and cuda_order.uses_values(rt, 0), cuda_order.refused()
order = wp.zeros(4, dtype=wp.uint64, device="cuda:0")
a = wp.zeros(1 << 20, dtype=float, device="cuda:0")
rt.synchronize()
# a wait nobody will satisfy, then work behind it, sent without waiting
rt.submit(exec_pb2.Command(cuda_value=exec_pb2.CudaValueCommand(
    op=exec_pb2.CudaValueCommand.WAIT, order=order._ref(), index=3, value=10**15)))
wp.copy(a, a)
rt.send_now()
rt._collect_inflight()
print("waiting", flush=True)
sys.stdin.readline()
"""


def test_a_client_that_dies_while_the_daemon_waits_for_it(wp, tvalues, weftd, spawn_client,
                                                          wait_for):
    before = weftd.stats()
    child = spawn_client(DYING)
    assert child.stdout.readline().strip() == "waiting", child.stderr.read()
    _still_serving(wp, tvalues)                     # another session on the same GPU goes on
    child.send_signal(signal.SIGKILL)
    child.wait(timeout=10)
    # reaping closes the session, which releases its wait (else the close would hang)
    assert wait_for(lambda: weftd.stats().sessions_reaped_total > before.sessions_reaped_total, 30.0), \
        "the dead client's session was not reaped (its stream still waits?)"
    _still_serving(wp, tvalues)
    _still_serving(wp)
