"""Operators on structs call the user's @wp.func of the operator's builtin name (Warp's operator
overloading: `a + b` is `add(a, b)`, `a * s` is `mul(a, s)`), found in the kernel's module scope
even though the kernel never names it; comparisons of two different types fail with Warp's
message. Results are checked against Python complex arithmetic on random values."""
import numpy as np
import pytest

import weft as wp


@wp.struct
class Cplx:
    re: float
    im: float


@wp.func
def add(a: Cplx, b: Cplx) -> Cplx:
    return Cplx(a.re + b.re, a.im + b.im)


@wp.func
def sub(a: Cplx, b: Cplx) -> Cplx:
    return Cplx(a.re - b.re, a.im - b.im)


@wp.func
def mul(a: Cplx, b: Cplx) -> Cplx:
    return Cplx(a.re * b.re - a.im * b.im, a.re * b.im + a.im * b.re)


@wp.func
def mul(a: Cplx, s: float) -> Cplx:  # noqa: F811 - a second overload of mul
    return Cplx(a.re * s, a.im * s)


@wp.kernel
def complex_ops(x: wp.array(dtype=wp.vec2), y: wp.array(dtype=wp.vec2), s: float,
                out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    a = Cplx(x[i][0], x[i][1])
    b = Cplx(y[i][0], y[i][1])
    c = (a * b + a - b) * s      # mul(add(...)...) through four user overloads
    f = 2.0 * s + 1.0            # plain floats still use the builtins
    out[i] = wp.vec2(c.re + f - f, c.im)


def test_struct_operators_call_user_funcs(rng):
    n = 64
    x = rng.uniform(-3, 3, size=(n, 2)).astype(np.float32)
    y = rng.uniform(-3, 3, size=(n, 2)).astype(np.float32)
    out = wp.zeros(n, dtype=wp.vec2)
    wp.launch(complex_ops, dim=n, inputs=[wp.array(x, dtype=wp.vec2), wp.array(y, dtype=wp.vec2), 0.5, out])
    a = x[:, 0].astype(np.float64) + 1j * x[:, 1]
    b = y[:, 0].astype(np.float64) + 1j * y[:, 1]
    ref = (a * b + a - b) * 0.5
    got = out.numpy()
    np.testing.assert_allclose(got[:, 0] + 1j * got[:, 1], ref, rtol=1e-5, atol=1e-5)


def test_struct_operator_without_user_func(kernel_module):
    m = kernel_module('''
        @wp.struct
        class P:
            v: float

        @wp.kernel
        def k(out: wp.array(dtype=float)):
            a = P(1.0)
            b = a / a
            out[0] = b.v
    ''')
    with pytest.raises(Exception, match=r"Couldn't find function overload for 'div'"):
        wp.launch(m.k, dim=1, inputs=[wp.zeros(1)])


def test_equality_of_different_types_is_refused(kernel_module):
    m = kernel_module('''
        @wp.kernel
        def k():
            wp.expect_neq(wp.vec3f(0.0, 0.0, 0.0), wp.vec2f(0.0, 0.0))
    ''')
    with pytest.raises(RuntimeError, match=r"Can't test equality for objects with different types$"):
        wp.launch(m.k, dim=1, inputs=[])
