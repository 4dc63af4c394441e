"""Language: array subscripts in 1-4 dimensions, wp.tid() in 1-4 dimensions (launch dim as a
tuple), strided views (slices), .shape and len(), arrays of vectors, and NumPy arrays passed
directly on a CPU launch with in-place writes copied back into the caller's array."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def copy1(src: wp.array(dtype=float), dst: wp.array(dtype=float)):
    i = wp.tid()
    dst[i] = src[i] + float(src.shape[0]) + float(len(src))


@wp.kernel
def copy2(src: wp.array2d(dtype=float), dst: wp.array2d(dtype=float)):
    i, j = wp.tid()
    dst[i, j] = src[i, j] * 2.0 + float(src.shape[1])


@wp.kernel
def copy3(src: wp.array3d(dtype=float), dst: wp.array3d(dtype=float)):
    i, j, k = wp.tid()
    dst[i, j, k] = src[i, j, k] + float(i * 100 + j * 10 + k)


@wp.kernel
def copy4(src: wp.array4d(dtype=float), dst: wp.array4d(dtype=float)):
    i, j, k, l = wp.tid()
    dst[i, j, k, l] = src[i, j, k, l] - float(l)


@wp.kernel
def index_math(out: wp.array(dtype=int, ndim=2)):
    i, j = wp.tid()
    out[i, j] = i * 1000 + j


@wp.kernel
def vec_array(points: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    p = points[i]
    points[i] = p * 2.0
    out[i] = p[0] + p[1] * 10.0 + p[2] * 100.0


@wp.kernel
def scale_inplace(a: wp.array(dtype=float), s: float):
    i = wp.tid()
    a[i] = a[i] * s


def test_dims_1_to_4(wp, rng):
    x1 = rng.standard_normal(33).astype(np.float32)
    d1 = wp.zeros(33, dtype=float)
    wp.launch(copy1, dim=33, inputs=[wp.array(x1), d1])
    np.testing.assert_allclose(d1.numpy(), x1 + 66.0, rtol=1e-6)

    x2 = rng.standard_normal((7, 5)).astype(np.float32)
    d2 = wp.zeros((7, 5), dtype=float)
    wp.launch(copy2, dim=(7, 5), inputs=[wp.array(x2), d2])
    np.testing.assert_allclose(d2.numpy(), x2 * 2 + 5.0, rtol=1e-6)

    x3 = rng.standard_normal((3, 4, 5)).astype(np.float32)
    d3 = wp.zeros((3, 4, 5), dtype=float)
    wp.launch(copy3, dim=(3, 4, 5), inputs=[wp.array(x3), d3])
    i, j, k = np.meshgrid(np.arange(3), np.arange(4), np.arange(5), indexing="ij")
    np.testing.assert_allclose(d3.numpy(), x3 + i * 100 + j * 10 + k, rtol=1e-6)

    x4 = rng.standard_normal((2, 3, 4, 5)).astype(np.float32)
    d4 = wp.zeros((2, 3, 4, 5), dtype=float)
    wp.launch(copy4, dim=(2, 3, 4, 5), inputs=[wp.array(x4), d4])
    np.testing.assert_allclose(d4.numpy(), x4 - np.arange(5), rtol=1e-6, atol=1e-6)


def test_tid_order_matches_numpy(wp):
    out = wp.zeros((13, 17), dtype=int)
    wp.launch(index_math, dim=(13, 17), outputs=[out])
    i, j = np.meshgrid(np.arange(13), np.arange(17), indexing="ij")
    np.testing.assert_array_equal(out.numpy(), i * 1000 + j)


def test_strided_views(wp, rng):
    base = rng.standard_normal((8, 6)).astype(np.float32)
    src = wp.array(base)
    dst = wp.zeros((4, 3), dtype=float)
    view = src[::2, 1::2]                      # strides in both dimensions
    wp.launch(copy2, dim=(4, 3), inputs=[view, dst])
    np.testing.assert_allclose(dst.numpy(), base[::2, 1::2] * 2 + 3.0, rtol=1e-6)


def test_vec3_arrays_read_and_write(wp, rng):
    p = rng.standard_normal((100, 3)).astype(np.float32)
    points = wp.array(p, dtype=wp.vec3)
    out = wp.zeros(100, dtype=float)
    wp.launch(vec_array, dim=100, inputs=[points, out])
    np.testing.assert_allclose(out.numpy(), p[:, 0] + p[:, 1] * 10 + p[:, 2] * 100,
                               rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(points.numpy(), p * 2, rtol=1e-6)


def test_numpy_arguments_are_copied_back(wp, rng):
    a = rng.standard_normal(1000).astype(np.float32)
    expected = a * 3.0
    wp.launch(scale_inplace, dim=len(a), inputs=[a, 3.0], device="cpu")
    np.testing.assert_allclose(a, expected, rtol=1e-6)
    # a list is no array (as in Warp): refused before anything is sent
    with pytest.raises(RuntimeError, match=r"argument 'a'.*expects an array of type "
                                           r"array\(ndim=1, dtype=float32\), but passed value "
                                           r"has type list"):
        wp.launch(scale_inplace, dim=3, inputs=[[1.0, 2.0, 3.0], 2.0], device="cpu")
    wp.synchronize()


@wp.kernel
def lower_bounds(arr: wp.array(dtype=wp.float64), values: wp.array(dtype=wp.float64),
                 out: wp.array2d(dtype=int)):
    i = wp.tid()
    out[i, 0] = wp.lower_bound(arr, values[i])
    out[i, 1] = wp.lower_bound(arr, 2, 7, values[i])


def test_lower_bound_as_warp(wp, rng):
    """Warp's lower_bound searches [begin, end - 1]: a value past the last element gives end - 1."""
    arr = np.sort(rng.standard_normal(10)) * 1e6
    values = np.concatenate([rng.standard_normal(20) * 2e6, arr[[0, 3, 9]], [arr[-1] * 2 + 1, -1e300, 1e300]])
    out = wp.zeros((len(values), 2), dtype=int)
    wp.launch(lower_bounds, dim=len(values), inputs=[wp.array(arr, dtype=wp.float64),
                                                     wp.array(values, dtype=wp.float64), out])
    ref_full = np.minimum(np.searchsorted(arr, values, side="left"), 9)
    ref_part = np.clip(2 + np.searchsorted(arr[2:7], values, side="left"), 2, 6)
    np.testing.assert_array_equal(out.numpy(), np.stack([ref_full, ref_part], axis=1))
