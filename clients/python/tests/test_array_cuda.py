"""GPU arrays through the daemon (skipped when it has no CUDA device): creation, fills of
slices, copies between cpu and cuda, clone/to, numpy() copies read in chunks, assign."""
import numpy as np
import pytest


@pytest.fixture
def cuda(wp):
    if not wp.is_cuda_available():
        pytest.skip("weftd has no CUDA device")
    return wp.get_cuda_device(0)


def test_cuda_is_the_default_device(wp, cuda):
    assert wp.get_device() == cuda and cuda.alias == "cuda:0"
    a = wp.zeros(4)
    assert a.device.is_cuda and a.ptr is None
    with pytest.raises(AttributeError):
        a.__array_interface__


@pytest.mark.parametrize("name", ["float32", "float64", "int32", "uint8", "float16"])
def test_cuda_round_trip(wp, cuda, name):
    rng = np.random.default_rng(20)
    dtype = getattr(wp, name)
    values = (rng.standard_normal((33, 7)) * 50).astype(wp.dtype_to_numpy(dtype))
    a = wp.array(values, dtype=dtype, device=cuda)
    assert a.device == "cuda:0"
    np.testing.assert_array_equal(a.numpy(), values)
    a[3:9, 2:5].fill_(1)
    values[3:9, 2:5] = 1
    np.testing.assert_array_equal(a.numpy(), values)
    np.testing.assert_array_equal(a[::3, 1].numpy(), values[::3, 1])


def test_cuda_cpu_copies(wp, cuda):
    rng = np.random.default_rng(21)
    ref = rng.standard_normal((100, 3)).astype(np.float32)
    host = wp.array(ref, dtype=wp.vec3, device="cpu")
    dev = host.to(cuda)
    assert dev.device.is_cuda
    np.testing.assert_array_equal(dev.numpy(), ref)
    back = wp.zeros_like(host)
    wp.copy(back, dev, dest_offset=10, src_offset=20, count=30)
    expected = np.zeros_like(ref)
    expected[10:40] = ref[20:50]
    np.testing.assert_array_equal(back.numpy(), expected)
    clone = wp.clone(dev, device="cpu")
    np.testing.assert_array_equal(clone.numpy(), ref)


def test_cuda_assign_and_large_read(wp, cuda):
    rng = np.random.default_rng(22)
    ref = rng.random(24 << 20, dtype=np.float32)   # 96 MiB: many Read chunks
    a = wp.empty(ref.size, dtype=wp.float32, device=cuda)
    a.assign(ref)
    np.testing.assert_array_equal(a.numpy(), ref)
    a[5:10].assign(np.arange(5, dtype=np.float32))
    ref[5:10] = np.arange(5)
    np.testing.assert_array_equal(a[:16].numpy(), ref[:16])
