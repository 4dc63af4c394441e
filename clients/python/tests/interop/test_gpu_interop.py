"""GPU interop (skipped without a CUDA device the daemon can run kernels on): a Torch tensor
made from a weft GPU array has the array's __cuda_array_interface__ data pointer and sees
kernel writes after the documented synchronization; DLPack export of GPU arrays; CPU data on a
GPU launch and GPU tensors on a CPU launch are clear errors; Numba both ways through
__cuda_array_interface__ (numba.cuda.as_cuda_array of a weft array, Numba device arrays in
launches, written in place)."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def add_one(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] + 1.0


def test_to_torch_of_gpu_array_is_zero_copy(wp, cuda, torch, rng):
    if not torch.cuda.is_available():
        pytest.skip("Torch has no CUDA device")
    values = rng.standard_normal(256).astype(np.float32)
    a = wp.array(values, device=cuda)
    t = wp.to_torch(a)
    assert t.device.type == "cuda"
    assert t.data_ptr() == a.__cuda_array_interface__["data"][0]
    wp.launch(add_one, dim=256, inputs=[a], device=cuda)
    wp.synchronize()
    np.testing.assert_allclose(t.cpu().numpy(), values.astype(np.float64) + 1.0, rtol=1e-6)
    t.mul_(2.0)
    torch.cuda.synchronize()
    np.testing.assert_allclose(a.numpy(), 2.0 * (values.astype(np.float64) + 1.0), rtol=1e-6)


def test_dlpack_device_of_gpu_array(wp, cuda):
    a = wp.zeros(4, dtype=float, device=cuda)
    assert a.__dlpack_device__() == (2, cuda.ordinal)
    with pytest.raises((BufferError, AttributeError)):   # AttributeError: no IPC mapping
        a.__dlpack__(dl_device=(1, 0), copy=False)


def test_device_mismatch_errors(wp, cuda, torch):
    with pytest.raises(Exception, match="launched on cuda"):
        wp.launch(add_one, dim=4, inputs=[np.zeros(4, np.float32)], device=cuda)
    if torch.cuda.is_available():
        with pytest.raises(Exception, match="launched on cpu"):
            wp.launch(add_one, dim=4, inputs=[torch.zeros(4, device="cuda")], device="cpu")


@wp.kernel
def scale_sum(x: wp.array(dtype=float), s: float, total: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] * s
    wp.atomic_add(total, 0, x[i])


def _torch_cuda(torch):
    if not torch.cuda.is_available():
        pytest.skip("Torch has no CUDA device")


def test_torch_cuda_tensor_as_launch_argument(wp, cuda, torch, rng):
    """A Torch CUDA tensor passed to wp.launch: imported by CUDA IPC in place where the client
    and weftd can (else moved into weft memory once, or copied and written back), writes seen
    by Torch and Torch's writes seen by the next launch."""
    _torch_cuda(torch)
    values = rng.standard_normal(5000).astype(np.float32)
    t = torch.tensor(values, device="cuda")
    total = wp.zeros(1, dtype=float, device=cuda)
    wp.launch(scale_sum, dim=t.shape[0], inputs=[t, 2.0, total], device=cuda)
    np.testing.assert_allclose(t.cpu().numpy(), values * 2.0, rtol=1e-6)
    t.add_(1.0)                       # Torch work before the next launch is visible to it
    total.zero_()
    wp.launch(scale_sum, dim=t.shape[0], inputs=[t, 3.0, total], device=cuda)
    ref = (values.astype(np.float64) * 2.0 + 1.0) * 3.0
    np.testing.assert_allclose(t.cpu().numpy(), ref, rtol=1e-5)
    np.testing.assert_allclose(total.numpy()[0], ref.sum(), rtol=1e-4, atol=1e-2)
    a = wp.from_torch(t)
    if a.ptr is not None:
        assert a.ptr == t.data_ptr()  # imported (or moved): zero-copy
    print("path:", "zero-copy" if a.ptr == t.data_ptr() else "copy")


def test_cupy_array_as_launch_argument_and_from_dlpack(wp, cuda, rng):
    cp = pytest.importorskip("cupy", reason="CuPy is not installed")
    values = rng.standard_normal(777).astype(np.float32)
    c = cp.asarray(values)
    total = wp.zeros(1, dtype=float, device=cuda)
    wp.launch(scale_sum, dim=c.size, inputs=[c, 0.5, total], device=cuda)
    np.testing.assert_allclose(cp.asnumpy(c), values * 0.5, rtol=1e-6)   # copied back
    np.testing.assert_allclose(total.numpy()[0], (values.astype(np.float64) * 0.5).sum(),
                               rtol=1e-4, atol=1e-3)
    a = wp.from_dlpack(c)
    assert a.device == cuda
    np.testing.assert_array_equal(a.numpy(), cp.asnumpy(c))
    strided = cp.asarray(rng.standard_normal((40, 6)).astype(np.float32))[:, ::2]
    wp.launch(add_one, dim=1, inputs=[cp.zeros(1, dtype=cp.float32)], device=cuda)
    b = wp.from_dlpack(strided)
    np.testing.assert_array_equal(b.numpy(), cp.asnumpy(strided))


def test_reused_framework_block_is_never_read_stale(wp, cuda, torch):
    """A framework block freed and handed out again (Torch's caching allocator reuses it at
    once): every launch reads the memory as it is then, never an old mapping's view (views are
    imported by CUDA IPC too; test_cuda_import.py covers segments freed with empty_cache)."""
    _torch_cuda(torch)
    total = wp.zeros(1, dtype=float, device=cuda)
    base = torch.zeros(2 * 4096, device="cuda")
    seen = set()
    for k in range(1, 6):
        block = torch.full((4096,), float(k), device="cuda")
        view = block[:]               # a view: imported (or copied in and back), never moved
        seen.add(view.data_ptr())
        total.zero_()
        wp.launch(scale_sum, dim=4096, inputs=[view, 1.0, total], device=cuda)
        assert total.numpy()[0] == pytest.approx(4096.0 * k)
        del view, block               # the block goes back to Torch's cache
    print(f"distinct block addresses over 5 rounds: {len(seen)}")
    del base


def test_gpu_device_mismatch_is_a_clear_error(wp, cuda, torch):
    _torch_cuda(torch)
    from weft.interop import cuda_import, external

    t = torch.zeros(4, device="cuda:0")
    with pytest.raises(external.InteropError, match="lives on cuda:0 but the target is cuda:1"):
        cuda_import.copy_in(t, None, "cuda:1", "x")
    with pytest.raises(Exception, match="launched on cpu"):
        wp.launch(add_one, dim=4, inputs=[t], device="cpu")


@wp.kernel
def bf16_negate(x: wp.array(dtype=wp.bfloat16), out: wp.array(dtype=wp.float32)):
    i = wp.tid()
    out[i] = wp.float32(x[i])
    x[i] = -x[i]


def test_bfloat16_gpu_tensors_both_ways(wp, cuda, torch, rng):
    if not torch.cuda.is_available():
        pytest.skip("Torch has no CUDA device")
    values = rng.standard_normal(64).astype(np.float32) * 100
    t = torch.tensor(values, dtype=torch.bfloat16, device=wp.device_to_torch(cuda))
    a = wp.from_torch(t)
    assert a.dtype is wp.bfloat16 and a.ptr == t.data_ptr()
    out = wp.zeros(64, dtype=wp.float32, device=cuda)
    wp.launch(bf16_negate, dim=64, inputs=[a, out], device=cuda)
    ref = torch.tensor(values, dtype=torch.bfloat16).double().numpy()
    np.testing.assert_array_equal(out.numpy(), ref.astype(np.float32))
    back = wp.to_torch(a)
    assert back.dtype == torch.bfloat16 and back.data_ptr() == t.data_ptr()
    np.testing.assert_array_equal(t.double().cpu().numpy(), -ref)


@pytest.fixture
def ncuda(cuda):
    """numba.cuda with a CUDA device (Numba's GPU support, the numba-cuda package), or skipped
    with the reason."""
    numba_cuda = pytest.importorskip("numba.cuda", reason="Numba (numba-cuda) is not installed")
    if not numba_cuda.is_available():
        pytest.skip("Numba sees no CUDA device")
    return numba_cuda


def test_numba_sees_a_weft_array_at_the_same_pointer(wp, cuda, ncuda, rng):
    """weft -> Numba through __cuda_array_interface__: numba.cuda.as_cuda_array of a weft GPU
    array is the daemon's memory (same device pointer, no copy); Numba's writes are seen by
    weft and weft's kernel writes by Numba after wp.synchronize()."""
    values = rng.standard_normal(1000).astype(np.float32)
    a = wp.array(values, device=cuda)
    if a.ptr is None:
        pytest.skip("CUDA IPC is not available in this client")
    d = ncuda.as_cuda_array(a)
    assert d.__cuda_array_interface__["data"][0] == a.ptr and d.shape == (1000,)
    np.testing.assert_array_equal(d.copy_to_host(), values)
    fresh = rng.standard_normal(1000).astype(np.float32)
    d.copy_to_device(fresh)                  # Numba writes the daemon's memory
    ncuda.synchronize()
    np.testing.assert_array_equal(a.numpy(), fresh)
    wp.launch(add_one, dim=1000, inputs=[a], device=cuda)
    wp.synchronize()
    np.testing.assert_allclose(d.copy_to_host(), fresh.astype(np.float64) + 1.0, rtol=1e-6)
    v = ncuda.as_cuda_array(a[::4])          # a strided view: the same memory, its strides
    assert v.__cuda_array_interface__["data"][0] == a.ptr and v.strides == (16,)
    np.testing.assert_allclose(v.copy_to_host(), fresh[::4].astype(np.float64) + 1.0, rtol=1e-6)


def test_numba_device_arrays_in_weft_launches(wp, cuda, ncuda, rng):
    """Numba -> weft through __cuda_array_interface__: a Numba device array passed to wp.launch
    is written in place (Numba's copy of it sees the kernel's writes), a strided one too, and
    one of another dtype than the parameter's is a clear error."""
    values = rng.standard_normal(3001).astype(np.float32)
    d = ncuda.to_device(values)
    total = wp.zeros(1, dtype=float, device=cuda)
    wp.launch(scale_sum, dim=d.size, inputs=[d, 0.5, total], device=cuda)
    wp.synchronize()
    np.testing.assert_allclose(d.copy_to_host(), values.astype(np.float64) * 0.5, rtol=1e-6)
    np.testing.assert_allclose(total.numpy()[0], (values.astype(np.float64) * 0.5).sum(),
                               rtol=1e-4, atol=1e-3)
    s = d[::3]
    total.zero_()
    wp.launch(scale_sum, dim=s.size, inputs=[s, 4.0, total], device=cuda)
    wp.synchronize()
    ref = values.astype(np.float64) * 0.5
    ref[::3] *= 4.0
    np.testing.assert_allclose(d.copy_to_host(), ref, rtol=1e-6)
    wrong = ncuda.to_device(np.arange(8, dtype=np.int64))
    with pytest.raises(Exception, match="int64|dtype|float"):
        wp.launch(scale_sum, dim=8, inputs=[wrong, 1.0, total], device=cuda)


def test_wp_array_of_a_cuda_array_interface_object_is_that_memory(wp, cuda, ncuda, rng):
    """wp.array(obj) of an object with __cuda_array_interface__ (here a Numba device array)
    wraps that memory, as Warp does: same pointer, a vector dtype over its trailing dimension,
    a new shape, kernel writes seen by the owner; on a CPU target it is Warp's error."""
    values = rng.standard_normal((500, 3)).astype(np.float32)
    d = ncuda.to_device(values)
    pointer = d.__cuda_array_interface__["data"][0]
    v = wp.array(d, dtype=wp.vec3, device=cuda)
    assert v.shape == (500,) and v.dtype == wp.vec3 and v.ptr == pointer
    np.testing.assert_array_equal(v.numpy(), values)
    flat = wp.array(d, dtype=float, shape=(1500,), device=cuda, requires_grad=True)
    assert flat.shape == (1500,) and flat.ptr == pointer and flat.grad is not None
    wp.launch(add_one, dim=1500, inputs=[flat], device=cuda)
    wp.synchronize()
    np.testing.assert_allclose(d.copy_to_host(), values.astype(np.float64) + 1.0, rtol=1e-6)
    with pytest.raises(RuntimeError, match="not CUDA-capable"):
        wp.array(d, device="cpu")
