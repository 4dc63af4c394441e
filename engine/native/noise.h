// Native library: Warp's procedural noise. noise (Perlin gradient noise in 1-4 D, values in
// about [-1, 1]), pnoise (periodic in each lattice dimension) and curlnoise (divergence-free, 2D
// and 3D, summed over octaves). Lattice gradients come from the PCG hash of the lattice point
// (random.h) as in Warp: 1D uniform in [-1, 1], 2D uniform on the circle, 3D/4D normalized
// Gaussian; interpolation by the quintic smootherstep. Not differentiable (as in Warp).
#pragma once

#include "random.h"

namespace wp {

WP_FUNC float32 noise_smootherstep(float32 t) { return t * t * t * (t * (t * 6.0f - 15.0f) + 10.0f); }
WP_FUNC float32 noise_smootherstep_grad(float32 t) { return 30.0f * t * t * (t * (t - 2.0f) + 1.0f); }

// Gradient at lattice point idx[0..D).
template <int D>
WP_FUNC void noise_lattice_gradient(uint32 seed, const int32* idx, float32* g) {
  const uint32 primes[4] = {73856093u, 19349663u, 83492791u, 2654435761u};
  uint32 h = 0;
  for (int k = 0; k < D; ++k) h ^= (uint32)idx[k] * primes[k];
  uint32 state = seed ^ h;
  if constexpr (D == 1) {
    g[0] = randf(state, -1.0f, 1.0f);
  } else if constexpr (D == 2) {
    float32 phi = randf(state, 0.0f, 2.0f * kPi);
    g[0] = cos(phi);
    g[1] = sin(phi);
  } else {
    float32 n2 = 0.0f;
    for (int k = 0; k < D; ++k) {
      g[k] = randn(state);
      n2 += g[k] * g[k];
    }
    float32 inv = n2 > 0.0f ? 1.0f / sqrt(n2) : 0.0f;
    for (int k = 0; k < D; ++k) g[k] *= inv;
  }
}

// Perlin noise at p (D components); period[k] > 0 wraps lattice dimension k (nullptr: none).
// Writes the gradient d value / d p into grad when grad != nullptr.
template <int D>
WP_FUNC float32 perlin(uint32 seed, const float32* p, const int32* period, float32* grad) {
  int32 x0[D];
  float32 f[D], s[D], ds[D];
  for (int k = 0; k < D; ++k) {
    if (!isfinite(p[k])) {  // NaN / inf input: NaN out (no out-of-range float->int conversion)
      if (grad)
        for (int j = 0; j < D; ++j) grad[j] = bits_to_float(0x7fc00000u);
      return bits_to_float(0x7fc00000u);
    }
    float32 fl = floor(p[k]);
    // The lattice index wraps modulo 2^32 (float -> int64 is defined for |fl| < 2^63).
    float32 clamped = fl > 9.0e18f ? 9.0e18f : (fl < -9.0e18f ? -9.0e18f : fl);
    x0[k] = (int32)(uint32)(uint64)(int64)clamped;
    f[k] = p[k] - fl;
    s[k] = noise_smootherstep(f[k]);
    ds[k] = noise_smootherstep_grad(f[k]);
  }
  float32 value = 0.0f;
  float32 dv[D];
  for (int k = 0; k < D; ++k) dv[k] = 0.0f;
  for (int corner = 0; corner < (1 << D); ++corner) {
    int32 idx[D];
    float32 off[D], w = 1.0f;
    for (int k = 0; k < D; ++k) {
      int c = (corner >> k) & 1;
      int32 i = x0[k] + c;
      if (period && period[k] > 0) {
        i %= period[k];
        if (i < 0) i += period[k];
      }
      idx[k] = i;
      off[k] = f[k] - (float32)c;
      w *= c ? s[k] : 1.0f - s[k];
    }
    float32 g[D];
    noise_lattice_gradient<D>(seed, idx, g);
    float32 d = 0.0f;
    for (int k = 0; k < D; ++k) d += g[k] * off[k];
    value += w * d;
    if (grad) {
      for (int k = 0; k < D; ++k) {
        // d w / d p_k: the k-th factor differentiated.
        float32 wk = 1.0f;
        for (int j = 0; j < D; ++j) {
          int c = (corner >> j) & 1;
          if (j == k) wk *= c ? ds[j] : -ds[j];
          else wk *= c ? s[j] : 1.0f - s[j];
        }
        dv[k] += w * g[k] + wk * d;
      }
    }
  }
  if (grad)
    for (int k = 0; k < D; ++k) grad[k] = dv[k];
  return value;
}

WP_FUNC float32 noise(uint32 state, float32 x) { return perlin<1>(state, &x, nullptr, nullptr); }
WP_FUNC float32 noise(uint32 state, const vec_t<2, float32>& p) { return perlin<2>(state, p.c, nullptr, nullptr); }
WP_FUNC float32 noise(uint32 state, const vec_t<3, float32>& p) { return perlin<3>(state, p.c, nullptr, nullptr); }
WP_FUNC float32 noise(uint32 state, const vec_t<4, float32>& p) { return perlin<4>(state, p.c, nullptr, nullptr); }
WP_FUNC float32 pnoise(uint32 state, float32 x, int32 px) { return perlin<1>(state, &x, &px, nullptr); }
WP_FUNC float32 pnoise(uint32 state, const vec_t<2, float32>& p, int32 px, int32 py) {
  const int32 per[2] = {px, py};
  return perlin<2>(state, p.c, per, nullptr);
}
WP_FUNC float32 pnoise(uint32 state, const vec_t<3, float32>& p, int32 px, int32 py, int32 pz) {
  const int32 per[3] = {px, py, pz};
  return perlin<3>(state, p.c, per, nullptr);
}
WP_FUNC float32 pnoise(uint32 state, const vec_t<4, float32>& p, int32 px, int32 py, int32 pz, int32 pt) {
  const int32 per[4] = {px, py, pz, pt};
  return perlin<4>(state, p.c, per, nullptr);
}

// 2D: the rotated gradient of one scalar potential, (d psi/dy, -d psi/dx), summed over octaves
// (frequency *= lacunarity, amplitude *= gain).
WP_FUNC vec_t<2, float32> curlnoise(uint32 state, const vec_t<2, float32>& p, uint32 octaves, float32 lacunarity, float32 gain) {
  vec_t<2, float32> r;
  float32 freq = 1.0f, amp = 1.0f;
  for (uint32 o = 0; o < octaves; ++o) {
    float32 q[2] = {p.c[0] * freq, p.c[1] * freq}, g[2];
    perlin<2>(state, q, nullptr, g);
    r.c[0] += amp * freq * g[1];
    r.c[1] -= amp * freq * g[0];
    freq *= lacunarity;
    amp *= gain;
  }
  return r;
}
// 3D: the curl of a vector potential of three decorrelated noise fields (seeds derived from state).
WP_FUNC vec_t<3, float32> curlnoise(uint32 state, const vec_t<3, float32>& p, uint32 octaves, float32 lacunarity, float32 gain) {
  vec_t<3, float32> r;
  const uint32 seeds[3] = {rand_pcg(state ^ 0x68bc21ebu), rand_pcg(state ^ 0x02e5be93u), rand_pcg(state ^ 0x967a889bu)};
  float32 freq = 1.0f, amp = 1.0f;
  for (uint32 o = 0; o < octaves; ++o) {
    float32 q[3] = {p.c[0] * freq, p.c[1] * freq, p.c[2] * freq};
    float32 g0[3], g1[3], g2[3];
    perlin<3>(seeds[0], q, nullptr, g0);
    perlin<3>(seeds[1], q, nullptr, g1);
    perlin<3>(seeds[2], q, nullptr, g2);
    r.c[0] += amp * freq * (g2[1] - g1[2]);
    r.c[1] += amp * freq * (g0[2] - g2[0]);
    r.c[2] += amp * freq * (g1[0] - g0[1]);
    freq *= lacunarity;
    amp *= gain;
  }
  return r;
}
// 4D input (x, y, z, t): the 3D curl at the time slice t.
WP_FUNC vec_t<3, float32> curlnoise(uint32 state, const vec_t<4, float32>& p, uint32 octaves, float32 lacunarity, float32 gain) {
  vec_t<3, float32> r;
  const uint32 seeds[3] = {rand_pcg(state ^ 0x68bc21ebu), rand_pcg(state ^ 0x02e5be93u), rand_pcg(state ^ 0x967a889bu)};
  float32 freq = 1.0f, amp = 1.0f;
  for (uint32 o = 0; o < octaves; ++o) {
    float32 q[4] = {p.c[0] * freq, p.c[1] * freq, p.c[2] * freq, p.c[3] * freq};
    float32 g0[4], g1[4], g2[4];
    perlin<4>(seeds[0], q, nullptr, g0);
    perlin<4>(seeds[1], q, nullptr, g1);
    perlin<4>(seeds[2], q, nullptr, g2);
    r.c[0] += amp * freq * (g2[1] - g1[2]);
    r.c[1] += amp * freq * (g0[2] - g2[0]);
    r.c[2] += amp * freq * (g1[0] - g0[1]);
    freq *= lacunarity;
    amp *= gain;
  }
  return r;
}

}  // namespace wp
