"""JAX interop on the CPU: from_jax / to_jax through DLPack (weft memory comes back as the same
allocation; JAX's own buffers are copied into a slab), the dtype/device helpers, jax_kernel
inside jax.jit (arrays, static scalars, vectors, launch and output dims) against float64
references, and the errors."""
import functools

import numpy as np
import pytest

import weft as wp


@wp.kernel
def axpy(a: wp.array(dtype=float), b: wp.array(dtype=float), s: float,
         out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = s * a[i] + b[i]


@wp.kernel
def vec_scale(v: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3),
              n: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = 0.5 * v[i]
    n[i] = wp.length(v[i])


def test_helpers(wp, jax):
    assert wp.dtype_from_jax(jax.numpy.float32) is wp.float32
    assert wp.dtype_from_jax(jax.numpy.int64) is wp.int64
    assert wp.dtype_to_jax(wp.vec3d) == jax.numpy.float64
    assert wp.dtype_from_jax(jax.numpy.bfloat16) is wp.bfloat16
    cpu = jax.devices("cpu")[0]
    assert wp.device_from_jax(cpu).is_cpu
    assert wp.device_to_jax("cpu") == cpu


def test_from_jax_and_to_jax(wp, jax, rng):
    values = rng.standard_normal((5, 3))
    x = jax.numpy.asarray(values)
    w = wp.from_jax(x, dtype=wp.vec3d)
    assert w.shape == (5,) and w.dtype is wp.vec3d
    np.testing.assert_array_equal(w.numpy(), values)
    back = wp.to_jax(w)
    np.testing.assert_array_equal(np.asarray(back), values)
    again = wp.from_jax(back, dtype=wp.vec3d)
    if back.unsafe_buffer_pointer() == w.ptr:             # JAX kept the slab: zero-copy back
        assert again.ptr == w.ptr
    np.testing.assert_array_equal(again.numpy(), values)
    with pytest.raises(TypeError, match="jax.Array"):
        wp.from_jax(values)


def test_jax_kernel_with_static_scalar(wp, jax, rng):
    from weft.jax_experimental import jax_kernel

    jax_axpy = jax_kernel(axpy)
    a = rng.standard_normal(100).astype(np.float32)
    b = rng.standard_normal(100).astype(np.float32)

    @functools.partial(jax.jit, static_argnames=["s"])
    def f(a, b, s):
        (out,) = jax_axpy(a, b, s)
        return out * 2.0

    out = np.asarray(f(jax.numpy.asarray(a), jax.numpy.asarray(b), 1.5))
    expected = 2.0 * (1.5 * a.astype(np.float64) + b.astype(np.float64))
    np.testing.assert_allclose(out, expected, rtol=1e-6, atol=1e-6)

    @jax.jit
    def traced(a, b, s):
        return jax_axpy(a, b, s)

    with pytest.raises(TypeError, match="traced"):
        traced(jax.numpy.asarray(a), jax.numpy.asarray(b), 1.5)


def test_jax_kernel_vectors_and_dims(wp, jax, rng):
    from weft.jax_experimental import jax_kernel

    jax_vec = jax_kernel(vec_scale, num_outputs=2)
    v = rng.standard_normal((9, 3)).astype(np.float32)
    half, norms = jax.jit(jax_vec)(jax.numpy.asarray(v))
    assert half.shape == (9, 3) and norms.shape == (9,)
    np.testing.assert_allclose(np.asarray(half), 0.5 * v.astype(np.float64), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(norms), np.linalg.norm(v.astype(np.float64), axis=1),
                               rtol=1e-6)
    half4, norms4 = jax_vec(jax.numpy.asarray(v), launch_dims=4,
                            output_dims={"out": 4, "n": 4})
    np.testing.assert_allclose(np.asarray(norms4),
                               np.linalg.norm(v[:4].astype(np.float64), axis=1), rtol=1e-6)
    with pytest.raises(TypeError, match="dtype"):
        jax_vec(jax.numpy.asarray(v.astype(np.float64)))
