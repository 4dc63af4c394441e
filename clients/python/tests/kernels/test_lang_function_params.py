"""@wp.func values as parameters (g: wp.Function): user funcs and builtins passed by name, by
keyword, as a default, through a local alias and through another func; each target compiles its
own instantiation. NumPy float64 references on random data. Errors: a value passed for a
wp.Function parameter, a function passed for a value parameter."""
import numpy as np
import pytest

import weft as wp


@wp.func
def double_it(x: wp.float64):
    return x * wp.float64(2.0)


@wp.func
def cube_it(x: wp.float64):
    return x * x * x


@wp.func
def apply(g: wp.Function, x: wp.float64):
    return g(x)


@wp.func
def apply2(g: wp.Function, x: wp.float64, y: wp.float64):
    return g(x, y)


@wp.func
def apply_default(x: wp.float64, g: wp.Function = cube_it):
    return g(x)


@wp.func
def apply_twice(g: wp.Function, x: wp.float64):
    h = g
    return apply(h, apply(g, x))


@wp.kernel
def function_param_kernel(x: wp.array(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    i = wp.tid()
    a = x[i]
    out[i, 0] = apply(double_it, a)
    out[i, 1] = apply(cube_it, a)
    out[i, 2] = apply(g=wp.sin, x=a)
    out[i, 3] = apply2(wp.max, a, wp.float64(0.25))
    out[i, 4] = apply_default(a)
    f = double_it
    out[i, 5] = apply_twice(f, a)


def test_function_parameters(wp, rng):
    n = 11
    x = rng.standard_normal(n)
    out = wp.zeros((n, 6), dtype=wp.float64)
    wp.launch(function_param_kernel, dim=n, inputs=[wp.array(x, dtype=wp.float64), out])
    expect = np.stack([2.0 * x, x ** 3, np.sin(x), np.maximum(x, 0.25), x ** 3, 4.0 * x], axis=1)
    np.testing.assert_allclose(out.numpy(), expect, rtol=1e-14)


def test_value_for_function_parameter(kernel_module):
    mod = kernel_module('''
import weft as wp

@wp.func
def apply(g: wp.Function, x: float):
    return g(x)

@wp.kernel
def k(out: wp.array(dtype=float)):
    out[0] = apply(1.0, 2.0)
''')
    with pytest.raises(wp.WarpCodegenError):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float)])


def test_function_for_value_parameter(kernel_module):
    mod = kernel_module('''
import weft as wp

@wp.func
def twice(x: float):
    return x * 2.0

@wp.func
def plain(x: float, y: float):
    return x + y

@wp.kernel
def k(out: wp.array(dtype=float)):
    out[0] = plain(twice, 2.0)
''')
    with pytest.raises(wp.WarpCodegenError):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float)])


TARGET = wp.max      # a global bound to a builtin


@wp.kernel
def global_target_kernel(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = apply2(TARGET, x[i], wp.float64(0.5))


def test_global_bound_to_builtin(wp, rng):
    x = rng.standard_normal(13)
    out = wp.zeros(13, dtype=wp.float64)
    wp.launch(global_target_kernel, dim=13, inputs=[wp.array(x, dtype=wp.float64), out])
    np.testing.assert_array_equal(out.numpy(), np.maximum(x, 0.5))


def test_builtins_callable_from_python():
    import math

    assert wp.sin(0.5) == pytest.approx(math.sin(0.5), rel=1e-15)
    assert wp.max(2.0, 3.5) == 3.5
    with pytest.raises(RuntimeError, match="inside a kernel"):
        wp.length(1.0)


def test_vector_builtins_callable_from_python(rng):
    # float64 references on random vectors; the result keeps the argument's vector type (Warp).
    for vt, tol in ((wp.vec3, 1e-6), (wp.vec3d, 1e-14), (wp.vec4, 1e-6)):
        a64 = rng.standard_normal(len(vt())) * 10.0 ** rng.uniform(-3, 3)
        b64 = rng.standard_normal(len(vt()))
        a, b = vt(*a64), vt(*b64)
        a64, b64 = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        assert wp.length(a) == pytest.approx(np.linalg.norm(a64), rel=1e-15)
        assert wp.length_sq(a) == pytest.approx(a64 @ a64, rel=1e-15)
        assert wp.dot(a, b) == pytest.approx(a64 @ b64, rel=1e-14, abs=1e-14)
        n = wp.normalize(a)
        assert type(n) is vt
        np.testing.assert_allclose(np.asarray(n, dtype=np.float64), a64 / np.linalg.norm(a64), rtol=tol)
        if len(a64) == 3:
            c = wp.cross(a, b)
            assert type(c) is vt
            np.testing.assert_allclose(np.asarray(c, dtype=np.float64), np.cross(a64, b64),
                                       rtol=tol, atol=tol * np.abs(a64).max() * np.abs(b64).max())
    assert list(wp.normalize(wp.vec3(0.0, 0.0, 0.0))) == [0.0, 0.0, 0.0]   # zero stays zero
    with pytest.raises(RuntimeError, match="vec3 for cross"):
        wp.cross(wp.vec2(1.0, 2.0), wp.vec2(3.0, 4.0))
    with pytest.raises(RuntimeError, match="one type"):
        wp.dot(wp.vec3(1.0, 2.0, 3.0), wp.vec3d(1.0, 2.0, 3.0))
