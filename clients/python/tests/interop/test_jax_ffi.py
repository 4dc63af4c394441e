"""wp.jax_kernel and wp.jax_callable on the CPU, through their XLA FFI targets: gradients through
jax.grad against float64 analytic references (including large magnitudes), jax.vmap (batched and
sequential), input-output arrays, Python callables that launch kernels, wrapper caching, and the
errors a caller can cause (traced scalars, duplicate or misplaced in-out names, oversized
launches, per-call overrides of a differentiable wrapper, CUDA-only graph modes on the CPU), and
jax.shard_map's varying mesh axes kept through a call."""
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import weft as wp


@wp.kernel
def cube_scale(a: wp.array(dtype=float), b: wp.array(dtype=float), s: float, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = s * a[i] * a[i] * a[i] + wp.sin(b[i])


@wp.kernel
def two_outputs(v: wp.array(dtype=wp.vec3), length: wp.array(dtype=float), half: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    length[i] = wp.length(v[i])
    half[i] = 0.5 * v[i]


@wp.kernel
def accumulate(a: wp.array(dtype=float), acc: wp.array(dtype=float), twice: wp.array(dtype=float)):
    i = wp.tid()
    acc[i] = acc[i] + a[i]
    twice[i] = 2.0 * a[i]


@wp.kernel
def scale_into(a: wp.array(dtype=float), s: float, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = s * a[i]


def double_then_add(a: wp.array(dtype=float), b: wp.array(dtype=float), out: wp.array(dtype=float)):
    wp.launch(scale_into, dim=a.shape, inputs=[a, 2.0, out], device="cpu")
    wp.launch(accumulate, dim=a.shape, inputs=[b, out, wp.empty_like(out)], device="cpu")


def _cpu(jax):
    return jax.default_device(jax.devices("cpu")[0])


def test_grad_through_a_kernel_matches_float64(jax, rng):
    jnp = jax.numpy
    f = wp.jax_kernel(cube_scale, enable_backward=True)
    for scale, magnitude in ((1.7, 1.0), (3.0e-4, 40.0)):   # ordinary and large values
        a = (rng.standard_normal(257) * magnitude).astype(np.float32)
        b = rng.uniform(-3, 3, 257).astype(np.float32)

        def loss(x, y, s=scale):
            return jnp.sum(f(x, y, s)[0] ** 2)

        with _cpu(jax):
            out = f(jnp.asarray(a), jnp.asarray(b), scale)[0]
            ga, gb = jax.jit(jax.grad(loss, argnums=(0, 1)))(jnp.asarray(a), jnp.asarray(b))
        a64, b64 = a.astype(np.float64), b.astype(np.float64)
        y = scale * a64 ** 3 + np.sin(b64)
        np.testing.assert_allclose(np.asarray(out), y, rtol=2e-6, atol=1e-6 * np.abs(y).max())
        np.testing.assert_allclose(np.asarray(ga), 2 * y * 3 * scale * a64 ** 2, rtol=2e-5,
                                   atol=1e-5 * np.abs(2 * y * 3 * scale * a64 ** 2).max())
        np.testing.assert_allclose(np.asarray(gb), 2 * y * np.cos(b64), rtol=2e-5, atol=1e-5)


def test_vmap_batches_and_sequential_match_a_loop(jax, rng):
    jnp = jax.numpy
    v = rng.standard_normal((4, 33, 3)).astype(np.float32)
    for method in ("broadcast_all", "sequential"):
        f = wp.jax_kernel(two_outputs, num_outputs=2, vmap_method=method)
        with _cpu(jax):
            length, half = jax.jit(jax.vmap(f))(jnp.asarray(v))
        np.testing.assert_allclose(np.asarray(length), np.linalg.norm(v.astype(np.float64), axis=-1), rtol=1e-6)
        np.testing.assert_allclose(np.asarray(half), 0.5 * v, rtol=1e-7)
    g = wp.jax_kernel(cube_scale, enable_backward=True)
    a = rng.standard_normal((3, 20)).astype(np.float32)
    b = rng.standard_normal((3, 20)).astype(np.float32)
    with _cpu(jax):
        grads = jax.vmap(jax.grad(lambda x, y: jnp.sum(g(x, y, 2.0)[0])))(jnp.asarray(a), jnp.asarray(b))
    np.testing.assert_allclose(np.asarray(grads), 6.0 * a.astype(np.float64) ** 2, rtol=1e-5)


def test_in_out_arrays_and_callables(jax, rng):
    jnp = jax.numpy
    a = rng.standard_normal(50).astype(np.float32)
    acc = rng.standard_normal(50).astype(np.float32)
    k = wp.jax_kernel(accumulate, num_outputs=2, in_out_argnames=["acc"])
    with _cpu(jax):
        new_acc, twice = jax.jit(k)(jnp.asarray(a), jnp.asarray(acc))
    np.testing.assert_allclose(np.asarray(new_acc), acc + a, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(twice), 2 * a, rtol=1e-7)
    c = wp.jax_callable(double_then_add, num_outputs=1)
    b = rng.standard_normal(50).astype(np.float32)
    with _cpu(jax):
        (out,) = jax.jit(c)(jnp.asarray(a), jnp.asarray(b))
    np.testing.assert_allclose(np.asarray(out), 2 * a + b, rtol=1e-6)


def test_wrappers_are_cached_by_their_settings():
    assert wp.jax_kernel(accumulate, num_outputs=2) is wp.jax_kernel(accumulate, num_outputs=2)
    assert wp.jax_kernel(accumulate, num_outputs=2, in_out_argnames=[]) is wp.jax_kernel(accumulate, num_outputs=2)
    assert wp.jax_kernel(accumulate, num_outputs=2, in_out_argnames=["acc"]) is not wp.jax_kernel(accumulate,
                                                                                               num_outputs=2)
    assert wp.jax_callable(double_then_add) is wp.jax_callable(double_then_add)


def test_errors_a_caller_can_cause(jax, rng):
    jnp = jax.numpy
    with pytest.raises(ValueError, match="must not contain duplicate names"):
        wp.jax_kernel(accumulate, num_outputs=2, in_out_argnames=["acc", "acc"])
    with pytest.raises(ValueError, match="did not match any function argument names"):
        wp.jax_kernel(accumulate, num_outputs=2, in_out_argnames=["nope"])
    with pytest.raises(ValueError, match="placed before output-only arguments"):
        wp.jax_kernel(accumulate, num_outputs=2, in_out_argnames=["twice"])
    with pytest.raises(ValueError, match="block_dim must be positive"):
        wp.jax_kernel(accumulate, block_dim=0)
    with pytest.raises(NotImplementedError):
        wp.jax_kernel(scale_into, output_dims=4, enable_backward=True)
    a = jnp.ones(8, dtype=jnp.float32)
    f = wp.jax_kernel(scale_into)
    with pytest.raises(TypeError, match="traced value"):
        jax.jit(lambda x, s: f(x, s))(a, 2.0)
    with pytest.raises(ValueError, match=r"extent 2147483649 in dimension 0"):
        jax.jit(lambda x: wp.jax_kernel(scale_into, launch_dims=2**31 + 1, output_dims=1)(x, 1.0)).lower(a)
    g = wp.jax_kernel(cube_scale, enable_backward=True)
    with pytest.raises(TypeError, match="launch_dims cannot be overridden per-call"):
        g(a, a, 1.0, launch_dims=8)
    with pytest.raises(TypeError, match="vmap_method cannot be overridden per-call"):
        g(a, a, 1.0, vmap_method="sequential")
    with pytest.raises(TypeError, match="dtype"):
        f(jnp.ones(8, dtype=jnp.int32), 1.0)
    c = wp.jax_callable(double_then_add, graph_mode=wp.JaxCallableGraphMode.WARP)
    with _cpu(jax), pytest.raises(Exception, match="WARP.*CPU"):
        jax.block_until_ready(jax.jit(c)(a, a))


def test_outputs_keep_the_inputs_varying_mesh_axes_under_shard_map(jax, client_env, tmp_path):
    """Inside jax.shard_map (check_vma), a call's outputs vary over the mesh axes its inputs vary
    over, as an XLA FFI call's do: a lax.scan carry through the call keeps its type. Run in a
    child with two host devices; wp.device_to_jax gives this process's own CPU device."""
    if not hasattr(jax, "shard_map") or not hasattr(jax.lax, "pcast"):
        pytest.skip("this JAX has no shard_map / lax.pcast")
    script = tmp_path / "shard_map_scan.py"
    script.write_text(textwrap.dedent("""
        import numpy as np, jax, jax.numpy as jp
        import weft as wp

        @wp.kernel
        def twice(a: wp.array(dtype=float), out: wp.array(dtype=float)):
            i = wp.tid()
            out[i] = 2.0 * a[i]

        def twice_callable(a: wp.array(dtype=float), out: wp.array(dtype=float)):
            wp.launch(twice, dim=a.shape, inputs=[a, out], device="cpu")

        devices = jax.local_devices(backend="cpu")
        assert wp.device_to_jax("cpu") == devices[0]
        mesh = jax.sharding.Mesh(np.array(devices[:2]), ("replicas",))
        spec = jax.sharding.PartitionSpec("replicas")
        for call in (wp.jax_kernel(twice, num_outputs=1), wp.jax_callable(twice_callable, num_outputs=1)):
            @jax.shard_map(mesh=mesh, in_specs=spec, out_specs=spec, check_vma=True)
            def scan_twice(x):
                return jax.lax.scan(lambda c, _: (call(c)[0], None), x, None, length=3)[0]
            x = np.random.default_rng().standard_normal(64).astype(np.float32)
            np.testing.assert_allclose(np.asarray(scan_twice(jp.asarray(x))), 8.0 * x, rtol=1e-6)
        print("ok")
    """))
    env = client_env({"XLA_FLAGS": "--xla_force_host_platform_device_count=2", "JAX_PLATFORMS": "cpu"})
    proc = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.strip().endswith("ok")
