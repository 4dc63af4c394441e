"""Builtins: wp.where / wp.select (note the reversed argument order of select), min, max,
clamp, abs, sign, step, nonzero on ints and floats including NaN, +-0 and +-inf."""
import numpy as np

import weft as wp


@wp.kernel
def pick(c: wp.array(dtype=int), a: wp.array(dtype=float), b: wp.array(dtype=float),
         out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    out[i, 0] = wp.where(c[i] > 0, a[i], b[i])
    out[i, 1] = wp.where(c[i] > 0, b[i], a[i])
    out[i, 2] = wp.min(a[i], b[i])
    out[i, 3] = wp.max(a[i], b[i])
    out[i, 4] = wp.clamp(a[i], -0.5, 0.5)
    out[i, 5] = wp.abs(a[i])
    out[i, 6] = wp.sign(a[i])
    out[i, 7] = wp.step(a[i])
    out[i, 8] = wp.nonzero(a[i])


@wp.kernel
def pick_select(c: wp.array(dtype=int), a: wp.array(dtype=float), b: wp.array(dtype=float),
                out: wp.array(dtype=float)):
    # wp.select is in Warp 1.17 (the compatibility target; removed in Warp 1.19)
    i = wp.tid()
    out[i] = wp.select(c[i] > 0, a[i], b[i])


@wp.kernel
def pick_int(a: wp.array(dtype=int), b: wp.array(dtype=int), out: wp.array(dtype=int, ndim=2)):
    i = wp.tid()
    out[i, 0] = wp.min(a[i], b[i])
    out[i, 1] = wp.max(a[i], b[i])
    out[i, 2] = wp.clamp(a[i], -100, 100)
    out[i, 3] = wp.abs(a[i])
    out[i, 4] = wp.sign(a[i])
    out[i, 5] = wp.where(a[i] < b[i], a[i], b[i])


def test_float_select_family(wp, rng):
    n = 1000
    a = np.concatenate([rng.standard_normal(n), [0.0, -0.0, np.inf, -np.inf, 0.5, -0.5]])
    b = np.concatenate([rng.standard_normal(n), [-0.0, 0.0, 1.0, 1.0, 2.0, -2.0]])
    a, b = a.astype(np.float32), b.astype(np.float32)
    c = rng.integers(-1, 2, len(a)).astype(np.int32)
    out = wp.zeros((len(a), 9), dtype=float)
    wp.launch(pick, dim=len(a), inputs=[wp.array(c), wp.array(a), wp.array(b)], outputs=[out])
    o = out.numpy()
    np.testing.assert_array_equal(o[:, 0], np.where(c > 0, a, b))
    np.testing.assert_array_equal(o[:, 1], np.where(c > 0, b, a))
    np.testing.assert_array_equal(o[:, 2], np.minimum(a, b))
    np.testing.assert_array_equal(o[:, 3], np.maximum(a, b))
    np.testing.assert_array_equal(o[:, 4], np.clip(a, -0.5, 0.5))
    np.testing.assert_array_equal(o[:, 5], np.abs(a))
    np.testing.assert_array_equal(o[:, 6], np.where(a < 0, -1.0, 1.0))
    np.testing.assert_array_equal(o[:, 7], np.where(a < 0, 1.0, 0.0))   # Warp: step(x) = x < 0
    np.testing.assert_array_equal(o[:, 8], np.where(a != 0, 1.0, 0.0))


def test_select_argument_order(wp, rng):
    a = rng.standard_normal(100).astype(np.float32)
    b = rng.standard_normal(100).astype(np.float32)
    c = rng.integers(-1, 2, 100).astype(np.int32)
    out = wp.zeros(100, dtype=float)
    wp.launch(pick_select, dim=100, inputs=[wp.array(c), wp.array(a), wp.array(b)], outputs=[out])
    np.testing.assert_array_equal(out.numpy(), np.where(c > 0, b, a))   # select(cond, false, true)


def test_int_select_family(wp, rng):
    n = 1000
    a = np.concatenate([rng.integers(-1000, 1000, n), [0, -2**31 + 1, 2**31 - 1]]).astype(np.int32)
    b = np.concatenate([rng.integers(-1000, 1000, n), [0, 5, -5]]).astype(np.int32)
    out = wp.zeros((len(a), 6), dtype=int)
    wp.launch(pick_int, dim=len(a), inputs=[wp.array(a), wp.array(b)], outputs=[out])
    o = out.numpy()
    np.testing.assert_array_equal(o[:, 0], np.minimum(a, b))
    np.testing.assert_array_equal(o[:, 1], np.maximum(a, b))
    np.testing.assert_array_equal(o[:, 2], np.clip(a, -100, 100))
    np.testing.assert_array_equal(o[:, 3], np.abs(a))
    np.testing.assert_array_equal(o[:, 4], np.where(a < 0, -1, 1))
    np.testing.assert_array_equal(o[:, 5], np.minimum(a, b))
