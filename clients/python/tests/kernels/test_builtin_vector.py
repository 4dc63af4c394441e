"""Builtins, vectors: constructors, +,-,* (scalar), /, dot, cross, length, length_sq,
normalize (zero vector -> zero vector, as Warp), cw_mul, cw_div, min/max/abs/sign per
component, argmin/argmax, outer, vec2/vec4/vec3d variants; against float64 NumPy."""
import numpy as np

import weft as wp


@wp.kernel
def vec_ops(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), s: float,
            fout: wp.array(dtype=float, ndim=2), vout: wp.array(dtype=wp.vec3, ndim=2)):
    i = wp.tid()
    x = a[i]
    y = b[i]
    fout[i, 0] = wp.dot(x, y)
    fout[i, 1] = wp.length(x)
    fout[i, 2] = wp.length_sq(x)
    fout[i, 3] = float(wp.argmin(x))
    fout[i, 4] = float(wp.argmax(x))
    fout[i, 5] = wp.min(x)
    fout[i, 6] = wp.max(x)
    vout[i, 0] = x + y
    vout[i, 1] = x - y
    vout[i, 2] = x * s
    vout[i, 3] = s * x
    vout[i, 4] = x / s
    vout[i, 5] = wp.cross(x, y)
    vout[i, 6] = wp.normalize(x)
    vout[i, 7] = wp.cw_mul(x, y)
    vout[i, 8] = wp.cw_div(x, y)
    vout[i, 9] = wp.min(x, y)
    vout[i, 10] = wp.max(x, y)
    vout[i, 11] = wp.abs(x)
    vout[i, 12] = wp.sign(x)
    vout[i, 13] = -x
    vout[i, 14] = wp.vec3(x[1])


@wp.kernel
def vec_variants(a: wp.array(dtype=wp.vec4), d: wp.array(dtype=wp.vec3d),
                 out: wp.array(dtype=float, ndim=2), dout: wp.array(dtype=wp.float64, ndim=2)):
    i = wp.tid()
    v = a[i]
    u = wp.vec2(v[0], v[3])
    out[i, 0] = wp.dot(v, v)
    out[i, 1] = wp.length(u)
    out[i, 2] = wp.normalize(v)[2]
    w = d[i]
    dout[i, 0] = wp.length(w)
    dout[i, 1] = wp.dot(w, wp.vec3d(wp.float64(1.0), wp.float64(2.0), wp.float64(3.0)))
    iv = wp.vec2i(3, -4)
    out[i, 3] = float(iv[0] * iv[1])


@wp.kernel
def outer_kernel(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    out[i] = wp.outer(a[i], b[i])


def _norm(x):
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    with np.errstate(all="ignore"):
        return np.where(n > 0, x / n, 0.0)


def test_vec3_ops(wp, rng):
    n = 500
    a = rng.standard_normal((n, 3)).astype(np.float32)
    b = rng.standard_normal((n, 3)).astype(np.float32) + 0.1
    a[0] = 0.0                    # normalize of the zero vector
    a[1] = [1e-30, -2e-30, 0.0]   # tiny magnitude: normalize must not return NaN/inf
    a[2] = [2e19, -2e19, 2e19]    # huge: length squared (1.2e39) overflows float32
    s = 1.75
    fout = wp.zeros((n, 7), dtype=float)
    vout = wp.zeros((n, 15), dtype=wp.vec3)
    wp.launch(vec_ops, dim=n, inputs=[wp.array(a, dtype=wp.vec3), wp.array(b, dtype=wp.vec3), s],
              outputs=[fout, vout])
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    f = fout.numpy()
    v = vout.numpy()
    np.testing.assert_allclose(f[3:, 0], (a64 * b64).sum(1)[3:], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(f[3:, 1], np.linalg.norm(a64, axis=1)[3:], rtol=1e-6)
    np.testing.assert_allclose(f[:, 2][3:], (a64 ** 2).sum(1)[3:], rtol=1e-6)
    np.testing.assert_array_equal(f[3:, 3], np.argmin(a, axis=1)[3:])
    np.testing.assert_array_equal(f[3:, 4], np.argmax(a, axis=1)[3:])
    np.testing.assert_array_equal(f[:, 5], a.min(1))
    np.testing.assert_array_equal(f[:, 6], a.max(1))
    rows = slice(3, None)
    np.testing.assert_allclose(v[rows, 0], (a64 + b64)[rows], rtol=1e-6)
    np.testing.assert_allclose(v[rows, 1], (a64 - b64)[rows], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(v[:, 2], a64 * s, rtol=1e-6)
    np.testing.assert_allclose(v[:, 3], a64 * s, rtol=1e-6)
    np.testing.assert_allclose(v[:, 4], a64 / s, rtol=1e-6)
    np.testing.assert_allclose(v[rows, 5], np.cross(a64, b64)[rows], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(v[rows, 6], _norm(a64)[rows], rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(v[0, 6], [0.0, 0.0, 0.0])      # Warp: zero stays zero
    assert np.all(np.isfinite(v[1, 6])), f"normalize of a tiny vector gave {v[1, 6]}"
    np.testing.assert_allclose(v[rows, 7], (a64 * b64)[rows], rtol=1e-6)
    np.testing.assert_allclose(v[rows, 8], (a64 / b64)[rows], rtol=1e-6)
    np.testing.assert_array_equal(v[:, 9], np.minimum(a, b))
    np.testing.assert_array_equal(v[:, 10], np.maximum(a, b))
    np.testing.assert_array_equal(v[:, 11], np.abs(a))
    np.testing.assert_array_equal(v[:, 12], np.where(a < 0, -1.0, 1.0))   # Warp: sign(0) = 1
    np.testing.assert_array_equal(v[:, 13], -a)
    np.testing.assert_array_equal(v[:, 14], np.repeat(a[:, 1:2], 3, axis=1))
    assert np.isinf(f[2, 2])      # 1.2e39 overflows float32 length_sq


def test_vec_variants(wp, rng):
    n = 100
    a = rng.standard_normal((n, 4)).astype(np.float32)
    d = rng.standard_normal((n, 3))
    out = wp.zeros((n, 4), dtype=float)
    dout = wp.zeros((n, 2), dtype=wp.float64)
    wp.launch(vec_variants, dim=n, inputs=[wp.array(a, dtype=wp.vec4), wp.array(d, dtype=wp.vec3d)],
              outputs=[out, dout])
    a64 = a.astype(np.float64)
    np.testing.assert_allclose(out.numpy()[:, 0], (a64 ** 2).sum(1), rtol=1e-5)
    np.testing.assert_allclose(out.numpy()[:, 1], np.hypot(a64[:, 0], a64[:, 3]), rtol=1e-6)
    np.testing.assert_allclose(out.numpy()[:, 2], _norm(a64)[:, 2], rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(out.numpy()[:, 3], -12.0)
    np.testing.assert_allclose(dout.numpy()[:, 0], np.linalg.norm(d, axis=1), rtol=1e-14)
    np.testing.assert_allclose(dout.numpy()[:, 1], d @ [1.0, 2.0, 3.0], rtol=1e-13, atol=1e-14)


def test_outer(wp, rng):
    a = rng.standard_normal((64, 3)).astype(np.float32)
    b = rng.standard_normal((64, 3)).astype(np.float32)
    out = wp.zeros(64, dtype=wp.mat33)
    wp.launch(outer_kernel, dim=64, inputs=[wp.array(a, dtype=wp.vec3), wp.array(b, dtype=wp.vec3)],
              outputs=[out])
    np.testing.assert_allclose(out.numpy(), np.einsum("ni,nj->nij", a, b), rtol=1e-6)
