"""JAX GPU arrays with weft (skipped with the reason where JAX has no CUDA backend or the client
cannot use CUDA IPC): wp.from_jax of a JAX CUDA array is imported by CUDA IPC in place (the
same device pointer) where the driver can export XLA's memory with a legacy IPC handle, and is
a copy otherwise (XLA's allocator on the lent H100, jax 0.11.2: cuIpcGetMemHandle answers
CUDA_ERROR_INVALID_VALUE, not cudaMalloc memory; with XLA_PYTHON_CLIENT_ALLOCATOR=platform too); wp.to_jax of a weft GPU array is a JAX array
over the weft memory (the same device pointer); values written by a weft launch are what JAX
reads, compared with a float64 NumPy reference."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def scale_into(x: wp.array(dtype=float), s: float, y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * s


def test_from_jax_and_to_jax_on_the_gpu_are_zero_copy(wp, jgpu, rng):
    jax, gpu, cuda = jgpu
    n = 4096
    values = rng.standard_normal(n).astype(np.float32)
    x = jax.device_put(values, gpu)
    x.block_until_ready()
    a = wp.from_jax(x)
    assert a.device.is_cuda
    from weft import _cuda_ipc

    try:
        _cuda_ipc.export_allocation(0, x.unsafe_buffer_pointer())
        exportable = True
    except _cuda_ipc.CudaError:
        exportable = False               # not cudaMalloc memory: copied (docs/interop.md)
    assert (a.ptr == x.unsafe_buffer_pointer()) == exportable
    out = wp.zeros(n, dtype=float, device=cuda)
    wp.launch(scale_into, dim=n, inputs=[a, 3.0, out], device=cuda)
    y = wp.to_jax(out)
    assert y.unsafe_buffer_pointer() == out.ptr, "to_jax copied"
    np.testing.assert_allclose(np.asarray(y), values.astype(np.float64) * 3.0, rtol=1e-6)
    z = (y * 2.0).block_until_ready()          # JAX work on weft memory
    np.testing.assert_allclose(np.asarray(z), values.astype(np.float64) * 6.0, rtol=1e-6)


def test_bfloat16_crosses_both_ways_on_the_gpu(wp, jgpu, rng):
    """A JAX bfloat16 CUDA array (DLPack kDLBfloat) becomes a weft bfloat16 array with the same
    values, and back; any other dtype asked for is refused (Warp's aliasing rule)."""
    jax, gpu, cuda = jgpu
    import jax.numpy as jnp

    values = rng.uniform(-1e3, 1e3, 1000).astype(np.float32)
    values[:4] = [0.0, -0.0, 1e-30, 3.0e38]
    xb = jax.device_put(jnp.asarray(values, dtype=jnp.bfloat16), gpu)
    a = wp.from_jax(xb)
    assert a.dtype == wp.bfloat16 and a.device.is_cuda and a.shape == (1000,)
    expect = np.asarray(xb.astype(jnp.float32))
    np.testing.assert_array_equal(a.numpy().astype(np.float32), expect)
    b = wp.from_jax(xb, dtype=wp.bfloat16)
    np.testing.assert_array_equal(b.numpy().astype(np.float32), expect)
    with pytest.raises(RuntimeError, match="bfloat16"):
        wp.from_jax(xb, dtype=wp.float16)
    w = wp.array(values, dtype=wp.bfloat16, device=cuda)
    j = wp.to_jax(w)
    assert j.dtype == jnp.bfloat16
    np.testing.assert_allclose(np.asarray(j.astype(jnp.float32)), values, rtol=1e-2)
