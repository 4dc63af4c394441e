"""Language: generic kernels (typing.Any parameters) are instantiated per launch argument
types (float32, float64, vec3 arrays) and by wp.overload; generic @wp.func called with
several types from one kernel."""
from typing import Any

import numpy as np

import weft as wp


@wp.kernel
def scale_any(a: wp.array(dtype=Any), s: Any):
    i = wp.tid()
    a[i] = a[i] * s


@wp.func
def add_twice(x: Any, y: Any):
    return x + y + y


@wp.kernel
def use_generic_func(f: wp.array(dtype=float), d: wp.array(dtype=wp.float64),
                     v: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    f[i] = add_twice(f[i], 1.0)
    d[i] = add_twice(d[i], wp.float64(0.25))
    v[i] = add_twice(v[i], wp.vec3(1.0, 2.0, 3.0))


def test_generic_kernel_instances(wp, rng):
    x32 = rng.standard_normal(50).astype(np.float32)
    x64 = rng.standard_normal(50)
    xv = rng.standard_normal((50, 3)).astype(np.float32)
    a32, a64 = wp.array(x32), wp.array(x64, dtype=wp.float64)
    av = wp.array(xv, dtype=wp.vec3)
    wp.launch(scale_any, dim=50, inputs=[a32, 2.0])
    wp.launch(scale_any, dim=50, inputs=[a64, wp.float64(3.0)])
    wp.launch(scale_any, dim=50, inputs=[av, 0.5])
    np.testing.assert_allclose(a32.numpy(), x32 * 2, rtol=1e-7)
    np.testing.assert_allclose(a64.numpy(), x64 * 3, rtol=1e-15)
    np.testing.assert_allclose(av.numpy(), xv * 0.5, rtol=1e-7)


def test_explicit_overload(wp):
    instance = wp.overload(scale_any, [wp.array(dtype=wp.float64), wp.float64])
    assert instance.param_types == ["array(float64,1)", "float64"]
    a = wp.full(4, 2.0, dtype=wp.float64)
    wp.launch(instance, dim=4, inputs=[a, wp.float64(1.5)])
    np.testing.assert_array_equal(a.numpy(), 3.0)


def test_generic_func_with_three_types(wp, rng):
    f = rng.standard_normal(20).astype(np.float32)
    d = rng.standard_normal(20)
    v = rng.standard_normal((20, 3)).astype(np.float32)
    fa, da, va = wp.array(f), wp.array(d, dtype=wp.float64), wp.array(v, dtype=wp.vec3)
    wp.launch(use_generic_func, dim=20, inputs=[fa, da, va])
    np.testing.assert_allclose(fa.numpy(), f + 2.0, rtol=1e-6)
    np.testing.assert_allclose(da.numpy(), d + 0.5, rtol=1e-15)
    np.testing.assert_allclose(va.numpy(), v + np.array([2.0, 4.0, 6.0]), rtol=1e-6)
