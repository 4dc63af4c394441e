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
