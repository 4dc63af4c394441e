"""Tuples as values: a name bound to a tuple (literal, a builtin's or func's multiple results),
len() and wp.static(len(t)) as constants, constant and run-time indices, unpacking, tuples
passed to a func's tuple[...] / tuple[T, ...] / Any parameter and returned as tuple[...];
NumPy float64 references on random data. Errors: a run-time index into a tuple of mixed types,
a tuple parameter of other element types."""
from typing import Any

import numpy as np
import pytest

import weft as wp


@wp.func
def weighted(values: tuple[wp.vec3d, wp.float64]) -> wp.float64:
    return wp.length(values[0]) * values[1]


@wp.func
def total(values: tuple[wp.float64, ...]):
    out = wp.float64(0.0)
    for i in range(wp.static(len(values))):
        out += values[i] * wp.float64(i + 1)
    return out


@wp.func
def total_any(values: Any):
    out = wp.float64(0.0)
    for i in range(len(values)):
        out += values[i]
    return out


@wp.func
def split(x: wp.float64) -> tuple[wp.float64, wp.vec3d]:
    return (x * wp.float64(2.0), wp.vec3d(x, x + wp.float64(1.0), x * x))


@wp.kernel
def tuple_kernel(x: wp.array(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    i = wp.tid()
    a = x[i]
    t = (wp.vec3d(a, a * wp.float64(2.0), wp.float64(3.0)), a * a, i)
    out[i, 0] = weighted((t[0], t[1]))
    out[i, 1] = wp.float64(len(t) + wp.static(len(t)))
    v, s, k = t
    out[i, 2] = v[1] + s + wp.float64(k)
    out[i, 3] = total((a, a * a, wp.float64(1.0)))
    out[i, 4] = total_any((a, wp.float64(2.0)))
    r = split(a)
    h, w = r
    out[i, 5] = r[0] + h + w[2]
    q = (a, a + wp.float64(1.0), a + wp.float64(2.0))
    j = i % 3
    out[i, 6] = q[j]


def test_tuples(wp, rng):
    n = 9
    x = rng.standard_normal(n)
    out = wp.zeros((n, 7), dtype=wp.float64)
    wp.launch(tuple_kernel, dim=n, inputs=[wp.array(x, dtype=wp.float64), out])
    i = np.arange(n)
    length = np.sqrt(x * x + 4.0 * x * x + 9.0)
    expect = np.stack([
        length * x * x,
        np.full(n, 6.0),
        2.0 * x + x * x + i,
        x + 2.0 * x * x + 3.0,
        x + 2.0,
        2.0 * x + 2.0 * x + x * x,
        x + (i % 3),
    ], axis=1)
    np.testing.assert_allclose(out.numpy(), expect, rtol=1e-13)


def test_runtime_index_needs_one_type(kernel_module):
    mod = kernel_module('''
import weft as wp

@wp.kernel
def k(out: wp.array(dtype=float)):
    i = wp.tid()
    t = (1.0, 2)
    out[i] = float(t[i])
''')
    with pytest.raises(wp.WarpCodegenError, match="elements of one type"):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float)])


def test_tuple_parameter_types_must_match(kernel_module):
    mod = kernel_module('''
import weft as wp

@wp.func
def f(v: tuple[int, float]) -> float:
    return float(v[0]) + v[1]

@wp.kernel
def k(out: wp.array(dtype=float)):
    out[0] = f((1.0, 2.0))
''')
    with pytest.raises(wp.WarpCodegenError):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float)])


def test_tuple_bound_in_a_branch_is_not_used_after_it(kernel_module):
    mod = kernel_module('''
import weft as wp

@wp.kernel
def k(out: wp.array(dtype=float), c: int):
    t = (1.0, 2.0)
    if c > 0:
        t = (3.0, 4.0)
    out[0] = t[0]
''')
    with pytest.raises(wp.WarpCodegenError, match="depends on the path taken"):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float), 1])


@wp.kernel
def tuple_in_loop(out: wp.array(dtype=float)):
    acc = float(0.0)
    for i in range(3):
        t = (float(i), float(i) * 2.0)
        acc += t[0] + t[1]
    out[0] = acc


def test_tuple_bound_inside_a_loop(wp):
    out = wp.zeros(1, dtype=float)
    wp.launch(tuple_in_loop, dim=1, inputs=[out])
    assert out.numpy()[0] == 9.0
