"""Builtins, quaternions (x, y, z, w), transforms (p, q) and spatial vectors: axis-angle,
rotate/rotate_inv, multiply, inverse, to_matrix, from_matrix, slerp (incl. nearly identical
rotations), rpy; transform_point/vector/multiply/inverse; spatial_dot/cross/cross_dual/top/
bottom; against float64 NumPy implementations of the same formulas."""
import numpy as np

import weft as wp


def qmul(a, b):
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def qconj(q):
    return q * np.array([-1, -1, -1, 1])


def qrot(q, v):
    vq = np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], axis=-1)
    return qmul(qmul(q, vq), qconj(q))[..., :3]


def qmat(q):
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)],
                    axis=-2)


def slerp(a, b, t):
    d = (a * b).sum(-1, keepdims=True)
    b = np.where(d < 0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1, 1))
    s = np.sin(theta)
    with np.errstate(all="ignore"):
        wa = np.where(s > 1e-6, np.sin((1 - t) * theta) / s, 1 - t)
        wb = np.where(s > 1e-6, np.sin(t * theta) / s, t)
    return wa * a + wb * b


def random_quats(rng, n):
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@wp.kernel
def quat_ops(qa: wp.array(dtype=wp.quat), qb: wp.array(dtype=wp.quat), v: wp.array(dtype=wp.vec3),
             axis: wp.array(dtype=wp.vec3), angle: wp.array(dtype=float), t: float,
             qout: wp.array(dtype=wp.quat, ndim=2), vout: wp.array(dtype=wp.vec3, ndim=2),
             mout: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    a = qa[i]
    b = qb[i]
    qout[i, 0] = a * b
    qout[i, 1] = wp.quat_inverse(a)
    qout[i, 2] = wp.quat_from_axis_angle(axis[i], angle[i])
    qout[i, 3] = wp.quat_slerp(a, b, t)
    qout[i, 4] = wp.normalize(a * 3.0)
    qout[i, 5] = wp.quat_from_matrix(wp.quat_to_matrix(a))
    qout[i, 6] = wp.quat_identity()
    qout[i, 7] = wp.quat(1.0, 2.0, 3.0, 4.0)
    vout[i, 0] = wp.quat_rotate(a, v[i])
    vout[i, 1] = wp.quat_rotate_inv(a, v[i])
    mout[i] = wp.quat_to_matrix(a)


@wp.kernel
def transform_ops(ta: wp.array(dtype=wp.transform), tb: wp.array(dtype=wp.transform),
                  p: wp.array(dtype=wp.vec3), tout: wp.array(dtype=wp.transform, ndim=2),
                  vout: wp.array(dtype=wp.vec3, ndim=2)):
    i = wp.tid()
    a = ta[i]
    b = tb[i]
    tout[i, 0] = wp.transform_multiply(a, b)
    tout[i, 1] = wp.transform_inverse(a)
    tout[i, 2] = wp.transform(wp.transform_get_translation(a), wp.transform_get_rotation(a))
    vout[i, 0] = wp.transform_point(a, p[i])
    vout[i, 1] = wp.transform_vector(a, p[i])


@wp.kernel
def spatial_ops(a: wp.array(dtype=wp.spatial_vector), b: wp.array(dtype=wp.spatial_vector),
                sout: wp.array(dtype=wp.spatial_vector, ndim=2), vout: wp.array(dtype=wp.vec3, ndim=2),
                fout: wp.array(dtype=float)):
    i = wp.tid()
    sout[i, 0] = wp.spatial_cross(a[i], b[i])
    sout[i, 1] = wp.spatial_cross_dual(a[i], b[i])
    sout[i, 2] = a[i] + b[i]
    vout[i, 0] = wp.spatial_top(a[i])
    vout[i, 1] = wp.spatial_bottom(a[i])
    fout[i] = wp.spatial_dot(a[i], b[i])


def _same_rotation(q, r, **tol):
    # q and -q are the same rotation
    sign = np.where((q * r).sum(-1, keepdims=True) < 0, -1.0, 1.0)
    np.testing.assert_allclose(q, r * sign, **tol)


def test_quaternions(wp, rng):
    n = 300
    qa = random_quats(rng, n)
    qb = random_quats(rng, n)
    qb[0] = qa[0]                                        # identical rotations
    qb[1] = qa[1] + 1e-7 * rng.standard_normal(4)        # nearly identical
    qb[1] /= np.linalg.norm(qb[1])
    v = rng.standard_normal((n, 3))
    axis = rng.standard_normal((n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(-np.pi, np.pi, n)
    t = 0.3
    f32 = lambda x: x.astype(np.float32)  # noqa: E731
    qout = wp.zeros((n, 8), dtype=wp.quat)
    vout = wp.zeros((n, 2), dtype=wp.vec3)
    mout = wp.zeros(n, dtype=wp.mat33)
    wp.launch(quat_ops, dim=n, inputs=[wp.array(f32(qa), dtype=wp.quat), wp.array(f32(qb), dtype=wp.quat),
                                       wp.array(f32(v), dtype=wp.vec3), wp.array(f32(axis), dtype=wp.vec3),
                                       wp.array(f32(angle)), t], outputs=[qout, vout, mout])
    q = qout.numpy()
    tol = dict(rtol=1e-5, atol=2e-6)
    np.testing.assert_allclose(q[:, 0], qmul(qa, qb), **tol)
    np.testing.assert_allclose(q[:, 1], qconj(qa), **tol)
    half = angle[:, None] / 2
    np.testing.assert_allclose(q[:, 2], np.concatenate([axis * np.sin(half), np.cos(half)], 1), **tol)
    assert np.all(np.isfinite(q[:2, 3])), f"slerp of (nearly) identical rotations: {q[:2, 3]}"
    _same_rotation(q[:, 3], slerp(qa, qb, t), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(q[:, 4], qa, **tol)
    _same_rotation(q[:, 5], qa, rtol=1e-4, atol=1e-5)
    np.testing.assert_array_equal(q[:, 6], np.broadcast_to([0, 0, 0, 1], (n, 4)))
    np.testing.assert_array_equal(q[:, 7], np.broadcast_to([1, 2, 3, 4], (n, 4)))
    vv = vout.numpy()
    np.testing.assert_allclose(vv[:, 0], qrot(qa, v), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(vv[:, 1], qrot(qconj(qa), v), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(mout.numpy(), qmat(qa), rtol=1e-5, atol=1e-5)


def test_transforms(wp, rng):
    n = 200
    pa, pb = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    qa, qb = random_quats(rng, n), random_quats(rng, n)
    p = rng.standard_normal((n, 3))
    ta = np.concatenate([pa, qa], 1).astype(np.float32)
    tb = np.concatenate([pb, qb], 1).astype(np.float32)
    tout = wp.zeros((n, 3), dtype=wp.transform)
    vout = wp.zeros((n, 2), dtype=wp.vec3)
    wp.launch(transform_ops, dim=n, inputs=[wp.array(ta, dtype=wp.transform),
                                            wp.array(tb, dtype=wp.transform),
                                            wp.array(p.astype(np.float32), dtype=wp.vec3)],
              outputs=[tout, vout])
    tt = tout.numpy()
    tol = dict(rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(tt[:, 0, :3], pa + qrot(qa, pb), **tol)
    np.testing.assert_allclose(tt[:, 0, 3:], qmul(qa, qb), **tol)
    np.testing.assert_allclose(tt[:, 1, :3], -qrot(qconj(qa), pa), **tol)
    np.testing.assert_allclose(tt[:, 1, 3:], qconj(qa), **tol)
    np.testing.assert_array_equal(tt[:, 2], ta)
    np.testing.assert_allclose(vout.numpy()[:, 0], pa + qrot(qa, p), **tol)
    np.testing.assert_allclose(vout.numpy()[:, 1], qrot(qa, p), **tol)


def test_spatial(wp, rng):
    n = 200
    a = rng.standard_normal((n, 6))
    b = rng.standard_normal((n, 6))
    sout = wp.zeros((n, 3), dtype=wp.spatial_vector)
    vout = wp.zeros((n, 2), dtype=wp.vec3)
    fout = wp.zeros(n, dtype=float)
    wp.launch(spatial_ops, dim=n, inputs=[wp.array(a.astype(np.float32), dtype=wp.spatial_vector),
                                          wp.array(b.astype(np.float32), dtype=wp.spatial_vector)],
              outputs=[sout, vout, fout])
    aw, av, bw, bv = a[:, :3], a[:, 3:], b[:, :3], b[:, 3:]
    s = sout.numpy()
    tol = dict(rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(s[:, 0], np.concatenate([np.cross(aw, bw),
                                                        np.cross(aw, bv) + np.cross(av, bw)], 1), **tol)
    np.testing.assert_allclose(s[:, 1], np.concatenate([np.cross(aw, bw) + np.cross(av, bv),
                                                        np.cross(aw, bv)], 1), **tol)
    np.testing.assert_allclose(s[:, 2], a + b, **tol)
    np.testing.assert_allclose(vout.numpy()[:, 0], aw, **tol)
    np.testing.assert_allclose(vout.numpy()[:, 1], av, **tol)
    np.testing.assert_allclose(fout.numpy(), (a * b).sum(1), **tol)


@wp.kernel
def transform_from_parts(p: wp.array(dtype=wp.vec3d), q: wp.array(dtype=wp.quatd),
                         out: wp.array(dtype=wp.transformd), out_p: wp.array(dtype=wp.transformd)):
    i = wp.tid()
    t = wp.transformd(p=p[i], q=q[i])
    u = wp.transformd(q=q[i], p=p[i])
    wp.expect_eq(t, u)
    wp.expect_near(wp.transform_get_rotation(t), q[i], wp.float64(0.0))
    wp.expect_near(wp.quat_to_matrix(q[i]), wp.quat_to_matrix(q[i]))
    out[i] = t
    out_p[i] = wp.transformd(p=p[i])


def test_transform_keyword_construction_and_expect_near_on_quat_mat(wp, rng):
    n = 12
    p = rng.standard_normal((n, 3)) * 1e9
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    out = wp.zeros(n, dtype=wp.transformd)
    out_p = wp.zeros(n, dtype=wp.transformd)
    wp.launch(transform_from_parts, dim=n, inputs=[wp.array(p, dtype=wp.vec3d), wp.array(q, dtype=wp.quatd),
                                                   out, out_p])
    np.testing.assert_array_equal(out.numpy(), np.concatenate([p, q], axis=1))
    np.testing.assert_array_equal(out_p.numpy(), np.concatenate([p, np.tile([0, 0, 0, 1.0], (n, 1))], axis=1))


@wp.kernel
def quat_builtins_in_kernel(rpy: wp.array(dtype=wp.vec3), axis: wp.array(dtype=wp.vec3),
                            v: wp.array(dtype=wp.vec3), out: wp.array2d(dtype=float)):
    i = wp.tid()
    q = wp.quat_rpy(rpy[i][0], rpy[i][1], rpy[i][2])
    a = wp.quat_from_axis_angle(axis[i], rpy[i][0])
    r = wp.quat_rotate(a, v[i])
    p = wp.transform_point(wp.transform(v[i], q), axis[i])
    for k in range(4):
        out[i, k] = q[k]
    for k in range(3):
        out[i, 4 + k] = r[k]
        out[i, 7 + k] = p[k]


def test_quaternion_builtins_called_from_python_match_kernels(wp, rng):
    """wp.quat_rpy, quat_from_axis_angle, quat_rotate, transform_point, quat_identity and
    quat_to_matrix called from Python give what the kernel builtins give (float64 math there,
    float32 results)."""
    n = 16
    rpy = rng.uniform(-np.pi, np.pi, size=(n, 3)).astype(np.float32)
    axis = rng.standard_normal((n, 3))
    axis = (axis / np.linalg.norm(axis, axis=1, keepdims=True)).astype(np.float32)
    v = (rng.standard_normal((n, 3)) * 10).astype(np.float32)
    out = wp.zeros((n, 10), dtype=float)
    wp.launch(quat_builtins_in_kernel, dim=n, inputs=[wp.array(rpy, dtype=wp.vec3), wp.array(axis, dtype=wp.vec3),
                                                      wp.array(v, dtype=wp.vec3), out])
    got = out.numpy()
    for i in range(n):
        q = wp.quat_rpy(*(float(x) for x in rpy[i]))
        a = wp.quat_from_axis_angle(wp.vec3(*axis[i]), float(rpy[i][0]))
        r = wp.quat_rotate(a, wp.vec3(*v[i]))
        p = wp.transform_point(wp.transform(wp.vec3(*v[i]), q), wp.vec3(*axis[i]))
        np.testing.assert_allclose(got[i], np.concatenate([np.asarray(q), np.asarray(r), np.asarray(p)]),
                                   rtol=2e-5, atol=2e-5)
        m = np.asarray(wp.quat_to_matrix(q), dtype=np.float64)
        np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-6)
    assert list(wp.quat_identity(dtype=wp.float64)) == [0.0, 0.0, 0.0, 1.0]
    assert type(wp.quat_identity(dtype=wp.float64)) is wp.quatd


@wp.kernel
def scalar_over_quat(x: wp.array(dtype=wp.quatd), y: wp.array(dtype=wp.quatd)):
    i = wp.tid()
    y[i] = wp.float64(2.0) / x[i]


def test_scalar_divided_by_a_quaternion_and_its_gradient(wp, rng):
    x = rng.uniform(0.5, 4.0, size=(6, 4)) * rng.choice([-1.0, 1.0], size=(6, 4))
    xa = wp.array(x, dtype=wp.quatd, requires_grad=True)
    y = wp.zeros(6, dtype=wp.quatd, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(scalar_over_quat, dim=6, inputs=[xa, y])
    np.testing.assert_allclose(y.numpy(), 2.0 / x, rtol=1e-15)
    tape.backward(grads={y: wp.array(np.ones((6, 4)), dtype=wp.quatd)})
    np.testing.assert_allclose(xa.grad.numpy(), -2.0 / x ** 2, rtol=1e-14)
