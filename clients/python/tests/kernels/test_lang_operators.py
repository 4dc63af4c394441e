"""Language: arithmetic, comparison, boolean and bitwise operators on int32/uint32/float32/
float64, integer overflow (two's complement wrap, as Warp's C++ does), division by zero of
floats (inf/nan), and operator precedence; against NumPy references."""
import numpy as np

import weft as wp


@wp.kernel
def int_ops(a: wp.array(dtype=int), b: wp.array(dtype=int), out: wp.array(dtype=int, ndim=2)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i, 0] = x + y
    out[i, 1] = x - y
    out[i, 2] = x * y
    out[i, 3] = x & y
    out[i, 4] = x | y
    out[i, 5] = x ^ y
    out[i, 6] = ~x
    out[i, 7] = x << 3
    out[i, 8] = x >> 2
    out[i, 9] = -x
    out[i, 10] = x + y * 2 - (x - y) * 3


@wp.kernel
def int_div_mod(a: wp.array(dtype=int), b: wp.array(dtype=int), out: wp.array(dtype=int, ndim=2)):
    i = wp.tid()
    out[i, 0] = a[i] // b[i]
    out[i, 1] = a[i] % b[i]


@wp.kernel
def uint_ops(a: wp.array(dtype=wp.uint32), b: wp.array(dtype=wp.uint32),
             out: wp.array(dtype=wp.uint32, ndim=2)):
    i = wp.tid()
    out[i, 0] = a[i] + b[i]
    out[i, 1] = a[i] - b[i]
    out[i, 2] = a[i] * b[i]
    out[i, 3] = a[i] >> wp.uint32(5)
    out[i, 4] = a[i] ^ b[i]


@wp.kernel
def compare_bool(a: wp.array(dtype=float), b: wp.array(dtype=float), out: wp.array(dtype=int, ndim=2)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i, 0] = int(x < y)
    out[i, 1] = int(x <= y)
    out[i, 2] = int(x > y)
    out[i, 3] = int(x >= y)
    out[i, 4] = int(x == y)
    out[i, 5] = int(x != y)
    out[i, 6] = int((x > 0.0) and (y > 0.0))
    out[i, 7] = int((x > 0.0) or (y > 0.0))
    out[i, 8] = int(not (x > 0.0))


@wp.kernel
def float_ops(a: wp.array(dtype=float), b: wp.array(dtype=float), out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i, 0] = x + y
    out[i, 1] = x - y
    out[i, 2] = x * y
    out[i, 3] = x / y
    out[i, 4] = -x
    out[i, 5] = x ** 2.0
    out[i, 6] = x * y + x / (y * y + 1.0)


@wp.kernel
def double_ops(a: wp.array(dtype=wp.float64), b: wp.array(dtype=wp.float64),
               out: wp.array(dtype=wp.float64, ndim=2)):
    i = wp.tid()
    out[i, 0] = a[i] * b[i] + a[i]
    out[i, 1] = a[i] / b[i]
    out[i, 2] = a[i] - wp.float64(1.0e-300) * b[i]


def test_int32_ops_and_overflow(wp, rng):
    a = np.concatenate([rng.integers(-2**31, 2**31, 1000), [2**31 - 1, -2**31, 0, -1]])
    b = np.concatenate([rng.integers(-2**31, 2**31, 1000), [1, -1, 0, 2**31 - 1]])
    a, b = a.astype(np.int32), b.astype(np.int32)
    out = wp.zeros((len(a), 11), dtype=int)
    wp.launch(int_ops, dim=len(a), inputs=[wp.array(a), wp.array(b)], outputs=[out])
    with np.errstate(over="ignore"):
        ref = np.stack([a + b, a - b, a * b, a & b, a | b, a ^ b, ~a, a << 3, a >> 2, -a,
                        a + b * np.int32(2) - (a - b) * np.int32(3)], axis=1)
    np.testing.assert_array_equal(out.numpy(), ref)


def test_int_div_mod_nonnegative(wp, rng):
    a = rng.integers(0, 2**31, 1000).astype(np.int32)
    b = rng.integers(1, 1000, 1000).astype(np.int32)
    out = wp.zeros((len(a), 2), dtype=int)
    wp.launch(int_div_mod, dim=len(a), inputs=[wp.array(a), wp.array(b)], outputs=[out])
    np.testing.assert_array_equal(out.numpy(), np.stack([a // b, a % b], axis=1))


def test_int_div_mod_negative_like_warp(wp, rng):
    # Warp 1.19 (checked on its CPU backend): `//` on ints floors like Python, while `%` is
    # C's truncated remainder (sign of the dividend): -5 // 3 == -2 and -5 % 3 == -2
    a = np.concatenate([rng.integers(-10**6, 10**6, 1000), [-5, -7, 5, 7, -6]]).astype(np.int32)
    b = np.concatenate([rng.integers(1, 100, 1000) * rng.choice([-1, 1], 1000),
                        [3, 3, -3, -3, 3]]).astype(np.int32)
    out = wp.zeros((len(a), 2), dtype=int)
    wp.launch(int_div_mod, dim=len(a), inputs=[wp.array(a), wp.array(b)], outputs=[out])
    np.testing.assert_array_equal(out.numpy()[:, 0], np.floor_divide(a, b))
    np.testing.assert_array_equal(out.numpy()[:, 1], np.fmod(a, b))


def test_uint32_wraps(wp, rng):
    a = np.concatenate([rng.integers(0, 2**32, 1000), [0, 2**32 - 1]]).astype(np.uint32)
    b = np.concatenate([rng.integers(0, 2**32, 1000), [1, 2]]).astype(np.uint32)
    out = wp.zeros((len(a), 5), dtype=wp.uint32)
    wp.launch(uint_ops, dim=len(a), inputs=[wp.array(a), wp.array(b)], outputs=[out])
    with np.errstate(over="ignore"):
        ref = np.stack([a + b, a - b, a * b, a >> np.uint32(5), a ^ b], axis=1)
    np.testing.assert_array_equal(out.numpy(), ref)


def test_comparisons_and_bool_ops(wp, rng):
    a = np.concatenate([rng.integers(-3, 3, 500), [np.nan, 0.0, np.inf]]).astype(np.float32)
    b = np.concatenate([rng.integers(-3, 3, 500), [1.0, np.nan, np.inf]]).astype(np.float32)
    out = wp.zeros((len(a), 9), dtype=int)
    wp.launch(compare_bool, dim=len(a), inputs=[wp.array(a), wp.array(b)], outputs=[out])
    with np.errstate(invalid="ignore"):
        ref = np.stack([a < b, a <= b, a > b, a >= b, a == b, a != b, (a > 0) & (b > 0),
                        (a > 0) | (b > 0), ~(a > 0)], axis=1).astype(np.int32)
    np.testing.assert_array_equal(out.numpy(), ref)


def test_float32_arithmetic_with_hard_inputs(wp, rng):
    a = np.concatenate([rng.standard_normal(1000) * 10.0 ** rng.integers(-30, 30, 1000),
                        [1e38, -1e38, 1e-45, 0.0, np.inf, np.nan, 1.0]]).astype(np.float32)
    b = np.concatenate([rng.standard_normal(1000) * 10.0 ** rng.integers(-30, 30, 1000),
                        [1e38, 1e-38, 1e-45, 0.0, -np.inf, 1.0, 0.0]]).astype(np.float32)
    out = wp.zeros((len(a), 7), dtype=float)
    wp.launch(float_ops, dim=len(a), inputs=[wp.array(a), wp.array(b)], outputs=[out])
    with np.errstate(all="ignore"):
        ref = np.stack([a + b, a - b, a * b, a / b, -a, a * a,
                        a * b + a / (b * b + np.float32(1.0))], axis=1)
    got = out.numpy()
    # IEEE float32 results: exact except rounding of fused/unfused steps
    np.testing.assert_allclose(got[:, :5], ref[:, :5], rtol=2e-7, atol=0, equal_nan=True)
    # x ** 2.0 is pow(): CUDA's powf is within 4 ulp (the CUDA programming guide's table of
    # single-precision functions), not correctly rounded; near the subnormal range an ulp is
    # 2**-149 absolute
    np.testing.assert_allclose(got[:, 5], ref[:, 5], rtol=4 * 2.0**-23, atol=4 * 2.0**-149,
                               equal_nan=True)
    np.testing.assert_allclose(got[:, 6], ref[:, 6], rtol=1e-5, atol=1e-30, equal_nan=True)


def test_float64_keeps_double_precision(wp, rng):
    a = rng.standard_normal(1000)
    b = rng.standard_normal(1000) + 3.0
    out = wp.zeros((1000, 3), dtype=wp.float64)
    wp.launch(double_ops, dim=1000, inputs=[wp.array(a, dtype=wp.float64),
                                            wp.array(b, dtype=wp.float64)], outputs=[out])
    ref = np.stack([a * b + a, a / b, a - 1e-300 * b], axis=1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-15, atol=1e-300)
