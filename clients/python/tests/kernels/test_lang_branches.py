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


@wp.kernel
def array_truth(maybe: wp.array(dtype=float), idx: wp.indexedarray(dtype=float), out: wp.array(dtype=int)):
    out[0] = 1 if maybe else 0
    if not maybe:
        out[1] = 1
    if idx:
        out[2] = 1
    out[3] = int(not idx)


def test_an_array_is_true_unless_it_is_none(wp, rng, device):
    """`if arr:` / `not arr` on array and indexed-array parameters, as Warp: None is false."""
    data = wp.array(rng.uniform(-1, 1, 8).astype(np.float32), device=device)
    idx = wp.indexedarray(data, [wp.array(np.array([1, 3], dtype=np.int32), device=device)])
    out = wp.zeros(4, dtype=int, device=device)
    wp.launch(array_truth, dim=1, inputs=[data, idx, out], device=device)
    np.testing.assert_array_equal(out.numpy(), [1, 0, 1, 0])
    out.zero_()
    wp.launch(array_truth, dim=1, inputs=[None, None, out], device=device)
    np.testing.assert_array_equal(out.numpy(), [0, 1, 0, 1])
