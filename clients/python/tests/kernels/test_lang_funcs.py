"""Language: @wp.func calls (nested), return from funcs including early returns and multiple
values, overloads by annotation types, generic funcs over typing.Any instantiated per argument
type, funcs taking and returning vectors and arrays."""
from typing import Any

import numpy as np

import weft as wp


@wp.func
def square(x: float):
    return x * x


@wp.func
def sum_of_squares(x: float, y: float):
    return square(x) + square(y)          # nested call


@wp.func
def clamp_early(x: float, lo: float, hi: float):
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@wp.func
def min_max_sum(a: wp.vec3):
    lo = wp.min(wp.min(a[0], a[1]), a[2])
    hi = wp.max(wp.max(a[0], a[1]), a[2])
    return lo, hi, a[0] + a[1] + a[2]


@wp.func
def kind(x: float):
    return 1.0


@wp.func
def kind(x: int):  # noqa: F811 - overload by annotation type
    return 2.0


@wp.func
def kind(x: wp.vec3):  # noqa: F811
    return 3.0


@wp.func
def twice(x: Any):
    return x + x


@wp.func
def read_at(arr: wp.array(dtype=float), i: int):
    return arr[i] * 2.0


@wp.kernel
def funcs_kernel(a: wp.array(dtype=float), b: wp.array(dtype=float), out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i, 0] = sum_of_squares(x, y)
    out[i, 1] = clamp_early(x, -0.5, 0.5)
    lo, hi, s = min_max_sum(wp.vec3(x, y, x * y))
    out[i, 2] = lo
    out[i, 3] = hi
    out[i, 4] = s
    out[i, 5] = kind(x) + kind(i) * 10.0 + kind(wp.vec3(x, y, 0.0)) * 100.0
    v = twice(wp.vec3(x, y, 1.0))
    out[i, 6] = twice(x) + float(twice(i)) + v[2]
    out[i, 7] = read_at(a, i)
    d = twice(wp.float64(x))
    out[i, 8] = float(d)


def test_funcs(wp, rng):
    n = 777
    a = rng.standard_normal(n).astype(np.float32)
    b = rng.standard_normal(n).astype(np.float32)
    out = wp.zeros((n, 9), dtype=float)
    wp.launch(funcs_kernel, dim=n, inputs=[wp.array(a), wp.array(b)], outputs=[out])
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    c = a64 * b64
    idx = np.arange(n)
    ref = np.stack([a64 * a64 + b64 * b64, np.clip(a64, -0.5, 0.5),
                    np.minimum(np.minimum(a64, b64), c), np.maximum(np.maximum(a64, b64), c),
                    a64 + b64 + c, np.full(n, 321.0), 2 * a64 + 2 * idx + 2.0, 2 * a64,
                    2 * a64], axis=1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=2e-6, atol=1e-6)
