// Adjoint codegen, numerically: kernels are generated with enable_backward, compiled with
// clang into a shared object, run forward and backward on the CPU, and their gradients
// compared with float64 central finite differences (and closed forms) on fresh random
// inputs. Covers loops whose carried values are overwritten (products, recurrences, while,
// break/continue), nested @wp.func calls with multiple returns and early returns, atomics,
// array reads/writes and a spread of differentiable builtins.
#include <dlfcn.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "engine/codegen/generate_module.h"
#include "engine/native/launch_abi.h"

namespace weft {
namespace {

using FwdFn = void (*)(const wp::launch_context_t*, const void*, wp::int64, wp::int64);
using BwdFn = void (*)(const wp::launch_context_t*, const void*, const void*, wp::int64, wp::int64);

struct Built {
  void* handle = nullptr;
  KernelLayout layout;
  FwdFn fwd = nullptr;
  BwdFn bwd = nullptr;
  std::string error;
};

Symbol Wp() {
  Symbol s;
  s.name = "wp";
  s.kind = Symbol::Kind::kBuiltinModule;
  return s;
}

FunctionSource Fn(const std::string& name, const std::string& src, std::vector<std::string> types,
                  std::vector<std::string> names, bool kernel = true) {
  FunctionSource f;
  f.name = name;
  f.source = src;
  f.file = "grad.py";
  f.first_line = 1;
  f.is_kernel = kernel;
  f.param_types = std::move(types);
  f.param_names = std::move(names);
  f.key = "grad." + name;
  return f;
}

Built Build(const ModuleSource& m, const std::string& kernel) {
  Built b;
  CodegenOptions o;
  o.enable_backward = true;
  std::vector<Diagnostic> diags;
  auto gm = GenerateModule(m, o, &diags);
  if (!gm.ok()) {
    b.error = gm.status().message();
    for (const auto& d : diags) b.error += "\n" + d.ToString();
    return b;
  }
  static int counter = 0;
  std::string base = ::testing::TempDir() + "/weft_grad_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
  std::ofstream(base + ".cpp") << gm->source;
  std::string cmd = "clang++-19 -std=c++17 -O1 -shared -fPIC -I" WEFT_NATIVE_DIR " -o " + base + ".so " + base + ".cpp > " +
                    base + ".log 2>&1";
  if (std::system(cmd.c_str()) != 0) {
    std::ifstream in(base + ".log");
    b.error = "compile failed: " + std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()).substr(0, 4000);
    return b;
  }
  b.handle = dlopen((base + ".so").c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!b.handle) {
    b.error = dlerror();
    return b;
  }
  for (const auto& k : gm->kernels) {
    if (k.name != kernel) continue;
    b.layout = k;
    b.fwd = reinterpret_cast<FwdFn>(dlsym(b.handle, k.forward_symbol.c_str()));
    b.bwd = reinterpret_cast<BwdFn>(dlsym(b.handle, k.backward_symbol.c_str()));
  }
  if (!b.fwd || !b.bwd) b.error = "symbols not found";
  return b;
}

// A float64 array with a gradient buffer, viewed as wp::array_t.
struct Arr {
  std::vector<double> data, grad;
  int64_t rows = 0, cols = 1;  // cols > 1: 2-d
  wp::array_abi_t View(bool of_grad) {
    wp::array_abi_t a{};
    a.data = of_grad ? grad.data() : data.data();
    a.grad = nullptr;
    a.ndim = cols > 1 ? 2 : 1;
    a.shape[0] = rows;
    a.strides[0] = cols * 8;
    if (cols > 1) {
      a.shape[1] = cols;
      a.strides[1] = 8;
    }
    return a;
  }
};

struct Launch {
  Built* b;
  std::vector<uint8_t> args, adj;
  explicit Launch(Built* built) : b(built), args(built->layout.args_size), adj(built->layout.args_size) {}
  void SetArray(int p, Arr& a) {
    auto v = a.View(false), g = a.View(true);
    std::memcpy(args.data() + b->layout.params[p].offset, &v, sizeof v);
    std::memcpy(adj.data() + b->layout.params[p].offset, &g, sizeof g);
  }
  template <typename T>
  void SetScalar(int p, T v) {
    std::memcpy(args.data() + b->layout.params[p].offset, &v, sizeof v);
  }
  wp::launch_error_t Run(int64_t n, bool backward) {
    wp::launch_error_t err{};
    wp::launch_context_t ctx{};
    ctx.bounds.ndim = 1;
    ctx.bounds.shape[0] = n;
    ctx.bounds.size = n;
    ctx.error = &err;
    if (backward) b->bwd(&ctx, args.data(), adj.data(), 0, n);
    else b->fwd(&ctx, args.data(), 0, n);
    return err;
  }
};

// Checks d(sum of out.grad-weighted outputs)/d(in) from the backward pass against central
// differences of the forward pass. `setup` binds params; `in` and `out` are the arrays.
void CheckGradient(Built& b, Arr& in, Arr& out, int64_t threads, const std::function<void(Launch&)>& setup,
                   double tol, const char* what) {
  ASSERT_EQ(b.error, "") << what;
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> w(0.5, 1.5);
  std::vector<double> seed(out.data.size());
  for (auto& s : seed) s = w(rng);
  auto forward = [&]() {
    std::fill(out.data.begin(), out.data.end(), 0.0);
    Launch l(&b);
    setup(l);
    auto e = l.Run(threads, false);
    EXPECT_EQ(e.kind, 0) << what << " line " << e.line;
    double s = 0;
    for (size_t i = 0; i < out.data.size(); ++i) s += seed[i] * out.data[i];
    return s;
  };
  forward();
  std::fill(in.grad.begin(), in.grad.end(), 0.0);
  out.grad = seed;
  {
    Launch l(&b);
    setup(l);
    auto e = l.Run(threads, true);
    EXPECT_EQ(e.kind, 0) << what;
  }
  std::vector<double> analytic = in.grad;
  for (size_t k = 0; k < in.data.size(); ++k) {
    double x0 = in.data[k];
    double h = 1e-6 * std::max(1.0, std::fabs(x0));
    in.data[k] = x0 + h;
    double fp = forward();
    in.data[k] = x0 - h;
    double fm = forward();
    in.data[k] = x0;
    double fd = (fp - fm) / (2 * h);
    EXPECT_NEAR(analytic[k], fd, tol * std::max(1.0, std::fabs(fd))) << what << ": d/d in[" << k << "]";
  }
}

ModuleSource Module1(const std::string& name, const std::string& src, std::vector<std::string> types,
                     std::vector<std::string> names) {
  ModuleSource m;
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn(name, src, std::move(types), std::move(names)));
  return m;
}

const std::vector<std::string> kInOut = {"array(float64,1)", "array(float64,1)"};
const std::vector<std::string> kInOutN = {"array(float64,1)", "array(float64,1)", "int32"};

std::vector<double> Random(size_t n, double lo, double hi, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> d(lo, hi);
  std::vector<double> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}

TEST(CodegenAutodiff, LoopProductWithOverwrittenCarriedValue) {
  // Warp's own adjoint is wrong here (its docs list it as a limitation); weft recomputes.
  auto m = Module1("prod",
                   "def prod(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64), n: int):\n"
                   "    p = wp.float64(1.0)\n"
                   "    for i in range(n):\n"
                   "        p = p * x[i]\n"
                   "    out[0] = p\n",
                   kInOutN, {"x", "out", "n"});
  Built b = Build(m, "prod");
  Arr x{Random(7, 0.5, 1.5, 1), std::vector<double>(7), 7};
  Arr out{std::vector<double>(1), std::vector<double>(1), 1};
  CheckGradient(b, x, out, 1, [&](Launch& l) { l.SetArray(0, x); l.SetArray(1, out); l.SetScalar<int32_t>(2, 7); },
                1e-6, "product loop");
  // closed form: d p / d x_k = prod_{j != k} x_j
  for (size_t k = 0; k < 7; ++k) {
    double e = 1;
    for (size_t j = 0; j < 7; ++j)
      if (j != k) e *= x.data[j];
    EXPECT_NEAR(x.grad[k] / out.grad[0], e, 1e-12);
  }
}

TEST(CodegenAutodiff, WhileRecurrenceBreakContinue) {
  auto m = Module1("rec",
                   "def rec(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64), n: int):\n"
                   "    i = wp.tid()\n"
                   "    y = x[i]\n"
                   "    k = int(0)\n"
                   "    while k < n:\n"
                   "        k += 1\n"
                   "        if k == 2:\n"
                   "            continue\n"
                   "        y = wp.sin(y) * y + x[(i + k) % 4] * 0.5\n"
                   "        if k > 5:\n"
                   "            break\n"
                   "    s = y\n"
                   "    for j in range(3):\n"
                   "        s = s * s * 0.5 + y\n"
                   "    out[i] = s\n",
                   kInOutN, {"x", "out", "n"});
  Built b = Build(m, "rec");
  Arr x{Random(4, -1.0, 1.0, 2), std::vector<double>(4), 4};
  Arr out{std::vector<double>(4), std::vector<double>(4), 4};
  CheckGradient(b, x, out, 4, [&](Launch& l) { l.SetArray(0, x); l.SetArray(1, out); l.SetScalar<int32_t>(2, 9); },
                1e-5, "while recurrence");
}

TEST(CodegenAutodiff, NestedFuncsMultipleReturnsEarlyReturn) {
  ModuleSource m;
  m.symbols.push_back(Wp());
  auto sym = [&](const char* n) {
    Symbol s;
    s.name = n;
    s.kind = Symbol::Kind::kFunction;
    s.target = std::string("grad.") + n;
    m.symbols.push_back(s);
  };
  sym("polar");
  sym("soft");
  sym("accumulate");
  m.functions.push_back(Fn("polar",
                           "def polar(x: wp.float64, y: wp.float64):\n"
                           "    return wp.sqrt(x * x + y * y), wp.atan2(y, x)\n",
                           {"float64", "float64"}, {"x", "y"}, false));
  m.functions.push_back(Fn("soft",
                           "def soft(r: wp.float64, t: wp.float64) -> wp.float64:\n"
                           "    if r > 1.2:\n"
                           "        return r * t\n"
                           "    q = r\n"
                           "    for j in range(3):\n"
                           "        q = q * t + wp.exp(-q)\n"
                           "    return q\n",
                           {"float64", "float64"}, {"r", "t"}, false));
  m.functions.push_back(Fn("accumulate",
                           "def accumulate(a: wp.array(dtype=wp.float64), i: int) -> wp.float64:\n"
                           "    r, t = polar(a[2 * i], a[2 * i + 1])\n"
                           "    return soft(r, t)\n",
                           {"array(float64,1)", "int32"}, {"a", "i"}, false));
  m.functions.push_back(Fn("k",
                           "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                           "    i = wp.tid()\n"
                           "    v = accumulate(x, i)\n"
                           "    wp.atomic_add(out, 0, v * v)\n"
                           "    out[1 + i] = wp.max(v, wp.float64(0.1)) + wp.abs(x[0])\n",
                           kInOut, {"x", "out"}));
  Built b = Build(m, "k");
  Arr x{Random(8, -1.0, 1.0, 3), std::vector<double>(8), 8};
  Arr out{std::vector<double>(5), std::vector<double>(5), 5};
  CheckGradient(b, x, out, 4, [&](Launch& l) { l.SetArray(0, x); l.SetArray(1, out); }, 1e-5, "nested funcs");
}

TEST(CodegenAutodiff, VectorMatrixQuatBuiltins) {
  auto m = Module1("k",
                   "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                   "    i = wp.tid()\n"
                   "    b = 12 * i\n"
                   "    v = wp.vec3d(x[b], x[b + 1], x[b + 2])\n"
                   "    w = wp.vec3d(x[b + 3], x[b + 4], x[b + 5])\n"
                   "    m = wp.mat33d(v, w, wp.cross(v, w))\n"
                   "    m[1, 1] = m[1, 1] + x[b + 6]\n"
                   "    d = wp.determinant(m)\n"
                   "    mi = wp.inverse(m)\n"
                   "    q = wp.quat_from_axis_angle(wp.normalize(w), x[b + 7])\n"
                   "    r = wp.quat_rotate(q, v)\n"
                   "    t = wp.transformd(w, q)\n"
                   "    p = wp.transform_point(t, v * x[b + 8])\n"
                   "    s = wp.length(r) + wp.dot(p, mi @ v) + d * wp.tanh(x[b + 9]) + wp.pow(wp.abs(x[b + 10]) + 0.5, x[b + 11])\n"
                   "    s += wp.length_sq(wp.outer(v, w) * p) + mi[0, 2] + r.y + wp.clamp(x[b + 10], -0.3, 0.3)\n"
                   "    out[i] = s\n",
                   kInOut, {"x", "out"});
  Built b = Build(m, "k");
  Arr x{Random(24, -1.0, 1.0, 4), std::vector<double>(24), 24};
  Arr out{std::vector<double>(2), std::vector<double>(2), 2};
  CheckGradient(b, x, out, 2, [&](Launch& l) { l.SetArray(0, x); l.SetArray(1, out); }, 1e-5, "vec/mat/quat");
}

TEST(CodegenAutodiff, WarpPointsLossGradientIsTwoX) {
  ModuleSource m;
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn("loss",
                           "def loss(xs: wp.array(dtype=float, ndim=2), l: wp.array(dtype=float)):\n"
                           "    tid = wp.tid()\n"
                           "    wp.atomic_add(l, 0, xs[tid, 0] ** 2.0 + xs[tid, 1] ** 2.0)\n",
                           {"array(float32,2)", "array(float32,1)"}, {"xs", "l"}));
  Built b = Build(m, "loss");
  ASSERT_EQ(b.error, "");
  std::vector<float> xs = {0.5f, -1.0f, 2.0f, 0.25f, -3.0f, 1.5f}, gx(6, 0.f), l(1, 0.f), gl(1, 1.f);
  auto arr = [](float* p, int64_t r, int64_t c) {
    wp::array_abi_t a{};
    a.data = p;
    a.ndim = c > 1 ? 2 : 1;
    a.shape[0] = r;
    a.strides[0] = c * 4;
    a.shape[1] = c > 1 ? c : 0;
    a.strides[1] = c > 1 ? 4 : 0;
    return a;
  };
  Launch ln(&b);
  auto a0 = arr(xs.data(), 3, 2), g0 = arr(gx.data(), 3, 2), a1 = arr(l.data(), 1, 1), g1 = arr(gl.data(), 1, 1);
  std::memcpy(ln.args.data() + b.layout.params[0].offset, &a0, 88);
  std::memcpy(ln.adj.data() + b.layout.params[0].offset, &g0, 88);
  std::memcpy(ln.args.data() + b.layout.params[1].offset, &a1, 88);
  std::memcpy(ln.adj.data() + b.layout.params[1].offset, &g1, 88);
  EXPECT_EQ(ln.Run(3, false).kind, 0);
  float expect = 0;
  for (float v : xs) expect += v * v;
  EXPECT_NEAR(l[0], expect, 1e-5);
  EXPECT_EQ(ln.Run(3, true).kind, 0);
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(gx[k], 2 * xs[k], 1e-5) << k;
}

TEST(CodegenAutodiff, OutOfBoundsReadStopsTheThreadAndReports) {
  auto m = Module1("oob",
                   "def oob(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64), n: int):\n"
                   "    i = wp.tid()\n"
                   "    out[i] = x[i + n]\n",
                   kInOutN, {"x", "out", "n"});
  Built b = Build(m, "oob");
  ASSERT_EQ(b.error, "");
  Arr x{{1, 2, 3}, {0, 0, 0}, 3};
  Arr out{{7, 7, 7}, {0, 0, 0}, 3};
  Launch l(&b);
  l.SetArray(0, x);
  l.SetArray(1, out);
  l.SetScalar<int32_t>(2, 2);
  auto e = l.Run(3, false);
  EXPECT_EQ(e.kind, wp::LAUNCH_OUT_OF_BOUNDS);
  EXPECT_EQ(e.line, 3);
  EXPECT_EQ(e.array_param, 0);
  EXPECT_EQ(e.ndim, 1);
  EXPECT_EQ(e.index[0], 3);
  EXPECT_EQ(e.shape[0], 3);
  EXPECT_STREQ(e.message, "x");
  EXPECT_EQ(out.data[0], 3);  // thread 0 read x[2]
  EXPECT_EQ(out.data[1], 7);  // threads 1, 2 stopped before writing
  EXPECT_EQ(out.data[2], 7);
}

TEST(CodegenAutodiff, AdjointAccessesAreBoundsCheckedAgainstTheAdjointArray) {
  // Reads x[i], writes out[i + 1]: in the backward pass the
  // adjoint arrays (gradients) are indexed at the same places; an adjoint array smaller than its
  // primal must be reported, never written past.
  auto m = Module1("adjoob",
                   "def adjoob(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64), n: int):\n"
                   "    i = wp.tid()\n"
                   "    out[i + 1] = x[i] * 2.0\n",
                   kInOutN, {"x", "out", "n"});
  Built b = Build(m, "adjoob");
  ASSERT_EQ(b.error, "");
  Arr x{{1, 2, 3}, {0, 0, 0}, 3};
  Arr out{{0, 0, 0, 0}, {1, 1, 1, 1}, 4};
  Launch l(&b);
  l.SetArray(0, x);
  l.SetArray(1, out);
  EXPECT_EQ(l.Run(3, false).kind, 0);
  EXPECT_EQ(l.Run(3, true).kind, 0);
  EXPECT_EQ(x.grad, (std::vector<double>{2, 2, 2}));
  // The gradient of x: 1 element (+ a guard) for a primal of 3.
  std::vector<double> small_grad = {0, -99};
  wp::array_abi_t g = x.View(true);
  g.data = small_grad.data();
  g.shape[0] = 1;
  std::memcpy(l.adj.data() + b.layout.params[0].offset, &g, sizeof g);
  auto e = l.Run(3, true);
  EXPECT_EQ(e.kind, wp::LAUNCH_OUT_OF_BOUNDS);
  EXPECT_EQ(e.array_param, 0);
  EXPECT_EQ(e.shape[0], 1);
  EXPECT_STREQ(e.message, "x");
  EXPECT_EQ(small_grad[1], -99);   // nothing written past the adjoint array
  // A smaller gradient of `out` (read by the adjoint of the store).
  Launch l2(&b);
  l2.SetArray(0, x);
  l2.SetArray(1, out);
  std::vector<double> small_out_grad = {1, -99};
  wp::array_abi_t og = out.View(true);
  og.data = small_out_grad.data();
  og.shape[0] = 1;
  std::memcpy(l2.adj.data() + b.layout.params[1].offset, &og, sizeof og);
  e = l2.Run(3, true);
  EXPECT_EQ(e.kind, wp::LAUNCH_OUT_OF_BOUNDS);
  EXPECT_EQ(e.array_param, 1);
  // A None gradient (no gradient wanted) is not an error.
  Launch l3(&b);
  l3.SetArray(0, x);
  l3.SetArray(1, out);
  wp::array_abi_t none{};
  none.ndim = 1;
  std::memcpy(l3.adj.data() + b.layout.params[0].offset, &none, sizeof none);
  EXPECT_EQ(l3.Run(3, true).kind, 0);
}

TEST(CodegenAutodiff, DivApproxInverseApproxForwardAndGradient) {
  auto m = Module1("k",
                   "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                   "    i = wp.tid()\n"
                   "    b = 8 * i\n"
                   "    v = wp.vec3d(x[b], x[b + 1], x[b + 2])\n"
                   "    d = x[b + 7] + wp.float64(3.0)\n"
                   "    m = wp.mat22d(x[b + 3] + wp.float64(2.0), x[b + 4], x[b + 5], x[b + 6] + wp.float64(2.0))\n"
                   "    s = wp.div_approx(x[b], d) + wp.length_sq(wp.div_approx(v, d))\n"
                   "    s += wp.dot(wp.div_approx(d, v + wp.vec3d(wp.float64(3.0), wp.float64(3.0), wp.float64(3.0))), v)\n"
                   "    mi = wp.inverse_approx(m)\n"
                   "    s += mi[0, 0] + mi[0, 1] * x[b] + mi[1, 0] + mi[1, 1] * wp.float64(2.0)\n"
                   "    s += wp.div_approx(m, d)[1, 0] + wp.div_approx(d, m)[0, 0]\n"
                   "    out[i] = s\n",
                   kInOut, {"x", "out"});
  Built b = Build(m, "k");
  ASSERT_EQ(b.error, "");
  Arr x{Random(16, -0.8, 0.8, 11), std::vector<double>(16), 16};
  Arr out{std::vector<double>(2), std::vector<double>(2), 2};
  auto setup = [&](Launch& l) { l.SetArray(0, x); l.SetArray(1, out); };
  {
    Launch l(&b);
    setup(l);
    ASSERT_EQ(l.Run(2, false).kind, 0);
  }
  for (int i = 0; i < 2; ++i) {  // float64 reference
    const double* a = x.data.data() + 8 * i;
    double d = a[7] + 3.0, m00 = a[3] + 2.0, m01 = a[4], m10 = a[5], m11 = a[6] + 2.0;
    double s = a[0] / d;
    for (int c = 0; c < 3; ++c) s += (a[c] / d) * (a[c] / d) + d / (a[c] + 3.0) * a[c];
    double det = m00 * m11 - m01 * m10;
    s += m11 / det + (-m01 / det) * a[0] + (-m10 / det) + (m00 / det) * 2.0;
    s += m10 / d + d / m00;
    EXPECT_NEAR(out.data[i], s, 1e-12 * std::max(1.0, std::fabs(s))) << i;
  }
  CheckGradient(b, x, out, 2, setup, 1e-6, "div_approx/inverse_approx");
}

TEST(CodegenAutodiff, UnotAndBlockDimOnCpu) {
  auto m = Module1("k",
                   "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                   "    i = wp.tid()\n"
                   "    r = wp.float64(0.0)\n"
                   "    if wp.unot(i % 2):\n"
                   "        r += wp.float64(1.0)\n"
                   "    if wp.unot(i > 2):\n"
                   "        r += wp.float64(2.0)\n"
                   "    if wp.unot(x):\n"
                   "        r += wp.float64(4.0)\n"
                   "    r += wp.float64(wp.block_dim()) * wp.float64(10.0)\n"
                   "    out[i] = r * x[i]\n",
                   kInOut, {"x", "out"});
  Built b = Build(m, "k");
  ASSERT_EQ(b.error, "");
  Arr x{Random(5, 0.5, 1.5, 12), std::vector<double>(5), 5};
  Arr out{std::vector<double>(5), std::vector<double>(5), 5};
  Launch l(&b);
  l.SetArray(0, x);
  l.SetArray(1, out);
  ASSERT_EQ(l.Run(5, false).kind, 0);
  for (int i = 0; i < 5; ++i) {
    double r = (i % 2 == 0 ? 1.0 : 0.0) + (i > 2 ? 0.0 : 2.0) + 10.0;  // x is not None; one thread per block
    EXPECT_NEAR(out.data[i], r * x.data[i], 1e-15) << i;
  }
}

struct V3 {
  double x, y, z;
};
V3 Sub(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 Add(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 Mul(V3 a, double s) { return {a.x * s, a.y * s, a.z * s}; }
double Dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V3 Cross(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }

// Reference for closest_point_edge_edge: the minimum of |p1 + d1 s - p2 - d2 t| over the unit
// square is the interior stationary point or lies on one of the four sides.
void SegmentSegmentReference(V3 p1, V3 q1, V3 p2, V3 q2, double* s_out, double* t_out, double* d_out) {
  V3 d1 = Sub(q1, p1), d2 = Sub(q2, p2), r = Sub(p1, p2);
  auto dist = [&](double s, double t) {
    V3 w = Sub(Add(p1, Mul(d1, s)), Add(p2, Mul(d2, t)));
    return std::sqrt(Dot(w, w));
  };
  auto c01 = [](double x) { return std::min(1.0, std::max(0.0, x)); };
  double best = 1e300, bs = 0, bt = 0;
  auto consider = [&](double s, double t) {
    double d = dist(s, t);
    if (d < best) best = d, bs = s, bt = t;
  };
  double a = Dot(d1, d1), b = Dot(d1, d2), e = Dot(d2, d2), c = Dot(d1, r), f = Dot(d2, r);
  double det = a * e - b * b;
  double si = (b * f - c * e) / det, ti = (a * f - b * c) / det;
  if (si >= 0 && si <= 1 && ti >= 0 && ti <= 1) consider(si, ti);
  for (double s : {0.0, 1.0}) consider(s, c01((f + b * s) / e));
  for (double t : {0.0, 1.0}) consider(c01((b * t - c) / a), t);
  *s_out = bs, *t_out = bt, *d_out = best;
}

TEST(CodegenAutodiff, ClosestPointEdgeEdgeForwardAndGradient) {
  auto m = Module1("k",
                   "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                   "    i = wp.tid()\n"
                   "    b = 12 * i\n"
                   "    p1 = wp.vec3d(x[b], x[b + 1], x[b + 2])\n"
                   "    q1 = wp.vec3d(x[b + 3], x[b + 4], x[b + 5])\n"
                   "    p2 = wp.vec3d(x[b + 6], x[b + 7], x[b + 8])\n"
                   "    q2 = wp.vec3d(x[b + 9], x[b + 10], x[b + 11])\n"
                   "    r = wp.closest_point_edge_edge(p1, q1, p2, q2, wp.float64(1.0e-12))\n"
                   "    out[3 * i] = r[0]\n"
                   "    out[3 * i + 1] = r[1]\n"
                   "    out[3 * i + 2] = r[2]\n",
                   kInOut, {"x", "out"});
  Built b = Build(m, "k");
  ASSERT_EQ(b.error, "");
  const int n = 24;
  Arr x{Random(12 * n, -1.0, 1.0, 21), std::vector<double>(12 * n), 12 * n};
  Arr out{std::vector<double>(3 * n), std::vector<double>(3 * n), 3 * n};
  auto setup = [&](Launch& l) { l.SetArray(0, x); l.SetArray(1, out); };
  {
    Launch l(&b);
    setup(l);
    ASSERT_EQ(l.Run(n, false).kind, 0);
  }
  int clamped = 0;
  for (int i = 0; i < n; ++i) {
    const double* a = x.data.data() + 12 * i;
    double s, t, d;
    SegmentSegmentReference({a[0], a[1], a[2]}, {a[3], a[4], a[5]}, {a[6], a[7], a[8]}, {a[9], a[10], a[11]}, &s, &t, &d);
    EXPECT_NEAR(out.data[3 * i], s, 1e-9) << i;
    EXPECT_NEAR(out.data[3 * i + 1], t, 1e-9) << i;
    EXPECT_NEAR(out.data[3 * i + 2], d, 1e-12) << i;
    clamped += (s == 0 || s == 1 || t == 0 || t == 1);
  }
  EXPECT_GT(clamped, 3);       // the clamped branches are exercised
  EXPECT_LT(clamped, n - 3);   // and the interior one
  CheckGradient(b, x, out, n, setup, 1e-5, "closest_point_edge_edge");
}

// Reference for intersect_tri_tri (triangles in general position): they overlap iff an edge
// of one crosses the other.
bool SegmentHitsTriangle(V3 p, V3 q, V3 a, V3 b, V3 c) {
  V3 n = Cross(Sub(b, a), Sub(c, a));
  double dp = Dot(n, Sub(p, a)), dq = Dot(n, Sub(q, a));
  if ((dp > 0 && dq > 0) || (dp < 0 && dq < 0) || dp == dq) return false;
  V3 h = Add(p, Mul(Sub(q, p), dp / (dp - dq)));
  double s1 = Dot(n, Cross(Sub(b, a), Sub(h, a))), s2 = Dot(n, Cross(Sub(c, b), Sub(h, b))),
         s3 = Dot(n, Cross(Sub(a, c), Sub(h, c)));
  return (s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0);
}

TEST(CodegenAutodiff, IntersectTriTriAgainstEdgeCrossingReference) {
  auto m = Module1("k",
                   "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                   "    i = wp.tid()\n"
                   "    b = 18 * i\n"
                   "    v0 = wp.vec3d(x[b], x[b + 1], x[b + 2])\n"
                   "    v1 = wp.vec3d(x[b + 3], x[b + 4], x[b + 5])\n"
                   "    v2 = wp.vec3d(x[b + 6], x[b + 7], x[b + 8])\n"
                   "    u0 = wp.vec3d(x[b + 9], x[b + 10], x[b + 11])\n"
                   "    u1 = wp.vec3d(x[b + 12], x[b + 13], x[b + 14])\n"
                   "    u2 = wp.vec3d(x[b + 15], x[b + 16], x[b + 17])\n"
                   "    hit = wp.intersect_tri_tri(v0, v1, v2, u0, u1, u2)\n"
                   "    hf = wp.intersect_tri_tri(wp.vec3f(v0), wp.vec3f(v1), wp.vec3f(v2), wp.vec3f(u0), wp.vec3f(u1), wp.vec3f(u2))\n"
                   "    out[2 * i] = wp.float64(hit)\n"
                   "    out[2 * i + 1] = wp.float64(hf)\n",
                   kInOut, {"x", "out"});
  Built b = Build(m, "k");
  ASSERT_EQ(b.error, "");
  const int random_pairs = 400;
  std::vector<double> data = Random(18 * random_pairs, -1.0, 1.0, 31);
  // Coplanar hard cases (z = 0): identical, one inside the other, disjoint, sharing a vertex.
  std::vector<std::vector<double>> coplanar = {
      {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0},
      {0, 0, 0, 4, 0, 0, 0, 4, 0, 0.5, 0.5, 0, 1, 0.5, 0, 0.5, 1, 0},
      {0, 0, 0, 1, 0, 0, 0, 1, 0, 2, 2, 0, 3, 2, 0, 2, 3, 0},
      {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 0, 0, 2, 0, 0, 2, 1, 0},
      {0, 0, 0, 1, 0, 0, 0, 1, 0, 0.6, 0.6, 0, 2, 0.6, 0, 0.6, 2, 0},
  };
  const double coplanar_expect[] = {1, 1, 0, 1, 0};
  for (auto& c : coplanar) data.insert(data.end(), c.begin(), c.end());
  const int n = random_pairs + static_cast<int>(coplanar.size());
  Arr x{data, std::vector<double>(data.size()), static_cast<int64_t>(data.size())};
  Arr out{std::vector<double>(2 * n), std::vector<double>(2 * n), 2 * n};
  Launch l(&b);
  l.SetArray(0, x);
  l.SetArray(1, out);
  ASSERT_EQ(l.Run(n, false).kind, 0);
  int hits = 0;
  for (int i = 0; i < random_pairs; ++i) {
    const double* a = x.data.data() + 18 * i;
    V3 v[3], u[3];
    for (int k = 0; k < 3; ++k) {
      v[k] = {a[3 * k], a[3 * k + 1], a[3 * k + 2]};
      u[k] = {a[9 + 3 * k], a[10 + 3 * k], a[11 + 3 * k]};
    }
    bool expect = false;
    for (int k = 0; k < 3; ++k) {
      expect = expect || SegmentHitsTriangle(v[k], v[(k + 1) % 3], u[0], u[1], u[2]);
      expect = expect || SegmentHitsTriangle(u[k], u[(k + 1) % 3], v[0], v[1], v[2]);
    }
    hits += expect;
    EXPECT_EQ(out.data[2 * i], expect ? 1.0 : 0.0) << "pair " << i;
    EXPECT_EQ(out.data[2 * i + 1], expect ? 1.0 : 0.0) << "pair " << i << " (float32)";
  }
  EXPECT_GT(hits, 20);
  EXPECT_LT(hits, random_pairs - 20);
  for (size_t c = 0; c < coplanar.size(); ++c) {
    EXPECT_EQ(out.data[2 * (random_pairs + c)], coplanar_expect[c]) << "coplanar case " << c;
    EXPECT_EQ(out.data[2 * (random_pairs + c) + 1], coplanar_expect[c]) << "coplanar case " << c << " (float32)";
  }
}

TEST(CodegenAutodiff, TransformSetTranslationAndRotationRebindTheVariable) {
  auto m = Module1("k",
                   "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                   "    i = wp.tid()\n"
                   "    b = 12 * i\n"
                   "    t = wp.transformd(wp.vec3d(x[b], x[b + 1], x[b + 2]), wp.quatd(x[b + 3], x[b + 4], x[b + 5], x[b + 6]))\n"
                   "    t0 = t\n"
                   "    wp.transform_set_translation(t, wp.vec3d(x[b + 7], x[b + 8], x[b + 9]) * x[b])\n"
                   "    s = wp.dot(wp.transform_get_translation(t), wp.vec3d(x[b + 1], x[b + 2], x[b + 3]))\n"
                   "    s += wp.dot(wp.transform_get_rotation(t), wp.quatd(x[b + 4], x[b + 5], x[b + 6], x[b + 7]))\n"
                   "    wp.transform_set_rotation(t, wp.quatd(x[b + 10], x[b + 11], x[b + 1], x[b + 2]) * x[b + 3])\n"
                   "    s += wp.dot(wp.transform_get_rotation(t), wp.quatd(x[b + 8], x[b + 9], x[b + 10], x[b + 11])) * t.p[1]\n"
                   "    s += t0.p[0] * wp.float64(3.0)\n"
                   "    out[i] = s\n",
                   kInOut, {"x", "out"});
  Built b = Build(m, "k");
  ASSERT_EQ(b.error, "");
  Arr x{Random(36, -1.0, 1.0, 41), std::vector<double>(36), 36};
  Arr out{std::vector<double>(3), std::vector<double>(3), 3};
  auto setup = [&](Launch& l) { l.SetArray(0, x); l.SetArray(1, out); };
  {
    Launch l(&b);
    setup(l);
    ASSERT_EQ(l.Run(3, false).kind, 0);
  }
  for (int i = 0; i < 3; ++i) {
    const double* a = x.data.data() + 12 * i;
    double p[3] = {a[7] * a[0], a[8] * a[0], a[9] * a[0]};
    double s = p[0] * a[1] + p[1] * a[2] + p[2] * a[3];
    s += a[3] * a[4] + a[4] * a[5] + a[5] * a[6] + a[6] * a[7];
    double q2[4] = {a[10] * a[3], a[11] * a[3], a[1] * a[3], a[2] * a[3]};
    s += (q2[0] * a[8] + q2[1] * a[9] + q2[2] * a[10] + q2[3] * a[11]) * p[1];
    s += a[0] * 3.0;  // the copy taken before the set keeps the old translation
    EXPECT_NEAR(out.data[i], s, 1e-12) << i;
  }
  CheckGradient(b, x, out, 3, setup, 1e-6, "transform_set_*");
}

TEST(CodegenAutodiff, TidInsideFuncsIsTheCallingThread) {
  ModuleSource m;
  m.symbols.push_back(Wp());
  for (const char* n : {"scaled", "outer_f"}) {
    Symbol s;
    s.name = n;
    s.kind = Symbol::Kind::kFunction;
    s.target = std::string("grad.") + n;
    m.symbols.push_back(s);
  }
  m.functions.push_back(Fn("scaled",
                           "def scaled(x: wp.array(dtype=wp.float64)) -> wp.float64:\n"
                           "    i = wp.tid()\n"
                           "    return x[i] * x[i] * wp.float64(i + 1)\n",
                           {"array(float64,1)"}, {"x"}, false));
  m.functions.push_back(Fn("outer_f",
                           "def outer_f(x: wp.array(dtype=wp.float64), k: int) -> wp.float64:\n"
                           "    return scaled(x) + wp.float64(k) * x[wp.tid()]\n",
                           {"array(float64,1)", "int32"}, {"x", "k"}, false));
  m.functions.push_back(Fn("k",
                           "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                           "    i = wp.tid()\n"
                           "    out[i] = outer_f(x, 3)\n",
                           kInOut, {"x", "out"}));
  Built b = Build(m, "k");
  ASSERT_EQ(b.error, "");
  const int n = 6;
  Arr x{Random(n, -1.0, 1.0, 51), std::vector<double>(n), n};
  Arr out{std::vector<double>(n), std::vector<double>(n), n};
  auto setup = [&](Launch& l) { l.SetArray(0, x); l.SetArray(1, out); };
  {
    Launch l(&b);
    setup(l);
    ASSERT_EQ(l.Run(n, false).kind, 0);
  }
  for (int i = 0; i < n; ++i) EXPECT_NEAR(out.data[i], x.data[i] * x.data[i] * (i + 1) + 3 * x.data[i], 1e-14) << i;
  CheckGradient(b, x, out, n, setup, 1e-6, "tid in funcs");
  for (int i = 0; i < n; ++i) EXPECT_NEAR(x.grad[i] / out.grad[i], 2 * x.data[i] * (i + 1) + 3, 1e-9) << i;
}

TEST(CodegenAutodiff, TidUnpackedInsideFuncOf2dLaunch) {
  ModuleSource m;
  m.symbols.push_back(Wp());
  Symbol s;
  s.name = "cell";
  s.kind = Symbol::Kind::kFunction;
  s.target = "grad.cell";
  m.symbols.push_back(s);
  m.functions.push_back(Fn("cell",
                           "def cell() -> wp.float64:\n"
                           "    i, j = wp.tid()\n"
                           "    return wp.float64(10 * i + j)\n",
                           {}, {}, false));
  m.functions.push_back(Fn("k",
                           "def k(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):\n"
                           "    i, j = wp.tid()\n"
                           "    out[3 * i + j] = cell()\n",
                           kInOut, {"x", "out"}));
  Built b = Build(m, "k");
  ASSERT_EQ(b.error, "");
  Arr x{std::vector<double>(1), std::vector<double>(1), 1};
  Arr out{std::vector<double>(6, -1.0), std::vector<double>(6), 6};
  Launch l(&b);
  l.SetArray(0, x);
  l.SetArray(1, out);
  wp::launch_error_t err{};
  wp::launch_context_t ctx{};
  ctx.bounds.ndim = 2;
  ctx.bounds.shape[0] = 2;
  ctx.bounds.shape[1] = 3;
  ctx.bounds.size = 6;
  ctx.error = &err;
  b.fwd(&ctx, l.args.data(), 0, 6);
  ASSERT_EQ(err.kind, 0);
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_EQ(out.data[3 * i + j], 10.0 * i + j) << i << "," << j;
}


// A differentiable `a[i].x *= v` has no adjoint (Warp's error): the forward build compiles and
// names the error on every kernel that reaches it, through a func too; generating adjoints fails
// with it at its line. `+=` on a slot and `*=` on a whole element keep their adjoints.
TEST(CodegenAutodiff, SlotMultiplyRefusesTheAdjointNotTheForwardCode) {
  ModuleSource m;
  m.symbols.push_back(Wp());
  m.functions.push_back(Fn("scale_x",
                           "def scale_x(y: wp.array(dtype=wp.vec3), s: float, i: int):\n"
                           "    y[i].x *= s\n",
                           {"array(vec(3,float32),1)", "float32", "int32"}, {"y", "s", "i"}, false));
  m.functions.back().key = "grad.scale_x";
  Symbol f;
  f.name = "scale_x";
  f.kind = Symbol::Kind::kFunction;
  f.target = "grad.scale_x";
  m.symbols.push_back(f);
  m.functions.push_back(Fn("through_func",
                           "def through_func(y: wp.array(dtype=wp.vec3), s: wp.array(dtype=float)):\n"
                           "    i = wp.tid()\n"
                           "    scale_x(y, s[i], i)\n",
                           {"array(vec(3,float32),1)", "array(float32,1)"}, {"y", "s"}));
  m.functions.push_back(Fn("fine",
                           "def fine(y: wp.array(dtype=wp.vec3), s: wp.array(dtype=float)):\n"
                           "    i = wp.tid()\n"
                           "    y[i].x += s[i]\n"
                           "    y[i] *= s[i]\n",
                           {"array(vec(3,float32),1)", "array(float32,1)"}, {"y", "s"}));
  CodegenOptions o;
  std::vector<Diagnostic> diags;
  auto fwd = GenerateModule(m, o, &diags);
  ASSERT_TRUE(fwd.ok()) << fwd.status().message();
  ASSERT_EQ(fwd->kernels.size(), 2u);
  for (const auto& k : fwd->kernels) {
    if (k.name == "fine") {
      EXPECT_EQ(k.adjoint_refused, "");
    } else {
      EXPECT_NE(k.adjoint_refused.find("grad.py:2:"), std::string::npos) << k.adjoint_refused;
      EXPECT_NE(k.adjoint_refused.find("Differentiable composite slot augmented assignments"), std::string::npos);
    }
  }
  o.enable_backward = true;
  diags.clear();
  auto bwd = GenerateModule(m, o, &diags);
  ASSERT_FALSE(bwd.ok());
  ASSERT_EQ(diags.size(), 1u);
  EXPECT_EQ(diags[0].location.line, 2u);
  EXPECT_NE(diags[0].message.find("enable_backward=False"), std::string::npos);
}

}  // namespace
}  // namespace weft
