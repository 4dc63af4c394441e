"""Language: assignments, tuple unpacking, augmented assignment, variable reassignment with a
new value of the same type; against NumPy float64 references on fresh random data."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def assign_chain(a: wp.array(dtype=float), b: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    z = x * y
    z = z + x          # reassignment
    w = z
    out[i] = w - y


@wp.func
def split(x: float):
    return x * 2.0, x + 1.0


@wp.kernel
def unpack(a: wp.array(dtype=float), out0: wp.array(dtype=float), out1: wp.array(dtype=float),
           out2: wp.array(dtype=float)):
    i = wp.tid()
    p, q = split(a[i])
    v = wp.vec3(a[i], 2.0 * a[i], 3.0 * a[i])
    out0[i] = p
    out1[i] = q
    out2[i] = v[0] + v[1] + v[2]


@wp.kernel
def augmented(a: wp.array(dtype=float), n: wp.array(dtype=int), out: wp.array(dtype=float),
              iout: wp.array(dtype=int)):
    i = wp.tid()
    x = a[i]
    x += 1.5
    x *= 2.0
    x -= 0.25
    x /= 4.0
    out[i] = x
    k = n[i]
    k += 7
    k *= 3
    k -= 2
    iout[i] = k
    out[i] += 1.0      # augmented assignment to an array element


def test_assign_chain(wp, rng):
    n = 1000
    a = rng.standard_normal(n).astype(np.float32)
    b = rng.standard_normal(n).astype(np.float32)
    out = wp.zeros(n, dtype=float)
    wp.launch(assign_chain, dim=n, inputs=[wp.array(a), wp.array(b), out])
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    np.testing.assert_allclose(out.numpy(), a64 * b64 + a64 - b64, rtol=1e-5, atol=1e-6)


def test_tuple_unpacking(wp, rng):
    n = 257
    a = rng.uniform(-100, 100, n).astype(np.float32)
    o0, o1, o2 = (wp.zeros(n, dtype=float) for _ in range(3))
    wp.launch(unpack, dim=n, inputs=[wp.array(a)], outputs=[o0, o1, o2])
    a64 = a.astype(np.float64)
    np.testing.assert_allclose(o0.numpy(), 2 * a64, rtol=1e-6)
    np.testing.assert_allclose(o1.numpy(), a64 + 1, rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(o2.numpy(), 6 * a64, rtol=1e-6, atol=1e-5)


def test_augmented_assignment(wp, rng):
    n = 500
    a = rng.standard_normal(n).astype(np.float32)
    k = rng.integers(-1000, 1000, n).astype(np.int32)
    out = wp.zeros(n, dtype=float)
    iout = wp.zeros(n, dtype=int)
    wp.launch(augmented, dim=n, inputs=[wp.array(a), wp.array(k)], outputs=[out, iout])
    ref = ((a.astype(np.float64) + 1.5) * 2.0 - 0.25) / 4.0 + 1.0
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(iout.numpy(), (k.astype(np.int64) + 7) * 3 - 2)


@wp.kernel
def rebind_to_other_types(a: wp.array3d(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    sub = a[1]                 # array(float64, 2)
    out[0] = sub[2, 3]
    sub = a[1, 2]              # the same name, now array(float64, 1): straight-line code
    out[1] = sub[3]
    sub = a[1, 2, 3] * 2.0     # and a float64
    out[2] = sub


def test_a_name_rebound_to_another_type_in_straight_line_code(wp, rng):
    x = rng.standard_normal((3, 4, 5)) * 1e100
    out = wp.zeros(3, dtype=wp.float64)
    wp.launch(rebind_to_other_types, dim=1, inputs=[wp.array(x, dtype=wp.float64), out])
    np.testing.assert_array_equal(out.numpy(), [x[1, 2, 3], x[1, 2, 3], 2.0 * x[1, 2, 3]])


def test_a_name_keeps_its_type_inside_a_branch(wp, kernel_module):
    mod = kernel_module("""
@wp.kernel
def k(a: wp.array(dtype=float), flag: int):
    x = a[0]
    if flag > 0:
        x = wp.vec3(1.0)
    a[0] = x
""")
    with pytest.raises(Exception, match="inside a branch or loop"):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float), 1])
