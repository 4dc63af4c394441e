"""Warp's rules for NaN in min/max/clamp and their adjoints (C fmin/fmax: a NaN operand is a
missing value; the gradient goes to the operand the forward returned), NaN in atomic_min/max,
copysign's adjoint on signed zeros, and bit_count on every integer type; against NumPy
(np.fmin/np.fmax, int.bit_count) on random data with NaNs mixed in."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def minmax_clamp(a: wp.array(dtype=wp.float64), b: wp.array(dtype=wp.float64),
                 lo: wp.array(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    i = wp.tid()
    out[i, 0] = wp.min(a[i], b[i])
    out[i, 1] = wp.max(a[i], b[i])
    out[i, 2] = wp.clamp(a[i], lo[i], b[i])
    v = wp.vec3d(a[i], b[i], lo[i])
    out[i, 3] = wp.min(v)
    out[i, 4] = wp.max(v)


@wp.kernel
def min_loss(a: wp.array(dtype=wp.float64), b: wp.array(dtype=wp.float64),
             out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = wp.min(a[i], b[i]) + 2.0 * wp.max(a[i], b[i])


@wp.kernel
def atomic_minmax(slot_min: wp.array(dtype=float), slot_max: wp.array(dtype=float),
                  v: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_min(slot_min, i, v[i])
    wp.atomic_max(slot_max, i, v[i])


def _with_nans(rng, n):
    a = rng.uniform(-3.0, 3.0, size=n)
    a[rng.random(n) < 0.3] = np.nan
    return a


def test_min_max_clamp_ignore_nan(wp, rng, device):
    n = 64
    a, b, lo = _with_nans(rng, n), _with_nans(rng, n), rng.uniform(-3.0, 0.0, size=n)
    out = wp.zeros((n, 5), dtype=wp.float64, device=device)
    wp.launch(minmax_clamp, dim=n, device=device,
              inputs=[wp.array(a, dtype=wp.float64, device=device),
                      wp.array(b, dtype=wp.float64, device=device),
                      wp.array(lo, dtype=wp.float64, device=device), out])
    got = out.numpy()
    np.testing.assert_array_equal(got[:, 0], np.fmin(a, b))
    np.testing.assert_array_equal(got[:, 1], np.fmax(a, b))
    np.testing.assert_array_equal(got[:, 2], np.fmin(np.fmax(lo, a), b))
    stacked = np.stack([a, b, lo], axis=1)
    np.testing.assert_array_equal(got[:, 3], np.fmin.reduce(stacked, axis=1))
    np.testing.assert_array_equal(got[:, 4], np.fmax.reduce(stacked, axis=1))


def test_min_max_gradients_skip_nan_operands(wp, rng, device):
    n = 64
    a, b = _with_nans(rng, n), _with_nans(rng, n)
    wa = wp.array(a, dtype=wp.float64, device=device, requires_grad=True)
    wb = wp.array(b, dtype=wp.float64, device=device, requires_grad=True)
    out = wp.zeros(n, dtype=wp.float64, device=device, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(min_loss, dim=n, inputs=[wa, wb, out], device=device)
    tape.backward(grads={out: wp.array(np.ones(n), dtype=wp.float64, device=device)})
    # min -> 1 to the operand it returned, max -> 2 to the operand it returned (ties: b)
    min_to_a = ~np.isnan(a) & (np.isnan(b) | (a < b))
    max_to_a = ~np.isnan(a) & (np.isnan(b) | (a > b))
    np.testing.assert_array_equal(wa.grad.numpy(), np.where(min_to_a, 1.0, 0.0) + np.where(max_to_a, 2.0, 0.0))
    np.testing.assert_array_equal(wb.grad.numpy(), np.where(min_to_a, 0.0, 1.0) + np.where(max_to_a, 0.0, 2.0))


def test_atomic_min_max_nan_slots(wp, rng, device):
    n = 64
    s, v = _with_nans(rng, n).astype(np.float32), _with_nans(rng, n).astype(np.float32)
    smin = wp.array(s, dtype=float, device=device)
    smax = wp.array(s, dtype=float, device=device)
    wp.launch(atomic_minmax, dim=n, inputs=[smin, smax, wp.array(v, dtype=float, device=device)],
              device=device)
    np.testing.assert_array_equal(smin.numpy(), np.fmin(s, v))
    np.testing.assert_array_equal(smax.numpy(), np.fmax(s, v))


@pytest.mark.parametrize("name", ["int8", "uint8", "int16", "uint16", "int32", "uint32",
                                  "int64", "uint64"])
def test_bit_count(wp, rng, device, name, kernel_module):
    mod = kernel_module(f'''
@wp.kernel
def count(values: wp.array(dtype=wp.{name}), counts: wp.array(dtype=wp.int32)):
    i = wp.tid()
    counts[i] = wp.bit_count(values[i])
''')
    np_t = np.dtype(name)
    unsigned = np.dtype(f"uint{np_t.itemsize * 8}")
    bits = np.frombuffer(rng.bytes(200 * np_t.itemsize), dtype=unsigned).copy()
    bits[:3] = [0, np.iinfo(unsigned).max, 1]
    values = wp.array(bits.view(np_t), dtype=getattr(wp, name), device=device)
    counts = wp.zeros(len(bits), dtype=wp.int32, device=device)
    wp.launch(mod.count, dim=len(bits), inputs=[values, counts], device=device)
    np.testing.assert_array_equal(counts.numpy(), [int(x).bit_count() for x in bits])


def test_bit_count_rejects_floats(wp, kernel_module, device):
    mod = kernel_module('''
@wp.kernel
def count_float(values: wp.array(dtype=float), counts: wp.array(dtype=wp.int32)):
    counts[0] = wp.bit_count(values[0])
''')
    with pytest.raises(wp.WeftCompileError, match="bit_count"):
        wp.launch(mod.count_float, dim=1, device=device,
                  inputs=[wp.zeros(1, dtype=float, device=device), wp.zeros(1, dtype=wp.int32, device=device)])
