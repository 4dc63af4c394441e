#!/usr/bin/env bash
# Builds bench/fault_probe/fault_probe.c against the CUDA driver API (the stub libcuda links
# here, the GPU machine's driver runs it) into build/fault_probe/fault_probe.
set -euo pipefail
cd "$(dirname "$0")/../.."
mkdir -p build/fault_probe
/usr/local/cuda/bin/nvcc -O2 -o build/fault_probe/fault_probe bench/fault_probe/fault_probe.c \
  -lcuda -L/usr/local/cuda/lib64/stubs
echo "built build/fault_probe/fault_probe"
