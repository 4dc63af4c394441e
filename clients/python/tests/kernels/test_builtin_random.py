"""Builtins, random: rand_init/randi/randf/randn/randu determinism per (seed, offset),
ranges, and distribution moments (uniform mean/variance, normal mean/variance/kurtosis),
plus Warp's sampling helpers (sample_unit_sphere_surface, sample_unit_disk)."""
import numpy as np

import weft as wp


@wp.kernel
def draw(seed: int, f: wp.array(dtype=float), g: wp.array(dtype=float), r: wp.array(dtype=float),
         k: wp.array(dtype=int), s: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    state = wp.rand_init(seed, i)
    f[i] = wp.randf(state)
    g[i] = wp.randn(state)
    r[i] = wp.randf(state, -2.0, 3.0)
    k[i] = wp.randi(state, -5, 5)
    s[i] = wp.sample_unit_sphere_surface(state)
    d[i] = wp.sample_unit_disk(state)


def _draw(wp, seed, n):
    arrays = [wp.zeros(n, dtype=float), wp.zeros(n, dtype=float), wp.zeros(n, dtype=float),
              wp.zeros(n, dtype=int), wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec2)]
    wp.launch(draw, dim=n, inputs=[seed] + arrays)
    return [a.numpy() for a in arrays]


def test_random_distributions(wp, rng):
    n = 200_000
    seed = int(rng.integers(0, 2**31 - 1))
    f, g, r, k, s, d = _draw(wp, seed, n)
    assert f.min() >= 0.0 and f.max() < 1.0
    assert abs(f.mean() - 0.5) < 5 * np.sqrt(1 / 12 / n)
    assert abs(f.var() - 1 / 12) < 0.01
    assert abs(g.mean()) < 5 / np.sqrt(n)
    assert abs(g.var() - 1.0) < 0.02
    kurt = ((g - g.mean()) ** 4).mean() / g.var() ** 2
    assert abs(kurt - 3.0) < 0.1
    assert r.min() >= -2.0 and r.max() < 3.0 and abs(r.mean() - 0.5) < 0.02
    assert k.min() >= -5 and k.max() < 5 and set(np.unique(k)) == set(range(-5, 5))
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1.0, rtol=1e-5)
    assert np.all(np.abs(s.mean(0)) < 0.02)
    assert np.all(np.linalg.norm(d, axis=1) <= 1.0 + 1e-6)
    # uniform over the disk: mean squared radius is 1/2
    assert abs((d ** 2).sum(1).mean() - 0.5) < 0.01


def test_random_is_deterministic_per_seed(wp, rng):
    seed = int(rng.integers(0, 2**31 - 1))
    a = _draw(wp, seed, 1000)
    b = _draw(wp, seed, 1000)
    c = _draw(wp, seed + 1, 1000)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0], c[0])
    # threads get different streams
    assert len(np.unique(a[0])) > 990
