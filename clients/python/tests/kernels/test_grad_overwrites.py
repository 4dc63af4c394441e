"""An overwritten value gets no gradient (Warp's adj_array_store): reversing `a[i] = v`
moves a's gradient into v and clears it when the gradient array is a's own .grad (a tape's
backward, or an explicit adjoint launch given a.grad), so a dead write and a copy over a
kernel's output pass nothing back; gradients given as separate adj_inputs buffers, and arrays
with retain_grad=True, keep theirs. Also daemon tapes' record_func callbacks (run between the
adjoints) and tape.gradients of a struct. Checked against float64 references from fresh random
data."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def scale(x: wp.array(dtype=float), y: wp.array(dtype=float), s: float):
    i = wp.tid()
    y[i] = x[i] * s


@wp.kernel
def weighted_sum(x: wp.array(dtype=float), w: wp.array(dtype=float), loss: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(loss, 0, x[i] * w[i])


def _data(rng, n):
    return rng.uniform(-2, 2, n).astype(np.float32)


def test_a_copy_over_a_kernel_output_passes_nothing_to_the_dead_write(rng):
    n = 64
    x = wp.array(_data(rng, n), requires_grad=True)
    s = wp.array(_data(rng, n), requires_grad=True)
    w_np = _data(rng, n)
    w = wp.array(w_np)
    y = wp.zeros(n, requires_grad=True)
    loss = wp.zeros(1, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(scale, n, inputs=[x, y, 3.0])        # dead: overwritten by the copy
        wp.copy(y, s)
        wp.launch(weighted_sum, n, inputs=[y, w, loss])
    tape.backward(loss)
    np.testing.assert_allclose(s.grad.numpy(), w_np, rtol=1e-6)
    np.testing.assert_array_equal(x.grad.numpy(), 0.0)
    np.testing.assert_array_equal(y.grad.numpy(), 0.0)  # consumed by the copy's adjoint


def test_a_chain_of_clones_overwritten_by_kernels(rng):
    n = 32
    x_np = _data(rng, n)
    w_np = _data(rng, n)
    x = wp.array(x_np, requires_grad=True)
    w = wp.array(w_np)
    loss = wp.zeros(1, requires_grad=True)
    scales = rng.uniform(0.5, 1.5, 3)
    tape = wp.Tape()
    with tape:
        q = x
        for s in scales:
            out = wp.clone(q)                             # overwritten at once: dead
            wp.launch(scale, n, inputs=[q, out, float(s)])
            q = out
        wp.launch(weighted_sum, n, inputs=[q, w, loss])
    tape.backward(loss)
    expected = w_np.astype(np.float64) * np.prod(np.float32(scales).astype(np.float64))
    np.testing.assert_allclose(x.grad.numpy(), expected, rtol=1e-5)


def test_a_kernel_overwriting_its_own_input_element(rng):
    """y = 2x, then y = y * 3 in place: d(sum w*y)/dx = 6 w (the first y's gradient is moved
    through the in-place store, not counted twice)."""
    n = 48
    x_np = _data(rng, n)
    w_np = _data(rng, n)
    x = wp.array(x_np, requires_grad=True)
    w = wp.array(w_np)
    y = wp.zeros(n, requires_grad=True)
    loss = wp.zeros(1, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(scale, n, inputs=[x, y, 2.0])
        wp.launch(scale, n, inputs=[y, y, 3.0])
        wp.launch(weighted_sum, n, inputs=[y, w, loss])
    tape.backward(loss)
    np.testing.assert_allclose(x.grad.numpy(), 6.0 * w_np.astype(np.float64), rtol=1e-6)


def test_separate_adjoint_buffers_are_not_consumed(rng):
    n = 40
    x = wp.array(_data(rng, n), requires_grad=True)
    y = wp.zeros(n, requires_grad=True)
    adj_y_np = _data(rng, n)
    adj_x = wp.zeros(n)
    adj_y = wp.array(adj_y_np)                          # not y.grad: the caller's buffer
    wp.launch(scale, n, inputs=[x, y, 5.0], adj_inputs=[adj_x, adj_y, 0.0], adjoint=True)
    np.testing.assert_allclose(adj_x.numpy(), 5.0 * adj_y_np.astype(np.float64), rtol=1e-6)
    np.testing.assert_array_equal(adj_y.numpy(), adj_y_np)
    # given the arrays' own gradients, the store's adjoint consumes y.grad
    y.grad.assign(adj_y_np)
    wp.launch(scale, n, inputs=[x, y, 5.0], adj_inputs=[x.grad, y.grad, 0.0], adjoint=True)
    np.testing.assert_allclose(x.grad.numpy(), 5.0 * adj_y_np.astype(np.float64), rtol=1e-6)
    np.testing.assert_array_equal(y.grad.numpy(), 0.0)


@wp.kernel
def square(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * x[i]


def test_record_func_runs_between_the_daemon_tapes_adjoints(rng):
    """wp.Tape.record_func on a daemon tape: the callback runs at its place in the reverse pass
    (after the adjoints of later launches, before those of earlier ones)."""
    n = 32
    x_np = _data(rng, n)
    w_np = _data(rng, n)
    x = wp.array(x_np, requires_grad=True)
    w = wp.array(w_np)
    y = wp.zeros(n, requires_grad=True)
    z = wp.zeros(n, requires_grad=True)
    loss = wp.zeros(1, requires_grad=True)
    tape = wp.Tape()
    calls = []

    def square_backward():
        calls.append(float(z.grad.numpy()[0]))     # the later launch's adjoint ran already
        wp.launch(square, n, inputs=[y, z], adj_inputs=[y.grad, z.grad], adj_outputs=[],
                  adjoint=True)

    with tape:
        wp.launch(scale, n, inputs=[x, y, 2.0])
        wp.launch(square, n, inputs=[y, z], record_tape=False)
        tape.record_func(square_backward, arrays=[y, z])
        wp.launch(weighted_sum, n, inputs=[z, w, loss])
    assert tape.mode == "daemon"
    tape.backward(loss)
    assert calls == [pytest.approx(float(w_np[0]))]
    expected = 8.0 * x_np.astype(np.float64) * w_np      # d/dx sum(w (2x)^2)
    np.testing.assert_allclose(x.grad.numpy(), expected, rtol=1e-5, atol=1e-6)


@wp.struct
class Pair:
    x: wp.array(dtype=float)
    y: wp.array(dtype=float)


@wp.kernel
def pair_dot(p: Pair, out: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(out, 0, p.x[i] * p.y[i])


def test_tape_gradients_of_a_struct_are_a_struct_of_gradients(rng):
    n = 16
    x_np, y_np = _data(rng, n), _data(rng, n)
    p = Pair()
    p.x = wp.array(x_np, requires_grad=True)
    p.y = wp.array(y_np, requires_grad=True)
    out = wp.zeros(1, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(pair_dot, n, inputs=[p, out])
    tape.backward(out)
    grads = tape.gradients[p]
    assert grads._struct_type is p._struct_type
    np.testing.assert_allclose(grads.x.numpy(), y_np, rtol=1e-6)
    np.testing.assert_allclose(grads.y.numpy(), x_np, rtol=1e-6)
    tape.zero()
    np.testing.assert_array_equal(grads.x.numpy(), 0.0)


def test_retain_grad_keeps_an_overwritten_arrays_gradient(rng):
    """retain_grad=True (Warp's): the gradient of the array stays through the store's adjoint
    (and the dead write upstream then receives it); it needs requires_grad."""
    n = 24
    x_np, w_np = _data(rng, n), _data(rng, n)
    x = wp.array(x_np, requires_grad=True)
    w = wp.array(w_np)
    y = wp.zeros(n, requires_grad=True, retain_grad=True)
    assert y.retain_grad and y[2:5].retain_grad
    loss = wp.zeros(1, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(scale, n, inputs=[x, y, 3.0])
        wp.launch(weighted_sum, n, inputs=[y, w, loss])
    tape.backward(loss)
    np.testing.assert_allclose(y.grad.numpy(), w_np, rtol=1e-6)         # kept
    np.testing.assert_allclose(x.grad.numpy(), 3.0 * w_np.astype(np.float64), rtol=1e-6)
    with pytest.raises(ValueError, match="requires_grad"):
        wp.zeros(3, retain_grad=True)
    y.requires_grad = False
    assert not y.retain_grad


def test_tape_visualize_shows_scopes_and_repeated_launches(rng, tmp_path):
    n = 8
    x = wp.array(_data(rng, n), requires_grad=True)
    w = wp.array(_data(rng, n))
    loss = wp.zeros(1, requires_grad=True)
    tape = wp.Tape()
    with tape:
        tape.record_scope_begin("my loop")
        for _ in range(5):
            wp.launch(weighted_sum, n, inputs=[x, w, loss])
        tape.record_scope_end()
        wp.launch(scale, n, inputs=[x, x, 1.0])
    path = tmp_path / "tape.dot"
    text = tape.visualize(str(path), array_labels={x: "positions"})
    assert path.read_text() == text
    assert text.startswith("digraph") and "repeated 5x" in text and "my loop" in text
    assert text.count("weighted_sum") == 1 and "scale" in text and "positions" in text
    assert "cluster" in text and "array: dtype=float32" in text
    assert "repeated" not in tape.visualize(simplify_graph=False)
