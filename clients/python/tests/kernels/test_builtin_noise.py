"""Builtins, noise: noise/pnoise (1-4 D) and curlnoise (2D, 3D, 4D input, optional octaves,
lacunarity and gain) against a float64 NumPy model of Warp's algorithm (PCG-hashed lattice
gradients, quintic interpolation along x, then y, z, t), on random points; their adjoints
(tape.backward) against the model's gradient and the central-difference Jacobian of its curl."""
import numpy as np
import pytest

import weft as wp

_PRIMES = [73856093, 19349663, 53471161, 10000019]
_M32 = 0xFFFFFFFF


def _pcg(state):
    b = (state * 747796405 + 2891336453) & _M32
    c = (((b >> ((b >> 28) + 4)) ^ b) * 277803737) & _M32
    return ((c >> 22) ^ c) & _M32


def _rand_init(seed, offset=None):
    if offset is None:
        return _pcg(seed & _M32)
    return _pcg(((seed & _M32) + _pcg(offset & _M32)) & _M32)


def _lattice_gradient(state, idx):
    d = len(idx)
    h = ((idx[-1] & _M32) * _PRIMES[d - 1] + state) & _M32
    for k in range(d - 2, -1, -1):
        h = (((idx[k] & _M32) * _PRIMES[k]) & _M32) ^ h
    draws = []
    for _ in range(d):
        h = _pcg(h)
        draws.append((h >> 8) / 16777216.0)
    if d == 1:
        return np.array([2.0 * draws[0] - 1.0])
    g = np.array(draws) - 0.5
    n = np.linalg.norm(g)
    return g / n if n > 0 else g * 0.0


def _smooth(t):
    return t * t * t * (t * (t * 6 - 15) + 10), 30 * t * t * (t * (t - 2) + 1)


def _noise_ref(state, p, period=None):
    """Value and gradient of Warp's noise at p (float64)."""
    p = np.atleast_1d(np.asarray(p, dtype=np.float64))
    d = len(p)
    fl = np.floor(p)
    lo = fl.astype(np.int64)
    if period is not None:
        lo = np.array([int(np.fmod(lo[k], period[k])) for k in range(d)])
        hi = np.array([int(np.fmod(lo[k] + 1, period[k])) for k in range(d)])
    else:
        hi = lo + 1
    f = p - fl
    vals, grads = [], []
    for corner in range(1 << d):
        bits = [(corner >> k) & 1 for k in range(d)]
        idx = [int(hi[k] if bits[k] else lo[k]) for k in range(d)]
        off = np.array([f[k] - bits[k] for k in range(d)])
        g = _lattice_gradient(state, idx)
        vals.append(off @ g)
        grads.append(g.copy())
    for k in range(d):
        s, s1 = _smooth(f[k])
        nv, ng = [], []
        for j in range(len(vals) // 2):
            a0, a1 = vals[2 * j], vals[2 * j + 1]
            g = grads[2 * j] + (grads[2 * j + 1] - grads[2 * j]) * s
            g[k] += (a1 - a0) * s1
            nv.append(a0 + (a1 - a0) * s)
            ng.append(g)
        vals, grads = nv, ng
    return vals[0], grads[0]


def _curl_ref(state, p, octaves=1, lac=2.0, gain=0.5):
    p = np.asarray(p, dtype=np.float64)
    freq, amp = 1.0, 1.0
    if len(p) == 2:
        s = np.zeros(2)
        for _ in range(octaves):
            s += amp * _noise_ref(state, freq * p)[1]
            amp *= gain
            freq *= lac
        return np.array([-s[1], s[0]])
    s1, s2, s3 = np.zeros(len(p)), np.zeros(len(p)), np.zeros(len(p))
    for _ in range(octaves):
        q = freq * p
        s1 += amp * _noise_ref(state, q)[1]
        state = _rand_init(state, 10019689)
        s2 += amp * _noise_ref(state, q)[1]
        state = _rand_init(state, 13112221)
        s3 += amp * _noise_ref(state, q)[1]
        amp *= gain
        freq *= lac
    return np.array([s3[1] - s2[2], s1[2] - s3[0], s2[0] - s1[1]])


@wp.kernel
def noise_kernel(seed: int, x: wp.array(dtype=float), p2: wp.array(dtype=wp.vec2), p3: wp.array(dtype=wp.vec3),
                 p4: wp.array(dtype=wp.vec4), out: wp.array2d(dtype=float)):
    i = wp.tid()
    state = wp.rand_init(seed)
    out[i, 0] = wp.noise(state, x[i])
    out[i, 1] = wp.noise(state, p2[i])
    out[i, 2] = wp.noise(state, p3[i])
    out[i, 3] = wp.noise(state, p4[i])
    out[i, 4] = wp.pnoise(state, x[i], 3)
    out[i, 5] = wp.pnoise(state, p2[i], 3, 5)
    out[i, 6] = wp.pnoise(state, p3[i], 3, 5, 7)
    out[i, 7] = wp.pnoise(state, p4[i], 3, 5, 7, 2)


def _points(rng, n, d):
    # keep the points a little away from lattice planes (the model's floor is float64)
    p = rng.uniform(-6.0, 6.0, size=(n, d)).astype(np.float32)
    frac = p - np.floor(p)
    return np.where((frac < 1e-3) | (frac > 1 - 1e-3), p + np.float32(0.01), p).astype(np.float32)


def test_noise_and_pnoise_match_warps_algorithm(wp, rng):
    n = 64
    seed = int(rng.integers(0, 2**31 - 1))
    x = _points(rng, n, 1)[:, 0]
    p2, p3, p4 = _points(rng, n, 2), _points(rng, n, 3), _points(rng, n, 4)
    out = wp.zeros((n, 8), dtype=float)
    wp.launch(noise_kernel, dim=n, inputs=[seed, wp.array(x, dtype=float), wp.array(p2, dtype=wp.vec2),
                                           wp.array(p3, dtype=wp.vec3), wp.array(p4, dtype=wp.vec4), out])
    got = out.numpy()
    state = _rand_init(seed)
    pts = [x[:, None], p2, p3, p4]
    periods = [[3], [3, 5], [3, 5, 7], [3, 5, 7, 2]]
    for i in range(n):
        for d in range(4):
            v, _ = _noise_ref(state, pts[d][i])
            pv, _ = _noise_ref(state, pts[d][i], periods[d])
            assert abs(got[i, d] - v) < 2e-6, (i, d, got[i, d], v)
            assert abs(got[i, 4 + d] - pv) < 2e-6, (i, d, got[i, 4 + d], pv)
    assert np.abs(got).max() > 0.1     # not a constant


def test_pnoise_is_periodic(wp, rng):
    n = 32
    seed = int(rng.integers(0, 2**31 - 1))
    # Warp's period wraps the lattice index with C's remainder (negative indices stay negative),
    # so the noise repeats with the period on non-negative coordinates
    p4 = np.abs(_points(rng, n, 4))
    shifted = (p4 + np.array([3, 5, 7, 2], dtype=np.float32) * rng.integers(1, 4, size=(n, 1))).astype(np.float32)
    outs = []
    for pts in (p4, shifted):
        out = wp.zeros((n, 8), dtype=float)
        wp.launch(noise_kernel, dim=n, inputs=[seed, wp.array(pts[:, 0], dtype=float), wp.array(pts[:, :2], dtype=wp.vec2),
                                               wp.array(pts[:, :3], dtype=wp.vec3), wp.array(pts, dtype=wp.vec4), out])
        outs.append(out.numpy())
    # the shift is not exact in float32 for every point: compare with a float32 rounding bound
    np.testing.assert_allclose(outs[0][:, 7], outs[1][:, 7], atol=1e-4)


@wp.kernel
def curl_kernel(seed: int, octaves: wp.uint32, lac: float, gain: float, p2: wp.array(dtype=wp.vec2),
                p3: wp.array(dtype=wp.vec3), p4: wp.array(dtype=wp.vec4), c2: wp.array(dtype=wp.vec2),
                c3: wp.array(dtype=wp.vec3), c4: wp.array(dtype=wp.vec3), d2: wp.array(dtype=wp.vec2),
                d3: wp.array(dtype=wp.vec3), d4: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    state = wp.rand_init(seed)
    c2[i] = wp.curlnoise(state, p2[i], octaves, lac, gain)
    c3[i] = wp.curlnoise(state, p3[i], octaves, lac, gain)
    c4[i] = wp.curlnoise(state, p4[i], octaves, lac, gain)
    d2[i] = wp.curlnoise(state, p2[i])
    d3[i] = wp.curlnoise(state, p3[i], octaves)
    d4[i] = wp.curlnoise(state, p4[i], octaves, lac)


def test_curlnoise_matches_warps_algorithm(wp, rng):
    n = 24
    seed = int(rng.integers(0, 2**31 - 1))
    octaves, lac, gain = 3, float(rng.uniform(1.5, 2.5)), float(rng.uniform(0.3, 0.7))
    p2, p3, p4 = _points(rng, n, 2), _points(rng, n, 3), _points(rng, n, 4)
    outs = [wp.zeros(n, dtype=t) for t in (wp.vec2, wp.vec3, wp.vec3, wp.vec2, wp.vec3, wp.vec3)]
    wp.launch(curl_kernel, dim=n, inputs=[seed, wp.uint32(octaves), lac, gain, wp.array(p2, dtype=wp.vec2),
                                          wp.array(p3, dtype=wp.vec3), wp.array(p4, dtype=wp.vec4)] + outs)
    c2, c3, c4, d2, d3, d4 = (o.numpy() for o in outs)
    state = _rand_init(seed)
    for i in range(n):
        np.testing.assert_allclose(c2[i], _curl_ref(state, p2[i], octaves, lac, gain), atol=5e-5)
        np.testing.assert_allclose(c3[i], _curl_ref(state, p3[i], octaves, lac, gain), atol=5e-5)
        np.testing.assert_allclose(c4[i], _curl_ref(state, p4[i], octaves, lac, gain), atol=5e-5)
        np.testing.assert_allclose(d2[i], _curl_ref(state, p2[i]), atol=5e-5)
        np.testing.assert_allclose(d3[i], _curl_ref(state, p3[i], octaves), atol=5e-5)
        np.testing.assert_allclose(d4[i], _curl_ref(state, p4[i], octaves, lac), atol=5e-5)


@wp.kernel
def noise_loss(seed: int, p3: wp.array(dtype=wp.vec3), x: wp.array(dtype=float), w: wp.array(dtype=float),
               loss: wp.array(dtype=float)):
    i = wp.tid()
    state = wp.rand_init(seed)
    v = w[0] * wp.noise(state, p3[i]) + w[1] * wp.pnoise(state, p3[i], 4, 3, 5) + w[2] * wp.noise(state, x[i])
    wp.atomic_add(loss, 0, v)


def test_noise_adjoint_is_the_analytic_gradient(wp, rng):
    n = 32
    seed = int(rng.integers(0, 2**31 - 1))
    p3 = wp.array(_points(rng, n, 3), dtype=wp.vec3, requires_grad=True)
    x = wp.array(_points(rng, n, 1)[:, 0], dtype=float, requires_grad=True)
    wv = rng.uniform(0.5, 2.0, size=3)
    w = wp.array(wv.astype(np.float32), dtype=float)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(noise_loss, dim=n, inputs=[seed, p3, x, w, loss])
    tape.backward(loss=loss)
    state = _rand_init(seed)
    pts, xs = p3.numpy(), x.numpy()
    want3 = np.array([wv[0] * _noise_ref(state, q)[1] + wv[1] * _noise_ref(state, q, [4, 3, 5])[1] for q in pts])
    want1 = np.array([wv[2] * _noise_ref(state, [v])[1][0] for v in xs])
    np.testing.assert_allclose(p3.grad.numpy(), want3, atol=2e-5)
    np.testing.assert_allclose(x.grad.numpy(), want1, atol=2e-5)


@wp.kernel
def curl_loss(seed: int, octaves: wp.uint32, p2: wp.array(dtype=wp.vec2), p3: wp.array(dtype=wp.vec3),
              p4: wp.array(dtype=wp.vec4), w: wp.vec3, loss: wp.array(dtype=float)):
    i = wp.tid()
    state = wp.rand_init(seed)
    c2 = wp.curlnoise(state, p2[i], octaves, 2.0, 0.5)
    c3 = wp.curlnoise(state, p3[i], octaves, 2.0, 0.5)
    c4 = wp.curlnoise(state, p4[i], octaves, 2.0, 0.5)
    wp.atomic_add(loss, 0, c2[0] * w[0] + c2[1] * w[1] + wp.dot(c3, w) + wp.dot(c4, w))


@pytest.mark.parametrize("octaves", [1, 2])
def test_curlnoise_adjoint_is_the_jacobian(wp, rng, octaves):
    n = 12
    seed = int(rng.integers(0, 2**31 - 1))
    arrays = [wp.array(_points(rng, n, d), dtype=t, requires_grad=True)
              for d, t in ((2, wp.vec2), (3, wp.vec3), (4, wp.vec4))]
    wv = rng.uniform(-1.0, 1.0, size=3)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(curl_loss, dim=n, inputs=[seed, wp.uint32(octaves)] + arrays + [wp.vec3(*wv), loss])
    tape.backward(loss=loss)
    state = _rand_init(seed)
    h = 1e-5
    for a in arrays:
        pts = a.numpy().astype(np.float64)
        d = pts.shape[1]
        wd = wv[:2] if d == 2 else wv
        want = np.zeros_like(pts)
        for i in range(n):
            for k in range(d):
                e = np.zeros(d)
                e[k] = h
                dc = (_curl_ref(state, pts[i] + e, octaves) - _curl_ref(state, pts[i] - e, octaves)) / (2 * h)
                want[i, k] = dc @ wd
        np.testing.assert_allclose(a.grad.numpy(), want, atol=5e-4 * octaves * 2)
