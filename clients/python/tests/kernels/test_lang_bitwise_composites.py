"""Bitwise operators on integer vectors and matrices, componentwise as in Warp (`&`, `|`, `^`,
`<<`, `>>`, `~`), and `&=`/`|=`/`^=` on array elements of those types (atomic per component),
against NumPy on random data."""
import numpy as np

import weft as wp

mat22ui = wp.types.matrix(shape=(2, 2), dtype=wp.uint32)


@wp.kernel
def vec_bits(a: wp.array(dtype=wp.vec3ui), b: wp.array(dtype=wp.vec3ui), s: wp.array(dtype=wp.vec3ui),
             out: wp.array2d(dtype=wp.vec3ui), acc: wp.array(dtype=wp.vec3ui)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    out[i, 0] = x & y
    out[i, 1] = x | y
    out[i, 2] = x ^ y
    out[i, 3] = x << s[i]
    out[i, 4] = x >> s[i]
    out[i, 5] = ~x
    acc[0] ^= x
    acc[1] |= y
    acc[2] &= x | y


@wp.kernel
def mat_bits(a: wp.array(dtype=mat22ui), b: wp.array(dtype=mat22ui), out: wp.array2d(dtype=mat22ui)):
    i = wp.tid()
    out[i, 0] = a[i] & b[i]
    out[i, 1] = (a[i] | b[i]) ^ ~a[i]
    out[i, 2] = a[i] << mat22ui(wp.uint32(3))
    out[i, 3] = a[i] >> mat22ui(wp.uint32(5))


def test_vector_bitwise(wp, rng):
    n = 64
    a = rng.integers(0, 2**32, size=(n, 3), dtype=np.uint32)
    b = rng.integers(0, 2**32, size=(n, 3), dtype=np.uint32)
    s = rng.integers(0, 32, size=(n, 3), dtype=np.uint32)
    out = wp.zeros((n, 6), dtype=wp.vec3ui)
    acc = wp.array(np.stack([np.zeros(3), np.zeros(3), np.full(3, 2**32 - 1)]).astype(np.uint32), dtype=wp.vec3ui)
    wp.launch(vec_bits, dim=n, inputs=[wp.array(a, dtype=wp.vec3ui), wp.array(b, dtype=wp.vec3ui),
                                       wp.array(s, dtype=wp.vec3ui), out, acc])
    ref = np.stack([a & b, a | b, a ^ b, a << s, a >> s, ~a], axis=1)
    np.testing.assert_array_equal(out.numpy(), ref)
    np.testing.assert_array_equal(acc.numpy()[0], np.bitwise_xor.reduce(a, axis=0))
    np.testing.assert_array_equal(acc.numpy()[1], np.bitwise_or.reduce(b, axis=0))
    np.testing.assert_array_equal(acc.numpy()[2], np.bitwise_and.reduce(a | b, axis=0))


def test_matrix_bitwise(wp, rng):
    n = 32
    a = rng.integers(0, 2**32, size=(n, 2, 2), dtype=np.uint32)
    b = rng.integers(0, 2**32, size=(n, 2, 2), dtype=np.uint32)
    out = wp.zeros((n, 4), dtype=mat22ui)
    wp.launch(mat_bits, dim=n, inputs=[wp.array(a, dtype=mat22ui), wp.array(b, dtype=mat22ui), out])
    ref = np.stack([a & b, (a | b) ^ ~a, a << np.uint32(3), a >> np.uint32(5)], axis=1)
    np.testing.assert_array_equal(out.numpy(), ref)


@wp.kernel
def reduce_bits(a: wp.array(dtype=wp.uint32), v: wp.array(dtype=wp.vec2ui), acc: wp.array(dtype=wp.uint32),
                vacc: wp.array(dtype=wp.vec2ui)):
    i = wp.tid()
    acc[0] ^= a[i]
    acc[1] |= a[i] & wp.uint32(0x0F0F0F0F)
    acc[2] &= a[i] | wp.uint32(0x80000001)
    vacc[0] ^= v[i]


def test_bitwise_augmented_assignment_on_array_elements_is_atomic(wp, rng):
    """`arr[i] ^= x` from many threads onto one element: atomic (Warp's rule for &=, |=, ^=),
    so the result is the NumPy reduction whatever the thread interleaving."""
    n = 200_003
    a = rng.integers(0, 2**32, size=n, dtype=np.uint32)
    v = rng.integers(0, 2**32, size=(n, 2), dtype=np.uint32)
    acc = wp.array(np.array([0, 0, 2**32 - 1], dtype=np.uint32), dtype=wp.uint32)
    vacc = wp.zeros(1, dtype=wp.vec2ui)
    wp.launch(reduce_bits, dim=n, inputs=[wp.array(a, dtype=wp.uint32), wp.array(v, dtype=wp.vec2ui), acc, vacc])
    got = acc.numpy()
    assert got[0] == np.bitwise_xor.reduce(a)
    assert got[1] == np.bitwise_or.reduce(a & np.uint32(0x0F0F0F0F))
    assert got[2] == np.bitwise_and.reduce(a | np.uint32(0x80000001))
    np.testing.assert_array_equal(vacc.numpy()[0], np.bitwise_xor.reduce(v, axis=0))
