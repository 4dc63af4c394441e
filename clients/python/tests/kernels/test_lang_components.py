"""Language: vector/matrix/quaternion component reads and writes (v[0], v.x, m[i, j], m[i]),
component assignment (also a transform's .p and .q, on a local and on an array element, with
their adjoints), and vectors/matrices of other lengths and dtypes (vec5 via
wp.types.vector, mat22d) as kernel arguments and array elements."""
import numpy as np

import weft as wp

vec5 = wp.types.vector(length=5, dtype=float)
mat23 = wp.types.matrix(shape=(2, 3), dtype=float)


@wp.kernel
def components(vs: wp.array(dtype=wp.vec3), ms: wp.array(dtype=wp.mat33),
               out: wp.array(dtype=float, ndim=2), vout: wp.array(dtype=wp.vec3),
               mout: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    v = vs[i]
    m = ms[i]
    out[i, 0] = v[0] + v[1] * 2.0 + v[2] * 3.0
    out[i, 1] = v.x - v.y + v.z
    out[i, 2] = m[0, 0] + m[1, 2] * 2.0 + m[2, 1] * 3.0
    row = m[1]
    out[i, 3] = row[0] + row[1] + row[2]
    w = wp.vec3()
    w[0] = v[2]
    w[1] = v[0]
    w[2] = v[1]
    vout[i] = w
    n = wp.mat33()
    for r in range(3):
        for c in range(3):
            n[r, c] = m[c, r]
    mout[i] = n


@wp.kernel
def custom_types(a: wp.array(dtype=vec5), s: vec5, m: mat23, d: wp.mat22d,
                 out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    v = a[i] + s
    t = float(0.0)
    for k in range(5):
        t += v[k]
    out[i, 0] = t
    out[i, 1] = m[1, 2] + m[0, 0]
    out[i, 2] = float(d[0, 1] + d[1, 0])


def test_vector_matrix_components(wp, rng):
    n = 200
    v = rng.standard_normal((n, 3)).astype(np.float32)
    m = rng.standard_normal((n, 3, 3)).astype(np.float32)
    out = wp.zeros((n, 4), dtype=float)
    vout = wp.zeros(n, dtype=wp.vec3)
    mout = wp.zeros(n, dtype=wp.mat33)
    wp.launch(components, dim=n, inputs=[wp.array(v, dtype=wp.vec3), wp.array(m, dtype=wp.mat33)],
              outputs=[out, vout, mout])
    v64, m64 = v.astype(np.float64), m.astype(np.float64)
    ref = np.stack([v64[:, 0] + 2 * v64[:, 1] + 3 * v64[:, 2], v64[:, 0] - v64[:, 1] + v64[:, 2],
                    m64[:, 0, 0] + 2 * m64[:, 1, 2] + 3 * m64[:, 2, 1], m64[:, 1, :].sum(1)], axis=1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(vout.numpy(), v[:, [2, 0, 1]])
    np.testing.assert_array_equal(mout.numpy(), np.transpose(m, (0, 2, 1)))


def test_custom_vector_and_matrix_types(wp, rng):
    n = 50
    a = rng.standard_normal((n, 5)).astype(np.float32)
    s = rng.standard_normal(5).astype(np.float32)
    m = rng.standard_normal((2, 3)).astype(np.float32)
    d = rng.standard_normal((2, 2))
    out = wp.zeros((n, 3), dtype=float)
    wp.launch(custom_types, dim=n, inputs=[wp.array(a, dtype=vec5), vec5(*s.tolist()),
                                           mat23(*m.ravel().tolist()),
                                           wp.mat22d(*d.ravel().tolist()), out])
    ref = np.stack([(a.astype(np.float64) + s).sum(1), np.full(n, m[1, 2] + m[0, 0]),
                    np.full(n, d[0, 1] + d[1, 0])], axis=1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-5, atol=1e-5)


@wp.kernel
def set_transform_parts(p: wp.array(dtype=wp.vec3), q: wp.array(dtype=wp.quat),
                        y: wp.array(dtype=wp.transform), z: wp.array(dtype=wp.transform)):
    i = wp.tid()
    t = wp.transform_identity()
    t.p = p[i] * 2.0
    t.q = q[i]
    z[i] = t
    y[i].p = p[i]


def test_transform_translation_and_rotation_assignment(wp, rng):
    n = 8
    p_np = rng.standard_normal((n, 3))
    q_np = rng.standard_normal((n, 4))
    y_np = rng.standard_normal((n, 7))
    p = wp.array(p_np, dtype=wp.vec3, requires_grad=True)
    q = wp.array(q_np, dtype=wp.quat, requires_grad=True)
    y = wp.array(y_np, dtype=wp.transform, requires_grad=True)
    z = wp.zeros(n, dtype=wp.transform, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(set_transform_parts, dim=n, inputs=[p, q, y, z])
    want_y = y_np.copy()
    want_y[:, :3] = p_np
    np.testing.assert_allclose(y.numpy(), want_y, rtol=1e-6)
    np.testing.assert_allclose(z.numpy(), np.concatenate([2.0 * p_np, q_np], axis=1), rtol=1e-6)
    seed_y, seed_z = rng.standard_normal((n, 7)), rng.standard_normal((n, 7))
    tape.backward(grads={y: wp.array(seed_y, dtype=wp.transform), z: wp.array(seed_z, dtype=wp.transform)})
    np.testing.assert_allclose(p.grad.numpy(), seed_y[:, :3] + 2.0 * seed_z[:, :3], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(q.grad.numpy(), seed_z[:, 3:], rtol=1e-5, atol=1e-6)
