"""wp.transform_compose / transform_decompose / transform_from_matrix / transform_to_matrix
(Warp's @wp.func helpers) for float32 and float64: against a float64 NumPy reference built from
the quaternion's rotation matrix on random data, round trips, and the gradient of a composed
matrix's entries with respect to the scale (d(s_j R_ij)/ds_j = R_ij)."""
import numpy as np

import weft as wp


def rot(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def make(dtype):
    vec3 = wp.types.vector(3, dtype)
    quat = wp.types.quaternion(dtype)
    mat44 = wp.types.matrix((4, 4), dtype)
    transform = wp.types.transformation(dtype)

    @wp.kernel
    def roundtrip(p: wp.array(dtype=vec3), q: wp.array(dtype=quat), s: wp.array(dtype=vec3),
                  m: wp.array(dtype=mat44), p2: wp.array(dtype=vec3), q2: wp.array(dtype=quat),
                  s2: wp.array(dtype=vec3), t: wp.array(dtype=transform), tm: wp.array(dtype=mat44)):
        i = wp.tid()
        mm = wp.transform_compose(p[i], q[i], s[i])
        m[i] = mm
        a, b, c = wp.transform_decompose(mm)
        p2[i] = a
        q2[i] = b
        s2[i] = c
        tm[i] = wp.transform_to_matrix(wp.transformation(p[i], q[i]))
        t[i] = wp.transform_from_matrix(tm[i])

    @wp.kernel
    def scale_sum(p: wp.array(dtype=vec3), q: wp.array(dtype=quat), s: wp.array(dtype=vec3),
                  out: wp.array(dtype=dtype)):
        i = wp.tid()
        mm = wp.transform_compose(p[i], q[i], s[i])
        out[i] = mm[0, 0] + mm[1, 1] + mm[2, 2]

    return vec3, quat, mat44, transform, roundtrip, scale_sum


KERNELS = {np.float32: make(wp.float32), np.float64: make(wp.float64)}


def test_transform_funcs_against_numpy(wp, rng):
    for np_t, tol in ((np.float32, 2e-5), (np.float64, 1e-12)):
        vec3, quat, mat44, transform, roundtrip, _ = KERNELS[np_t]
        n = 20
        p = rng.standard_normal((n, 3))
        q = rng.standard_normal((n, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        q *= np.sign(q[:, 3:4])                       # w >= 0: quat_from_matrix's branch
        s = rng.uniform(0.5, 3.0, (n, 3))
        arrays = [wp.zeros(n, dtype=t) for t in (mat44, vec3, quat, vec3, transform, mat44)]
        wp.launch(roundtrip, dim=n, inputs=[wp.array(p.astype(np_t), dtype=vec3), wp.array(q.astype(np_t), dtype=quat),
                                            wp.array(s.astype(np_t), dtype=vec3), *arrays])
        m, p2, q2, s2, t, tm = (a.numpy().astype(np.float64) for a in arrays)
        ref = np.zeros((n, 4, 4))
        for i in range(n):
            ref[i, :3, :3] = rot(q[i]) * s[i][None, :]
            ref[i, :3, 3] = p[i]
            ref[i, 3, 3] = 1.0
        np.testing.assert_allclose(m, ref, atol=tol * 10)
        np.testing.assert_allclose(p2, p, atol=tol * 10)
        np.testing.assert_allclose(s2, s, atol=tol * 10)
        np.testing.assert_allclose(np.abs(np.sum(q2 * q, axis=1)), 1.0, atol=tol * 10)   # same rotation
        ref_tm = ref.copy()
        ref_tm[:, :3, :3] = np.stack([rot(x) for x in q])
        np.testing.assert_allclose(tm, ref_tm, atol=tol * 10)
        np.testing.assert_allclose(t[:, :3], p, atol=tol * 10)


def test_transform_compose_gradient(wp, rng):
    vec3, quat, _, _, _, scale_sum = KERNELS[np.float64]
    n = 8
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    s = wp.array(rng.uniform(0.5, 2.0, (n, 3)), dtype=vec3, requires_grad=True)
    out = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(scale_sum, dim=n, inputs=[wp.array(rng.standard_normal((n, 3)), dtype=vec3),
                                            wp.array(q, dtype=quat), s, out])
    tape.backward(grads={out: wp.ones(n, dtype=wp.float64)})
    ref = np.stack([np.diag(rot(x)) for x in q])       # d(trace of s-scaled R)/ds_j = R_jj
    np.testing.assert_allclose(s.grad.numpy(), ref, atol=1e-12)
