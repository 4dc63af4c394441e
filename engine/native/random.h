// Native library: Warp's random numbers. A uint32 state advanced by a PCG hash (the same hash
// and the same transforms as Warp, so streams follow the same distributions): rand_init,
// randi, randu, randf, randn, sample_cdf, the sample_* helpers, poisson, lower_bound.
// Functions that draw take `uint32& state` and advance it, as Warp's do.
#pragma once

#include "array.h"
#include "vec.h"

namespace wp {

WP_FUNC uint32 rand_pcg(uint32 state) {
  uint32 b = state * 747796405u + 2891336453u;
  uint32 c = ((b >> ((b >> 28u) + 4u)) ^ b) * 277803737u;
  return (c >> 22u) ^ c;
}
WP_FUNC uint32 rand_init(int32 seed) { return rand_pcg((uint32)seed); }
WP_FUNC uint32 rand_init(int32 seed, int32 offset) { return rand_pcg((uint32)seed + rand_pcg((uint32)offset)); }

WP_FUNC int32 randi(uint32& state) {
  state = rand_pcg(state);
  return (int32)state;
}
// [low, high); high <= low yields low.
WP_FUNC int32 randi(uint32& state, int32 low, int32 high) {
  state = rand_pcg(state);
  uint32 span = (uint32)high - (uint32)low;
  if ((int64)high <= (int64)low) return low;
  return (int32)(state % span + (uint32)low);
}
WP_FUNC uint32 randu(uint32& state) {
  state = rand_pcg(state);
  return state;
}
WP_FUNC uint32 randu(uint32& state, uint32 low, uint32 high) {
  state = rand_pcg(state);
  if (high <= low) return low;
  return state % (high - low) + low;
}
// Uniform in [0, 1) with 24 random bits.
WP_FUNC float32 randf(uint32& state) {
  state = rand_pcg(state);
  return (float32)(state >> 8) * (1.0f / 16777216.0f);
}
WP_FUNC float32 randf(uint32& state, float32 low, float32 high) { return (high - low) * randf(state) + low; }
// Standard normal by Box-Muller (two draws).
WP_FUNC float32 randn(uint32& state) {
  float32 u1 = randf(state);
  float32 u2 = randf(state);
  return sqrt(-2.0f * log(u1 + 1.0e-9f)) * cos(2.0f * kPi * u2);
}

// First index in [begin, end) whose value is >= v (arr sorted ascending). The range is clamped
// to the array (user-supplied bounds never read outside it); a None array gives `begin`.
template <typename T>
WP_FUNC int32 lower_bound(const array_t<T>& arr, int32 begin, int32 end, T v) {
  if (!arr.data) return begin;
  int64 n = arr.shape[0];
  // Warp's search: over [begin, end - 1], so a value past the last element gives end - 1
  int32 lo = begin < 0 ? 0 : begin;
  int32 hi = ((int64)end > n ? (int32)n : end) - 1;
  while (lo < hi) {
    int32 mid = lo + (hi - lo) / 2;
    if (load(arr, mid) < v) lo = mid + 1;
    else hi = mid;
  }
  return lo;
}
template <typename T>
WP_FUNC int32 lower_bound(const array_t<T>& arr, T v) { return lower_bound(arr, 0, (int32)arr.shape[0], v); }
// Index drawn from a cumulative distribution (ascending, last entry 1).
WP_FUNC int32 sample_cdf(uint32& state, const array_t<float32>& cdf) {
  float32 u = randf(state);
  int32 n = cdf.data ? (int32)cdf.shape[0] : 0;
  if (n <= 0) return 0;
  int32 i = lower_bound(cdf, u);
  return i < n ? i : n - 1;
}

// Uniform in the triangle: barycentric (u, v) with u, v >= 0, u + v <= 1.
WP_FUNC vec_t<2, float32> sample_triangle(uint32& state) {
  float32 r = sqrt(randf(state));
  float32 u = 1.0f - r;
  float32 v = randf(state) * r;
  return vec_t<2, float32>(u, v);
}
WP_FUNC vec_t<2, float32> sample_unit_ring(uint32& state) {
  float32 theta = randf(state, 0.0f, 2.0f * kPi);
  return vec_t<2, float32>(cos(theta), sin(theta));
}
WP_FUNC vec_t<2, float32> sample_unit_disk(uint32& state) {
  float32 r = sqrt(randf(state));
  float32 theta = randf(state, 0.0f, 2.0f * kPi);
  return vec_t<2, float32>(r * cos(theta), r * sin(theta));
}
WP_FUNC vec_t<3, float32> sample_unit_sphere_surface(uint32& state) {
  float32 phi = acos(1.0f - 2.0f * randf(state));
  float32 theta = randf(state, 0.0f, 2.0f * kPi);
  return vec_t<3, float32>(cos(theta) * sin(phi), sin(theta) * sin(phi), cos(phi));
}
WP_FUNC vec_t<3, float32> sample_unit_sphere(uint32& state) {
  float32 phi = acos(1.0f - 2.0f * randf(state));
  float32 theta = randf(state, 0.0f, 2.0f * kPi);
  float32 r = pow(randf(state), 1.0f / 3.0f);
  return vec_t<3, float32>(r * cos(theta) * sin(phi), r * sin(theta) * sin(phi), r * cos(phi));
}
// Hemispheres are the z >= 0 half.
WP_FUNC vec_t<3, float32> sample_unit_hemisphere_surface(uint32& state) {
  float32 phi = acos(1.0f - randf(state));
  float32 theta = randf(state, 0.0f, 2.0f * kPi);
  return vec_t<3, float32>(cos(theta) * sin(phi), sin(theta) * sin(phi), cos(phi));
}
WP_FUNC vec_t<3, float32> sample_unit_hemisphere(uint32& state) {
  float32 phi = acos(1.0f - randf(state));
  float32 theta = randf(state, 0.0f, 2.0f * kPi);
  float32 r = pow(randf(state), 1.0f / 3.0f);
  return vec_t<3, float32>(r * cos(theta) * sin(phi), r * sin(theta) * sin(phi), r * cos(phi));
}
// Centered at the origin: [-0.5, 0.5)^n.
WP_FUNC vec_t<2, float32> sample_unit_square(uint32& state) {
  float32 x = randf(state) - 0.5f;
  float32 y = randf(state) - 0.5f;
  return vec_t<2, float32>(x, y);
}
WP_FUNC vec_t<3, float32> sample_unit_cube(uint32& state) {
  float32 x = randf(state) - 0.5f;
  float32 y = randf(state) - 0.5f;
  float32 z = randf(state) - 0.5f;
  return vec_t<3, float32>(x, y, z);
}

// log Gamma for x > 0 (Stirling series after shifting x >= 8); used by poisson.
WP_FUNC float64 lgamma_pos(float64 x) {
  float64 shift = 0.0;
  while (x < 8.0) {
    shift -= log(x);
    x += 1.0;
  }
  float64 ix = 1.0 / x, ix2 = ix * ix;
  float64 series = ix * (1.0 / 12.0 - ix2 * (1.0 / 360.0 - ix2 * (1.0 / 1260.0 - ix2 / 1680.0)));
  return shift + (x - 0.5) * log(x) - x + 0.91893853320467274178 + series;
}
// Poisson(lam): multiplication method for lam < 10, Hormann's PTRS rejection up to 1e9, the
// normal approximation above (saturating at 2^32 - 1; inf gives 2^32 - 1, NaN or lam <= 0 give 0).
WP_FUNC uint32 poisson(uint32& state, float32 lam) {
  if (!(lam > 0.0f)) return 0;
  if (lam < 10.0f) {
    float64 limit = exp((float64)-lam), p = 1.0;
    uint32 k = 0;
    for (;;) {
      p *= (float64)randf(state);
      if (p <= limit) return k;
      ++k;
    }
  }
  if (!(lam < 1.0e9f)) {  // huge (or inf): the normal approximation, saturated to uint32
    float64 k = floor((float64)lam + sqrt((float64)lam) * (float64)randn(state) + 0.5);
    return k >= 4294967295.0 || !(k == k) ? 4294967295u : (k <= 0.0 ? 0u : (uint32)k);
  }
  float64 l = lam, slam = sqrt(l), loglam = log(l);
  float64 b = 0.931 + 2.53 * slam;
  float64 a = -0.059 + 0.02483 * b;
  float64 inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
  float64 vr = 0.9277 - 3.6224 / (b - 2.0);
  for (;;) {
    float64 u = (float64)randf(state) - 0.5;
    float64 v = (float64)randf(state);
    float64 us = 0.5 - abs(u);
    float64 k = floor((2.0 * a / us + b) * u + l + 0.43);
    if (us >= 0.07 && v <= vr) return (uint32)k;
    if (k < 0.0 || (us < 0.013 && v > us)) continue;
    if (log(v) + log(inv_alpha) - log(a / (us * us) + b) <= -l + k * loglam - lgamma_pos(k + 1.0)) return (uint32)k;
  }
}

}  // namespace wp
