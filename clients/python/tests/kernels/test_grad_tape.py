"""Autodiff API: wp.Tape recording, backward(loss=l) and backward(grads={a: g}), zero(),
reset(), gradients[a]; requires_grad arrays' .grad; wp.launch(adjoint=True) without a tape;
a backward on an empty tape is a clear error; Warp's documentation examples unchanged but
for the import: the 2D points loss optimized for 500 steps and the Rosenbrock adjoint."""
import numpy as np
import pytest

import weft as wp


# --- Warp docs: a loss over 2D points, optimized with tape.zero()/tape.backward(loss=l) ---
@wp.kernel
def loss_kernel(xs: wp.array(dtype=float, ndim=2), l: wp.array(dtype=float)):
    tid = wp.tid()
    wp.atomic_add(l, 0, xs[tid, 0] ** 2.0 + xs[tid, 1] ** 2.0)


@wp.kernel
def gradient_step(xs: wp.array(dtype=float, ndim=2), grad: wp.array(dtype=float, ndim=2),
                  alpha: float):
    i, j = wp.tid()
    xs[i, j] = xs[i, j] - alpha * grad[i, j]


# --- Warp docs: Rosenbrock, used with an adjoint launch --------------------------------------
@wp.kernel
def eval_rosenbrock(
    xs: wp.array(dtype=wp.vec2),
    # outputs
    z: wp.array(dtype=float),
):
    i = wp.tid()
    x = xs[i]
    a = 1.0
    b = 100.0
    z[i] = (a - x[0]) ** 2.0 + b * (x[1] - x[0] ** 2.0) ** 2.0


@wp.kernel
def scale_by(x: wp.array(dtype=float), s: float, y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * s


def test_points_loss_descends_to_zero(wp, rng):
    n = 100
    xs = wp.array(rng.uniform(-1, 1, (n, 2)).astype(np.float32), dtype=float, requires_grad=True)
    l = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(loss_kernel, dim=len(xs), inputs=[xs, l])
    first = l.numpy()[0]
    np.testing.assert_allclose(first, (xs.numpy().astype(np.float64) ** 2).sum(), rtol=1e-5)
    for _ in range(500):
        tape.zero()
        tape.backward(loss=l)
        wp.launch(gradient_step, dim=(n, 2), inputs=[xs, xs.grad, 0.01])
    final = (xs.numpy().astype(np.float64) ** 2).sum()
    assert final < first * 1e-6, (first, final)          # (1 - 2*0.01)^1000 ~ 1.7e-9
    assert np.all(tape.gradients[xs].numpy() == xs.grad.numpy())


def test_points_loss_with_torch_adam(wp, rng):
    torch = pytest.importorskip("torch")
    n = 50
    xs = wp.array(rng.uniform(-1, 1, (n, 2)).astype(np.float32), dtype=float, requires_grad=True)
    l = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(loss_kernel, dim=n, inputs=[xs, l])
    params = torch.tensor(xs.numpy(), requires_grad=True)
    opt = torch.optim.Adam([params], lr=0.02)
    for _ in range(500):
        tape.zero()
        tape.backward(loss=l)
        params.grad = torch.from_numpy(xs.grad.numpy().copy())
        opt.step()
        xs.assign(params.detach().numpy())
    assert (params.detach().numpy() ** 2).sum() < 1e-2


def _assert_close_scaled(actual, expected, rtol, atol):
    # assert_allclose with a per-element absolute tolerance
    err = np.abs(actual.astype(np.float64) - expected)
    bound = atol + rtol * np.abs(expected)
    worst = np.argmax(err - bound)
    assert np.all(err <= bound), f"element {worst}: |{actual.flat[worst]} - {expected.flat[worst]}| > {bound.flat[worst]}"


def test_rosenbrock_adjoint_launch(wp, rng):
    n = 64
    xy_np = rng.uniform(-2, 2, (n, 2)).astype(np.float32)
    xy = wp.array(xy_np, dtype=wp.vec2, requires_grad=True)
    z = wp.zeros(n, dtype=float, requires_grad=True)
    wp.launch(eval_rosenbrock, dim=n, inputs=[xy], outputs=[z])
    z.grad.fill_(1.0)
    wp.launch(kernel=eval_rosenbrock, dim=n, inputs=[xy], outputs=[z], adj_inputs=[xy.grad],
              adj_outputs=[z.grad], adjoint=True)
    x, y = xy_np[:, 0].astype(np.float64), xy_np[:, 1].astype(np.float64)
    # float32 rounding of y - x*x cancels: the tolerance scales with the magnitude of the terms
    # that cancel (8 float32 ulps of them), not with the (possibly tiny) result.
    eps = 8 * np.finfo(np.float32).eps
    scale_z = (1 - x) ** 2 + 100 * (np.abs(y) + x * x) ** 2
    _assert_close_scaled(z.numpy(), (1 - x) ** 2 + 100 * (y - x * x) ** 2, 1e-5, eps * scale_z)
    dx = -2 * (1 - x) - 400 * x * (y - x * x)
    dy = 200 * (y - x * x)
    scale_dx = 2 * np.abs(1 - x) + 400 * np.abs(x) * (np.abs(y) + x * x)
    scale_dy = 200 * (np.abs(y) + x * x)
    _assert_close_scaled(xy.grad.numpy(), np.stack([dx, dy], 1), 1e-4, eps * np.stack([scale_dx, scale_dy], 1))


def test_backward_with_grads_zero_and_reset(wp, rng):
    x_np = rng.standard_normal(32).astype(np.float32)
    x = wp.array(x_np, dtype=float, requires_grad=True)
    y = wp.zeros(32, dtype=float, requires_grad=True)
    assert x.grad is not None and x.grad.shape == x.shape
    np.testing.assert_array_equal(x.grad.numpy(), 0.0)
    tape = wp.Tape()
    with tape:
        wp.launch(scale_by, dim=32, inputs=[x, 3.0], outputs=[y])
    seed = rng.standard_normal(32).astype(np.float32)
    tape.backward(grads={y: wp.array(seed)})
    np.testing.assert_allclose(tape.gradients[x].numpy(), 3.0 * seed, rtol=1e-6)
    tape.backward(grads={y: wp.array(seed)})            # gradients accumulate
    np.testing.assert_allclose(x.grad.numpy(), 6.0 * seed, rtol=1e-6)
    tape.zero()
    np.testing.assert_array_equal(x.grad.numpy(), 0.0)
    tape.reset()
    with pytest.raises(RuntimeError, match="empty"):
        tape.backward(grads={y: wp.array(seed)})


def test_empty_tape_is_a_clear_error(wp):
    tape = wp.Tape()
    l = wp.zeros(1, dtype=float, requires_grad=True)
    with pytest.raises(RuntimeError, match="empty"):
        tape.backward(loss=l)


def test_loss_without_grad_is_a_clear_error(wp):
    x = wp.zeros(4, dtype=float, requires_grad=True)
    y = wp.zeros(4, dtype=float)
    tape = wp.Tape()
    with tape:
        wp.launch(scale_by, dim=4, inputs=[x, 2.0], outputs=[y])
    with pytest.raises(RuntimeError, match="requires_grad"):
        tape.backward(loss=y)
