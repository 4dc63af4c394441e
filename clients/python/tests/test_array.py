"""wp.array against NumPy on a real daemon: creation (every dtype, inference as Warp does),
empty/zeros/ones/full and *_like, from_numpy, numpy() zero-copy views, slices and their
fills, copy/clone/assign, reshape/flatten/view/transpose, list(), the errors Warp gives."""
import numpy as np
import pytest

@pytest.fixture(autouse=True)
def _cpu_by_default(wp):
    """These tests are about CPU arrays (zero-copy views): make cpu the default device even
    where the daemon has a GPU (Warp's default is then cuda:0)."""
    with wp.ScopedDevice("cpu"):
        yield


SCALAR_NAMES = ["bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32",
                "uint64", "float16", "float32", "float64"]


def random_values(rng, np_dtype, shape):
    np_dtype = np.dtype(np_dtype)
    if np_dtype == np.bool_:
        return rng.integers(0, 2, size=shape).astype(bool)
    if np.issubdtype(np_dtype, np.integer):
        info = np.iinfo(np_dtype)
        return rng.integers(info.min, info.max, size=shape, endpoint=True, dtype=np_dtype)
    return (rng.standard_normal(shape) * 100).astype(np_dtype)


@pytest.mark.parametrize("name", SCALAR_NAMES)
def test_array_round_trips_every_scalar_dtype(wp, name):
    rng = np.random.default_rng(abs(hash(name)) % 2**32)
    dtype = getattr(wp, name)
    values = random_values(rng, wp.dtype_to_numpy(dtype), (37, 5))
    a = wp.array(values, dtype=dtype, device="cpu")
    assert a.shape == (37, 5) and a.ndim == 2 and a.size == 185 and len(a) == 37
    assert a.dtype is dtype
    assert a.strides == (5 * values.itemsize, values.itemsize)
    assert a.device == "cpu" and a.device.is_cpu
    out = a.numpy()
    assert out.dtype == values.dtype
    np.testing.assert_array_equal(out, values)


def test_dtype_inference_follows_warp(wp):
    assert wp.array([1.0, 2.0]).dtype is wp.float64
    assert wp.array([1, 2]).dtype is wp.int64
    assert wp.array([True, False]).dtype is wp.bool
    assert wp.array(np.zeros(3, np.float32)).dtype is wp.float32
    assert wp.array(np.zeros(3, np.uint16)).dtype is wp.uint16
    assert wp.array([wp.vec3(1, 2, 3), wp.vec3(4, 5, 6)]).dtype is wp.vec3
    scalar = wp.array(2.5)
    assert scalar.shape == (1,) and scalar.numpy()[0] == 2.5


def test_list_of_tuples_with_vec3_dtype(wp):
    points = [(1.0, 2.0, 3.0), (4.0, 5.0, 6.0), (-1.5, 0.25, 9.0)]
    a = wp.array(points, dtype=wp.vec3)
    assert a.shape == (3,) and a.dtype is wp.vec3
    np.testing.assert_array_equal(a.numpy(), np.float32(points))
    assert a.list() == [wp.vec3(p) for p in points]


def test_composite_dtypes_from_numpy(wp):
    rng = np.random.default_rng(5)
    m = rng.standard_normal((4, 6, 3, 3))
    a = wp.array(m, dtype=wp.mat33d)
    assert a.shape == (4, 6) and a.dtype is wp.mat33d
    np.testing.assert_array_equal(a.numpy(), m)
    flat = rng.standard_normal(12).astype(np.float32)
    v = wp.array(flat, dtype=wp.vec4)
    assert v.shape == (3,)
    np.testing.assert_array_equal(v.numpy(), flat.reshape(3, 4))
    q = wp.array(rng.standard_normal((5, 4)), dtype=wp.quatd)
    assert q.shape == (5,) and wp.types.type_str(q.dtype) == "quat(float64)"
    with pytest.raises(RuntimeError, match="innermost"):
        wp.array(np.zeros((4, 5)), dtype=wp.vec3)
    for dtype in (wp.vec2b, wp.mat33d, wp.quat):    # an empty list: an empty array of that dtype
        e = wp.array([], dtype=dtype)
        assert e.shape == (0,) and e.size == 0 and e.dtype is dtype


def test_data_with_shape_reshapes(wp):
    data = np.arange(24, dtype=np.int32)
    a = wp.array(data, shape=(2, 3, 4))
    np.testing.assert_array_equal(a.numpy(), data.reshape(2, 3, 4))
    with pytest.raises(RuntimeError, match="reshape"):
        wp.array(data, shape=(5, 5))


@pytest.mark.parametrize("name", ["float32", "float64", "int32", "uint8", "float16", "bool"])
def test_empty_zeros_ones_full(wp, name):
    dtype = getattr(wp, name)
    np_dtype = wp.dtype_to_numpy(dtype)
    shape = (3, 7)
    z = wp.zeros(shape, dtype=dtype)
    np.testing.assert_array_equal(z.numpy(), np.zeros(shape, np_dtype))
    o = wp.ones(shape, dtype=dtype)
    np.testing.assert_array_equal(o.numpy(), np.ones(shape, np_dtype))
    f = wp.full(shape, 1 if name == "bool" else 3, dtype=dtype)
    np.testing.assert_array_equal(f.numpy(), np.full(shape, 1 if name == "bool" else 3, np_dtype))
    e = wp.empty(shape, dtype=dtype)
    assert e.shape == shape and e.dtype is dtype and e.numpy().shape == shape
    for like, expected in ((wp.zeros_like(f), 0), (wp.ones_like(f), 1),
                           (wp.full_like(f, 1), 1)):
        assert like.shape == shape and like.dtype is dtype
        np.testing.assert_array_equal(like.numpy(), np.full(shape, expected, np_dtype))
    assert wp.empty_like(f).shape == shape


def test_defaults_and_value_inference(wp):
    assert wp.zeros(4).dtype is wp.float32
    assert wp.empty(4).dtype is wp.float32
    assert wp.full(3, 2).dtype is wp.int32
    assert wp.full(3, 2.0).dtype is wp.float32
    assert wp.full(3, True).dtype is wp.bool
    v = wp.full(5, wp.vec3(1, 2, 3))
    assert v.dtype is wp.vec3
    np.testing.assert_array_equal(v.numpy(), np.tile(np.float32([1, 2, 3]), (5, 1)))
    m = wp.full((2, 2), 1.5, dtype=wp.mat22)
    np.testing.assert_array_equal(m.numpy(), np.full((2, 2, 2, 2), 1.5, np.float32))
    assert wp.zeros(0).size == 0 and wp.zeros(0).numpy().shape == (0,)


def test_from_numpy_infers_vectors_and_matrices(wp):
    rng = np.random.default_rng(6)
    assert wp.from_numpy(rng.standard_normal(8)).dtype is wp.float64
    v = wp.from_numpy(rng.standard_normal((8, 3)).astype(np.float32))
    assert v.dtype is wp.vec3 and v.shape == (8,)
    m = wp.from_numpy(rng.standard_normal((8, 3, 3)).astype(np.float32))
    assert m.dtype is wp.mat33 and m.shape == (8,)
    s = wp.from_numpy(np.arange(6, dtype=np.int32), dtype=wp.int32, shape=(2, 3))
    np.testing.assert_array_equal(s.numpy(), np.arange(6).reshape(2, 3))


def test_numpy_is_a_zero_copy_view(wp):
    a = wp.zeros(1000, dtype=wp.float32)
    view1 = a.numpy()
    view2 = a.numpy()
    assert view1.__array_interface__["data"][0] == view2.__array_interface__["data"][0]
    assert view1.__array_interface__["data"][0] == a.ptr
    view1[10:20] = 4.0
    b = wp.clone(a)
    expected = np.zeros(1000, np.float32)
    expected[10:20] = 4.0
    np.testing.assert_array_equal(b.numpy(), expected)
    # writes by the daemon show up in the existing view
    a.fill_(2.0)
    wp.synchronize()
    np.testing.assert_array_equal(view1, np.full(1000, 2.0, np.float32))


def test_numpy_view_keeps_memory_alive(wp):
    a = wp.array(np.arange(100, dtype=np.float64))
    view = a.numpy()
    del a
    import gc

    gc.collect()
    wp.zeros(100, dtype=wp.float64)  # would reuse the block if the view did not hold it
    wp.synchronize()
    np.testing.assert_array_equal(view, np.arange(100, dtype=np.float64))


def test_array_interface_and_array_protocol(wp):
    data = np.random.default_rng(7).standard_normal((4, 5)).astype(np.float32)
    a = wp.array(data)
    assert a.__array_interface__["shape"] == (4, 5)
    assert a.__array_interface__["typestr"] == "<f4"
    np.testing.assert_array_equal(np.asarray(a), data)
    np.testing.assert_array_equal(np.array(a, dtype=np.float64), data.astype(np.float64))
    assert np.asarray(a).__array_interface__["data"][0] == a.ptr


def test_slices_are_views_and_fill(wp):
    ref = np.zeros(16, np.float32)
    a = wp.zeros(16, dtype=wp.float32)
    a[:4].fill_(1.0)
    ref[:4] = 1.0
    a[1:9:2].fill_(2.0)
    ref[1:9:2] = 2.0
    a[-3:].fill_(3.0)
    ref[-3:] = 3.0
    a[10:12].zero_()
    ref[10:12] = 0
    np.testing.assert_array_equal(a.numpy(), ref)
    view = a[2:10:3]
    assert view._handle == a._handle and view.shape == (3,) and view.strides == (12,)
    np.testing.assert_array_equal(view.numpy(), ref[2:10:3])
    assert a[100:200].size == 0


def test_multidimensional_indexing(wp):
    rng = np.random.default_rng(8)
    ref = rng.standard_normal((4, 5, 6))
    a = wp.array(ref)
    np.testing.assert_array_equal(a[2].numpy(), ref[2])
    np.testing.assert_array_equal(a[1, 3].numpy(), ref[1, 3])
    np.testing.assert_array_equal(a[:, 2].numpy(), ref[:, 2])
    np.testing.assert_array_equal(a[1:3, ::2, 4:].numpy(), ref[1:3, ::2, 4:])
    np.testing.assert_array_equal(a[-1, ..., 0].numpy(), ref[-1, ..., 0])
    a[:, 1].fill_(9.0)
    ref[:, 1] = 9.0
    a[3, 4].fill_(-1.0)
    ref[3, 4] = -1.0
    np.testing.assert_array_equal(a.numpy(), ref)
    with pytest.raises(IndexError):
        a[4]
    with pytest.raises(IndexError):
        a[0, 0, 0, 0]
    with pytest.raises(IndexError):
        a[::-1]


def test_python_scope_element_access_errors_like_warp(wp):
    a = wp.zeros(4)
    with pytest.raises(TypeError, match="Item assignment is not supported"):
        a[0] = 1.0
    with pytest.raises(TypeError, match="Item assignment is not supported"):
        a[1:3] = 1.0
    with pytest.raises(RuntimeError, match="Item indexing is not supported"):
        a[0]
    np.testing.assert_array_equal(a.numpy(), np.zeros(4, np.float32))


def test_copy_with_offsets_and_count(wp):
    rng = np.random.default_rng(9)
    src_np = rng.standard_normal(50)
    dst_np = rng.standard_normal(40)
    src, dst = wp.array(src_np), wp.array(dst_np)
    wp.copy(dst, src, dest_offset=5, src_offset=10, count=20)
    dst_np[5:25] = src_np[10:30]
    np.testing.assert_array_equal(dst.numpy(), dst_np)
    whole = wp.empty(50, dtype=wp.float64)
    wp.copy(whole, src)
    np.testing.assert_array_equal(whole.numpy(), src_np)
    grid = wp.zeros((5, 10), dtype=wp.float64)
    wp.copy(grid, src)  # same size, different shape: flat copy
    np.testing.assert_array_equal(grid.numpy(), src_np.reshape(5, 10))
    # Warp's wording for each refusal
    with pytest.raises(RuntimeError, match=r"copy a range of 20 element\(s\) to destination offset \(30\) "
                                           r"exceeds the destination size \(40\)"):
        wp.copy(dst, src, dest_offset=30, count=20)
    with pytest.raises(RuntimeError, match=r"from source offset \(45\) exceeds the source size \(50\)"):
        wp.copy(dst, src, src_offset=45, count=10)
    with pytest.raises(RuntimeError, match="destination dtype=float32, source dtype=float64"):
        wp.copy(wp.zeros(4, dtype=wp.float32), wp.zeros(4, dtype=wp.float64))
    strided = wp.zeros((6, 6), dtype=wp.float64)[::2, ::2]
    with pytest.raises(RuntimeError, match="only supported for 1-D non-contiguous arrays"):
        wp.copy(wp.zeros_like(strided), strided, count=2)
    with pytest.raises(RuntimeError, match=r"destination shape=\(3, 2\), source shape=\(3, 3\)"):
        wp.copy(wp.zeros((6, 2), dtype=wp.float64)[::2], strided)
    indexed = wp.indexedarray(src, [wp.array(np.array([1, 3], dtype=np.int32))])
    assert not indexed.is_contiguous and src.is_contiguous
    with pytest.raises(RuntimeError, match="not supported when copying to/from non-contiguous indexed"):
        wp.copy(wp.zeros(2, dtype=wp.float64), indexed, count=1)
    np.testing.assert_array_equal(dst.numpy(), dst_np)


def test_copy_between_dtypes_of_one_size_moves_bytes(wp):
    """Warp's rule: wp.copy moves bytes between any two dtypes of one element size (contiguous,
    strided, with offsets, through the daemon's copy); a size mismatch is refused."""
    rng = np.random.default_rng(11)
    f = rng.standard_normal(12).astype(np.float32)
    ints = wp.zeros(12, dtype=wp.int32)
    wp.copy(ints, wp.array(f))
    np.testing.assert_array_equal(ints.numpy(), f.view(np.int32))
    back = wp.zeros((6, 2), dtype=wp.float32)
    wp.copy(back[::2], wp.array(f.view(np.uint32)).reshape((6, 2))[1::2])
    expected = np.zeros((6, 2), dtype=np.float32)
    expected[::2] = f.reshape(6, 2)[1::2]
    np.testing.assert_array_equal(back.numpy(), expected)
    windows = wp.zeros(8, dtype=wp.uint32)
    wp.copy(windows, wp.array(f), dest_offset=2, src_offset=5, count=4)
    np.testing.assert_array_equal(windows.numpy()[2:6], f[5:9].view(np.uint32))
    vec = wp.zeros(4, dtype=wp.vec3)
    wp.copy(vec, wp.array(f.view(np.int32).reshape(4, 3), dtype=wp.vec3i))
    np.testing.assert_array_equal(vec.numpy(), f.reshape(4, 3))
    with pytest.raises(RuntimeError, match="destination dtype=float64, source dtype=float32"):
        wp.copy(wp.zeros(12, dtype=wp.float64), wp.array(f))


def test_strided_copy_and_clone(wp):
    rng = np.random.default_rng(10)
    ref = rng.standard_normal((6, 8)).astype(np.float32)
    a = wp.array(ref)
    column = wp.clone(a[:, 3])
    assert column.is_contiguous and column._handle != a._handle
    np.testing.assert_array_equal(column.numpy(), ref[:, 3])
    b = wp.zeros((6, 8), dtype=wp.float32)
    wp.copy(b[::2, 1::3], a[1::2, ::3])
    expected = np.zeros_like(ref)
    expected[::2, 1::3] = ref[1::2, ::3]
    np.testing.assert_array_equal(b.numpy(), expected)


def test_assign(wp):
    rng = np.random.default_rng(11)
    a = wp.zeros((3, 4), dtype=wp.float64)
    values = rng.standard_normal((3, 4))
    a.assign(values)
    np.testing.assert_array_equal(a.numpy(), values)
    b = wp.zeros((3, 4), dtype=wp.float64)
    b.assign(a)
    np.testing.assert_array_equal(b.numpy(), values)
    b[:, 1].assign([1.0, 2.0, 3.0])
    values[:, 1] = [1.0, 2.0, 3.0]
    np.testing.assert_array_equal(b.numpy(), values)
    v = wp.zeros(2, dtype=wp.vec3)
    v.assign([(1, 2, 3), (4, 5, 6)])
    np.testing.assert_array_equal(v.numpy(), [[1, 2, 3], [4, 5, 6]])
    with pytest.raises(RuntimeError, match="Cannot assign"):
        v.assign(np.zeros(5))


def test_reshape_flatten_view_transpose(wp):
    ref = np.arange(24, dtype=np.int32).reshape(2, 3, 4)
    a = wp.array(ref)
    r = a.reshape((4, -1))
    assert r.shape == (4, 6) and r._handle == a._handle
    np.testing.assert_array_equal(r.numpy(), ref.reshape(4, 6))
    np.testing.assert_array_equal(a.flatten().numpy(), ref.reshape(-1))
    np.testing.assert_array_equal(a.view(wp.uint32).numpy(), ref.view(np.uint32))
    np.testing.assert_array_equal(a.view(wp.float32).numpy(), ref.view(np.float32))
    t = a.transpose()
    assert t.shape == (4, 3, 2) and not t.is_contiguous
    np.testing.assert_array_equal(t.numpy(), ref.transpose())
    np.testing.assert_array_equal(a.transpose((0, 2, 1)).numpy(), ref.transpose(0, 2, 1))
    with pytest.raises(RuntimeError):
        a.reshape((5, 5))
    with pytest.raises(RuntimeError):
        t.reshape(-1)
    with pytest.raises(TypeError, match="cannot create an array view with dtype float64"):
        a.view(wp.float64)
    np.testing.assert_array_equal(t.contiguous().numpy(), ref.transpose())


def test_view_between_vectors_and_scalars(wp):
    """array.view as Warp's: a vector/matrix array seen as its scalar gains the element's
    dimensions, a scalar array with contiguous trailing dimensions seen as a vector/matrix
    loses them (one element: shape (1,)); sizes that do not fit raise Warp's TypeError."""
    ref = np.arange(16, dtype=np.float32).reshape(4, 4)
    v = wp.array(ref, dtype=wp.vec4, device="cpu")
    f = v.view(float)
    assert f.shape == (4, 4) and f.strides == (16, 4) and f.dtype is wp.float32
    np.testing.assert_array_equal(f.numpy(), ref)
    m = wp.array(ref.reshape(4, 2, 2), dtype=wp.mat22, device="cpu").view(wp.float32)
    assert m.shape == (4, 2, 2) and m.strides == (16, 8, 4)
    back = wp.array(ref, dtype=float, device="cpu").view(wp.vec4)
    assert back.shape == (4,) and back.strides == (16,) and back.dtype is wp.vec4
    np.testing.assert_array_equal(back.numpy(), ref)
    one = wp.array([[1, 2], [3, 4]], dtype=float, device="cpu").view(wp.mat22)
    assert one.shape == (1,)
    np.testing.assert_array_equal(one.numpy()[0], [[1, 2], [3, 4]])
    with pytest.raises(TypeError, match="source scalar dtype float32 has size 4 bytes, but "
                                        "target dtype has size 8 bytes"):
        v.view(wp.float64)
    with pytest.raises(TypeError, match="source dtype has size 4 bytes, but target scalar "
                                        "dtype float64 has size 8 bytes"):
        wp.array(ref, dtype=float, device="cpu").view(wp.vec4d)
    with pytest.raises(RuntimeError, match="is not compatible with the requested data type"):
        wp.array(ref, dtype=float, device="cpu").view(wp.vec3)


def test_list_and_str(wp):
    a = wp.array([1.5, 2.5, 3.5], dtype=wp.float32)
    assert a.list() == [1.5, 2.5, 3.5]
    assert str(a) == str(np.float32([1.5, 2.5, 3.5]))
    m = wp.array(np.eye(2, dtype=np.float32)[None], dtype=wp.mat22)
    assert m.list() == [wp.mat22(1, 0, 0, 1)]


def test_requires_grad_gives_zero_gradient(wp):
    a = wp.array(np.ones(10, np.float32), requires_grad=True)
    assert a.requires_grad
    assert a.grad is not None and a.grad.shape == (10,) and a.grad.dtype is wp.float32
    np.testing.assert_array_equal(a.grad.numpy(), np.zeros(10, np.float32))
    a.grad.fill_(3.0)
    np.testing.assert_array_equal(a[2:5].grad.numpy(), np.full(3, 3.0, np.float32))
    np.testing.assert_array_equal(a.numpy(), np.ones(10, np.float32))
    assert wp.zeros(3).grad is None and not wp.zeros(3).requires_grad
    assert wp.zeros_like(a).requires_grad


def test_bad_shapes_are_refused_before_the_daemon(wp):
    with pytest.raises(ValueError):
        wp.zeros((-1, 3))
    with pytest.raises(RuntimeError, match="4 dimensions"):
        wp.zeros((1, 1, 1, 1, 1))
    with pytest.raises(TypeError):
        wp.zeros("abc")


def test_many_arrays_are_freed(wp, weftd):
    import gc

    wp.synchronize()
    before = weftd.stats().arrays
    for _ in range(200):
        wp.zeros(1000)
    gc.collect()
    wp.zeros(1)  # a create drains the deferred frees
    wp.synchronize()
    after = weftd.stats().arrays
    assert after <= before + 2


def test_array_of_structs(wp):
    @wp.struct
    class Particle:
        pos: wp.vec3
        mass: wp.float64
        id: wp.int32

    items = [Particle(pos=wp.vec3(i, 2 * i, -i), mass=0.5 * i, id=i) for i in range(5)]
    a = wp.array(items, dtype=Particle)
    assert a.shape == (5,)
    records = a.numpy()
    np.testing.assert_array_equal(records["pos"], [[i, 2 * i, -i] for i in range(5)])
    np.testing.assert_array_equal(records["mass"], [0.5 * i for i in range(5)])
    np.testing.assert_array_equal(records["id"], list(range(5)))
    a[1:3].fill_(Particle(pos=wp.vec3(9, 9, 9), mass=-1.0, id=42))
    records = a.numpy()
    assert records["id"].tolist() == [0, 42, 42, 3, 4]
    assert records["mass"].tolist() == [0.0, -1.0, -1.0, 1.5, 2.0]


def _mapped(name):
    with open("/proc/self/maps") as maps:
        return any(("/dev/shm" + name) in line for line in maps)


def test_slabs_are_unmapped_when_nothing_uses_them(wp):
    import gc

    a = wp.zeros(8 << 20, dtype=wp.float32)     # 32 MiB: a slab of its own
    name = a._info.shm_name
    view = a.numpy()
    view[-1] = 5.0
    assert _mapped(name)
    del a
    gc.collect()
    assert _mapped(name), "the NumPy view must keep the memory mapped"
    assert view[-1] == 5.0
    del view
    gc.collect()
    assert not _mapped(name), "an unused slab must not stay mapped (it would pin its memory)"


def test_allocation_with_explicit_strides_reaches_exactly_its_bytes(wp):
    # gapped and transposed layouts: capacity = item + sum((dim - 1) * stride), as Warp
    a = wp.empty((3, 3), dtype=wp.int32, strides=(16, 12))
    assert (a.capacity, a.shape, a.strides) == (4 + 2 * 16 + 2 * 12, (3, 3), (16, 12))
    t = wp.zeros((5, 3), dtype=wp.vec3, strides=(12, 60))
    assert t.capacity == wp.zeros((5, 3), dtype=wp.vec3).capacity
    assert not t.numpy().any()

    @wp.kernel
    def write(x: wp.array2d(dtype=float)):
        i, j = wp.tid()
        x[i, j] = float(i * 10 + j)

    g = wp.zeros((3, 4), dtype=float, strides=(4, 12), requires_grad=True)   # column-major
    wp.launch(write, dim=(3, 4), inputs=[g])
    np.testing.assert_array_equal(g.numpy(), np.arange(3)[:, None] * 10.0 + np.arange(4)[None, :])
    assert g.grad.shape == (3, 4)
    # an empty array has no bytes and no address; bad strides are refused as Warp refuses them
    e = wp.empty((0, 3), dtype=wp.int32, strides=(4, 16))
    assert e.capacity == 0 and e.ptr is None
    assert wp.empty(0, dtype=float).ptr is None
    with pytest.raises(ValueError, match="Invalid number of strides, expected 2 strides, got 1"):
        wp.empty((0, 3), dtype=wp.int32, strides=(4,))
    with pytest.raises(NotImplementedError, match="Negative strides"):
        wp.empty((3, 3), dtype=wp.int32, strides=(16, -4))
    with pytest.raises(ValueError, match="alignment"):
        wp.empty((3, 3), dtype=wp.int32, strides=(16, 6))
