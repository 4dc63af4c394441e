// Codegen end-to-end to C++ source: representative kernels (Warp docs, every language
// construct, funcs, structs, generics, loops, autodiff) are generated for the CPU and CUDA
// targets, forward and backward, and must compile with clang (syntax only) against
// engine/native; the CUDA target is compiled by NVRTC for sm_75 and sm_90 (CI's check that
// every test kernel compiles for the GPU, on a machine without one).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>

#include "engine/codegen/generate_module.h"
#include "engine/native/launch_abi.h"

#if WEFT_WITH_CUDA
#include "engine/jit/cuda/nvrtc_compiler.h"
#endif

namespace weft {
namespace {

FunctionSource Fn(const std::string& name, const std::string& src, std::vector<std::string> types,
                  std::vector<std::string> names, bool kernel = true, const std::string& key = "") {
  FunctionSource f;
  f.name = name;
  f.source = src;
  f.file = "test_kernels.py";
  f.first_line = 10;
  f.is_kernel = kernel;
  f.param_types = std::move(types);
  f.param_names = std::move(names);
  f.key = key.empty() ? name : key;
  return f;
}

Symbol Wp() {
  Symbol s;
  s.name = "wp";
  s.kind = Symbol::Kind::kBuiltinModule;
  s.target = "warp";
  return s;
}
Symbol FuncSym(const std::string& name, const std::string& key) {
  Symbol s;
  s.name = name;
  s.kind = Symbol::Kind::kFunction;
  s.target = key;
  return s;
}

// The CUDA flavour compiled by NVRTC (as weftd compiles it) to CUBINs for the architectures CI
// checks, sm_75 and sm_90, in parallel; "" when every one compiles (or NVRTC is absent).
std::string CompileCudaForEveryArch(const std::string& source, const std::string& file) {
#if WEFT_WITH_CUDA
  if (!jit::NvrtcVersion().ok()) return "";
  const int archs[] = {75, 90};
  std::string errors[2];
  auto compile = [&](int i) {
    jit::NvrtcOptions options;
    options.sm = archs[i];
    options.include_dirs = {WEFT_NATIVE_DIR};
    options.extra_flags = {"--fmad=false"};
    auto out = jit::NvrtcCompile(source, file, options);
    if (!out.ok()) errors[i] = "NVRTC sm_" + std::to_string(archs[i]) + " FAILED (" + file + "):\n" +
                               out.status().message().substr(0, 6000);
  };
  std::thread other(compile, 1);
  compile(0);
  other.join();
  return errors[0] + errors[1];
#else
  (void)source, (void)file;
  return "";
#endif
}

// Generates, writes and compiles; returns "" on success or the compiler output.
std::string CompileWith(const ModuleSource& m, const CodegenOptions& o, std::string* source = nullptr) {
  std::vector<Diagnostic> diags;
  auto gm = GenerateModule(m, o, &diags);
  if (!gm.ok()) {
    std::string s = gm.status().message();
    for (const auto& d : diags) s += "\n" + d.ToString();
    return "GENERATE FAILED: " + s;
  }
  if (source) *source = gm->source;
  static int counter = 0;
  std::string base = ::testing::TempDir() + "/weft_codegen_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
  std::string file = base + (o.target == Target::kCpu ? ".cpp" : ".cu");
  std::ofstream(file) << gm->source;
  std::string cmd;
  if (o.target == Target::kCpu) {
    cmd = "clang++-19 -std=c++17 -fsyntax-only -Wno-unused-variable -I" WEFT_NATIVE_DIR " " + file + " > " + base + ".log 2>&1";
  } else {
    return CompileCudaForEveryArch(gm->source, file);
  }
  if (std::system(cmd.c_str()) != 0) {
    std::ifstream in(base + ".log");
    std::string log((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return "COMPILE FAILED (" + file + "):\n" + log.substr(0, 6000);
  }
  return "";
}

void ExpectCompiles(const ModuleSource& m, bool cuda = false) {
  for (bool backward : {false, true}) {
    CodegenOptions o;
    o.enable_backward = backward;
    EXPECT_EQ(CompileWith(m, o), "") << "backward=" << backward;
    if (cuda) {
      o.target = Target::kCuda;
      EXPECT_EQ(CompileWith(m, o), "") << "cuda backward=" << backward;
    }
  }
}

// CUDA entries take the launch context and the argument block as __grid_constant__ parameters:
// a kernel whose body hands their address to an out-of-line path (here the geometry error
// report of wp.mesh_get_point) addresses them in the parameter space instead of making every
// thread copy them to local memory first (the entry's PTX local memory, with and without). The entries stride over the grid by
// default; grid_stride=false gives one index per thread (no loop) and says so in the layout.
TEST(CodegenKernels, CudaEntriesUseGridConstantParametersAndOptionalGridStride) {
  ModuleSource m;
  m.name = "entry_mod";
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn("points",
                           "def points(mesh: wp.uint64, out: wp.array(dtype=wp.vec3)):\n"
                           "    i = wp.tid()\n"
                           "    out[i] = wp.mesh_get_point(mesh, i)\n",
                           {"uint64", "array(vec(3,float32),1)"}, {"mesh", "out"}));
  for (bool stride : {true, false}) {
    CodegenOptions o;
    o.target = Target::kCuda;
    o.enable_backward = true;
    o.grid_stride = stride;
    std::vector<Diagnostic> diags;
    auto gm = GenerateModule(m, o, &diags);
    ASSERT_TRUE(gm.ok()) << gm.status().message();
    const std::string& src = gm->source;
    const size_t entry = src.find("void weft_points_cuda_forward(");
    ASSERT_NE(entry, std::string::npos) << src;
    const std::string fwd = src.substr(entry, src.find("\n}\n", entry) - entry);
    EXPECT_NE(fwd.find("const WP_GRID_CONSTANT wp::launch_context_t __ctx, const WP_GRID_CONSTANT"), std::string::npos) << fwd;
    EXPECT_EQ(fwd.find("for (") != std::string::npos, stride) << fwd;
    ASSERT_EQ(gm->kernels.size(), 1u);
    EXPECT_EQ(gm->kernels[0].grid_stride, stride);
    EXPECT_EQ(CompileWith(m, o), "") << "grid_stride=" << stride;
#if WEFT_WITH_CUDA
    if (!jit::NvrtcVersion().ok()) continue;
    // The entry's own local memory (PTX), with the parameters as generated and with
    // __grid_constant__ turned off.
    auto entry_local_bytes = [&](bool grid_constant) -> long {
      jit::NvrtcOptions n;
      n.sm = 90;
      n.cubin = false;   // PTX, to read the entry
      n.include_dirs = {WEFT_NATIVE_DIR};
      n.extra_flags = {"--fmad=false"};
      if (!grid_constant) n.extra_flags.push_back("-DWP_GRID_CONSTANT=");
      auto ptx = jit::NvrtcCompile(src, "entry_mod.cu", n);
      EXPECT_TRUE(ptx.ok()) << ptx.status().message();
      if (!ptx.ok()) return -1;
      const std::string text(ptx->image.begin(), ptx->image.end());
      const size_t at = text.find(".entry weft_points_cuda_forward(");
      EXPECT_NE(at, std::string::npos);
      const std::string body = text.substr(at, text.find("\n}\n", at) - at);
      const size_t depot = body.find("__local_depot0[");
      return depot == std::string::npos ? 0 : std::stol(body.substr(depot + 15));
    };
    const long with = entry_local_bytes(true), without = entry_local_bytes(false);
    EXPECT_GE(without - with, static_cast<long>(sizeof(wp::launch_context_t)))
        << "per-thread local memory of the entry: " << with << " bytes with __grid_constant__, " << without << " without";
#endif
  }
}

TEST(CodegenKernels, SaxpyCompilesAndReportsLayout) {
  ModuleSource m;
  m.name = "saxpy_mod";
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn("saxpy",
                           "def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):\n"
                           "    i = wp.tid()\n"
                           "    y[i] = a * x[i] + y[i]\n",
                           {"array(float32,1)", "array(float32,1)", "float32"}, {"x", "y", "a"}));
  ExpectCompiles(m, true);
  std::vector<Diagnostic> diags;
  auto gm = GenerateModule(m, {}, &diags);
  ASSERT_TRUE(gm.ok()) << gm.status().message();
  ASSERT_EQ(gm->kernels.size(), 1u);
  const auto& k = gm->kernels[0];
  EXPECT_EQ(k.forward_symbol, "weft_saxpy_cpu_forward");
  EXPECT_EQ(k.backward_symbol, "");
  ASSERT_EQ(k.params.size(), 3u);
  EXPECT_EQ(k.params[0].offset, 0u);
  EXPECT_EQ(k.params[0].size, 88u);
  EXPECT_TRUE(k.params[0].is_array);
  EXPECT_EQ(k.params[0].array_dtype, "float32");
  EXPECT_EQ(k.params[1].offset, 88u);
  EXPECT_EQ(k.params[2].offset, 176u);
  EXPECT_EQ(k.params[2].size, 4u);
  EXPECT_EQ(k.args_size, 184u);
  EXPECT_EQ(gm->source.find("adj_"), std::string::npos) << "forward-only modules carry no adjoint code";
}


// The bounds checks of a statement's loads come before its first load (they move up past pure
// code), so the loads follow each other with no branch between them and the GPU has them in
// flight together; a check never moves above a store (a thread whose access fails still stops
// before any side effect it would not have had).
TEST(CodegenKernels, LoadChecksMoveUpButNotPastStores) {
  ModuleSource m;
  m.name = "hoist_mod";
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn("saxpy",
                           "def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):\n"
                           "    i = wp.tid()\n"
                           "    y[i] = a * x[i] + y[i]\n",
                           {"array(float32,1)", "array(float32,1)", "float32"}, {"x", "y", "a"}));
  m.functions.push_back(Fn("after_store",
                           "def after_store(x: wp.array(dtype=float), y: wp.array(dtype=float), j: int):\n"
                           "    i = wp.tid()\n"
                           "    y[i] = 1.0\n"
                           "    y[i] = x[j] * 2.0\n",
                           {"array(float32,1)", "array(float32,1)", "int32"}, {"x", "y", "j"}));
  for (Target t : {Target::kCpu, Target::kCuda}) {
    CodegenOptions o;
    o.target = t;
    std::vector<Diagnostic> diags;
    auto gm = GenerateModule(m, o, &diags);
    ASSERT_TRUE(gm.ok()) << gm.status().message();
    const std::string& src = gm->source;
    auto body = [&](const std::string& kernel) {
      size_t b = src.find("weft_kernel_" + kernel);
      b = src.find("_forward_body(", b);
      return src.substr(b, src.find("\n}\n", b) - b);
    };
    const std::string saxpy = body("saxpy");
    const size_t first_load = saxpy.find("wp::load(");
    ASSERT_NE(first_load, std::string::npos) << saxpy;
    EXPECT_LT(saxpy.find("\"x\", var_"), first_load) << saxpy;
    EXPECT_LT(saxpy.find("\"y\", var_"), first_load) << saxpy;
    const size_t second_load = saxpy.find("wp::load(", first_load + 1);
    ASSERT_NE(second_load, std::string::npos) << saxpy;
    EXPECT_EQ(saxpy.substr(first_load, second_load - first_load).find("cg_check"), std::string::npos)
        << "no check between the two loads:\n" << saxpy;
    EXPECT_EQ(saxpy.find("\"y\", var_", saxpy.find("\"y\", var_") + 1), std::string::npos)
        << "y[i] is checked once (the store's check repeats the load's):\n" << saxpy;
    const std::string after = body("after_store");
    const size_t store = after.find("wp::store(");
    ASSERT_NE(store, std::string::npos) << after;
    EXPECT_GT(after.find("\"x\", var_"), store) << "the check of x[j] stays after the store:\n" << after;
  }
  ExpectCompiles(m, true);
}

ModuleSource OneKernel(const std::string& name, const std::string& src, std::vector<std::string> types,
                       std::vector<std::string> names) {
  ModuleSource m;
  m.name = "mod";
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn(name, src, std::move(types), std::move(names)));
  return m;
}

TEST(CodegenKernels, WarpParticleIntegrate) {
  ModuleSource m = OneKernel("integrate",
                             "def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), f: wp.array(dtype=wp.vec3),\n"
                             "              w: wp.array(dtype=float), gravity: wp.vec3, dt: float):\n"
                             "    tid = wp.tid()\n"
                             "    x0 = x[tid]\n"
                             "    v0 = v[tid]\n"
                             "    f0 = f[tid]\n"
                             "    inv_mass = w[tid]\n"
                             "    v1 = v0 + (f0 * inv_mass + gravity * wp.step(0.0 - inv_mass)) * dt\n"
                             "    x1 = x0 + v1 * dt\n"
                             "    x[tid] = x1\n"
                             "    v[tid] = v1\n",
                             {"array(vec(3,float32),1)", "array(vec(3,float32),1)", "array(vec(3,float32),1)",
                              "array(float32,1)", "vec(3,float32)", "float32"},
                             {"x", "v", "f", "w", "gravity", "dt"});
  ExpectCompiles(m, true);
}

TEST(CodegenKernels, ControlFlowLoopsAndFlags) {
  ModuleSource m = OneKernel("flow",
                             "def flow(a: wp.array(dtype=float), out: wp.array2d(dtype=float), n: int):\n"
                             "    i, j = wp.tid()\n"
                             "    s = float(0.0)\n"
                             "    p = 1.0\n"
                             "    for k in range(n):\n"
                             "        if k == 3:\n"
                             "            continue\n"
                             "        p = p * a[k]\n"
                             "        if p > 100.0:\n"
                             "            break\n"
                             "        s += p\n"
                             "    for k in range(n - 1, -1, -2):\n"
                             "        s = s - a[k] * 0.5\n"
                             "    c = int(0)\n"
                             "    while c < 10:\n"
                             "        c += 1\n"
                             "        s = s * 0.9\n"
                             "    if s > 1.0:\n"
                             "        s = 1.0\n"
                             "    elif s < -1.0:\n"
                             "        s = -1.0\n"
                             "    else:\n"
                             "        s = s * 2.0\n"
                             "    t = s if i > j else -s\n"
                             "    if not (i < 0 or j < 0) and a[0] >= 0.0:\n"
                             "        out[i, j] = t + float(c)\n",
                             {"array(float32,1)", "array(float32,2)", "int32"}, {"a", "out", "n"});
  ExpectCompiles(m, true);
}

TEST(CodegenKernels, FuncsMultipleReturnsGenericsAndEarlyReturn) {
  ModuleSource m;
  m.symbols.push_back(Wp());
  m.symbols.push_back(FuncSym("split", "m.split"));
  m.symbols.push_back(FuncSym("clamp01", "m.clamp01"));
  m.symbols.push_back(FuncSym("twice", "m.twice"));
  m.symbols.push_back(FuncSym("first", "m.first"));
  m.functions.push_back(Fn("split", "def split(v: wp.vec3):\n    return v[0], v[1] + v[2]\n", {"vec(3,float32)"},
                           {"v"}, false, "m.split"));
  m.functions.push_back(Fn("clamp01",
                           "def clamp01(x: float) -> float:\n"
                           "    if x < 0.0:\n"
                           "        return 0.0\n"
                           "    if x > 1.0:\n"
                           "        return 1.0\n"
                           "    return x\n",
                           {"float32"}, {"x"}, false, "m.clamp01"));
  m.functions.push_back(Fn("twice", "def twice(x: Any):\n    return x + x\n", {"any"}, {"x"}, false, "m.twice"));
  m.functions.push_back(Fn("first",
                           "def first(a: wp.array(dtype=float), n: int):\n"
                           "    for i in range(n):\n"
                           "        if a[i] > 0.0:\n"
                           "            return i\n"
                           "    return -1\n",
                           {"array(float32,1)", "int32"}, {"a", "n"}, false, "m.first"));
  m.functions.push_back(Fn("k",
                           "def k(pts: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):\n"
                           "    i = wp.tid()\n"
                           "    a, b = split(pts[i])\n"
                           "    v = twice(pts[i])\n"
                           "    n = twice(3)\n"
                           "    f = first(out, 4)\n"
                           "    out[i] = clamp01(a * b) + v.x + float(n + f)\n",
                           {"array(vec(3,float32),1)", "array(float32,1)"}, {"pts", "out"}));
  ExpectCompiles(m, true);
}

TEST(CodegenKernels, StructsVectorsMatricesQuatsTransforms) {
  ModuleSource m;
  m.symbols.push_back(Wp());
  Symbol st;
  st.name = "Particle";
  st.kind = Symbol::Kind::kType;
  st.target = "struct(m.Particle)";
  m.symbols.push_back(st);
  // Arrays of structs hold no arrays (an array member inside array memory is refused): the
  // array parameter's elements are Bodies, the struct parameter holds the array.
  Symbol body = st;
  body.name = "Body";
  body.target = "struct(m.Body)";
  m.symbols.push_back(body);
  StructDef inner{"m.Inner", {{"k", "float32"}, {"q", "quat(float32)"}}};
  StructDef p{"m.Particle", {{"pos", "vec(3,float32)"}, {"mass", "float32"}, {"inner", "struct(m.Inner)"},
                             {"forces", "array(vec(3,float32),1)"}}};
  StructDef b{"m.Body", {{"pos", "vec(3,float32)"}, {"inner", "struct(m.Inner)"}}};
  m.structs = {p, inner, b};
  m.functions.push_back(Fn("k",
                           "def k(ps: wp.array(dtype=Body), s: Particle, out: wp.array(dtype=wp.mat33)):\n"
                           "    i = wp.tid()\n"
                           "    q = Particle()\n"
                           "    q.pos = s.pos * 2.0\n"
                           "    q.pos[1] = 3.0\n"
                           "    q.inner.k = s.mass\n"
                           "    e = ps[i]\n"
                           "    f = s.forces[i] + e.pos\n"
                           "    s.forces[i] = f\n"
                           "    m = wp.mat33(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)\n"
                           "    m2 = wp.outer(f, q.pos) + wp.transpose(m) @ m\n"
                           "    m2[0, 1] = wp.dot(f, f)\n"
                           "    m2[2] = wp.cross(f, wp.vec3(0.0, 1.0, 0.0))\n"
                           "    r = wp.quat_from_axis_angle(wp.normalize(f), 0.5)\n"
                           "    t = wp.transform(q.pos, r)\n"
                           "    p2 = wp.transform_point(t, f)\n"
                           "    rv = wp.quat_rotate(r, p2)\n"
                           "    d = wp.determinant(m2) + wp.length(rv) + m2[1, 1] + rv.z + t.p[0]\n"
                           "    iv = wp.inverse(m2) * d\n"
                           "    col = wp.mat33(f, rv, p2)\n"
                           "    iv = iv + col\n"
                           "    vd = wp.vec3d(f)\n"
                           "    h = wp.vec2h(wp.float16(1.0), wp.float16(2.0))\n"
                           "    iv[0, 0] = iv[0, 0] + float(vd[0]) + float(h[1])\n"
                           "    sv = wp.spatial_vector(f, rv)\n"
                           "    iv[1, 1] += wp.spatial_dot(sv, sv)\n"
                           "    out[i] = iv\n",
                           {"array(struct(m.Body),1)", "struct(m.Particle)", "array(mat(3,3,float32),1)"},
                           {"ps", "s", "out"}));
  ExpectCompiles(m, true);
  std::vector<Diagnostic> diags;
  auto gm = GenerateModule(m, {}, &diags);
  ASSERT_TRUE(gm.ok());
  const auto& sp = gm->kernels[0].params[1];
  // Particle: pos @0 (12), mass @12, inner {k @0, q @4 (16)} @16 size 20, forces @40 (88, align 8) -> 128
  ASSERT_EQ(sp.fields.size(), 4u);
  EXPECT_EQ(sp.fields[1].offset, 12u);
  EXPECT_EQ(sp.fields[2].offset, 16u);
  EXPECT_EQ(sp.fields[2].size, 20u);
  EXPECT_EQ(sp.fields[3].offset, 40u);
  EXPECT_EQ(sp.size, 128u);
  EXPECT_EQ(sp.align, 8u);
  EXPECT_EQ(gm->kernels[0].params[2].offset, 88u + 128u);
}

TEST(CodegenKernels, AtomicsRandomPrintAndBuiltinsByKeyword) {
  ModuleSource m = OneKernel("k",
                             "def k(a: wp.array(dtype=float), c: wp.array(dtype=wp.int32), g: wp.array3d(dtype=float), seed: int):\n"
                             "    i = wp.tid()\n"
                             "    rng = wp.rand_init(seed, i)\n"
                             "    x = wp.randf(rng)\n"
                             "    y = wp.randf(rng, -1.0, 1.0)\n"
                             "    z = wp.randn(rng)\n"
                             "    d = wp.sample_unit_sphere(rng)\n"
                             "    n = wp.randi(rng, 0, 10)\n"
                             "    wp.atomic_add(a, 0, x + y + z + d[0])\n"
                             "    old = wp.atomic_max(c, 1, n)\n"
                             "    wp.atomic_min(g, 0, 1, 2, x)\n"
                             "    a[1] += 2.0\n"
                             "    a[2] -= y\n"
                             "    c[0] += 1\n"
                             "    wp.printf(\"%d %f\\n\", i, x)\n"
                             "    print(x)\n"
                             "    wp.expect_eq(old, old)\n"
                             "    w = wp.where(x > 0.5, x, y)\n"
                             "    e = wp.clamp(w, low=0.0, high=1.0)\n"
                             "    m = max(abs(e), min(x, 0.5)) + wp.sqrt(2.0) + wp.pi\n"
                             "    g[0, 0, 0] = m + float(len(a)) + float(a.shape[0]) + float(g.shape[2])\n",
                             {"array(float32,1)", "array(int32,1)", "array(float32,3)", "int32"},
                             {"a", "c", "g", "seed"});
  ExpectCompiles(m, true);
}

// `y[i] += x[i]`: evaluating the indices and the value emits new variables; the array's type
// must not be read through a reference into the (reallocated) variable table.
TEST(CodegenKernels, AugmentedAssignToArrayElements) {
  ModuleSource m = OneKernel("aug",
                             "def aug(x: wp.array(dtype=float), y: wp.array(dtype=float), a: wp.array2d(dtype=wp.vec3),\n"
                             "        b: wp.array4d(dtype=wp.float64)):\n"
                             "    i = wp.tid()\n"
                             "    y[i] += x[i]\n"
                             "    y[i + 1] -= x[i] * x[i + 2] + wp.sin(x[i])\n"
                             "    a[i, i + 1] += wp.vec3(x[i], x[i + 1], 1.0)\n"
                             "    b[i, 0, i + 1, 2] += wp.float64(x[i])\n"
                             "    y[i] *= 2.0\n",
                             {"array(float32,1)", "array(float32,1)", "array(vec(3,float32),2)", "array(float64,4)"},
                             {"x", "y", "a", "b"});
  ExpectCompiles(m, true);
}

// Warp-compatibility forms: keyword arguments and int-first overloads of @wp.func, the
// out-parameter form of multi-result builtins, positional struct constructors,
// wp.types.vector / wp.types.matrix, negative component indices, bool vectors and transform
// atomics; forward and backward, CPU and CUDA.
TEST(CodegenKernels, WarpCompatibilityForms) {
  ModuleSource m;
  m.name = "compat";
  m.symbols.push_back(Wp());
  m.symbols.push_back(FuncSym("scale", "compat.scale"));
  Symbol st;
  st.name = "Body";
  st.kind = Symbol::Kind::kType;
  st.target = "struct(compat.Body)";
  m.symbols.push_back(st);
  m.structs.push_back({"compat.Body", {{"x", "vec(3,float32)"}, {"m", "float32"}}});
  FunctionSource scale = Fn("scale", "def scale(a: float, b: float = 2.0, n: int = 1):\n    return a * b * float(n)\n",
                            {"float32", "float32", "int32"}, {"a", "b", "n"}, false, "compat.scale");
  m.functions.push_back(scale);
  m.functions.push_back(Fn("k",
                           "def k(A: wp.array(dtype=wp.mat33), t: wp.array(dtype=wp.transform), out: wp.array(dtype=float)):\n"
                           "    i = wp.tid()\n"
                           "    U = wp.mat33()\n"
                           "    s = wp.vec3()\n"
                           "    V = wp.mat33()\n"
                           "    wp.svd3(A[i], U, s, V)\n"
                           "    axis = wp.vec3()\n"
                           "    angle = float(0.0)\n"
                           "    wp.quat_to_axis_angle(wp.quat_identity(), axis, angle)\n"
                           "    b = Body(s, 2.0)\n"
                           "    v = wp.types.vector(s, dtype=wp.float64)\n"
                           "    w = wp.types.matrix(1.0, shape=(3, 2))\n"
                           "    flags = wp.types.vector(True, False, length=2)\n"
                           "    if v[-2] > wp.float64(0.0) and flags[-1]:\n"
                           "        s[-1] = 1.0\n"
                           "    out[i] = scale(b.m, n=3) + scale(a=s[0]) + U[-1, -1] + w[-1][0] + angle\n"
                           "    t[i] += wp.transform_identity()\n",
                           {"array(mat(3,3,float32),1)", "array(transform(float32),1)", "array(float32,1)"},
                           {"A", "t", "out"}));
  ExpectCompiles(m, true);
  std::vector<Diagnostic> diags;
  auto gm = GenerateModule(m, {}, &diags);
  ASSERT_TRUE(gm.ok()) << gm.status().message();
  // Generated lines name the user's file and line (a C++ error there points at the user).
  EXPECT_NE(gm->source.find("#line 15 \"test_kernels.py\""), std::string::npos);
}

// Sub-array views (fewer indices than ndim) and constant vector slices, read and written.
TEST(CodegenKernels, ArrayViewsAndVectorSlices) {
  ModuleSource m = OneKernel("views",
                             "def views(a: wp.array2d(dtype=float), b: wp.array3d(dtype=wp.vec4), out: wp.array2d(dtype=wp.vec2)):\n"
                             "    i = wp.tid()\n"
                             "    row = a[i]\n"
                             "    plane = b[i]\n"
                             "    v = plane[0, 1]\n"
                             "    w = v[1:3] * row[0]\n"
                             "    v[::-2] += w\n"
                             "    out[i][0] = v[-2:]\n"
                             "    b[i][1][0] = v\n",
                             {"array(float32,2)", "array(vec(4,float32),3)", "array(vec(2,float32),2)"},
                             {"a", "b", "out"});
  ExpectCompiles(m, true);
}

// The trusted-index variant (CodegenOptions::trust_tid_indices) drops exactly the forward checks
// of p[i] with p a 1-D array parameter and i = wp.tid(): x[i], y[i] (loads, the store, the
// atomic) and w[i] through an alias, never x[j] with j = i + 1, a 2-D parameter's m[i, 0], an
// array that is one parameter or another depending on the thread, or a gradient access. The layout lists the parameters whose extents a launch must prove
// (whatever the option), and both variants compile (clang; NVRTC for sm_75 and sm_90).
TEST(CodegenKernels, TrustedTidIndicesSkipOnlyProvenChecks) {
  ModuleSource m;
  m.name = "trusted_mod";
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn("k",
                           "def k(x: wp.array(dtype=float), y: wp.array(dtype=float), m: wp.array2d(dtype=float),\n"
                           "      z: wp.array(dtype=float), w: wp.array(dtype=float)):\n"
                           "    i = wp.tid()\n"
                           "    j = i + 1\n"
                           "    y[i] = x[i] * x[j] + m[i, 0]\n"
                           "    wp.atomic_add(y, i, 1.0)\n"
                           "    z = w\n"
                           "    z[i] = 2.0\n"
                           "    v = x\n"
                           "    if i > 4:\n"
                           "        v = y\n"
                           "    v[i] = 3.0\n",
                           {"array(float32,1)", "array(float32,1)", "array(float32,2)", "array(float32,1)",
                            "array(float32,1)"},
                           {"x", "y", "m", "z", "w"}));
  auto count = [](const std::string& s, const std::string& what) {
    size_t n = 0;
    for (size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
    return n;
  };
  auto body_of = [](const std::string& src, const std::string& name) {
    const size_t at = src.find(name + "(const wp::launch_context_t");
    return at == std::string::npos ? std::string() : src.substr(at, src.find("\n}\n", at) - at);
  };
  size_t checks[2] = {0, 0}, adjoint_checks[2] = {0, 0};
  for (bool trust : {false, true}) {
    CodegenOptions o;
    o.target = Target::kCuda;
    o.enable_backward = true;
    o.grid_stride = false;
    o.trust_tid_indices = trust;
    std::vector<Diagnostic> diags;
    auto gm = GenerateModule(m, o, &diags);
    ASSERT_TRUE(gm.ok()) << gm.status().message();
    ASSERT_EQ(gm->kernels.size(), 1u);
    EXPECT_EQ(gm->kernels[0].tid_indexed_params, (std::vector<uint32_t>{0, 1, 4})) << "trust=" << trust;
    const std::string fwd = body_of(gm->source, "_forward_body");
    const std::string bwd = body_of(gm->source, "_backward_body");
    ASSERT_FALSE(fwd.empty() || bwd.empty()) << gm->source;
    checks[trust] = count(fwd, "wp::cg_check(");
    adjoint_checks[trust] = count(bwd, "wp::cg_check_adj(");
    EXPECT_EQ(CompileWith(m, o), "") << "trust=" << trust;
    EXPECT_EQ(CompileCudaForEveryArch(gm->source, "trusted_mod"), "") << "trust=" << trust;
  }
  // z = w makes z the parameter w itself (w is listed); v is x or y depending on the thread (a
  // phi, not a parameter): v[i] keeps its check. Trusted: x[j], m[i, 0] and v[i] are left.
  EXPECT_EQ(checks[1], 3u) << checks[0];
  EXPECT_GE(checks[0], checks[1] + 2);
  EXPECT_EQ(adjoint_checks[0], adjoint_checks[1]);
  EXPECT_GT(adjoint_checks[1], 0u);
  // A CPU module, and a module without bounds checks, list nothing.
  CodegenOptions cpu;
  std::vector<Diagnostic> diags;
  auto gm = GenerateModule(m, cpu, &diags);
  ASSERT_TRUE(gm.ok());
  EXPECT_TRUE(gm->kernels[0].tid_indexed_params.empty());
  CodegenOptions unchecked;
  unchecked.target = Target::kCuda;
  unchecked.bounds_checks = false;
  gm = GenerateModule(m, unchecked, &diags);
  ASSERT_TRUE(gm.ok());
  EXPECT_TRUE(gm->kernels[0].tid_indexed_params.empty());
}

// The CUDA module of `m` with adjoint entries, trusted-index or checked, lean or grid-stride.
Expected<GeneratedModule> CudaVariant(const ModuleSource& m, bool trust, bool grid_stride) {
  CodegenOptions o;
  o.target = Target::kCuda;
  o.enable_backward = true;
  o.grid_stride = grid_stride;
  o.trust_tid_indices = trust;
  std::vector<Diagnostic> diags;
  return GenerateModule(m, o, &diags);
}

// The text of entry point `symbol` in `gm`'s source (empty when it has none).
std::string EntryText(const GeneratedModule& gm, const std::string& symbol) {
  const size_t at = gm.source.find("void " + symbol + "(");
  return at == std::string::npos ? std::string() : gm.source.substr(at, gm.source.find("\n}\n", at) - at);
}

// The coarsened entry (KernelLayout::coarse_symbol) exists only in the trusted-index variant of a
// lean (not grid-stride) CUDA module, prefetches exactly the 1-D parameters the body loads at
// wp.tid() (x, y for saxpy; never a parameter only stored to, which a prefetch would read for
// nothing), runs the forward body for kCoarseFactor logical threads, and compiles for every
// architecture CI builds for.
TEST(CodegenKernels, CoarsenedEntryOnlyWhereProvenAndPrefetchesOnlyLoads) {
  ModuleSource m;
  m.name = "coarse_mod";
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn("saxpy",
                           "def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), out: wp.array(dtype=float),\n"
                           "          a: float):\n"
                           "    i = wp.tid()\n"
                           "    out[i] = a * x[i] + y[i]\n",
                           {"array(float32,1)", "array(float32,1)", "array(float32,1)", "float32"},
                           {"x", "y", "out", "a"}));
  m.functions.push_back(Fn("fill",
                           "def fill(out: wp.array(dtype=float)):\n"
                           "    i = wp.tid()\n"
                           "    out[i] = float(i)\n",
                           {"array(float32,1)"}, {"out"}));
  for (bool trust : {false, true}) {
    for (bool grid_stride : {false, true}) {
      auto gm = CudaVariant(m, trust, grid_stride);
      ASSERT_TRUE(gm.ok()) << gm.status().message();
      ASSERT_EQ(gm->kernels.size(), 2u);
      const KernelLayout& saxpy = gm->kernels[0];
      const KernelLayout& fill = gm->kernels[1];
      EXPECT_TRUE(fill.coarse_symbol.empty()) << "nothing loaded at wp.tid(): nothing to prefetch";
      if (!trust || grid_stride) {
        EXPECT_TRUE(saxpy.coarse_symbol.empty()) << "trust=" << trust << " grid_stride=" << grid_stride;
        EXPECT_EQ(gm->source.find("cg_prefetch_l2"), std::string::npos);
        continue;
      }
      EXPECT_EQ(saxpy.coarse_symbol, saxpy.forward_symbol + "_x" + std::to_string(kCoarseFactor));
      EXPECT_EQ(saxpy.coarse_loaded_bytes, 8u);   // x and y, float32
      const std::string entry = EntryText(*gm, saxpy.coarse_symbol);
      ASSERT_FALSE(entry.empty()) << gm->source;
      EXPECT_NE(entry.find("wp::cg_prefetch_l2(__args.p0, __j)"), std::string::npos) << entry;
      EXPECT_NE(entry.find("wp::cg_prefetch_l2(__args.p1, __j)"), std::string::npos) << entry;
      EXPECT_EQ(entry.find("__args.p2, __j"), std::string::npos) << "out is only stored to: " << entry;
      EXPECT_NE(entry.find("_forward_body(&__ctx, __args, __j)"), std::string::npos) << entry;
      EXPECT_EQ(CompileCudaForEveryArch(gm->source, "coarse_mod"), "");
    }
  }
  // The CPU target has no GPU entries at all.
  std::vector<Diagnostic> diags;
  CodegenOptions cpu;
  cpu.trust_tid_indices = true;
  auto gm = GenerateModule(m, cpu, &diags);
  ASSERT_TRUE(gm.ok());
  EXPECT_TRUE(gm->kernels[0].coarse_symbol.empty());
}

// The trusted lean entry prefetches into L2 what the body loads at wp.tid() only after a store
// (the compiler cannot hoist such a load: the arrays may overlap), for 1-D launches only; loads
// under a branch (maybe never executed), loads before any store, the checked and grid-stride
// variants and the adjoint entries prefetch nothing.
TEST(CodegenKernels, TrustedEntryPrefetchesLoadsThatFollowAStore) {
  ModuleSource m;
  m.name = "late_loads";
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn("integrate",
                           "def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), g: wp.vec3, dt: float):\n"
                           "    i = wp.tid()\n"
                           "    vi = v[i] + g * dt\n"
                           "    v[i] = vi\n"
                           "    x[i] = x[i] + vi * dt\n",
                           {"array(vec(3,float32),1)", "array(vec(3,float32),1)", "vec(3,float32)", "float32"},
                           {"x", "v", "g", "dt"}));
  m.functions.push_back(Fn("saxpy",
                           "def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):\n"
                           "    i = wp.tid()\n"
                           "    y[i] = a * x[i] + y[i]\n",
                           {"array(float32,1)", "array(float32,1)", "float32"}, {"x", "y", "a"}));
  m.functions.push_back(Fn("branchy",
                           "def branchy(x: wp.array(dtype=float), y: wp.array(dtype=float), z: wp.array(dtype=float),\n"
                           "            a: float):\n"
                           "    i = wp.tid()\n"
                           "    y[i] = a\n"
                           "    if a > 0.0:\n"
                           "        y[i] = x[i]\n"
                           "    z[i] = z[i] + y[i]\n",
                           {"array(float32,1)", "array(float32,1)", "array(float32,1)", "float32"},
                           {"x", "y", "z", "a"}));
  for (bool trust : {false, true}) {
    for (bool grid_stride : {false, true}) {
      auto gm = CudaVariant(m, trust, grid_stride);
      ASSERT_TRUE(gm.ok()) << gm.status().message();
      ASSERT_EQ(gm->kernels.size(), 3u);
      const std::string integrate = EntryText(*gm, gm->kernels[0].forward_symbol);
      const std::string saxpy = EntryText(*gm, gm->kernels[1].forward_symbol);
      const std::string branchy = EntryText(*gm, gm->kernels[2].forward_symbol);
      ASSERT_FALSE(integrate.empty() || saxpy.empty() || branchy.empty()) << gm->source;
      EXPECT_EQ(saxpy.find("cg_prefetch_l2"), std::string::npos) << "x and y are loaded before the store: " << saxpy;
      const std::string backward = EntryText(*gm, gm->kernels[0].backward_symbol);
      ASSERT_FALSE(backward.empty());
      EXPECT_EQ(backward.find("cg_prefetch_l2"), std::string::npos) << backward;
      if (!trust || grid_stride) {
        EXPECT_EQ(integrate.find("cg_prefetch_l2"), std::string::npos) << integrate;
        EXPECT_EQ(branchy.find("cg_prefetch_l2"), std::string::npos) << branchy;
        continue;
      }
      // x is loaded after v's store; v before any store.
      const size_t guard = integrate.find("if (__ctx.bounds.ndim == 1) {");
      const size_t prefetch = integrate.find("wp::cg_prefetch_l2(__args.p0, __i);");
      const size_t body = integrate.find("_forward_body(&__ctx, __args, __i)");
      ASSERT_NE(guard, std::string::npos) << integrate;
      EXPECT_TRUE(guard < prefetch && prefetch < body && body != std::string::npos) << integrate;
      EXPECT_EQ(integrate.find("__args.p1, __i"), std::string::npos) << integrate;
      // z is loaded after y's store, unconditionally; x only under the branch.
      EXPECT_NE(branchy.find("wp::cg_prefetch_l2(__args.p2, __i)"), std::string::npos) << branchy;
      EXPECT_EQ(branchy.find("__args.p0, __i"), std::string::npos) << branchy;
      EXPECT_EQ(branchy.find("__args.p1, __i"), std::string::npos) << "y is only stored before: " << branchy;
      EXPECT_EQ(CompileCudaForEveryArch(gm->source, "late_loads"), "");
    }
  }
}

}  // namespace
}  // namespace weft
