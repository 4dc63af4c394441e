#!/usr/bin/env bash
# Builds bench/kernel_variants/{saxpy,integrate}_variants and launch_latency (host + sm_90 device code, CUDA runtime
# linked statically so the GPU machine needs only its driver) into build/kernel_variants/.
set -euo pipefail
cd "$(dirname "$0")/../.."
NVCC=${NVCC:-/usr/local/cuda/bin/nvcc}
mkdir -p build/kernel_variants
for name in saxpy_variants integrate_variants; do
  "$NVCC" -std=c++17 --fmad=false -O3 -arch=sm_90 -cudart static -I engine/native \
    --resource-usage -o "build/kernel_variants/$name" "bench/kernel_variants/$name.cu" 2>&1 |
    grep -E "Compiling entry|Used [0-9]+ registers" | paste - - |
    sed -E "s/.*function '([^']+)'.*Used ([0-9]+) registers.*/\1: \2 registers/"
  echo "built build/kernel_variants/$name"
done
# The driver-level launch probe calls libcuda directly (the stub links; the machine's driver runs).
"$NVCC" -std=c++17 -O2 -arch=sm_90 -cudart static -o build/kernel_variants/launch_latency \
  bench/kernel_variants/launch_latency.cu -L/usr/local/cuda/lib64/stubs -lcuda -lpthread
echo "built build/kernel_variants/launch_latency"
