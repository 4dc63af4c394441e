"""Language: if/elif/else (nested, with early writes), ternary expressions, and branches on
NaN (comparisons with NaN are false, as in C and Warp)."""
import numpy as np

import weft as wp


@wp.kernel
def classify(a: wp.array(dtype=float), out: wp.array(dtype=int)):
    i = wp.tid()
    x = a[i]
    if x < -1.0:
        out[i] = -2
    elif x < 0.0:
        out[i] = -1
    elif x == 0.0:
        out[i] = 0
    else:
        if x > 1.0:
            out[i] = 2
        else:
            out[i] = 1


@wp.kernel
def ternary(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    x = a[i]
    out[i] = x * 2.0 if x > 0.5 else -x


@wp.kernel
def branch_assigns(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    y = 0.0
    if a[i] > 0.0:
        y = wp.sqrt(a[i])
    else:
        y = a[i] * a[i]
    out[i] = y


def _classify_ref(x):
    return np.select([x < -1, x < 0, x == 0, x > 1], [-2, -1, 0, 2], default=1)


def test_if_elif_else(wp, rng):
    a = np.concatenate([rng.uniform(-3, 3, 1000), [0.0, -0.0, 1.0, -1.0, np.nan, np.inf,
                                                  -np.inf]]).astype(np.float32)
    out = wp.zeros(len(a), dtype=int)
    wp.launch(classify, dim=len(a), inputs=[wp.array(a)], outputs=[out])
    ref = _classify_ref(a.astype(np.float64))
    ref[np.isnan(a)] = 1          # every comparison with NaN is false -> the final else
    np.testing.assert_array_equal(out.numpy(), ref)


def test_ternary(wp, rng):
    a = rng.uniform(-2, 2, 2000).astype(np.float32)
    out = wp.zeros(len(a), dtype=float)
    wp.launch(ternary, dim=len(a), inputs=[wp.array(a)], outputs=[out])
    a64 = a.astype(np.float64)
    np.testing.assert_allclose(out.numpy(), np.where(a64 > 0.5, 2 * a64, -a64), rtol=1e-7)


def test_variables_assigned_in_branches(wp, rng):
    a = rng.standard_normal(1000).astype(np.float32)
    out = wp.zeros(len(a), dtype=float)
    wp.launch(branch_assigns, dim=len(a), inputs=[wp.array(a)], outputs=[out])
    a64 = a.astype(np.float64)
    ref = np.where(a64 > 0, np.sqrt(np.abs(a64)), a64 * a64)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-6)
