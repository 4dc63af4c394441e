"""NumPy interop: wp.from_numpy / wp.array(ndarray) copies, np.array(w) and np.asarray(w)
through __array_interface__ (zero-copy views of the slab), dtype_to_numpy/dtype_from_numpy,
NumPy arrays and __array_interface__/__array__ objects as launch arguments (copied in and back,
or used in place when they already view a weft array), and the errors for unsupported dtypes,
mismatched devices and element layouts."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def scale_add(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def vec_norms(v: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp.length(v[i])


def test_dtype_conversions_round_trip(wp):
    for name in ["bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32",
                 "uint64", "float16", "float32", "float64"]:
        t = getattr(wp, name)
        np_type = wp.dtype_to_numpy(t)
        assert np.dtype(np_type).name == name
        assert wp.dtype_from_numpy(np_type) is t
    with pytest.raises(TypeError):
        wp.dtype_from_numpy(np.complex64)


def test_from_numpy_and_array_copy(wp, rng):
    data = rng.standard_normal((50, 3))
    a = wp.from_numpy(data, dtype=wp.vec3d)
    b = wp.array(data)
    assert a.shape == (50,) and a.dtype is wp.vec3d
    assert b.shape == (50, 3) and b.dtype is wp.float64
    np.testing.assert_array_equal(a.numpy(), data)
    data[0, 0] = 1234.0                                     # copies: the source is independent
    assert a.numpy()[0, 0] != 1234.0 and b.numpy()[0, 0] != 1234.0


def test_np_array_of_weft_array_via_array_interface(wp, rng):
    values = rng.standard_normal(16).astype(np.float32)
    w = wp.array(values, dtype=float, device="cpu")
    iface = w.__array_interface__
    assert iface["data"][0] == w.ptr and iface["typestr"] == "<f4"
    view = np.asarray(w)
    assert view.ctypes.data == w.ptr                        # zero-copy
    view[3] = 99.0
    assert w.numpy()[3] == 99.0
    copied = np.array(w)
    np.testing.assert_array_equal(copied, w.numpy())
    assert copied.ctypes.data != w.ptr


def test_numpy_launch_arguments_are_copied_back(wp, rng):
    x = rng.standard_normal(300).astype(np.float32)
    y = rng.standard_normal(300).astype(np.float32)
    expected = 2.5 * x.astype(np.float64) + y.astype(np.float64)
    wp.launch(scale_add, dim=300, inputs=[x, y, 2.5], device="cpu")
    np.testing.assert_allclose(y, expected, rtol=1e-6, atol=1e-6)


def test_numpy_view_of_weft_array_is_used_in_place(wp, rng):
    x = wp.array(rng.standard_normal(64).astype(np.float32), device="cpu")
    y = wp.zeros(64, dtype=float, device="cpu")
    y_view = y.numpy()                                      # a NumPy view of the slab
    x_ref = x.numpy().astype(np.float64)
    wp.launch(scale_add, dim=64, inputs=[x.numpy(), y_view, 3.0], device="cpu")
    # the kernel wrote the weft array itself (no temporary): y sees it through the daemon
    np.testing.assert_allclose(y.numpy(), 3.0 * x_ref, rtol=1e-6)
    # a strided view of the slab is used in place as well
    wp.launch(scale_add, dim=32, inputs=[x.numpy()[::2], y_view[1::2], 1.0], device="cpu")
    expected = 3.0 * x_ref
    expected[1::2] += x_ref[::2]
    np.testing.assert_allclose(y.numpy(), expected, rtol=1e-6, atol=1e-6)


def test_array_interface_and_array_protocol_objects(wp, rng):
    values = rng.standard_normal((20, 3)).astype(np.float32)

    class Interface:                                        # exposes only __array_interface__
        def __init__(self, a):
            self._a = a
            self.__array_interface__ = a.__array_interface__

    class Protocol:                                          # exposes only __array__
        def __init__(self, a):
            self._a = a

        def __array__(self, dtype=None, copy=None):
            return self._a

    out1 = wp.zeros(20, dtype=float, device="cpu")
    out2 = np.zeros(20, dtype=np.float32)
    wp.launch(vec_norms, dim=20, inputs=[Interface(values), out1], device="cpu")
    wp.launch(vec_norms, dim=20, inputs=[Protocol(values), Interface(out2)], device="cpu")
    expected = np.linalg.norm(values.astype(np.float64), axis=1)
    np.testing.assert_allclose(out1.numpy(), expected, rtol=1e-6)
    np.testing.assert_allclose(out2, expected, rtol=1e-6)


def test_launch_argument_errors(wp):
    y = wp.zeros(4, dtype=float, device="cpu")
    with pytest.raises(Exception, match="unsupported dtype complex64"):
        wp.launch(scale_add, dim=4, inputs=[np.zeros(4, np.complex64), y, 1.0], device="cpu")
    with pytest.raises(Exception, match=r"trailing dimensions must be \(3,\)"):
        wp.launch(vec_norms, dim=4, inputs=[np.zeros((4, 2), np.float32), y], device="cpu")
    with pytest.raises(Exception, match="not contiguous"):
        wp.launch(vec_norms, dim=4, inputs=[np.zeros((4, 6), np.float32)[:, ::2], y],
                  device="cpu")
    with pytest.raises(RuntimeError, match=r"expects an array of type array\(ndim=1, dtype=float32\), "
                                           r"but passed value has type object"):
        wp.launch(scale_add, dim=4, inputs=[object(), y, 1.0], device="cpu")
