"""The launch hot path (per-kernel launch plan, ArgValues cached on arrays, struct-packed
scalars) gives the same results as the general path: views of one array, arrays swapped
between launches, scalars of every fast kind, int wrap-around like a C cast, and the same
argument errors after the plan exists."""
import numpy as np
import pytest

import weft as wp
from weft._kernel.errors import WeftLaunchError


@wp.kernel
def axpy_fast(x: wp.array(dtype=float), a: float, k: int, u: wp.uint8, d: wp.float64,
              y: wp.array(dtype=float), out_k: wp.array(dtype=int),
              out_d: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] = a * x[i] + y[i]
    if i == 0:
        out_k[0] = k
        out_k[1] = int(u)
        out_d[0] = d


def test_views_and_swapped_arrays_stay_correct(wp, rng):
    n = 100
    xs = rng.standard_normal(n).astype(np.float32)
    ys = rng.standard_normal(n).astype(np.float32)
    x = wp.array(xs)
    y = wp.array(ys)
    k = wp.zeros(2, dtype=int)
    d = wp.zeros(1, dtype=wp.float64)
    expected = ys.astype(np.float64)
    for step, a in enumerate([0.5, 0.5, -1.25, 3.0]):
        wp.launch(axpy_fast, dim=n, inputs=[x, a, step, 7, 0.1 * step], outputs=[y, k, d])
        expected = np.float32(a) * xs.astype(np.float64) + expected
        np.testing.assert_allclose(y.numpy(), expected, rtol=1e-5, atol=1e-5)
        assert list(k.numpy()) == [step, 7]
        assert d.numpy()[0] == 0.1 * step
    # views of the same arrays (other offsets/shapes, same handle), then fresh arrays
    xv, yv = x[10:60], y[20:70]
    before = y.numpy().astype(np.float64)
    wp.launch(axpy_fast, dim=50, inputs=[xv, 2.0, 1, 2, 0.0], outputs=[yv, k, d])
    after = before.copy()
    after[20:70] = 2.0 * xs[10:60].astype(np.float64) + before[20:70]
    np.testing.assert_allclose(y.numpy(), after, rtol=1e-5, atol=1e-5)
    x2 = wp.array(rng.standard_normal(n).astype(np.float32))
    y2 = wp.zeros(n, dtype=float)
    wp.launch(axpy_fast, dim=n, inputs=[x2, 1.0, 1, 2, 0.0], outputs=[y2, k, d])
    np.testing.assert_array_equal(y2.numpy(), x2.numpy())
    np.testing.assert_allclose(y.numpy(), after, rtol=1e-5, atol=1e-5)


def test_scalars_wrap_and_convert_like_the_general_path(wp):
    x = wp.zeros(1, dtype=float)
    y = wp.zeros(1, dtype=float)
    k = wp.zeros(2, dtype=int)
    d = wp.zeros(1, dtype=wp.float64)
    cases = [(2**31 + 5, -2**31 + 5), (-2**31 - 1, 2**31 - 1), (True, 1), (np.int64(-3), -3)]
    for value, want in cases:
        wp.launch(axpy_fast, dim=1, inputs=[x, 1, value, 300, np.float64(0.25)],
                  outputs=[y, k, d])
        assert list(k.numpy()) == [want, 300 % 256], value
        assert d.numpy()[0] == 0.25


def test_argument_errors_after_the_plan_exists(wp):
    x = wp.zeros(4, dtype=float)
    y = wp.zeros(4, dtype=float)
    k = wp.zeros(2, dtype=int)
    d = wp.zeros(1, dtype=wp.float64)
    wp.launch(axpy_fast, dim=4, inputs=[x, 1.0, 1, 1, 1.0], outputs=[y, k, d])
    with pytest.raises(WeftLaunchError, match="'y'.*dtype float32"):
        wp.launch(axpy_fast, dim=4, inputs=[x, 1.0, 1, 1, 1.0],
                  outputs=[wp.zeros(4, dtype=wp.float64), k, d])
    with pytest.raises(WeftLaunchError, match="'x'.*dimension"):
        wp.launch(axpy_fast, dim=4, inputs=[wp.zeros((2, 2), dtype=float), 1.0, 1, 1, 1.0],
                  outputs=[y, k, d])
    with pytest.raises(WeftLaunchError, match="'k'"):
        wp.launch(axpy_fast, dim=4, inputs=[x, 1.0, 1.5, 1, 1.0], outputs=[y, k, d])
    with pytest.raises(WeftLaunchError, match="number of arguments"):
        wp.launch(axpy_fast, dim=4, inputs=[x, 1.0], outputs=[y])
    wp.synchronize()


@wp.kernel
def composite_values(v: wp.vec3, d: wp.vec3d, m: wp.mat22, q: wp.quat, iv: wp.vec2i,
                     out: wp.array(dtype=wp.float64)):
    out[0] = wp.float64(v[0])
    out[1] = wp.float64(v[2])
    out[2] = d[1]
    out[3] = wp.float64(m[0, 1])
    out[4] = wp.float64(m[1, 0])
    out[5] = wp.float64(q[3])
    out[6] = wp.float64(iv[1])


def test_composite_values_pack_like_the_general_path(wp, rng):
    """Vector, matrix and quaternion arguments take their components' bytes when the value's
    storage matches the parameter; any other value (a float32 vector for a vec3d, a quat for a
    vec4, a tuple, a NumPy array) converts as the general path does, before and after the
    fast path has seen a matching class."""
    out = wp.zeros(7, dtype=wp.float64)
    for _ in range(3):
        a, b, c = (float(x) for x in rng.uniform(-1e3, 1e3, 3))
        tiny = float(rng.uniform(1e-30, 1e-29))
        args = [wp.vec3(a, b, tiny), wp.vec3d(a, 1e300 * c / abs(c), b),
                wp.mat22(a, b, c, tiny), wp.quat(0.0, 0.0, 0.0, c), wp.vec2i(3, -2**31)]
        wp.launch(composite_values, dim=1, inputs=args, outputs=[out])
        want = [np.float32(a), np.float32(tiny), 1e300 * c / abs(c), np.float32(b),
                np.float32(c), np.float32(c), -2**31]
        np.testing.assert_array_equal(out.numpy(), np.array(want, dtype=np.float64))
        # values of other classes: converted (float32 -> float64, tuples, NumPy, quat as vec4)
        other = [(a, b, tiny), wp.vec3(a, 7.5, b),          # float32 storage for the vec3d
                 np.array([[a, b], [c, tiny]]), wp.vec4(0.0, 0.0, 0.0, c), [3, -2**31]]
        wp.launch(composite_values, dim=1, inputs=other, outputs=[out])
        want[2] = 7.5
        np.testing.assert_array_equal(out.numpy(), np.array(want, dtype=np.float64))


def test_composite_value_of_the_wrong_size_is_refused(wp):
    out = wp.zeros(7, dtype=wp.float64)
    good = [wp.vec3(), wp.vec3d(), wp.mat22(), wp.quat(), wp.vec2i()]
    wp.launch(composite_values, dim=1, inputs=good, outputs=[out])
    for i, bad in enumerate([wp.vec4(), wp.vec2d(), wp.vec3(), wp.vec2(), wp.vec3i()]):
        args = list(good)
        args[i] = bad
        with pytest.raises(WeftLaunchError, match="components"):
            wp.launch(composite_values, dim=1, inputs=args, outputs=[out])
