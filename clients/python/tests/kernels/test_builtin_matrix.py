"""Builtins, matrices: constructors (scalars row-major, identity, diag), mat*vec, mat*mat,
transpose, inverse (2x2, 3x3, 4x4; a singular matrix gives the zero matrix, as Warp),
determinant, trace, get_diag, ddot, outer, skew, cw_mul, matrix_from_rows/cols, float64."""
import numpy as np

import weft as wp


@wp.kernel
def mat3_ops(a: wp.array(dtype=wp.mat33), b: wp.array(dtype=wp.mat33), v: wp.array(dtype=wp.vec3),
             mout: wp.array(dtype=wp.mat33, ndim=2), vout: wp.array(dtype=wp.vec3, ndim=2),
             fout: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    m = a[i]
    n = b[i]
    x = v[i]
    mout[i, 0] = m * n
    mout[i, 1] = wp.transpose(m)
    mout[i, 2] = wp.inverse(m)
    mout[i, 3] = m + n
    mout[i, 4] = m - n
    mout[i, 5] = m * 2.0
    mout[i, 6] = wp.diag(x)
    mout[i, 7] = wp.identity(n=3, dtype=float)
    mout[i, 8] = wp.skew(x)
    mout[i, 9] = wp.cw_mul(m, n)
    mout[i, 10] = wp.matrix_from_rows(x, x * 2.0, x * 3.0)
    mout[i, 11] = wp.matrix_from_cols(x, x * 2.0, x * 3.0)
    mout[i, 12] = wp.mat33(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0)
    vout[i, 0] = m * x
    vout[i, 1] = x * m
    vout[i, 2] = wp.get_diag(m)
    fout[i, 0] = wp.determinant(m)
    fout[i, 1] = wp.trace(m)
    fout[i, 2] = wp.ddot(m, n)


@wp.kernel
def inverses(a2: wp.array(dtype=wp.mat22), a4: wp.array(dtype=wp.mat44),
             o2: wp.array(dtype=wp.mat22), o4: wp.array(dtype=wp.mat44),
             d: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    o2[i] = wp.inverse(a2[i])
    o4[i] = wp.inverse(a4[i])
    d[i, 0] = wp.determinant(a2[i])
    d[i, 1] = wp.determinant(a4[i])


@wp.kernel
def mat_double(a: wp.array(dtype=wp.mat33d), out: wp.array(dtype=wp.mat33d), det: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = wp.inverse(a[i])
    det[i] = wp.determinant(a[i])


def _well_conditioned(rng, n, k):
    return (rng.standard_normal((n, k, k)) + 3 * np.eye(k)).astype(np.float32)


def _assert_inverse(got, a):
    """float32 inverses are accurate to ~eps * cond(a) relative to the largest entry."""
    a64 = a.astype(np.float64)
    ref = np.linalg.inv(a64)
    cond = np.linalg.cond(a64)
    err = np.abs(got - ref).max(axis=(1, 2))
    bound = 1e-6 * cond * np.abs(ref).max(axis=(1, 2)) + 1e-6
    bad = np.nonzero(err > bound)[0]
    assert bad.size == 0, (f"inverse error above 1e-6*cond*max|inv| for matrices {bad[:5]}: "
                           f"errors {err[bad[:5]]}, bounds {bound[bad[:5]]}")


def test_mat33_ops(wp, rng):
    n = 300
    a = _well_conditioned(rng, n, 3)
    a[0] = [[1, 2, 3], [2, 4, 6], [0, 1, 1]]       # singular
    b = rng.standard_normal((n, 3, 3)).astype(np.float32)
    v = rng.standard_normal((n, 3)).astype(np.float32)
    mout = wp.zeros((n, 13), dtype=wp.mat33)
    vout = wp.zeros((n, 3), dtype=wp.vec3)
    fout = wp.zeros((n, 3), dtype=float)
    wp.launch(mat3_ops, dim=n, inputs=[wp.array(a, dtype=wp.mat33), wp.array(b, dtype=wp.mat33),
                                       wp.array(v, dtype=wp.vec3)], outputs=[mout, vout, fout])
    a64, b64, v64 = a.astype(np.float64), b.astype(np.float64), v.astype(np.float64)
    m = mout.numpy()
    tol = dict(rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(m[:, 0], a64 @ b64, **tol)
    np.testing.assert_array_equal(m[:, 1], np.transpose(a, (0, 2, 1)))
    _assert_inverse(m[1:, 2], a[1:])
    np.testing.assert_array_equal(m[0, 2], np.zeros((3, 3)))   # singular -> zero (Warp)
    np.testing.assert_allclose(m[:, 3], a64 + b64, **tol)
    np.testing.assert_allclose(m[:, 4], a64 - b64, **tol)
    np.testing.assert_allclose(m[:, 5], 2 * a64, **tol)
    np.testing.assert_array_equal(m[:, 6], np.einsum("ni,ij->nij", v, np.eye(3)))
    np.testing.assert_array_equal(m[:, 7], np.broadcast_to(np.eye(3), (n, 3, 3)))
    skew = np.zeros((n, 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -v64[:, 2], v64[:, 1], -v64[:, 0]
    skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = v64[:, 2], -v64[:, 1], v64[:, 0]
    np.testing.assert_allclose(m[:, 8], skew, **tol)
    np.testing.assert_allclose(m[:, 9], a64 * b64, **tol)
    rows = np.stack([v64, 2 * v64, 3 * v64], axis=1)
    np.testing.assert_allclose(m[:, 10], rows, **tol)
    np.testing.assert_allclose(m[:, 11], np.transpose(rows, (0, 2, 1)), **tol)
    np.testing.assert_array_equal(m[:, 12], np.broadcast_to(np.arange(1, 10).reshape(3, 3),
                                                            (n, 3, 3)))
    vv = vout.numpy()
    np.testing.assert_allclose(vv[:, 0], np.einsum("nij,nj->ni", a64, v64), **tol)
    np.testing.assert_allclose(vv[:, 1], np.einsum("ni,nij->nj", v64, a64), **tol)
    np.testing.assert_array_equal(vv[:, 2], np.diagonal(a, axis1=1, axis2=2))
    f = fout.numpy()
    np.testing.assert_allclose(f[:, 0], np.linalg.det(a64), rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(f[:, 1], np.trace(a64, axis1=1, axis2=2), **tol)
    np.testing.assert_allclose(f[:, 2], (a64 * b64).sum((1, 2)), **tol)


def test_inverse_determinant_2_and_4(wp, rng):
    n = 200
    a2 = _well_conditioned(rng, n, 2)
    a4 = _well_conditioned(rng, n, 4)
    a2[0] = [[1, 2], [2, 4]]
    a4[0] = np.outer([1, 2, 3, 4], [1, 1, 1, 1])
    o2 = wp.zeros(n, dtype=wp.mat22)
    o4 = wp.zeros(n, dtype=wp.mat44)
    d = wp.zeros((n, 2), dtype=float)
    wp.launch(inverses, dim=n, inputs=[wp.array(a2, dtype=wp.mat22), wp.array(a4, dtype=wp.mat44)],
              outputs=[o2, o4, d])
    _assert_inverse(o2.numpy()[1:], a2[1:])
    _assert_inverse(o4.numpy()[1:], a4[1:])
    assert np.all(np.isfinite(o2.numpy()[0])) and np.all(np.isfinite(o4.numpy()[0]))
    np.testing.assert_array_equal(o2.numpy()[0], 0.0)
    np.testing.assert_array_equal(o4.numpy()[0], 0.0)
    np.testing.assert_allclose(d.numpy()[:, 0], np.linalg.det(a2.astype(np.float64)), rtol=1e-5,
                               atol=1e-5)
    np.testing.assert_allclose(d.numpy()[:, 1], np.linalg.det(a4.astype(np.float64)), rtol=1e-4,
                               atol=1e-4)


def test_float64_matrices(wp, rng):
    a = rng.standard_normal((100, 3, 3)) + 3 * np.eye(3)
    out = wp.zeros(100, dtype=wp.mat33d)
    det = wp.zeros(100, dtype=wp.float64)
    wp.launch(mat_double, dim=100, inputs=[wp.array(a, dtype=wp.mat33d)], outputs=[out, det])
    np.testing.assert_allclose(out.numpy(), np.linalg.inv(a), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(det.numpy(), np.linalg.det(a), rtol=1e-12)


@wp.kernel
def det_inv44(a: wp.array(dtype=wp.mat44), det: wp.array(dtype=float), inv: wp.array(dtype=wp.mat44)):
    i = wp.tid()
    det[i] = wp.determinant(a[i])
    inv[i] = wp.inverse(a[i])


def test_float32_4x4_determinant_and_inverse_are_rounded_once(wp, rng):
    """A float32 4x4 determinant and inverse are computed in float64 and rounded once, so they
    stay accurate where the cofactor expansion cancels: nearly singular matrices (a row almost a
    combination of two others) and entries of very different magnitudes, against float64."""
    n = 256
    a = rng.standard_normal((n, 4, 4))
    a[:, 3] = a[:, 0] * rng.uniform(0.5, 2, (n, 1)) + a[:, 1] * rng.uniform(0.5, 2, (n, 1)) \
        + rng.standard_normal((n, 4)) * 10.0 ** rng.uniform(-5, -2, (n, 1))
    a *= 10.0 ** rng.uniform(-3, 3, (n, 1, 1))
    a32 = a.astype(np.float32)
    ref = a32.astype(np.float64)
    det, inv = wp.zeros(n, dtype=float), wp.zeros(n, dtype=wp.mat44)
    wp.launch(det_inv44, dim=n, inputs=[wp.array(a32, dtype=wp.mat44), det, inv])
    want = np.linalg.det(ref)
    # one rounding to float32 of a float64 result whose own error is far below it
    np.testing.assert_allclose(det.numpy(), want, rtol=2e-6)
    want_inv = np.linalg.inv(ref)
    scale = np.abs(want_inv).max(axis=(1, 2), keepdims=True)
    assert (np.abs(inv.numpy() - want_inv) <= 2e-6 * scale).all()
