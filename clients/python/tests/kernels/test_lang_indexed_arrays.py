"""Indexed arrays (wp.indexedarray): kernel reads, writes, atomics, views and .shape through
per-dimension int32 index arrays in 1-4 dimensions (NumPy float64 references on random data),
their gradients, the host-side forms (numpy, fill_, zero_, assign, wp.copy, a[I]), and the
attacks: index values outside the data array, index arrays of the wrong dtype or rank sent
straight to the daemon, and an index array of another kind."""
from typing import Any, Literal

import numpy as np
import pytest

import weft as wp


@wp.kernel
def scale_add_1d(a: wp.indexedarray(dtype=wp.float64), out: wp.array(dtype=wp.float64), s: wp.float64):
    i = wp.tid()
    out[i] = a[i] + wp.float64(a.shape[0])
    a[i] = a[i] * s
    wp.atomic_add(a, i, wp.float64(1.0))


@wp.kernel
def scale_add_2d(a: wp.indexedarray2d(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    i, j = wp.tid()
    out[i, j] = a[i, j] + a[i][j] * wp.float64(10.0) + wp.float64(a.shape[1])
    a[i, j] = a[i, j] * wp.float64(2.0)
    wp.atomic_sub(a, i, j, wp.float64(0.5))


@wp.kernel
def read_3d(a: wp.indexedarray[wp.float64, Literal[3]], out: wp.array3d(dtype=wp.float64)):
    i, j, k = wp.tid()
    v = a[i]
    out[i, j, k] = a[i, j, k] + v[j, k] + a[i, j][k]


@wp.kernel
def read_4d(a: wp.indexedarray4d[wp.float64], out: wp.array4d(dtype=wp.float64)):
    i, j, k, l = wp.tid()
    out[i, j, k, l] = a[i, j, k, l] - a[i, j][k, l]


@wp.kernel
def inc_any(a: Any):
    i = wp.tid()
    a[i] = a[i] + 1


wp.overload(inc_any, [wp.array1d[int]])
wp.overload(inc_any, [wp.indexedarray[int]])


@wp.kernel
def square(a: wp.indexedarray(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = a[i] * a[i] * 3.0


@wp.kernel
def read_at(a: wp.indexedarray(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a[i]


@wp.kernel
def write_at(a: wp.indexedarray(dtype=float)):
    i = wp.tid()
    a[i] = 9.0


@wp.kernel
def atomic_at(a: wp.indexedarray(dtype=float)):
    i = wp.tid()
    wp.atomic_add(a, i, 9.0)


def _ix(indices, shape):
    return np.ix_(*[np.arange(n) if idx is None else idx for idx, n in zip(indices, shape)])


def _indexed(rng, data_np, pattern):
    """(indexedarray, numpy index vectors) with random index arrays where pattern[d] is True."""
    data = wp.array(data_np, dtype=wp.float64)
    idx_np, idx_wp = [], []
    for d, on in enumerate(pattern):
        if on:
            n = data_np.shape[d]
            k = int(rng.integers(1, n + 1))
            v = rng.choice(n, size=k, replace=False).astype(np.int32)
            idx_np.append(v)
            idx_wp.append(wp.array(v, dtype=wp.int32))
        else:
            idx_np.append(None)
            idx_wp.append(None)
    return data, wp.indexedarray(data, idx_wp), idx_np


def test_indexed_1d_read_write_atomic(wp, rng):
    ref = rng.standard_normal(23)
    data, ia, (idx,) = _indexed(rng, ref, [True])
    assert ia.shape == (len(idx),) and ia.ndim == 1 and ia.size == len(idx)
    out = wp.zeros(ia.size, dtype=wp.float64)
    wp.launch(scale_add_1d, dim=ia.size, inputs=[ia, out, 3.0])
    np.testing.assert_allclose(out.numpy(), ref[idx] + len(idx), rtol=1e-15)
    expect = ref.copy()
    expect[idx] = ref[idx] * 3.0 + 1.0
    np.testing.assert_allclose(data.numpy(), expect, rtol=1e-15)   # others untouched


@pytest.mark.parametrize("pattern", [(True, True), (True, False), (False, True)])
def test_indexed_2d(wp, rng, pattern):
    ref = rng.standard_normal((9, 7))
    data, ia, idx = _indexed(rng, ref, pattern)
    sel = _ix(idx, ref.shape)
    out = wp.zeros(ia.shape, dtype=wp.float64)
    wp.launch(scale_add_2d, dim=ia.shape, inputs=[ia, out])
    np.testing.assert_allclose(out.numpy(), ref[sel] + ref[sel] * 10.0 + ia.shape[1], rtol=1e-14)
    expect = ref.copy()
    expect[sel] = ref[sel] * 2.0 - 0.5
    np.testing.assert_allclose(data.numpy(), expect, rtol=1e-15)


def test_indexed_3d_4d_views(wp, rng):
    ref3 = rng.standard_normal((5, 6, 4))
    _, ia3, idx3 = _indexed(rng, ref3, (True, False, True))
    out3 = wp.zeros(ia3.shape, dtype=wp.float64)
    wp.launch(read_3d, dim=ia3.shape, inputs=[ia3, out3])
    np.testing.assert_allclose(out3.numpy(), 3.0 * ref3[_ix(idx3, ref3.shape)], rtol=1e-14)

    ref4 = rng.standard_normal((4, 3, 5, 3))
    _, ia4, idx4 = _indexed(rng, ref4, (False, True, True, True))
    out4 = wp.full(ia4.shape, 7.0, dtype=wp.float64)
    wp.launch(read_4d, dim=ia4.shape, inputs=[ia4, out4])
    np.testing.assert_array_equal(out4.numpy(), 0.0)


def test_generic_overloads(wp):
    base = wp.zeros(6, dtype=int)
    idx = wp.array([5, 0, 2], dtype=wp.int32)
    wp.launch(inc_any, dim=3, inputs=[wp.indexedarray(base, [idx])])
    wp.launch(inc_any, dim=6, inputs=[base])
    np.testing.assert_array_equal(base.numpy(), [2, 1, 2, 1, 1, 2])


def test_gradient_through_indices(wp, rng):
    # duplicate indices: the gradient of each data element sums over its uses
    x = rng.standard_normal(8).astype(np.float32)
    idx = np.array([3, 1, 3, 7, 0], dtype=np.int32)
    data = wp.array(x, dtype=float, requires_grad=True)
    ia = wp.indexedarray(data, [wp.array(idx, dtype=wp.int32)])
    y = wp.zeros(len(idx), dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square, dim=len(idx), inputs=[ia, y])
    seed = rng.standard_normal(len(idx)).astype(np.float32)
    tape.backward(grads={y: wp.array(seed, dtype=float)})
    expect = np.zeros(8, dtype=np.float64)
    np.add.at(expect, idx, 6.0 * x[idx].astype(np.float64) * seed)
    np.testing.assert_allclose(data.grad.numpy(), expect, rtol=1e-5, atol=1e-6)


def test_host_forms(wp, rng):
    ref = rng.standard_normal((6, 5, 3)).astype(np.float32)
    data = wp.array(ref, dtype=float)
    i0 = np.array([4, 0, 2], dtype=np.int32)
    i2 = np.array([2, 1], dtype=np.int32)
    I0, I2 = wp.array(i0, dtype=wp.int32), wp.array(i2, dtype=wp.int32)
    ia = data[I0, :, I2]
    assert isinstance(ia, wp.indexedarray) and ia.shape == (3, 5, 2)
    sel = np.ix_(i0, np.arange(5), i2)
    np.testing.assert_array_equal(ia.numpy(), ref[sel])
    np.testing.assert_array_equal(wp.clone(ia).numpy(), ref[sel])

    ia.fill_(2.5)
    expect = ref.copy()
    expect[sel] = 2.5
    np.testing.assert_array_equal(data.numpy(), expect)
    vals = rng.standard_normal((3, 5, 2)).astype(np.float32)
    ia.assign(vals)
    expect[sel] = vals
    np.testing.assert_array_equal(data.numpy(), expect)
    dest = wp.zeros((3, 5, 2), dtype=float)
    wp.copy(dest, ia)
    np.testing.assert_array_equal(dest.numpy(), vals)
    ia.zero_()
    expect[sel] = 0.0
    np.testing.assert_array_equal(data.numpy(), expect)
    wp.copy(ia, wp.array(vals, dtype=float))
    expect[sel] = vals
    np.testing.assert_array_equal(data.numpy(), expect)


# ---- attacks ---------------------------------------------------------------------------------

@pytest.mark.parametrize("kernel", [read_at, write_at, atomic_at])
@pytest.mark.parametrize("bad", [8, 1 << 30, -1, -(1 << 31)])
def test_hostile_index_value_is_a_bounds_error(wp, kernel, bad):
    data = wp.full(8, 1.0, dtype=float)
    neighbour = wp.full(64, 5.0, dtype=float)
    idx = wp.array([0, 3, bad, 1], dtype=wp.int32)
    ia = wp.indexedarray(data, [idx])
    args = [ia, wp.zeros(4, dtype=float)] if kernel is read_at else [ia]
    wp.launch(kernel, dim=4, inputs=args)
    with pytest.raises(wp.WeftError) as info:
        wp.synchronize()
    message = str(info.value)
    assert "out of bounds" in message and f"[{bad}]" in message and "(8,)" in message, message
    np.testing.assert_array_equal(neighbour.numpy(), 5.0)
    # the session keeps working
    ok = wp.indexedarray(data, [wp.array([7, 6], dtype=wp.int32)])
    wp.launch(write_at, dim=2, inputs=[ok])
    assert data.numpy()[7] == 9.0 and data.numpy()[6] == 9.0


def test_launch_index_past_indexed_shape(wp):
    data = wp.zeros(8, dtype=float)
    ia = wp.indexedarray(data, [wp.array([1, 2], dtype=wp.int32)])
    wp.launch(write_at, dim=3, inputs=[ia])      # i = 2 is past the 2 indices
    with pytest.raises(wp.WeftError) as info:
        wp.synchronize()
    assert "out of bounds" in str(info.value) and "[2]" in str(info.value)
    np.testing.assert_array_equal(data.numpy()[[0, 3, 4, 5, 6, 7]], 0.0)


def test_client_rejects_bad_index_arrays(wp):
    data = wp.zeros(8, dtype=float)
    with pytest.raises(TypeError):
        wp.indexedarray(data, [wp.array([1.0, 2.0], dtype=float)])
    with pytest.raises(ValueError):
        wp.indexedarray(data, [wp.zeros((2, 2), dtype=wp.int32)])
    with pytest.raises(ValueError):
        wp.indexedarray(data, [wp.zeros(2, dtype=wp.int32), None])


@pytest.mark.parametrize("bad_index", ["float32", "2d", "int64"])
def test_daemon_validates_index_arrays(wp, bad_index):
    """Index arrays sent straight to the daemon (past the client's checks) go through the one
    array validation: int32, 1-D, or the launch is refused."""
    from weft import _runtime
    from weft._kernel import module as module_mod
    from weft.v1 import exec_pb2, types_pb2

    device = str(wp.get_device())
    data = wp.zeros(8, dtype=float)
    bad = {"float32": wp.zeros(4, dtype=float), "2d": wp.zeros((2, 2), dtype=wp.int32),
           "int64": wp.zeros(4, dtype=wp.int64)}[bad_index]
    compiled, info = module_mod.compile_kernel(write_at, device, backward=False)
    null = exec_pb2.ArgValue(array=types_pb2.ArrayRef(handle=0))
    arg = exec_pb2.ArgValue(struct_value=exec_pb2.StructValue(
        fields=[exec_pb2.ArgValue(array=data._ref()), exec_pb2.ArgValue(array=bad._ref())] +
        [null] * 3))
    cmd = exec_pb2.Command(launch=exec_pb2.LaunchCommand(
        module_id=compiled.module_id, kernel=info.name or write_at.name, dim=[4], args=[arg],
        device=device))
    _runtime.get_runtime().submit(cmd)
    with pytest.raises(wp.WeftError) as info_err:
        wp.synchronize()
    assert "indices0" in str(info_err.value), str(info_err.value)
    np.testing.assert_array_equal(data.numpy(), 0.0)


@wp.struct
class Holder:
    values: wp.indexedarray(dtype=float)
    scale: float


@wp.struct
class Outer:
    inner: Holder


@wp.kernel
def struct_square(o: Outer, y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = o.inner.values[i] * o.inner.values[i] * o.inner.scale


def test_indexed_array_in_nested_struct_with_gradient(wp, rng):
    x = rng.standard_normal(9).astype(np.float32)
    idx = np.array([8, 2, 2, 5], dtype=np.int32)
    data = wp.array(x, dtype=float, requires_grad=True)
    h = Holder()
    h.values = wp.indexedarray(data, [wp.array(idx, dtype=wp.int32)])
    h.scale = 1.5
    o = Outer()
    o.inner = h
    y = wp.zeros(len(idx), dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(struct_square, dim=len(idx), inputs=[o, y])
    np.testing.assert_allclose(y.numpy(), 1.5 * x[idx] ** 2, rtol=1e-6)
    seed = rng.standard_normal(len(idx)).astype(np.float32)
    tape.backward(grads={y: wp.array(seed, dtype=float)})
    expect = np.zeros(9, dtype=np.float64)
    np.add.at(expect, idx, 3.0 * x[idx].astype(np.float64) * seed)
    np.testing.assert_allclose(data.grad.numpy(), expect, rtol=1e-5, atol=1e-6)


@pytest.mark.usefixtures("needs_nvrtc")
def test_kernels_compile_for_cuda_without_a_gpu(wp):
    """The native forms of indexed arrays, fixed-size arrays and slices compile under NVRTC
    (forward and adjoint), also on a machine without a GPU."""
    from test_lang_fixed_arrays import reinterpret_kernel, slice_grad, slice_kernel, struct_kernel

    for k in (scale_add_2d, read_4d, square, atomic_at, struct_square, reinterpret_kernel, slice_grad,
              slice_kernel, struct_kernel):
        report = wp.compile(k, device="cuda", arch=90)
        assert report.kernel(k.name).registers > 0
        assert report.kernel(k.name, adjoint=True).registers > 0


@pytest.mark.parametrize("member", ["wp.indexedarray(dtype=float)", "wp.array(dtype=float)"])
def test_arrays_of_structs_holding_arrays_are_refused(kernel_module, member):
    """An array whose elements hold arrays would make the kernel read array descriptors (addresses)
    from memory the client writes: the compiler refuses such parameters, also nested in structs."""
    mod = kernel_module(f'''
import weft as wp

@wp.struct
class Holder:
    values: {member}

@wp.struct
class Outer:
    many: wp.array(dtype=Holder)

@wp.kernel
def direct(a: wp.array(dtype=Holder), out: wp.array(dtype=float)):
    out[0] = a[0].values[0]

@wp.kernel
def nested(o: Outer, out: wp.array(dtype=float)):
    out[0] = o.many[0].values[0]
''')
    for k in (mod.direct, mod.nested):
        with pytest.raises(wp.WarpCodegenError, match="array inside array memory"):
            wp.compile(k, device="cpu")
