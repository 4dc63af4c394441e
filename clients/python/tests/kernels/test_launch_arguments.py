"""wp.launch argument checking and packing: wrong argument count, wrong dtype, wrong ndim,
a scalar for an array and an array for a scalar are clear Python errors raised before
anything is sent; dim as int or tuple of up to 4; zero-size launches do nothing; scalars of
every dtype, vectors, matrices, quats and transforms as values; None for an array."""
import numpy as np
import pytest

import weft as wp
from weft._kernel.errors import WeftLaunchError


@wp.kernel
def takes_values(i8: wp.int8, u16: wp.uint16, i64: wp.int64, u64: wp.uint64, h: wp.float16,
                 d: wp.float64, b: wp.bool, v: wp.vec3, m: wp.mat22, q: wp.quat,
                 t: wp.transform, out: wp.array(dtype=wp.float64)):
    out[0] = wp.float64(i8)
    out[1] = wp.float64(u16)
    out[2] = wp.float64(i64)
    out[3] = wp.float64(u64)
    out[4] = wp.float64(h)
    out[5] = d
    if b:
        out[6] = wp.float64(1.0)
    out[7] = wp.float64(v[0] + v[1] + v[2])
    out[8] = wp.float64(m[0, 1] - m[1, 0])
    out[9] = wp.float64(q[3])
    out[10] = wp.float64(t.p[2] + t.q[0])


@wp.kernel
def maybe_array(a: wp.array(dtype=float), out: wp.array(dtype=int)):
    out[0] = 2           # does not touch `a`: None is a valid (null) array argument


@wp.kernel
def simple(a: wp.array(dtype=float), s: float):
    a[wp.tid()] = s


def test_every_value_type(wp):
    out = wp.zeros(11, dtype=wp.float64)
    wp.launch(takes_values, dim=1, inputs=[
        -100, 65000, -2**40, 2**63 + 5, 0.5, 1.0 / 3.0, True, wp.vec3(1.0, 2.0, 3.0),
        wp.mat22(1.0, 2.0, 3.0, 4.0), wp.quat(0.0, 0.0, 0.0, 1.0),
        wp.transform(wp.vec3(1.0, 2.0, 3.0), wp.quat(0.5, 0.0, 0.0, 0.5)), out])
    np.testing.assert_array_equal(out.numpy(), [-100, 65000, -2**40, float(2**63 + 5), 0.5,
                                                1.0 / 3.0, 1.0, 6.0, -1.0, 1.0, 3.5])


def test_tuples_and_numpy_as_values(wp):
    out = wp.zeros(11, dtype=wp.float64)
    wp.launch(takes_values, dim=1, inputs=[
        np.int8(3), 7, 9, 11, np.float16(0.25), np.float64(2.0), False, (1.0, 1.0, 1.0),
        np.array([[0.0, 5.0], [1.0, 0.0]]), (0.0, 0.0, 0.0, 2.0), [0, 0, 1, 0.5, 0, 0, 1], out])
    np.testing.assert_array_equal(out.numpy(), [3, 7, 9, 11, 0.25, 2.0, 0.0, 3.0, 4.0, 2.0, 1.5])


def test_none_array(wp):
    out = wp.zeros(1, dtype=int)
    wp.launch(maybe_array, dim=1, inputs=[None, out])
    assert out.numpy()[0] == 2


def test_argument_errors_are_raised_before_sending(wp):
    a = wp.zeros(4, dtype=float)
    with pytest.raises(TypeError, match="number of arguments"):
        wp.launch(simple, dim=4, inputs=[a])
    with pytest.raises(TypeError, match=r"'a'.*dtype float32.*int32"):
        wp.launch(simple, dim=4, inputs=[wp.zeros(4, dtype=int), 1.0])
    with pytest.raises(TypeError, match=r"'a'.*1 dimension"):
        wp.launch(simple, dim=4, inputs=[wp.zeros((2, 2), dtype=float), 1.0])
    with pytest.raises(TypeError, match=r"'s'"):
        wp.launch(simple, dim=4, inputs=[a, a])
    with pytest.raises(TypeError, match=r"'a'"):
        wp.launch(simple, dim=4, inputs=[3.0, 1.0])
    with pytest.raises(WeftLaunchError, match="1 to 4"):
        wp.launch(simple, dim=(1, 1, 1, 1, 1), inputs=[a, 1.0])
    # nothing was queued: the array is untouched and the next sync has no error
    wp.synchronize()
    np.testing.assert_array_equal(a.numpy(), 0.0)


def test_dims_and_empty_launch(wp):
    a = wp.zeros(6, dtype=float)
    wp.launch(simple, dim=0, inputs=[a, 1.0])
    wp.launch(simple, dim=(0, 3), inputs=[a, 1.0])
    np.testing.assert_array_equal(a.numpy(), 0.0)
    wp.launch(simple, dim=(6,), inputs=[a, 2.0])
    np.testing.assert_array_equal(a.numpy(), 2.0)


def test_launches_are_batched(wp, weftd):
    # many launches, one sync: the results are all there, in order
    a = wp.zeros(8, dtype=float)
    for k in range(200):
        wp.launch(simple, dim=8, inputs=[a, float(k)])
    np.testing.assert_array_equal(a.numpy(), 199.0)
