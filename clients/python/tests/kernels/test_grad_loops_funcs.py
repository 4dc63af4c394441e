"""Autodiff through control flow: for/while loops whose carried values are overwritten
(products p = p * x, nonlinear recurrences), dynamic trip counts, branches, and nested
@wp.func calls with multiple return values; tape gradients against float64 central finite
differences (Warp's own adjoints are wrong for overwritten loop values; weft's must not be)."""
import numpy as np

import weft as wp


@wp.kernel
def product_loop(x: wp.array(dtype=wp.float64), n: int, y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    p = wp.float64(1.0)
    for k in range(n):
        p = p * x[i]
    y[i] = p


@wp.kernel
def recurrence(x: wp.array(dtype=wp.float64), n: int, y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    s = x[i]
    for k in range(n):
        s = wp.sin(s) * x[i] + s * wp.float64(0.5)
    y[i] = s


@wp.kernel
def while_recurrence(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    s = x[i]
    k = int(0)
    while k < 6:
        s = s * s * wp.float64(0.5) + x[i]
        k += 1
    y[i] = s


@wp.kernel
def branchy(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    v = x[i]
    if v > wp.float64(0.0):
        v = wp.exp(v) * v
    else:
        v = v * v * v
    y[i] = v


@wp.func
def inner(a: wp.float64, b: wp.float64):
    return a * b, a + wp.sin(b)


@wp.func
def middle(a: wp.float64):
    p, q = inner(a, a * wp.float64(2.0))
    return p * q


@wp.kernel
def nested_funcs(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] = middle(x[i]) + middle(wp.cos(x[i]))


def _forward(wp, kernel, x, extra):
    y = wp.zeros(len(x), dtype=wp.float64)
    wp.launch(kernel, dim=len(x), inputs=[wp.array(x, dtype=wp.float64)] + extra, outputs=[y])
    return y.numpy()


def _check(wp, kernel, x, extra=(), rtol=1e-6):
    extra = list(extra)
    xa = wp.array(x, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(len(x), dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(kernel, dim=len(x), inputs=[xa] + extra, outputs=[y])
    tape.backward(grads={y: np.ones(len(x))})
    got = xa.grad.numpy()
    h = 1e-7 * np.maximum(np.abs(x), 1e-2)
    ref = (_forward(wp, kernel, x + h, extra) - _forward(wp, kernel, x - h, extra)) / (2 * h)
    worst = np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1.0))
    print(f"\ngradcheck {kernel.key}: worst relative error {worst:.2e}")
    np.testing.assert_allclose(got, ref, rtol=rtol, atol=rtol)
    return got


def test_product_loop_overwritten_value(wp, rng):
    x = rng.uniform(-1.5, 1.5, 200)
    n = 7
    got = _check(wp, product_loop, x, [n])
    np.testing.assert_allclose(got, n * x ** (n - 1), rtol=1e-12)   # analytic


def test_nonlinear_recurrence(wp, rng):
    _check(wp, recurrence, rng.uniform(-2, 2, 200), [10], rtol=1e-5)


def test_while_recurrence(wp, rng):
    _check(wp, while_recurrence, rng.uniform(-0.8, 0.8, 200), rtol=1e-5)


def test_branches(wp, rng):
    _check(wp, branchy, rng.uniform(-3, 3, 200))


def test_nested_funcs_with_multiple_returns(wp, rng):
    _check(wp, nested_funcs, rng.uniform(-2, 2, 200))
