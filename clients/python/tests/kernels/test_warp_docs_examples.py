"""Kernels from Warp's documentation, unchanged but for the import: saxpy launched with NumPy
inputs on device="cpu", and the semi-implicit Euler particle `integrate` kernel with wp.vec3
arrays; against float64 NumPy."""
import numpy as np

import weft as wp


# --- from Warp's docs (Basics: kernels) ---------------------------------------------------
@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


# --- from Warp's docs (Basics: semi-implicit Euler) ---------------------------------------
@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3),
              v: wp.array(dtype=wp.vec3),
              f: wp.array(dtype=wp.vec3),
              w: wp.array(dtype=float),
              gravity: wp.vec3,
              dt: float):
    # thread id
    tid = wp.tid()

    x0 = x[tid]
    v0 = v[tid]

    # Semi-implicit Euler step
    v1 = v0 + (f[tid] * w[tid] + gravity) * dt
    x1 = x0 + v1 * dt

    # write results
    x[tid] = x1
    v[tid] = v1


def test_saxpy_numpy_inputs_on_cpu(wp, rng):
    n = 1024
    x = rng.standard_normal(n).astype(np.float32)
    y = rng.standard_normal(n).astype(np.float32)
    y0 = y.copy()
    a = 2.5
    wp.launch(saxpy, dim=n, inputs=[x, y, a], device="cpu")
    np.testing.assert_allclose(y, a * x.astype(np.float64) + y0, rtol=1e-6, atol=1e-6)


def test_saxpy_weft_arrays(wp, rng):
    n = 100_000
    x = rng.standard_normal(n).astype(np.float32)
    y = rng.standard_normal(n).astype(np.float32)
    xa, ya = wp.array(x, dtype=float, device="cpu"), wp.array(y, dtype=float, device="cpu")
    wp.launch(saxpy, dim=n, inputs=[xa, ya, -0.5], device="cpu")
    np.testing.assert_allclose(ya.numpy(), -0.5 * x.astype(np.float64) + y, rtol=1e-6, atol=1e-6)


def test_integrate_semi_implicit_euler(wp, rng):
    n = 10_000
    steps = 20
    dt = 1.0 / 60.0
    gravity = np.array([0.0, -9.8, 0.0])
    x = rng.standard_normal((n, 3)).astype(np.float32)
    v = rng.standard_normal((n, 3)).astype(np.float32)
    f = rng.standard_normal((n, 3)).astype(np.float32)
    w = rng.uniform(0.5, 2.0, n).astype(np.float32)
    xa = wp.array(x, dtype=wp.vec3)
    va = wp.array(v, dtype=wp.vec3)
    fa = wp.array(f, dtype=wp.vec3)
    wa = wp.array(w, dtype=float)
    for _ in range(steps):
        wp.launch(integrate, dim=n, inputs=[xa, va, fa, wa, wp.vec3(0.0, -9.8, 0.0), dt])
    xr, vr = x.astype(np.float64), v.astype(np.float64)
    acc = f.astype(np.float64) * w[:, None].astype(np.float64) + gravity
    for _ in range(steps):
        vr = vr + acc * dt
        xr = xr + vr * dt
    np.testing.assert_allclose(va.numpy(), vr, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(xa.numpy(), xr, rtol=1e-5, atol=1e-5)
