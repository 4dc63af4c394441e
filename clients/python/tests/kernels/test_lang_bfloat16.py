"""wp.bfloat16 (float32's upper 16 bits, round to nearest even): Python scalars, arrays from
floats / uint16 bit patterns / NumPy, numpy() as ml_dtypes.bfloat16 (or the uint16 bits without
that package), kernel parameters and array elements, arithmetic and math builtins (computed in
float32, rounded back), atomics and gradients. References: float64 results rounded to bfloat16
with NumPy bit arithmetic, on fresh random data; a result may differ from the reference by one
bfloat16 ulp where float32 and float64 round differently."""
import numpy as np
import pytest

import weft as wp
from weft._kernel.typestr import bfloat16_bits_to_float32, float32_to_bfloat16_bits


def bf16(x):
    """float64 values rounded to bfloat16 (through float32, as the kernels do)."""
    return bfloat16_bits_to_float32(float32_to_bfloat16_bits(np.asarray(x, dtype=np.float32))).astype(np.float64)


def as_float(a):
    """float64 values of a bfloat16 array's numpy()."""
    values = a.numpy()
    if values.dtype == np.uint16:
        return bfloat16_bits_to_float32(values).astype(np.float64)
    return values.astype(np.float64)


@wp.kernel
def bf16_ops(a: wp.array(dtype=wp.bfloat16), b: wp.array(dtype=wp.bfloat16), s: wp.bfloat16,
             out: wp.array2d(dtype=wp.bfloat16), f: wp.array(dtype=wp.float32)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i, 0] = x + y
    out[i, 1] = x * y - s
    out[i, 2] = x / y
    out[i, 3] = wp.sin(x)
    out[i, 4] = wp.sqrt(wp.abs(x))
    out[i, 5] = wp.max(x, y)
    out[i, 6] = wp.bfloat16(f[i])          # float32 -> bfloat16 conversion
    f[i] = wp.float32(x) * 2.0             # and back


@wp.kernel
def bf16_atomic(out: wp.array(dtype=wp.bfloat16)):
    wp.atomic_add(out, 0, wp.bfloat16(1.0))


@wp.kernel
def bf16_square(x: wp.array(dtype=wp.bfloat16), loss: wp.array(dtype=wp.float32)):
    i = wp.tid()
    v = wp.float32(x[i])
    wp.atomic_add(loss, 0, v * v * 0.5)


def test_bfloat16_python_scalars_and_conversion():
    assert wp.bfloat16(3.14159).value == float(bf16(3.14159))
    assert wp.types.is_float(wp.bfloat16)
    assert wp.types.type_size_in_bytes(wp.bfloat16) == 2
    assert wp.dtype_to_numpy(wp.bfloat16) is np.uint16
    vals = np.array([0.0, 1.0, -2.5, 3.0e38, 1e-30, np.inf, -np.inf, 1.00390625, 1.01171875],
                    dtype=np.float32)
    bits = float32_to_bfloat16_bits(vals)
    # exact bit patterns: 1.00390625 is a tie (even: 1.0), 1.01171875 a tie (even: 1.015625)
    assert list(bits[[0, 1, 2, 5, 6, 7, 8]]) == [0x0000, 0x3F80, 0xC020, 0x7F80, 0xFF80, 0x3F80, 0x3F82]
    assert np.isnan(bfloat16_bits_to_float32(float32_to_bfloat16_bits(np.float32(np.nan))))


def test_bfloat16_arrays_from_floats_bits_and_numpy(wp, rng):
    x = rng.standard_normal(50).astype(np.float32) * 100
    a = wp.array(x, dtype=wp.bfloat16)
    assert a.dtype is wp.bfloat16
    np.testing.assert_array_equal(as_float(a), bf16(x))
    b = wp.array(x.tolist(), dtype=wp.bfloat16)              # a list of floats
    np.testing.assert_array_equal(as_float(b), bf16(x))
    raw = np.array([0x3F80, 0x4000, 0x4040], dtype=np.uint16)  # uint16 = bit patterns (Warp)
    np.testing.assert_array_equal(as_float(wp.array(raw, dtype=wp.bfloat16)), [1.0, 2.0, 3.0])
    z = wp.full(4, 2.5, dtype=wp.bfloat16)
    np.testing.assert_array_equal(as_float(z), [2.5] * 4)
    try:
        import ml_dtypes
    except ImportError:
        assert a.numpy().dtype == np.uint16
    else:
        assert a.numpy().dtype == ml_dtypes.bfloat16


def test_bfloat16_kernel_arithmetic(wp, rng):
    n = 200
    x = rng.uniform(-8, 8, n).astype(np.float32)
    y = rng.uniform(0.5, 4, n).astype(np.float32) * rng.choice([-1, 1], n)
    f = rng.standard_normal(n).astype(np.float32) * 10
    a = wp.array(x, dtype=wp.bfloat16)
    b = wp.array(y, dtype=wp.bfloat16)
    out = wp.zeros((n, 7), dtype=wp.bfloat16)
    fa = wp.array(f)
    s = wp.bfloat16(0.75)
    wp.launch(bf16_ops, dim=n, inputs=[a, b, s, out, fa])
    xa, ya = bf16(x), bf16(y)
    ref = np.stack([bf16(xa + ya), bf16(bf16(xa * ya) - 0.75), bf16(xa / ya), bf16(np.sin(xa)),
                    bf16(np.sqrt(np.abs(xa))), np.maximum(xa, ya), bf16(f)], axis=1)
    got = as_float(out).reshape(n, 7)
    ulp = np.abs(ref) * 2.0 ** -7                          # one bfloat16 ulp (8-bit significand)
    assert np.all(np.abs(got - ref) <= ulp + 1e-30), np.max(np.abs(got - ref) / (ulp + 1e-30))
    np.testing.assert_array_equal(fa.numpy(), (xa * 2.0).astype(np.float32))


def test_bfloat16_atomics_and_gradient(wp, rng):
    out = wp.zeros(1, dtype=wp.bfloat16)
    wp.launch(bf16_atomic, dim=10, inputs=[out])
    assert as_float(out)[0] == 10.0
    x = rng.uniform(-4, 4, 3).astype(np.float32)
    xa = wp.array(x, dtype=wp.bfloat16, requires_grad=True)
    loss = wp.zeros(1, dtype=wp.float32, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(bf16_square, dim=3, inputs=[xa, loss])
    tape.backward(loss)
    np.testing.assert_allclose(as_float(xa.grad), bf16(x), rtol=2.0 ** -7)   # d(x^2/2)/dx = x


vec3bf = wp.types.vector(3, dtype=wp.bfloat16)


@wp.kernel
def bf16_vectors(v: wp.array(dtype=vec3bf), out: wp.array(dtype=vec3bf), n: wp.array(dtype=wp.float32)):
    i = wp.tid()
    w = v[i] * wp.bfloat16(2.0) + vec3bf(wp.bfloat16(1.0), wp.bfloat16(0.5), wp.bfloat16(-1.0))
    out[i] = w
    n[i] = wp.float32(wp.dot(w, w))


def test_bfloat16_vectors(wp, rng):
    n = 40
    x = rng.uniform(-3, 3, (n, 3)).astype(np.float32)
    v = wp.array(x, dtype=vec3bf)
    out = wp.zeros(n, dtype=vec3bf)
    nn = wp.zeros(n, dtype=wp.float32)
    wp.launch(bf16_vectors, dim=n, inputs=[v, out, nn])
    w = bf16(bf16(bf16(x) * 2.0) + np.array([1.0, 0.5, -1.0]))
    np.testing.assert_array_equal(as_float(out).reshape(n, 3), w)
    # dot in bfloat16: each product and partial sum rounds; compare within a few ulps
    np.testing.assert_allclose(nn.numpy(), (w * w).sum(axis=1), rtol=2.0 ** -5)
    p = vec3bf(1.0, 2.0, 3.14159)              # Python values keep bfloat16 precision
    assert p[2] == float(bf16(3.14159))
