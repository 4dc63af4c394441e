"""DLPack both ways on the CPU: np.from_dlpack / torch / jax importing weft arrays zero-copy
(same data pointer, writes seen on both sides), wp.from_dlpack of NumPy, Torch and JAX producers
and of legacy capsules (zero-copy for weft memory, a copy otherwise), __dlpack_device__, the
stream rule of the array API standard, versioned capsules, and errors."""
import numpy as np
import pytest

import weft as wp


def test_dlpack_device_and_numpy_import_is_zero_copy(wp, rng):
    values = rng.standard_normal((8, 3)).astype(np.float32)
    a = wp.array(values, dtype=wp.vec3, device="cpu")
    assert a.__dlpack_device__() == (1, 0)
    view = np.from_dlpack(a)
    assert view.shape == (8, 3) and view.dtype == np.float32
    assert view.ctypes.data == a.ptr
    view[2, 1] = 7.5                                     # NumPy -> weft
    assert a.numpy()[2, 1] == 7.5
    a.fill_(wp.vec3(1.0, 2.0, 3.0))                      # weft -> NumPy (after a sync point)
    wp.synchronize()
    np.testing.assert_array_equal(view[5], [1.0, 2.0, 3.0])


def test_versioned_and_legacy_capsules(wp):
    a = wp.zeros(4, dtype=wp.float64, device="cpu")
    legacy = wp.to_dlpack(a)
    assert "dltensor" in repr(legacy)
    versioned = a.__dlpack__(max_version=(1, 0))
    assert "dltensor" in repr(versioned)
    back = wp.from_dlpack(legacy)
    assert back.ptr == a.ptr and back.dtype is wp.float64 and back.shape == (4,)
    with pytest.raises(Exception, match="already consumed|unconsumed"):
        wp.from_dlpack(legacy)


def test_stream_must_be_none_for_cpu_arrays(wp):
    a = wp.zeros(4, dtype=float, device="cpu")
    with pytest.raises(BufferError, match="stream must be None"):
        a.__dlpack__(stream=1)
    with pytest.raises(BufferError, match="without a copy"):
        a.__dlpack__(dl_device=(2, 0))


def test_from_dlpack_of_numpy_copies_foreign_memory(wp, rng):
    values = rng.standard_normal(10)
    a = wp.from_dlpack(values)
    assert a.dtype is wp.float64 and a.ptr != values.ctypes.data
    np.testing.assert_array_equal(a.numpy(), values)
    # a NumPy view of weft memory comes back as the same weft memory
    w = wp.array(values, device="cpu")
    again = wp.from_dlpack(w.numpy()[2:7])
    assert again.ptr == w.ptr + 2 * 8 and again.shape == (5,)


def test_dlpack_round_trips_with_torch(wp, torch, rng):
    values = rng.standard_normal((6, 4)).astype(np.float32)
    w = wp.array(values, device="cpu")
    t = torch.utils.dlpack.from_dlpack(w)                # weft -> Torch
    assert t.data_ptr() == w.ptr
    t[1, 2] = -3.0
    assert w.numpy()[1, 2] == -3.0
    w2 = wp.from_dlpack(t)                               # Torch (weft memory) -> weft
    assert w2.ptr == w.ptr and w2.shape == (6, 4)
    t_legacy = torch.utils.dlpack.from_dlpack(wp.to_dlpack(w))
    assert t_legacy.data_ptr() == w.ptr
    foreign = torch.arange(5, dtype=torch.int64)
    w3 = wp.from_dlpack(torch.utils.dlpack.to_dlpack(foreign))   # legacy capsule of Torch
    assert w3.dtype is wp.int64
    np.testing.assert_array_equal(w3.numpy(), np.arange(5))


def test_dlpack_round_trips_with_jax(wp, jax, rng):
    values = rng.standard_normal(32)
    w = wp.array(values, device="cpu")
    j = jax.dlpack.from_dlpack(w)                        # weft -> JAX
    np.testing.assert_array_equal(np.asarray(j), values)
    if j.unsafe_buffer_pointer() == w.ptr:               # JAX took the slab as it is
        w.numpy()[0] = 42.0
        assert float(j[0]) == 42.0
    x = jax.numpy.arange(12, dtype=jax.numpy.float32)
    wx = wp.from_dlpack(x)                               # JAX -> weft (a copy: JAX's memory)
    assert wx.dtype is wp.float32
    np.testing.assert_array_equal(wx.numpy(), np.arange(12, dtype=np.float32))


def test_from_dlpack_errors(wp, torch):
    with pytest.raises(TypeError, match="DLPack producer"):
        wp.from_dlpack([1, 2, 3])
    with pytest.raises(Exception, match="unsupported"):
        wp.from_dlpack(torch.zeros(3, dtype=torch.complex64))
    with pytest.raises(RuntimeError, match="Incompatible data types: DLPack float64 and Warp float32"):
        wp.from_dlpack(np.zeros(3, dtype=np.float64), dtype=wp.float32)


def test_from_dlpack_dtype_rules_follow_warp(wp):
    """wp.from_dlpack(dtype=) aliases as Warp's: bool8 as bool/int8/uint8, an integer as either
    signedness of its size, a float only as itself; other pairs raise a RuntimeError in Warp's
    words. Vector dtypes name their component's ctypes type (`_type_`), as Warp's."""
    import ctypes

    source = wp.zeros(2, dtype=wp.bool, device="cpu")
    with pytest.raises(RuntimeError, match="^Incompatible data types: DLPack bool8 and Warp float32$"):
        wp.from_dlpack(wp.to_dlpack(source), dtype=wp.float32)
    with pytest.raises(RuntimeError, match="DLPack int32 and Warp vec2h"):
        wp.from_dlpack(np.zeros((3, 2), dtype=np.int32), dtype=wp.vec2h)
    assert wp.from_dlpack(wp.to_dlpack(source), dtype=wp.uint8).dtype is wp.uint8
    ints = wp.from_dlpack(np.arange(4, dtype=np.int32), dtype=wp.uint32)
    assert ints.dtype is wp.uint32 and ints.numpy().tolist() == [0, 1, 2, 3]
    assert wp.vec2b._type_ is ctypes.c_int8 and wp.mat22d._type_ is ctypes.c_double
    assert wp.vec3h._type_ is ctypes.c_uint16 and wp.quatf._type_ is ctypes.c_float
    a = wp.zeros(5, dtype=wp.vec3us, device="cpu")
    b = wp.from_dlpack(wp.to_dlpack(a), dtype=wp.uint16)
    assert b.shape == (5, 3) and b.strides == (6, ctypes.sizeof(wp.vec3us._type_))


def test_bfloat16_through_dlpack(wp, torch, rng):
    """bfloat16 (which NumPy cannot carry) goes both ways as kDLBfloat: a weft array exports
    over its own memory, a Torch tensor (strided too) or a weft capsule imports as a
    wp.bfloat16 array holding the same bits."""
    values = (rng.standard_normal(9) * 1e3).astype(np.float32)
    ref = torch.tensor(values, dtype=torch.bfloat16)
    a = wp.array(values, dtype=wp.bfloat16)
    t = torch.from_dlpack(a)
    assert t.dtype == torch.bfloat16 and t.data_ptr() == a.ptr
    assert torch.equal(t, ref)
    back = wp.from_dlpack(wp.to_dlpack(a))
    assert back.dtype is wp.bfloat16
    np.testing.assert_array_equal(back.numpy().astype(np.float64), ref.double().numpy())
    strided = wp.from_dlpack(ref[1::3])
    assert strided.dtype is wp.bfloat16 and strided.shape == (3,)
    np.testing.assert_array_equal(strided.numpy().astype(np.float64), ref[1::3].double().numpy())
    with pytest.raises(TypeError, match="Expected a valid DLPack capsule"):
        class NotACapsule:
            def __dlpack_device__(self):
                return (1, 0)

            def __dlpack__(self, stream=None):
                return object()

        wp.from_dlpack(NotACapsule())
