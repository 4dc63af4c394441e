"""wp.get_cuda_kernel_properties and wp.get_suggested_block_size (weft/_kernel/kernel_properties.py,
ModuleService.KernelProperties) on cpu and cuda:0: Warp's answers and errors on the CPU (a
(1, 1) suggestion, RuntimeError for properties), argument checks, and on a GPU the driver's
registers, local memory and occupancy suggestion, with a launch at the suggested block size
exact against float64. Hostile requests: unknown modules and kernels, the CPU as a GPU."""
from __future__ import annotations

import numpy as np
import pytest

KERNELS = """
@wp.kernel
def axpy(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64), a: wp.float64):
    i = wp.tid()
    y[i] = a * x[i] + y[i]

@wp.kernel
def generic_scale(x: wp.array(dtype=Any), s: float):
    i = wp.tid()
    x[i] = x[i] * type(x[i])(s)
"""


@pytest.fixture
def kernels(kernel_module):
    return kernel_module("from typing import Any\n" + KERNELS)


def test_arguments_and_the_cpu(wp, kernels, device):
    with pytest.raises(TypeError, match="expected a Warp kernel"):
        wp.get_cuda_kernel_properties(lambda: None, device="cuda:0" if device != "cpu" else None)
    for bad in (0, -2, True, 1.5):
        with pytest.raises(ValueError, match="block_dim must be a positive integer"):
            wp.get_cuda_kernel_properties(kernels.axpy, block_dim=bad)
    if device == "cpu":
        assert wp.get_suggested_block_size(kernels.axpy) == (1, 1)
        with pytest.raises(RuntimeError, match="not a CUDA device"):
            wp.get_cuda_kernel_properties(kernels.axpy)
    else:
        with pytest.raises(RuntimeError, match="generic"):
            wp.get_cuda_kernel_properties(kernels.generic_scale)


def test_hostile_requests_are_clear_errors(wp, kernels, device):
    from weft import _runtime

    rt = _runtime.get_runtime()
    req = _runtime.module_pb2.KernelPropertiesRequest
    with pytest.raises(Exception, match="is not a GPU"):
        rt.call(rt.module_stub.KernelProperties, req(module_id="0" * 64, kernel="axpy", device="cpu"))
    if device == "cpu":
        return
    with pytest.raises(Exception, match="unknown module"):
        rt.call(rt.module_stub.KernelProperties, req(module_id="f" * 64, kernel="axpy", device=device))
    wp.get_cuda_kernel_properties(kernels.axpy)        # compiled for the GPU now
    from weft._kernel.module import compile_kernel

    compiled, _ = compile_kernel(kernels.axpy, device)
    with pytest.raises(Exception, match="has no kernel"):
        rt.call(rt.module_stub.KernelProperties, req(module_id=compiled.module_id, kernel="../etc", device=device))
    cpu_compiled, _ = compile_kernel(kernels.axpy, "cpu")
    with pytest.raises(Exception, match="compiled for the CPU"):
        rt.call(rt.module_stub.KernelProperties, req(module_id=cpu_compiled.module_id, kernel="axpy", device=device))


def test_the_drivers_answers_on_a_gpu(wp, kernels, device, rng):
    if device == "cpu":
        pytest.skip("CUDA kernel properties")
    props = wp.get_cuda_kernel_properties(kernels.axpy)
    assert set(props) == {"register_count", "local_memory_size"}
    assert 1 <= props["register_count"] <= 255 and props["local_memory_size"] >= 0
    assert wp.get_cuda_kernel_properties(kernels.axpy, block_dim=128) == props
    block, min_grid = wp.get_suggested_block_size(kernels.axpy)
    assert 32 <= block <= 1024 and block % 32 == 0
    assert min_grid >= wp.get_device(device).sm_count
    n = 100_003
    x = rng.standard_normal(n) * 10.0 ** rng.uniform(-8, 8, n)
    y = rng.standard_normal(n) * 10.0 ** rng.uniform(-8, 8, n)
    xa, ya = wp.array(x, dtype=wp.float64), wp.array(y, dtype=wp.float64)
    wp.launch(kernels.axpy, dim=n, inputs=[xa, ya, 1.5], block_dim=block)
    # float64 reference; an FMA on the GPU rounds once where NumPy rounds twice: within a few
    # ulps of the terms' magnitude (cancellation makes a relative bound on the result meaningless)
    err = np.abs(ya.numpy() - (1.5 * x + y))
    assert np.all(err <= 4.5e-16 * (np.abs(1.5 * x) + np.abs(y))), err.max()
