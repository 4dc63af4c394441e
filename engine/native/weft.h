// Native library umbrella: the only header generated modules include. Everything lives in
// namespace wp; the same text compiles under clang (CPU JIT, -std=c++17), g++ and NVRTC, with no
// standard library headers. docs/native.md describes the contract with the code generator.
#pragma once

#define WEFT_NATIVE_VERSION 3

#include "launch_abi.h"
#include "scalar.h"
#include "vec.h"
#include "mat.h"
#include "linalg.h"
#include "quat.h"
#include "transform.h"
#include "spatial.h"
#include "intersect.h"
#include "array.h"
#include "atomic.h"
#include "random.h"
#include "noise.h"
#include "print.h"
#include "expect.h"
#include "hash_grid.h"
#include "bvh.h"
#include "mesh.h"
#include "volume.h"
