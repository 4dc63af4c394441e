// What the kernel-variant benchmarks share: CHECK (a CUDA runtime call that must succeed, else
// the file, line and error, and exit), time_us (the median time per launch over 7 rounds of
// `reps` launches, timed with CUDA events on the default stream) and warp_array_t (Warp 1.19's
// array layout: int32 shape and strides, for the kernels written in Warp's form).
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

#define CHECK(call)                                                                    \
  do {                                                                                 \
    cudaError_t e_ = (call);                                                           \
    if (e_ != cudaSuccess) {                                                           \
      std::fprintf(stderr, "%s:%d: %s\n", __FILE__, __LINE__, cudaGetErrorString(e_)); \
      std::exit(1);                                                                    \
    }                                                                                  \
  } while (0)

struct warp_array_t {
  float* data;
  float* grad;
  int shape[4];
  int strides[4];
  int ndim;
};

template <typename Launch>
static double time_us(Launch launch, int reps) {
  cudaEvent_t start, stop;
  CHECK(cudaEventCreate(&start));
  CHECK(cudaEventCreate(&stop));
  std::vector<double> rounds;
  for (int r = 0; r < 7; ++r) {
    CHECK(cudaEventRecord(start));
    for (int k = 0; k < reps; ++k) launch();
    CHECK(cudaEventRecord(stop));
    CHECK(cudaEventSynchronize(stop));
    float ms = 0;
    CHECK(cudaEventElapsedTime(&ms, start, stop));
    rounds.push_back(ms * 1000.0 / reps);
  }
  std::sort(rounds.begin(), rounds.end());
  CHECK(cudaEventDestroy(start));
  CHECK(cudaEventDestroy(stop));
  return rounds[rounds.size() / 2];
}
