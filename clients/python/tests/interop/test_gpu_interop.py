"""GPU interop (skipped without a CUDA device the daemon can run kernels on): a Torch tensor
made from a weft GPU array has the array's __cuda_array_interface__ data pointer and sees
kernel writes after the documented synchronization; DLPack export of GPU arrays; CPU data on a
GPU launch and GPU tensors on a CPU launch are clear errors."""
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
    with pytest.raises(BufferError):
        a.__dlpack__(dl_device=(1, 0), copy=False)


def test_device_mismatch_errors(wp, cuda, torch):
    with pytest.raises(Exception, match="launched on cuda"):
        wp.launch(add_one, dim=4, inputs=[np.zeros(4, np.float32)], device=cuda)
    if torch.cuda.is_available():
        with pytest.raises(Exception, match="launched on cpu"):
            wp.launch(add_one, dim=4, inputs=[torch.zeros(4, device="cuda")], device="cpu")
