"""Issue 4: "a tape whose arrays were freed, or a backward on an empty tape: clear error,
nothing corrupted", against the daemon tape (TapeCommand in weftd).

What happens, by layer:
  - The Python wp.Tape keeps every array of a recorded launch alive (it holds the launch
    arguments), so dropping the user's last reference and gc.collect() frees nothing: the
    backward runs and the gradients are right. A tape dropped right after its backward()
    frees its arrays at once, but weftd orders each free after the session's queued
    commands, so the queued BACKWARD still finds them even when the executor is busy.
  - weftd's tape itself holds weak references only: an array freed in the daemon (here by a
    raw ArrayService.Free of its handle, which is what a client without that guarantee would
    do) makes BACKWARD fail with FAILED_PRECONDITION naming the kernel, the parameter and the
    handle ("... has since been freed; record the launches again"), and it checks every
    record before running any, so no gradient changes and the session goes on working.
  - backward on an empty tape: the Python tape raises RuntimeError("... empty ...") without
    a round trip; a raw BACKWARD of a tape id that recorded nothing is FAILED_PRECONDITION
    from weftd ("... recorded nothing"); neither changes anything."""
import gc
import os
import weakref

import numpy as np
import pytest

import weft as wp
from weft import _runtime
from weft.errors import WeftError
from weft.v1 import array_pb2, exec_pb2


@wp.kernel
def square_scaled(x: wp.array(dtype=float), s: float, y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = s * x[i] * x[i]


@wp.kernel
def sum_into(y: wp.array(dtype=float), loss: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(loss, 0, y[i])


def _daemon_tape():
    tape = wp.Tape()
    if os.environ.get("WEFT_TAPE", "").lower() == "client" or tape.mode != "daemon":
        pytest.skip("the daemon tape is off (WEFT_TAPE=client or an old weftd)")
    return tape


def _record(tape, x, s):
    """Records y = s*x^2, loss = sum(y) with y created here; returns (loss, weakref to y)."""
    y = wp.zeros(x.shape[0], dtype=float, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    with tape:
        wp.launch(square_scaled, dim=x.shape[0], inputs=[x, s], outputs=[y])
        wp.launch(sum_into, dim=x.shape[0], inputs=[y], outputs=[loss])
    return loss, weakref.ref(y)


def test_tape_keeps_recorded_arrays_alive(wp, rng):
    n = 257
    xs = rng.standard_normal(n).astype(np.float32)
    s = float(rng.uniform(0.5, 2.0))
    x = wp.array(xs, dtype=float, requires_grad=True)
    tape = _daemon_tape()
    loss, y_ref = _record(tape, x, s)
    gc.collect()
    wp.synchronize()            # sends any frees the finalizers queued
    assert y_ref() is not None, "the tape must keep its recorded arrays alive"
    tape.backward(loss=loss)
    expected = 2.0 * s * xs.astype(np.float64)
    np.testing.assert_allclose(x.grad.numpy(), expected, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(loss.numpy()[0], s * np.sum(xs.astype(np.float64) ** 2),
                               rtol=1e-4)
    # after the tape goes, its arrays go too
    del tape
    gc.collect()
    assert y_ref() is None


@wp.kernel
def busy(n: int, out: wp.array(dtype=float)):
    acc = float(0.0)
    for k in range(n):
        acc = acc + wp.sin(float(k))
    out[0] = acc


def test_frees_wait_for_a_queued_backward(wp, rng):
    """A BACKWARD is queued behind a long launch; the tape and its intermediate array are
    dropped at once and their frees reach weftd before the BACKWARD runs: weftd releases them
    only after the queued commands, so the gradient must be right."""
    n = 64
    xs = rng.standard_normal(n).astype(np.float32)
    s = float(rng.uniform(0.5, 2.0))
    x = wp.array(xs, dtype=float, requires_grad=True)
    sink = wp.zeros(1, dtype=float)
    for _ in range(3):
        x.grad.zero_()
        tape = _daemon_tape()
        loss, _ = _record(tape, x, s)
        wp.launch(busy, dim=1, inputs=[3_000_000, sink])   # the executor stays busy a while
        tape.backward(loss=loss)
        del tape, loss
        gc.collect()
        wp.zeros(1)                       # another call: pending frees go out now
        np.testing.assert_allclose(x.grad.numpy(), 2.0 * s * xs.astype(np.float64), rtol=1e-5, atol=1e-6)


def test_backward_with_a_freed_array_is_a_clear_error(wp, rng):
    n = 64
    xs = rng.standard_normal(n).astype(np.float32)
    s = float(rng.uniform(0.5, 2.0))
    x = wp.array(xs, dtype=float, requires_grad=True)
    tape = _daemon_tape()
    loss, y_ref = _record(tape, x, s)
    y = y_ref()
    wp.synchronize()
    loss_before = loss.numpy().copy()
    rt = _runtime.get_runtime()
    # free y in the daemon behind the Python tape's back
    rt.call(rt.array_stub.Free, array_pb2.FreeArrayRequest(handle=y._handle))
    with pytest.raises(WeftError) as info:
        tape.backward(loss=loss)
        wp.synchronize()
    text = str(info.value)
    assert info.value.code == "FAILED_PRECONDITION", text
    assert "freed" in text and "sum_into" in text and str(y._handle) in text, text
    # nothing ran: no gradient and no loss value changed
    np.testing.assert_array_equal(x.grad.numpy(), np.zeros(n, dtype=np.float32))
    np.testing.assert_array_equal(loss.grad.numpy(), np.zeros(1, dtype=np.float32))
    np.testing.assert_array_equal(loss.numpy(), loss_before)
    # the session still works: a fresh tape over the same x gives the right gradient
    x.grad.zero_()
    tape2 = _daemon_tape()
    loss2, _ = _record(tape2, x, s)
    tape2.backward(loss=loss2)
    np.testing.assert_allclose(x.grad.numpy(), 2.0 * s * xs.astype(np.float64),
                               rtol=1e-5, atol=1e-6)


def test_backward_on_an_empty_daemon_tape_is_a_clear_error(wp, rng):
    tape = _daemon_tape()
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    with tape:
        pass
    with pytest.raises(RuntimeError, match="empty"):
        tape.backward(loss=loss)
    # the daemon's own answer to a BACKWARD of a tape that recorded nothing
    rt = _runtime.get_runtime()
    wp.synchronize()
    rt.submit(exec_pb2.Command(tape=exec_pb2.TapeCommand(
        op=exec_pb2.TapeCommand.BACKWARD, tape_id=tape.tape_id)))
    with pytest.raises(WeftError) as info:
        wp.synchronize()
    assert info.value.code == "FAILED_PRECONDITION", str(info.value)
    assert "recorded nothing" in str(info.value) or "no launches" in str(info.value)
    np.testing.assert_array_equal(loss.grad.numpy(), np.zeros(1, dtype=np.float32))
    # the same tape records and differentiates normally afterwards
    n = 33
    xs = rng.standard_normal(n).astype(np.float32)
    x = wp.array(xs, dtype=float, requires_grad=True)
    loss2, _ = _record(tape, x, 1.5)
    tape.backward(loss=loss2)
    np.testing.assert_allclose(x.grad.numpy(), 3.0 * xs.astype(np.float64), rtol=1e-5,
                               atol=1e-6)


@wp.kernel
def read_far(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i + 1000]


def test_a_failed_launch_inside_a_tape_still_ends_the_recording(wp, rng, device):
    """A launch that fails inside `with tape:` (an out-of-bounds read) is reported at the next
    synchronize; leaving the block still stops the recording in weftd, so a later tape records
    and its backward gives the analytic gradient (as in Warp, whose tape ends in __exit__)."""
    n = 16
    xs = rng.uniform(0.5, 2.0, n).astype(np.float32)
    x = wp.array(xs, requires_grad=True, device=device)
    y = wp.zeros(n, requires_grad=True, device=device)
    broken = wp.Tape()
    with pytest.raises(WeftError, match="out of bounds|index"):
        with broken:
            wp.launch(read_far, dim=n, inputs=[x, y], device=device)
        wp.synchronize()
    tape = wp.Tape()
    with tape:
        wp.launch(square_scaled, dim=n, inputs=[x, 3.0, y], device=device)
    tape.backward(grads={y: wp.ones(n, device=device)})
    np.testing.assert_allclose(x.grad.numpy(), 6.0 * xs.astype(np.float64), rtol=1e-6)
