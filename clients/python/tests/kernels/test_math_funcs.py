"""Warp's math helpers (weft/_kernel/math_funcs.py) in kernels against float64 NumPy references:
vector norms on huge and tiny magnitudes, Euler angles for all twelve axis sequences (random
angles and gimbal lock), swing-twist angles, twists and wrenches moved between frames."""
import itertools

import numpy as np

import weft as wp


@wp.kernel
def norms(v: wp.array(dtype=wp.vec3), out: wp.array2d(dtype=float)):
    i = wp.tid()
    out[i, 0] = wp.norm_l1(v[i])
    out[i, 1] = wp.norm_l2(v[i])
    out[i, 2] = wp.norm_huber(v[i], 2.0)
    out[i, 3] = wp.norm_pseudo_huber(v[i], 2.0)
    out[i, 4] = wp.length(wp.smooth_normalize(v[i], 2.0))


def test_norms_against_float64(wp, rng):
    n = 64
    scale = 10.0 ** rng.uniform(-6, 6, size=(n, 1))
    x = (rng.standard_normal((n, 3)) * scale).astype(np.float32)
    out = wp.zeros((n, 5), dtype=float)
    wp.launch(norms, dim=n, inputs=[wp.array(x, dtype=wp.vec3), out])
    x64 = x.astype(np.float64)
    l2 = np.linalg.norm(x64, axis=1)
    ph = 2.0 * np.sqrt(1.0 + l2 * l2 / 4.0)
    ref = np.stack([np.abs(x64).sum(axis=1), l2, np.where(l2 <= 2.0, 0.5 * l2 * l2, 2.0 * (l2 - 1.0)), ph, l2 / ph],
                   axis=1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=2e-6, atol=1e-30)


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def _axis_quat(axis, angle):
    q = np.zeros(4)
    q[axis] = np.sin(angle / 2)
    q[3] = np.cos(angle / 2)
    return q


SEQUENCES = [s for s in itertools.product(range(3), repeat=3) if s[0] != s[1] and s[1] != s[2]]


@wp.kernel
def euler(e: wp.array(dtype=wp.vec3), seq: wp.array(dtype=wp.vec3i), q_out: wp.array(dtype=wp.quat),
          back: wp.array(dtype=wp.vec3)):
    t = wp.tid()
    s = seq[t]
    q = wp.quat_from_euler(e[t], s[0], s[1], s[2])
    q_out[t] = q
    back[t] = wp.quat_to_euler(q, s[0], s[1], s[2])


def test_euler_angles_all_sequences(wp, rng):
    per = 40
    seq = np.repeat(np.array(SEQUENCES, dtype=np.int32), per, axis=0)
    e = rng.uniform(-np.pi, np.pi, size=(len(seq), 3))
    for r, (i, j, k) in enumerate(seq):
        if r % 4 == 0:   # gimbal lock: the second angle at its singular value
            e[r, j] = rng.choice([np.pi / 2, -np.pi / 2]) if i != k else 0.0
    n = len(seq)
    q_out, back = wp.zeros(n, dtype=wp.quat), wp.zeros(n, dtype=wp.vec3)
    wp.launch(euler, dim=n, inputs=[wp.array(e.astype(np.float32), dtype=wp.vec3),
                                    wp.array(seq, dtype=wp.vec3i), q_out, back])
    q, eb = q_out.numpy().astype(np.float64), back.numpy().astype(np.float64)
    e32 = e.astype(np.float32).astype(np.float64)
    for r, (i, j, k) in enumerate(seq):
        ref = _qmul(_axis_quat(k, e32[r, k]), _qmul(_axis_quat(j, e32[r, j]), _axis_quat(i, e32[r, i])))
        np.testing.assert_allclose(q[r], ref, atol=2e-6)
        # the angles found rebuild the rotation (up to the quaternion's sign)
        third = eb[r, 3 - i - j] if i == k else eb[r, k]
        rebuilt = _qmul(_axis_quat(k, third), _qmul(_axis_quat(j, eb[r, j]), _axis_quat(i, eb[r, i])))
        if i == k:
            rebuilt = _qmul(_axis_quat(i, third), _qmul(_axis_quat(j, eb[r, j]), _axis_quat(i, eb[r, i])))
        err = min(np.abs(rebuilt - q[r]).max(), np.abs(rebuilt + q[r]).max())
        assert err < 2e-3 if r % 4 == 0 else err < 2e-5, (i, j, k, e32[r], eb[r], err)


@wp.kernel
def frames(t: wp.array(dtype=wp.transform), x: wp.array(dtype=wp.spatial_vector), r: wp.array(dtype=wp.vec3),
           out: wp.array2d(dtype=wp.spatial_vector), vel: wp.array(dtype=wp.vec3), rpy: wp.array(dtype=wp.vec3),
           twist: wp.array(dtype=float)):
    i = wp.tid()
    out[i, 0] = wp.transform_twist(t[i], x[i])
    out[i, 1] = wp.transform_wrench(t[i], x[i])
    vel[i] = wp.velocity_at_point(x[i], r[i])
    rpy[i] = wp.quat_to_rpy(wp.quat_rpy(r[i][0], r[i][1], r[i][2]))
    q = wp.mul(wp.quat_from_axis_angle(wp.vec3(1.0, 0.0, 0.0), 0.3),
               wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), r[i][2]))
    twist[i] = wp.quat_twist_angle_signed(wp.vec3(0.0, 0.0, 1.0), q) - r[i][2]


def _rotate(q, v):
    return _qmul(_qmul(q, np.append(v, 0.0)), q * np.array([-1, -1, -1, 1]))[:3]


def test_frames_twists_and_angles(wp, rng):
    n = 32
    p = rng.standard_normal((n, 3)) * 100
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x = rng.standard_normal((n, 6))
    r = rng.uniform(-1.2, 1.2, size=(n, 3))
    f32 = lambda a: a.astype(np.float32)  # noqa: E731
    out = wp.zeros((n, 2), dtype=wp.spatial_vector)
    vel, rpy, twist = wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=float)
    wp.launch(frames, dim=n, inputs=[wp.array(f32(np.concatenate([p, q], 1)), dtype=wp.transform),
                                     wp.array(f32(x), dtype=wp.spatial_vector), wp.array(f32(r), dtype=wp.vec3),
                                     out, vel, rpy, twist])
    p, q, x, r = (f32(a).astype(np.float64) for a in (p, q, x, r))
    got = out.numpy()
    for i in range(n):
        w = _rotate(q[i], x[i, :3])
        v = _rotate(q[i], x[i, 3:]) + np.cross(p[i], w)
        np.testing.assert_allclose(got[i, 0], np.concatenate([w, v]), rtol=1e-4, atol=1e-3)
        f = _rotate(q[i], x[i, 3:])
        tau = _rotate(q[i], x[i, :3]) + np.cross(p[i], f)
        np.testing.assert_allclose(got[i, 1], np.concatenate([tau, f]), rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(vel.numpy(), np.cross(x[:, :3], r) + x[:, 3:], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(rpy.numpy(), r, atol=2e-5)
    np.testing.assert_allclose(twist.numpy(), 0.0, atol=2e-6)


@wp.kernel
def between(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.quat),
            rotated: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    q = wp.quat_between_vectors(a[i], b[i])
    out[i] = q
    rotated[i] = wp.quat_rotate(q, wp.normalize(a[i]))


def test_quat_between_vectors_against_float64(wp, rng):
    """wp.quat_between_vectors (a warp.utils @wp.func in Warp) in a kernel and from Python: the
    unit shortest-arc rotation taking normalize(a) onto normalize(b), against the float64 rotation
    on random directions of magnitudes 1e-15..1e15, nearly parallel pairs and perpendicular pairs
    (opposite directions are excluded: Warp does not handle them either)."""
    n = 96
    a = rng.standard_normal((n, 3)) * 10.0 ** rng.uniform(-15, 15, size=(n, 1))
    b = rng.standard_normal((n, 3)) * 10.0 ** rng.uniform(-15, 15, size=(n, 1))
    b[:16] = a[:16] * 3.0 + rng.standard_normal((16, 3)) * 1e-4 * np.abs(a[:16])   # nearly parallel
    for k in range(16, 32):                                                          # perpendicular
        b[k] = np.cross(a[k], rng.standard_normal(3))
    ua = a / np.linalg.norm(a, axis=1, keepdims=True)
    ub = b / np.linalg.norm(b, axis=1, keepdims=True)
    keep = (ua * ub).sum(axis=1) > -0.9
    a, b, ua, ub = a[keep], b[keep], ua[keep], ub[keep]
    n = len(a)
    out = wp.zeros(n, dtype=wp.quat)
    rotated = wp.zeros(n, dtype=wp.vec3)
    wp.launch(between, dim=n, inputs=[wp.array(a.astype(np.float32), dtype=wp.vec3),
                                      wp.array(b.astype(np.float32), dtype=wp.vec3), out, rotated])
    c = np.cross(ua, ub)
    q64 = np.concatenate([c, 1.0 + (ua * ub).sum(axis=1, keepdims=True)], axis=1)
    q64 /= np.linalg.norm(q64, axis=1, keepdims=True)
    np.testing.assert_allclose(out.numpy(), q64, atol=2e-6)
    np.testing.assert_allclose(rotated.numpy(), ub, atol=5e-6)
    q = wp.quat_between_vectors(wp.vec3(*a[0].astype(np.float32)), wp.vec3(*b[0].astype(np.float32)))
    np.testing.assert_allclose(np.array(q, dtype=np.float64), q64[0], atol=2e-6)


def test_transform_expand():
    t = wp.transform_expand((1.0, 2.0, 3.0, 4.0, 3.0, 2.0, 1.0))
    assert t == wp.transformf(p=(1.0, 2.0, 3.0), q=(4.0, 3.0, 2.0, 1.0))
    assert isinstance(t, wp.transformf)
    import pytest

    with pytest.raises(ValueError, match="7 values"):
        wp.transform_expand((1.0, 2.0))
