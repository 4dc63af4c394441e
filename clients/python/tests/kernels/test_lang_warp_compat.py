"""Warp-compatibility features of the kernel language: augmented assignment to array elements
(`y[i] += x[i]`, atomic as in Warp) in 1-D to 4-D arrays of scalars and vectors, with values
that create temporaries; against NumPy float64 references on fresh random data, gradients
against float64 central finite differences."""
import numpy as np

import weft as wp


@wp.kernel
def add_1d(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] += x[i]


@wp.kernel
def sub_scaled_1d(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] -= wp.sin(x[i]) * x[i] + 2.0


@wp.kernel
def add_2d(a: wp.array2d(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    i, j = wp.tid()
    out[i, j] += a[i, j] * a[j, i]


@wp.kernel
def add_vec(v: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] += wp.cross(v[i], wp.vec3(1.0, 2.0, 3.0))


@wp.kernel
def histogram(keys: wp.array(dtype=int), counts: wp.array(dtype=int)):
    i = wp.tid()
    counts[keys[i] % 7] += 1


@wp.kernel
def square_accumulate(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] += x[i] * x[i] * wp.exp(x[i])


def test_augmented_array_assign_1d(wp, rng):
    n = 1000
    x = rng.standard_normal(n).astype(np.float32)
    y0 = rng.standard_normal(n).astype(np.float32)
    y = wp.array(y0)
    wp.launch(add_1d, dim=n, inputs=[wp.array(x), y])
    np.testing.assert_allclose(y.numpy(), y0.astype(np.float64) + x, rtol=1e-6, atol=1e-6)
    y = wp.array(y0)
    wp.launch(sub_scaled_1d, dim=n, inputs=[wp.array(x), y])
    x64 = x.astype(np.float64)
    np.testing.assert_allclose(y.numpy(), y0 - (np.sin(x64) * x64 + 2.0), rtol=1e-5, atol=1e-5)


def test_augmented_array_assign_2d_and_vectors(wp, rng):
    n = 17
    a = rng.standard_normal((n, n))
    out0 = rng.standard_normal((n, n))
    out = wp.array(out0, dtype=wp.float64)
    wp.launch(add_2d, dim=(n, n), inputs=[wp.array(a, dtype=wp.float64), out])
    np.testing.assert_allclose(out.numpy(), out0 + a * a.T, rtol=1e-12)

    m = 300
    v = rng.standard_normal((m, 3)).astype(np.float32)
    o0 = rng.standard_normal((m, 3)).astype(np.float32)
    o = wp.array(o0, dtype=wp.vec3)
    wp.launch(add_vec, dim=m, inputs=[wp.array(v, dtype=wp.vec3), o])
    ref = o0.astype(np.float64) + np.cross(v.astype(np.float64), np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(o.numpy(), ref, rtol=1e-5, atol=1e-5)


def test_augmented_array_assign_is_atomic(wp, rng):
    keys = rng.integers(0, 1 << 20, size=20000).astype(np.int32)
    counts = wp.zeros(7, dtype=int)
    wp.launch(histogram, dim=len(keys), inputs=[wp.array(keys, dtype=int), counts])
    np.testing.assert_array_equal(counts.numpy(), np.bincount(keys % 7, minlength=7))


def test_augmented_array_assign_gradient(wp, rng):
    n = 64
    x = rng.uniform(-1.5, 1.5, n)
    xa = wp.array(x, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square_accumulate, dim=n, inputs=[xa, y])
    tape.backward(grads={y: np.ones(n)})
    h = 1e-6

    def f(z):
        return z * z * np.exp(z)

    fd = (f(x + h) - f(x - h)) / (2 * h)
    np.testing.assert_allclose(xa.grad.numpy(), fd, rtol=1e-6, atol=1e-8)
