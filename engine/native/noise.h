// Native library: Warp's procedural noise, value-compatible with Warp 1.19. noise (Perlin
// gradient noise in 1-4 D), pnoise (periodic in each lattice dimension), curlnoise (2D, 3D and
// 4D input, summed over octaves), and their adjoints: d noise / d p from the analytic gradient,
// d curlnoise / d p from the analytic Hessian of the noise.
//
// The lattice: the gradient at integer point (i0, .., iD-1) is drawn from the hash
// (i0*P0) ^ (i1*P1) ^ ... ^ (iD-1*PD-1 + state) (Warp's primes and operator order): 1D one
// randf in [-1, 1); 2D-4D the normalized point of sample_unit_square/cube/hypercube. The value
// interpolates the corners' dot(offset, gradient) with the quintic smootherstep along x, then y,
// z and t, in that order (the order Warp's code rounds in).
#pragma once

#include "random.h"

namespace wp {

WP_FUNC float32 noise_smootherstep(float32 t) { return t * t * t * (t * (t * 6.0f - 15.0f) + 10.0f); }
WP_FUNC float32 noise_smootherstep_grad(float32 t) { return 30.0f * t * t * (t * (t - 2.0f) + 1.0f); }
WP_FUNC float32 noise_smootherstep_hess(float32 t) { return 60.0f * t * (t * (t * 2.0f - 3.0f) + 1.0f); }

// floor(x) as int32; NaN and out-of-range values give INT32_MIN (what x86's conversion gives,
// without the undefined behaviour of the C++ cast).
WP_FUNC int32 noise_floor_int(float32 x) {
  float32 f = floor(x);
  if (!(f >= -2147483648.0f && f < 2147483648.0f)) return (int32)0x80000000u;
  return (int32)f;
}
// Warp's periodic index `a % p` (C remainder); p == 0 or -1 gives 0 instead of a trap.
WP_FUNC int32 noise_wrap(int32 a, int32 p) {
  if (p == 0 || p == -1) return 0;
  return a % p;
}

// Lattice gradient at idx[0..D).
template <int D>
WP_FUNC void noise_lattice_gradient(uint32 state, const int32* idx, float32* g) {
  const uint32 primes[4] = {73856093u, 19349663u, 53471161u, 10000019u};
  uint32 h = (uint32)idx[D - 1] * primes[D - 1] + state;
  for (int k = D - 2; k >= 0; --k) h = ((uint32)idx[k] * primes[k]) ^ h;
  if constexpr (D == 1) {
    g[0] = randf(h, -1.0f, 1.0f);
  } else {
    for (int k = 0; k < D; ++k) g[k] = randf(h) - 0.5f;
    float32 l2 = g[0] * g[0];
    for (int k = 1; k < D; ++k) l2 = l2 + g[k] * g[k];
    float32 l = sqrt(l2);
    if (l > 0.0f)
      for (int k = 0; k < D; ++k) g[k] = g[k] / l;
    else
      for (int k = 0; k < D; ++k) g[k] = 0.0f;
  }
}

// One cell of the lattice: the low and high corner index and the offset d in [0, 1) per axis.
template <int D>
struct noise_cell_t {
  int32 lo[D], hi[D];
  float32 d[D];
};
template <int D>
WP_FUNC noise_cell_t<D> noise_cell(const float32* p, const int32* period) {
  noise_cell_t<D> c;
  for (int k = 0; k < D; ++k) {
    c.d[k] = p[k] - floor(p[k]);
    int32 i = noise_floor_int(p[k]);
    if (period) {
      c.lo[k] = noise_wrap(i, period[k]);
      c.hi[k] = noise_wrap((int32)((uint32)c.lo[k] + 1u), period[k]);
    } else {
      c.lo[k] = i;
      c.hi[k] = (int32)((uint32)i + 1u);
    }
  }
  return c;
}
// Corner `corner` (bit k set: the high index along axis k): its gradient and offset.
template <int D>
WP_FUNC void noise_corner(uint32 state, const noise_cell_t<D>& c, int corner, float32* g, float32* off) {
  int32 idx[D];
  for (int k = 0; k < D; ++k) {
    bool high = (corner >> k) & 1;
    idx[k] = high ? c.hi[k] : c.lo[k];
    off[k] = high ? c.d[k] - 1.0f : c.d[k];
  }
  noise_lattice_gradient<D>(state, idx, g);
}
template <int D>
WP_FUNC float32 noise_dot(const float32* a, const float32* b) {
  float32 s = a[0] * b[0];
  for (int k = 1; k < D; ++k) s = s + a[k] * b[k];
  return s;
}

// The noise value of a cell. The cell functions are out of line (WP_NOINLINE): one copy per
// dimension instead of one per call site (inlined, a 4-D curl noise adjoint alone kept NVRTC
// busy for minutes).
template <int D>
inline WP_NOINLINE WP_CALLABLE float32 noise_value(uint32 state, const noise_cell_t<D>& c) {
  float32 v[1 << D];
  for (int corner = 0; corner < (1 << D); ++corner) {
    float32 g[D], off[D];
    noise_corner<D>(state, c, corner, g, off);
    v[corner] = noise_dot<D>(off, g);
  }
  for (int k = 0, n = 1 << D; k < D; ++k, n >>= 1) {
    float32 s = noise_smootherstep(c.d[k]);
    for (int j = 0; j < n / 2; ++j) v[j] = (v[2 * j + 1] - v[2 * j]) * s + v[2 * j];
  }
  return v[0];
}

// The gradient d noise / d p of a cell, into grad[0..D).
template <int D>
inline WP_NOINLINE WP_CALLABLE void noise_gradient(uint32 state, const noise_cell_t<D>& c, float32* grad) {
  float32 v[1 << D], gr[1 << D][D];
  for (int corner = 0; corner < (1 << D); ++corner) {
    float32 off[D];
    noise_corner<D>(state, c, corner, gr[corner], off);
    v[corner] = noise_dot<D>(off, gr[corner]);
  }
  for (int k = 0, n = 1 << D; k < D; ++k, n >>= 1) {
    float32 s = noise_smootherstep(c.d[k]), s1 = noise_smootherstep_grad(c.d[k]);
    for (int j = 0; j < n / 2; ++j) {
      float32 a0 = v[2 * j], a1 = v[2 * j + 1];
      float32 slope = (a1 - a0) * s1;
      for (int i = 0; i < D; ++i) {
        float32 d0 = gr[2 * j][i], d1 = gr[2 * j + 1][i];
        gr[j][i] = ((d1 - d0) * s + slope * (i == k ? 1.0f : 0.0f)) + d0;
      }
      v[j] = (a1 - a0) * s + a0;
    }
  }
  for (int i = 0; i < D; ++i) grad[i] = gr[0][i];
}

// The Hessian d^2 noise / d p^2 of a cell, into hess[D][D]. Each interpolation step
// F = A + (B - A) S(u) along axis k composes value, gradient and Hessian by the product rule.
template <int D>
inline WP_NOINLINE WP_CALLABLE void noise_hessian(uint32 state, const noise_cell_t<D>& c, float32 (*hess)[D]) {
  struct level_t {
    float32 val;
    float32 grad[D];
    float32 hess[D][D];
  };
  level_t l[1 << D];
  for (int corner = 0; corner < (1 << D); ++corner) {
    float32 off[D];
    noise_corner<D>(state, c, corner, l[corner].grad, off);
    l[corner].val = noise_dot<D>(off, l[corner].grad);
    for (int i = 0; i < D; ++i)
      for (int j = 0; j < D; ++j) l[corner].hess[i][j] = 0.0f;
  }
  for (int k = 0, n = 1 << D; k < D; ++k, n >>= 1) {
    float32 s = noise_smootherstep(c.d[k]), s1 = noise_smootherstep_grad(c.d[k]), s2 = noise_smootherstep_hess(c.d[k]);
    for (int j = 0; j < n / 2; ++j) {
      const level_t a = l[2 * j], b = l[2 * j + 1];
      level_t& f = l[j];
      float32 dv = b.val - a.val, dg[D];
      f.val = a.val + dv * s;
      for (int i = 0; i < D; ++i) {
        dg[i] = b.grad[i] - a.grad[i];
        f.grad[i] = a.grad[i] + dg[i] * s;
      }
      f.grad[k] += dv * s1;
      for (int i = 0; i < D; ++i)
        for (int m = 0; m < D; ++m) f.hess[i][m] = a.hess[i][m] + (b.hess[i][m] - a.hess[i][m]) * s;
      for (int i = 0; i < D; ++i) {
        f.hess[i][k] += dg[i] * s1;
        f.hess[k][i] += dg[i] * s1;
      }
      f.hess[k][k] += dv * s2;
    }
  }
  for (int i = 0; i < D; ++i)
    for (int j = 0; j < D; ++j) hess[i][j] = l[0].hess[i][j];
}

// ---------------------------------------------------------------------------------------------
// noise / pnoise and their adjoints (adj_p += d noise / d p * adj_ret).
WP_FUNC float32 noise(uint32 state, float32 x) { return noise_value<1>(state, noise_cell<1>(&x, nullptr)); }
template <unsigned N>
WP_FUNC float32 noise(uint32 state, const vec_t<N, float32>& p) {
  return noise_value<(int)N>(state, noise_cell<(int)N>(p.c, nullptr));
}
template <typename AS>
WP_FUNC void adj_noise(uint32 state, float32 x, AS&, float32& adj_x, float32 adj_ret) {
  float32 g[1];
  noise_gradient<1>(state, noise_cell<1>(&x, nullptr), g);
  adj_x += g[0] * adj_ret;
}
template <unsigned N, typename AS>
WP_FUNC void adj_noise(uint32 state, const vec_t<N, float32>& p, AS&, vec_t<N, float32>& adj_p, float32 adj_ret) {
  float32 g[N];
  noise_gradient<(int)N>(state, noise_cell<(int)N>(p.c, nullptr), g);
  for (unsigned k = 0; k < N; ++k) adj_p.c[k] += g[k] * adj_ret;
}

WP_FUNC float32 pnoise(uint32 state, float32 x, int32 px) { return noise_value<1>(state, noise_cell<1>(&x, &px)); }
WP_FUNC float32 pnoise(uint32 state, const vec_t<2, float32>& p, int32 px, int32 py) {
  const int32 per[2] = {px, py};
  return noise_value<2>(state, noise_cell<2>(p.c, per));
}
WP_FUNC float32 pnoise(uint32 state, const vec_t<3, float32>& p, int32 px, int32 py, int32 pz) {
  const int32 per[3] = {px, py, pz};
  return noise_value<3>(state, noise_cell<3>(p.c, per));
}
WP_FUNC float32 pnoise(uint32 state, const vec_t<4, float32>& p, int32 px, int32 py, int32 pz, int32 pt) {
  const int32 per[4] = {px, py, pz, pt};
  return noise_value<4>(state, noise_cell<4>(p.c, per));
}
template <typename AS, typename AP>
WP_FUNC void adj_pnoise(uint32 state, float32 x, int32 px, AS&, float32& adj_x, AP&, float32 adj_ret) {
  float32 g[1];
  noise_gradient<1>(state, noise_cell<1>(&x, &px), g);
  adj_x += g[0] * adj_ret;
}
template <typename AS, typename AP>
WP_FUNC void adj_pnoise(uint32 state, const vec_t<2, float32>& p, int32 px, int32 py, AS&, vec_t<2, float32>& adj_p, AP&, AP&,
                        float32 adj_ret) {
  const int32 per[2] = {px, py};
  float32 g[2];
  noise_gradient<2>(state, noise_cell<2>(p.c, per), g);
  for (int k = 0; k < 2; ++k) adj_p.c[k] += g[k] * adj_ret;
}
template <typename AS, typename AP>
WP_FUNC void adj_pnoise(uint32 state, const vec_t<3, float32>& p, int32 px, int32 py, int32 pz, AS&, vec_t<3, float32>& adj_p, AP&,
                        AP&, AP&, float32 adj_ret) {
  const int32 per[3] = {px, py, pz};
  float32 g[3];
  noise_gradient<3>(state, noise_cell<3>(p.c, per), g);
  for (int k = 0; k < 3; ++k) adj_p.c[k] += g[k] * adj_ret;
}
template <typename AS, typename AP>
WP_FUNC void adj_pnoise(uint32 state, const vec_t<4, float32>& p, int32 px, int32 py, int32 pz, int32 pt, AS&,
                        vec_t<4, float32>& adj_p, AP&, AP&, AP&, AP&, float32 adj_ret) {
  const int32 per[4] = {px, py, pz, pt};
  float32 g[4];
  noise_gradient<4>(state, noise_cell<4>(p.c, per), g);
  for (int k = 0; k < 4; ++k) adj_p.c[k] += g[k] * adj_ret;
}

// ---------------------------------------------------------------------------------------------
// curlnoise. 2D: the rotated gradient (-dN/dy, dN/dx) of one field, summed over octaves
// (frequency *= lacunarity, amplitude *= gain). 3D and 4D input: the curl of three fields, the
// second and third with the state advanced by rand_init(state, 10019689) and
// rand_init(state, 13112221), the state carried on to the next octave (as Warp).
WP_FUNC vec_t<2, float32> curlnoise(uint32 state, const vec_t<2, float32>& p, uint32 octaves = 1u, float32 lacunarity = 2.0f,
                                    float32 gain = 0.5f) {
  float32 sum[2] = {0.0f, 0.0f};
  float32 freq = 1.0f, amp = 1.0f;
  for (uint32 o = 0; o < octaves; ++o) {
    float32 q[2] = {freq * p.c[0], freq * p.c[1]}, g[2];
    noise_gradient<2>(state, noise_cell<2>(q, nullptr), g);
    for (int k = 0; k < 2; ++k) sum[k] = sum[k] + amp * g[k];
    amp *= gain;
    freq *= lacunarity;
  }
  return vec_t<2, float32>(-sum[1], sum[0]);
}
template <unsigned N>
WP_FUNC vec_t<3, float32> curlnoise_3fields(uint32 state, const vec_t<N, float32>& p, uint32 octaves, float32 lacunarity,
                                            float32 gain) {
  float32 s1[N] = {}, s2[N] = {}, s3[N] = {};
  float32 freq = 1.0f, amp = 1.0f;
  for (uint32 o = 0; o < octaves; ++o) {
    float32 q[N], g1[N], g2[N], g3[N];
    for (unsigned k = 0; k < N; ++k) q[k] = freq * p.c[k];
    noise_cell_t<(int)N> cell = noise_cell<(int)N>(q, nullptr);
    noise_gradient<(int)N>(state, cell, g1);
    state = rand_init((int32)state, 10019689);
    noise_gradient<(int)N>(state, cell, g2);
    state = rand_init((int32)state, 13112221);
    noise_gradient<(int)N>(state, cell, g3);
    for (unsigned k = 0; k < N; ++k) {
      s1[k] = s1[k] + amp * g1[k];
      s2[k] = s2[k] + amp * g2[k];
      s3[k] = s3[k] + amp * g3[k];
    }
    amp *= gain;
    freq *= lacunarity;
  }
  return vec_t<3, float32>(s3[1] - s2[2], s1[2] - s3[0], s2[0] - s1[1]);
}
WP_FUNC vec_t<3, float32> curlnoise(uint32 state, const vec_t<3, float32>& p, uint32 octaves = 1u, float32 lacunarity = 2.0f,
                                    float32 gain = 0.5f) {
  return curlnoise_3fields<3>(state, p, octaves, lacunarity, gain);
}
WP_FUNC vec_t<3, float32> curlnoise(uint32 state, const vec_t<4, float32>& p, uint32 octaves = 1u, float32 lacunarity = 2.0f,
                                    float32 gain = 0.5f) {
  return curlnoise_3fields<4>(state, p, octaves, lacunarity, gain);
}

// adj_p += J^T adj_ret, J the Jacobian of curlnoise: per octave amp * freq times the
// Hessian(s) of the field(s) at the octave's point.
WP_FUNC void curlnoise_adjoint(uint32 state, const vec_t<2, float32>& p, uint32 octaves, float32 lacunarity, float32 gain,
                               vec_t<2, float32>& adj_p, const vec_t<2, float32>& adj_ret) {
  float32 freq = 1.0f, amp = 1.0f;
  for (uint32 o = 0; o < octaves; ++o) {
    float32 q[2] = {freq * p.c[0], freq * p.c[1]}, h[2][2];
    noise_hessian<2>(state, noise_cell<2>(q, nullptr), h);
    float32 k = amp * freq;
    for (int c = 0; c < 2; ++c) adj_p.c[c] += k * (-h[1][c] * adj_ret.c[0] + h[0][c] * adj_ret.c[1]);
    amp *= gain;
    freq *= lacunarity;
  }
}
template <unsigned N>
WP_FUNC void curlnoise_adjoint(uint32 state, const vec_t<N, float32>& p, uint32 octaves, float32 lacunarity, float32 gain,
                               vec_t<N, float32>& adj_p, const vec_t<3, float32>& adj_ret) {
  float32 freq = 1.0f, amp = 1.0f;
  for (uint32 o = 0; o < octaves; ++o) {
    float32 q[N], h1[N][N], h2[N][N], h3[N][N];
    for (unsigned k = 0; k < N; ++k) q[k] = freq * p.c[k];
    noise_cell_t<(int)N> cell = noise_cell<(int)N>(q, nullptr);
    noise_hessian<(int)N>(state, cell, h1);
    state = rand_init((int32)state, 10019689);
    noise_hessian<(int)N>(state, cell, h2);
    state = rand_init((int32)state, 13112221);
    noise_hessian<(int)N>(state, cell, h3);
    float32 k = amp * freq;
    for (unsigned c = 0; c < N; ++c)
      adj_p.c[c] += k * (adj_ret.c[0] * (h3[1][c] - h2[2][c]) + adj_ret.c[1] * (h1[2][c] - h3[0][c]) +
                         adj_ret.c[2] * (h2[0][c] - h1[1][c]));
    amp *= gain;
    freq *= lacunarity;
  }
}
// Adjoints for each arity of the call (octaves, lacunarity and gain are optional, as in Warp).
template <unsigned N, unsigned M, typename AS>
WP_FUNC void adj_curlnoise(uint32 state, const vec_t<N, float32>& p, AS&, vec_t<N, float32>& adj_p, const vec_t<M, float32>& adj_ret) {
  curlnoise_adjoint(state, p, 1u, 2.0f, 0.5f, adj_p, adj_ret);
}
template <unsigned N, unsigned M, typename AS, typename AO>
WP_FUNC void adj_curlnoise(uint32 state, const vec_t<N, float32>& p, uint32 octaves, AS&, vec_t<N, float32>& adj_p, AO&,
                           const vec_t<M, float32>& adj_ret) {
  curlnoise_adjoint(state, p, octaves, 2.0f, 0.5f, adj_p, adj_ret);
}
template <unsigned N, unsigned M, typename AS, typename AO, typename AL>
WP_FUNC void adj_curlnoise(uint32 state, const vec_t<N, float32>& p, uint32 octaves, float32 lacunarity, AS&, vec_t<N, float32>& adj_p,
                           AO&, AL&, const vec_t<M, float32>& adj_ret) {
  curlnoise_adjoint(state, p, octaves, lacunarity, 0.5f, adj_p, adj_ret);
}
template <unsigned N, unsigned M, typename AS, typename AO, typename AL, typename AG>
WP_FUNC void adj_curlnoise(uint32 state, const vec_t<N, float32>& p, uint32 octaves, float32 lacunarity, float32 gain, AS&,
                           vec_t<N, float32>& adj_p, AO&, AL&, AG&, const vec_t<M, float32>& adj_ret) {
  curlnoise_adjoint(state, p, octaves, lacunarity, gain, adj_p, adj_ret);
}

}  // namespace wp
