"""A @wp.func called from Python scope runs its Python body (as in Warp), with the client's
Python-side values: it gives the kernel's result on the same inputs (float64 reference on
random data), picks among overloads by the arguments, and wp.expect_eq from Python prints an
error to stdout when its arguments differ (Warp's behaviour) instead of raising."""
import numpy as np

import weft as wp

vec3b = wp.types.vector(length=3, dtype=wp.bool)


@wp.func
def blend(a: wp.vec3, b: wp.vec3, t: float):
    return a * (1.0 - t) + b * t


@wp.func
def scale(x: float, k: float):
    return x * k


@wp.func
def scale(x: int, k: int):  # noqa: F811 - an overload, as in Warp
    return x * k + 1


@wp.func
def bool_components():
    v = vec3b(True, False, True)
    v[0] = False
    v[-1] = True
    wp.expect_eq(v[0], False)
    wp.expect_eq(v[-1], True)
    wp.expect_eq(v[1], True)        # fails: printed, not raised
    return v


@wp.kernel
def blend_kernel(a: wp.array[wp.vec3], b: wp.array[wp.vec3], t: wp.array[float], out: wp.array[wp.vec3]):
    i = wp.tid()
    out[i] = blend(a[i], b[i], t[i])


def test_func_called_from_python_matches_the_kernel(wp, rng):
    n = 8
    a = rng.uniform(-2.0, 2.0, (n, 3))
    b = rng.uniform(-2.0, 2.0, (n, 3))
    t = rng.uniform(0.1, 0.9, n)
    out = wp.zeros(n, dtype=wp.vec3)
    wp.launch(blend_kernel, n, inputs=[wp.array(a.astype(np.float32), dtype=wp.vec3),
                                       wp.array(b.astype(np.float32), dtype=wp.vec3),
                                       wp.array(t.astype(np.float32), dtype=float)], outputs=[out])
    ref = a * (1.0 - t[:, None]) + b * t[:, None]
    for k in range(n):
        got = blend(wp.vec3(*a[k]), wp.vec3(*b[k]), float(t[k]))
        assert isinstance(got, wp.vec3)
        np.testing.assert_allclose(np.array(got, dtype=np.float64), ref[k], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-5, atol=1e-6)


def test_overload_chosen_by_the_arguments(wp, rng):
    x = float(rng.uniform(1.0, 2.0))
    assert scale(x, 3.0) == x * 3.0
    assert scale(4, 5) == 21


def test_expect_eq_from_python_prints(wp, capsys):
    v = bool_components()
    assert [bool(c) for c in v] == [False, False, True]
    printed = capsys.readouterr().out
    assert printed.count("expect_eq") == 1 and "False != True" in printed
