"""weft.types without a daemon: type strings, Warp's named types, vector/matrix values in
Python scope, NumPy dtype conversions and value_to_bytes against NumPy's own encoding."""
import builtins

import numpy as np
import pytest

import weft as wp
from weft import types

SCALARS = [
    (wp.bool, np.bool_, "bool"), (wp.int8, np.int8, "int8"), (wp.int16, np.int16, "int16"),
    (wp.int32, np.int32, "int32"), (wp.int64, np.int64, "int64"), (wp.uint8, np.uint8, "uint8"),
    (wp.uint16, np.uint16, "uint16"), (wp.uint32, np.uint32, "uint32"),
    (wp.uint64, np.uint64, "uint64"), (wp.float16, np.float16, "float16"),
    (wp.float32, np.float32, "float32"), (wp.float64, np.float64, "float64"),
]


@pytest.mark.parametrize("wp_type,np_type,name", SCALARS)
def test_scalar_type_str_and_numpy_round_trip(wp_type, np_type, name):
    assert types.type_str(wp_type) == name
    assert wp_type._type_str == name
    assert wp_type._shape_ == ()
    assert wp_type._length_ == 1
    assert wp_type._wp_scalar_type_ is wp_type
    assert wp.dtype_to_numpy(wp_type) is np_type
    assert wp.dtype_from_numpy(np_type) is wp_type
    assert wp.dtype_from_numpy(np.dtype(np_type)) is wp_type
    assert types.type_size_in_bytes(wp_type) == np.dtype(np_type).itemsize


def test_python_types_map_like_warp():
    assert types.type_str(builtins.float) == "float32"
    assert types.type_str(builtins.int) == "int32"
    assert types.type_str(builtins.bool) == "bool"
    assert types.type_str(wp.Any) == "any"
    assert wp.dtype_to_numpy(builtins.float) is np.float32


def test_unsupported_numpy_dtype_raises():
    with pytest.raises(TypeError, match="Cannot convert"):
        wp.dtype_from_numpy(np.complex64)
    with pytest.raises(TypeError, match="Cannot convert"):
        wp.dtype_to_numpy(wp.vec3)


@pytest.mark.parametrize("name,expected", [
    ("vec2", "vec(2,float32)"), ("vec3", "vec(3,float32)"), ("vec4", "vec(4,float32)"),
    ("vec2h", "vec(2,float16)"), ("vec3d", "vec(3,float64)"), ("vec2i", "vec(2,int32)"),
    ("vec4ub", "vec(4,uint8)"), ("vec3ul", "vec(3,uint64)"), ("vec3b", "vec(3,int8)"),
    ("mat22", "mat(2,2,float32)"), ("mat33", "mat(3,3,float32)"), ("mat44d", "mat(4,4,float64)"),
    ("mat33h", "mat(3,3,float16)"), ("quat", "quat(float32)"), ("quath", "quat(float16)"),
    ("quatd", "quat(float64)"), ("transform", "transform(float32)"),
    ("transformd", "transform(float64)"), ("spatial_vector", "vec(6,float32)"),
    ("spatial_vectord", "vec(6,float64)"), ("spatial_matrix", "mat(6,6,float32)"),
])
def test_named_types_have_canonical_strings(name, expected):
    t = getattr(wp, name)
    assert types.type_str(t) == expected
    assert t._type_str == expected


def test_vector_and_matrix_factories():
    assert wp.types.vector(3, wp.float32) is wp.vec3
    assert wp.types.vector(3, float) is wp.vec3
    assert wp.types.vector(2, int) is wp.vec2i
    vec5 = wp.types.vector(length=5, dtype=wp.float64)
    assert types.type_str(vec5) == "vec(5,float64)"
    assert vec5._shape_ == (5,) and vec5._length_ == 5 and vec5._wp_scalar_type_ is wp.float64
    m = wp.types.matrix(shape=(2, 3), dtype=wp.float16)
    assert types.type_str(m) == "mat(2,3,float16)"
    assert m._shape_ == (2, 3) and m._length_ == 6
    assert types.type_size_in_bytes(m) == 12
    assert types.type_size_in_bytes(wp.transform) == 28
    with pytest.raises(ValueError):
        wp.types.vector(-1, float)
    with pytest.raises(ValueError):
        wp.types.matrix((2, -3), float)
    # length 0: the type of an empty slice, as in Warp (no values to hold)
    assert wp.types.vector(0, float)._length_ == 0 and wp.types.vector(0, float)()._data.size == 0


def test_vector_values_behave_like_warp_python_scope():
    rng = np.random.default_rng(1)
    a_np, b_np = rng.standard_normal(3), rng.standard_normal(3)
    a, b = wp.vec3d(a_np), wp.vec3d(*b_np)
    assert len(a) == 3
    np.testing.assert_allclose(np.asarray(a + b), a_np + b_np)
    np.testing.assert_allclose(np.asarray(a - b), a_np - b_np)
    np.testing.assert_allclose(np.asarray(a * 2.5), a_np * 2.5)
    np.testing.assert_allclose(np.asarray(2.5 * a), a_np * 2.5)
    np.testing.assert_allclose(np.asarray(a / 4.0), a_np / 4.0)
    np.testing.assert_allclose(np.asarray(-a), -a_np)
    assert a.x == a_np[0] and a.y == a_np[1] and a.z == a_np[2]
    assert a[-1] == a_np[2]
    a[1] = 7.0
    assert a[1] == 7.0 and a.y == 7.0
    a.z = -1.0
    assert a[2] == -1.0
    assert wp.vec3(1.0) == wp.vec3(1.0, 1.0, 1.0)
    assert wp.vec3(1, 2, 3) == (1.0, 2.0, 3.0)
    assert wp.vec3(1, 2, 3) != wp.vec3(1, 2, 4)
    assert list(wp.vec2i(3, 4)) == [3, 4]
    assert isinstance(wp.vec2i(3, 4)[0], int)
    with pytest.raises(ValueError):
        wp.vec3(1.0, 2.0)
    with pytest.raises(IndexError):
        wp.vec3()[3]


def test_float32_vector_rounds_to_float32():
    v = wp.vec3(0.1, 0.2, 0.3)
    np.testing.assert_array_equal(np.asarray(v), np.float32([0.1, 0.2, 0.3]))


def test_matrix_values():
    rng = np.random.default_rng(2)
    m_np = rng.standard_normal((3, 3))
    v_np = rng.standard_normal(3)
    m = wp.mat33d(m_np)
    assert m[1, 2] == m_np[1, 2]
    np.testing.assert_allclose(np.asarray(m[1]), m_np[1])
    np.testing.assert_allclose(np.asarray(m @ wp.vec3d(v_np)), m_np @ v_np)
    np.testing.assert_allclose(np.asarray(m * m), m_np @ m_np)
    np.testing.assert_allclose(np.asarray(m + m), 2 * m_np)
    rows = wp.mat22(wp.vec2(1, 2), wp.vec2(3, 4))
    np.testing.assert_array_equal(np.asarray(rows), [[1, 2], [3, 4]])
    assert wp.mat22(1, 2, 3, 4) == rows
    m[0, 0] = 5.0
    assert m[0, 0] == 5.0
    assert np.asarray(wp.mat44()).shape == (4, 4)


def test_quat_and_transform_defaults():
    np.testing.assert_array_equal(np.asarray(wp.quat()), [0, 0, 0, 1])
    t = wp.transform(wp.vec3(1, 2, 3), wp.quat(0, 0, 0, 1))
    np.testing.assert_array_equal(np.asarray(t), [1, 2, 3, 0, 0, 0, 1])
    np.testing.assert_array_equal(np.asarray(t.p), [1, 2, 3])
    np.testing.assert_array_equal(np.asarray(wp.transform()), [0, 0, 0, 0, 0, 0, 1])
    # the parts are settable (Warp's t.p = ..., t.q = ...), with the component count checked
    t.p = wp.vec3(-4.5, 5.0, 6.0)
    t.q = (0.0, 0.6, 0.0, 0.8)
    np.testing.assert_array_equal(np.asarray(t), np.array([-4.5, 5, 6, 0, 0.6, 0, 0.8], dtype=np.float32))
    assert t.p == wp.vec3(-4.5, 5.0, 6.0)
    with pytest.raises(ValueError, match="takes 4 components, got 3"):
        t.q = wp.vec3(1, 2, 3)


@pytest.mark.parametrize("wp_type,np_type,name", SCALARS)
def test_value_to_bytes_scalars_match_numpy(wp_type, np_type, name):
    rng = np.random.default_rng(3)
    for _ in range(10):
        if np_type is np.bool_:
            value = bool(rng.integers(0, 2))
        elif np.issubdtype(np_type, np.integer):
            info = np.iinfo(np_type)
            value = int(rng.integers(info.min, info.max, endpoint=True, dtype=np_type))
        else:
            value = float(rng.standard_normal() * 1000)
        expected = np.asarray(value, dtype=np.dtype(np_type).newbyteorder("<")).tobytes()
        assert types.value_to_bytes(wp_type, value) == expected


def test_value_to_bytes_hard_cases():
    assert types.value_to_bytes(wp.float16, 1.0) == b"\x00\x3c"
    assert types.value_to_bytes(wp.float16, 65504.0) == b"\xff\x7b"
    assert types.value_to_bytes(wp.bool, True) == b"\x01"
    assert types.value_to_bytes(wp.int64, -1) == b"\xff" * 8
    assert types.value_to_bytes(wp.uint64, 2**64 - 1) == b"\xff" * 8
    assert types.value_to_bytes(builtins.float, 1.5) == np.float32(1.5).tobytes()
    assert types.value_to_bytes(wp.float32, wp.float32(2.5)) == np.float32(2.5).tobytes()
    assert types.value_to_bytes(wp.float32, float("inf")) == np.float32(np.inf).tobytes()


def test_value_to_bytes_composites():
    rng = np.random.default_rng(4)
    m = rng.standard_normal((3, 3))
    assert types.value_to_bytes(wp.mat33, m) == m.astype("<f4").tobytes()
    assert types.value_to_bytes(wp.mat33, wp.mat33(m)) == m.astype("<f4").tobytes()
    assert types.value_to_bytes(wp.vec3h, 1.0) == np.float16([1, 1, 1]).tobytes()
    assert types.value_to_bytes(wp.vec3, (1, 2, 3)) == np.float32([1, 2, 3]).tobytes()
    assert types.value_to_bytes(wp.transform, wp.transform()) == \
        np.float32([0, 0, 0, 0, 0, 0, 1]).tobytes()
    with pytest.raises(ValueError):
        types.value_to_bytes(wp.vec3, (1.0, 2.0))


def test_array_annotations_need_no_daemon():
    a = wp.array(dtype=wp.vec3)
    assert a.ndim == 1 and a.size == 0 and a._handle == 0
    assert types.type_str(a) == "array(vec(3,float32),1)"
    assert types.type_str(wp.array(dtype=float, ndim=2)) == "array(float32,2)"
    assert types.type_str(wp.array2d(dtype=wp.int8)) == "array(int8,2)"
    assert types.type_str(wp.array(dtype=wp.Any)) == "array(any,1)"
    assert wp.array(dtype=float)._ref().handle == 0


def test_bracket_array_annotations():
    alias = wp.array[wp.vec3]
    assert alias.dtype is wp.vec3 and alias.ndim == 1
    alias2 = wp.array2d[float]
    assert alias2.dtype is wp.float32 and alias2.ndim == 2
    assert types.type_str(alias2) == "array(float32,2)"
    assert types.type_str(wp.array4d(dtype=wp.mat22)) == "array(mat(2,2,float32),4)"


@pytest.mark.parametrize("wp_type,np_type,name", SCALARS)
def test_scalar_class_hierarchy_and_ctypes_like_warp(wp_type, np_type, name):
    import ctypes

    if name == "bool":
        assert not issubclass(wp_type, types.scalar_base)
    elif name.startswith(("int", "uint")):
        assert issubclass(wp_type, types.int_base) and not issubclass(wp_type, types.float_base)
    else:
        assert issubclass(wp_type, types.float_base) and not issubclass(wp_type, types.int_base)
    assert ctypes.sizeof(wp_type._type_) == np.dtype(np_type).itemsize
    # the bases are not dtypes
    for base in (types.scalar_base, types.int_base, types.float_base):
        assert not types.is_dtype(base)
    value = wp_type(1)
    assert ctypes.c_float(value).value == 1.0 and ctypes.c_bool(value).value is True
    if name != "bool" and not name.startswith("float"):
        assert ctypes.c_int(value).value == 1
        assert wp_type._type_(-1).value == np.array(-1).astype(np_type).item()


@pytest.mark.parametrize("name", ["int8", "uint8", "uint16", "uint32", "uint64", "int64"])
def test_integer_components_wrap_like_c(name):
    dtype = getattr(wp, name)
    np_t = np.dtype(name)
    v = wp.types.vector(4, dtype)(1, 2, 3, 4)
    v[0] = -1
    v[1:3] = (-2, 300)
    expected = np.array([-1, -2, 300, 4]).astype(np_t)
    assert list(v) == expected.tolist()
    m = wp.types.matrix((2, 2), dtype)(1, 2, 3, 4)
    m[1, 0] = -3
    assert m[1, 0] == np.array(-3).astype(np_t).item()


def test_matrix_from_vectors_in_python_scope():
    rng = np.random.default_rng()
    rows = rng.standard_normal((3, 4))
    vecs = [wp.types.vector(4, wp.float64)(*r) for r in rows]
    m = wp.matrix_from_rows(*vecs)
    assert type(m)._shape_ == (3, 4)
    np.testing.assert_array_equal(np.asarray(m), rows)
    c = wp.matrix_from_cols(*vecs)
    assert type(c)._shape_ == (4, 3)
    np.testing.assert_array_equal(np.asarray(c), rows.T)
    assert c.get_col(1) == vecs[1]
    assert c.get_row(2) == wp.types.vector(3, wp.float64)(*rows[:, 2])
    c.set_col(0, vecs[2])
    np.testing.assert_array_equal(np.asarray(c)[:, 0], rows[2])
    with pytest.raises(TypeError):
        wp.matrix_from_rows(wp.vec3(1.0, 2.0, 3.0), wp.vec2(1.0, 2.0))
    with pytest.raises(TypeError):
        wp.matrix_from_cols()


def test_log_levels_and_deterministic_mode_like_warp():
    assert (wp.LOG_DEBUG, wp.LOG_INFO, wp.LOG_WARNING, wp.LOG_ERROR) == (10, 20, 30, 40)
    assert wp.DeterministicMode.NOT_GUARANTEED == 0
    assert wp.config.DeterministicMode is wp.DeterministicMode


def test_type_size_counts_scalars_like_warp():
    """wp.types.type_size: scalars in one value (1 for scalars, Python int/float and structs)."""
    @wp.struct
    class Pair:
        a: float
        b: wp.vec3

    assert types.type_size(float) == 1 and types.type_size(int) == 1
    assert types.type_size(wp.float16) == 1 and types.type_size(wp.uint64) == 1
    assert types.type_size(wp.vec3) == 3 and types.type_size(wp.vec4h) == 4
    assert types.type_size(wp.mat33) == 9 and types.type_size(wp.types.matrix((2, 3), wp.float64)) == 6
    assert types.type_size(wp.quat) == 4 and types.type_size(wp.transform) == 7
    assert types.type_size(wp.spatial_vector) == 6
    assert types.type_size(Pair) == 1


def test_vector_arrays_from_data_of_other_inner_shapes(wp):
    """Warp's rules when data's inner dimensions are not the dtype's shape: trailing 1s go, then
    an innermost dimension of the dtype's length, or a multiple of it, holds the components."""
    rng = np.random.default_rng()
    x = rng.standard_normal((7, 3, 1)).astype(np.float32)
    a = wp.array(x, dtype=wp.vec3, device="cpu")
    assert a.shape == (7,)
    np.testing.assert_array_equal(a.numpy(), x[:, :, 0])
    y = rng.standard_normal((2, 12))
    b = wp.array(y, dtype=wp.vec3d, device="cpu")
    assert b.shape == (2, 4)
    np.testing.assert_array_equal(b.numpy().reshape(2, 12), y)
    m = wp.array(y.reshape(6, 4), dtype=wp.mat22d, device="cpu")
    assert m.shape == (6,)
    np.testing.assert_array_equal(m.numpy().reshape(6, 4), y.reshape(6, 4))
    with pytest.raises(RuntimeError, match="a multiple of 3"):
        wp.array(np.ones((3, 4), dtype=np.float32), dtype=wp.vec3, device="cpu")


def test_slices_of_vectors_and_matrices_in_python_scope_are_warp_values():
    rng = np.random.default_rng()
    data = rng.uniform(-100, 100, size=16).astype(np.float32)
    v = wp.vec4(*data[:4])
    part = v[1:]
    assert type(part).__name__ == "vec3f" and np.array_equal(np.asarray(part), data[1:4])
    v[1:] += wp.vec3(1.0, 2.0, 3.0)              # a vector, not a list concatenation
    np.testing.assert_allclose(np.asarray(v), data[:4] + [0.0, 1.0, 2.0, 3.0], rtol=1e-6)
    m = wp.mat44(*data)
    ref = data.reshape(4, 4)
    assert np.array_equal(np.asarray(m[1:3, ::2]), ref[1:3, ::2]) and m[1:3, ::2]._shape_ == (2, 2)
    assert np.array_equal(np.asarray(m[::-1, :1]), ref[::-1, :1])
    assert np.array_equal(np.asarray(m[:, 2]), ref[:, 2]) and np.array_equal(np.asarray(m[3]), ref[3])
    assert m[2, 3] == ref[2, 3]
    m[1:, :2] += wp.types.matrix((3, 2), wp.float32)(*([1.0] * 6))
    want = ref.copy()
    want[1:, :2] += 1.0
    np.testing.assert_allclose(np.asarray(m), want, rtol=1e-6)
    # integer slices keep the stored (wrapped) values
    u = wp.vec4ul(1, 2, 3, 4)
    u[0] = -1
    assert tuple(u[0:2]) == (2**64 - 1, 2)
    # slices selecting nothing compare equal whatever their shapes, as in kernels
    assert m[4:] == wp.types.matrix((0, 0), wp.float32)()
    assert v[4:] == wp.types.vector(0, wp.float32)()
    # % is C's remainder (the dividend's sign), componentwise
    np.testing.assert_array_equal(np.asarray(wp.vec3i(-7, 7, 9) % wp.vec3i(4, -4, 5)), [-3, 3, 4])
    np.testing.assert_allclose(np.asarray(wp.vec2(-7.5, 7.5) % wp.vec2(2.0, -2.0)), [-1.5, 1.5])
