"""Builtins, scalar math: every unary and binary float function against float64 NumPy (rounded
to float32) on fresh random data in its domain, plus hard inputs: huge/tiny magnitudes,
0, -0, +-inf, NaN (propagation), values outside the domain (sqrt(-1) and log(-1) are NaN;
acos(2) and asin(2) clamp as in Warp)."""
import math

import numpy as np
import pytest

import weft as wp

HARD = np.array([0.0, -0.0, 1.0, -1.0, 1e-45, -1e-45, 1e-38, 3.4e38, -3.4e38, np.inf, -np.inf,
                 np.nan, 0.5, 88.7, 89.0, -104.0, 1e10, -1e10], dtype=np.float32)

try:
    from scipy import special as _special
except ImportError:  # erf/erfinv references from math when scipy is absent
    _special = None


def _vec(fn):
    return np.vectorize(fn, otypes=[np.float64])


def _erfinv(y):
    if _special is not None:
        return _special.erfinv(y)
    def one(v):
        if not -1 < v < 1:
            return math.copysign(math.inf, v) if abs(v) == 1 else math.nan
        x = 0.0
        for _ in range(100):      # Newton on erf(x) - v
            x -= (math.erf(x) - v) / (2 / math.sqrt(math.pi) * math.exp(-x * x))
        return x
    return _vec(one)(y)


UNARY = {
    # name: (reference on float64, random domain (lo, hi), rtol, atol)
    "sin": (np.sin, (-10, 10), 2e-6, 2e-6),
    "cos": (np.cos, (-10, 10), 2e-6, 2e-6),
    "tan": (np.tan, (-1.5, 1.5), 5e-6, 2e-6),
    # Warp clamps the argument of asin/acos to [-1, 1] (so asin(2) = pi/2); NaN stays NaN here
    # (Warp 1.19 turns NaN into -pi/2 / pi through the clamp; weft propagates it)
    "asin": (lambda x: np.arcsin(np.clip(x, -1, 1)), (-1, 1), 2e-6, 1e-6),
    "acos": (lambda x: np.arccos(np.clip(x, -1, 1)), (-1, 1), 2e-6, 1e-6),
    "atan": (np.arctan, (-100, 100), 2e-6, 1e-6),
    "sinh": (np.sinh, (-10, 10), 2e-6, 1e-6),
    "cosh": (np.cosh, (-10, 10), 2e-6, 1e-6),
    "tanh": (np.tanh, (-10, 10), 2e-6, 1e-6),
    "sqrt": (np.sqrt, (0, 1e6), 1e-6, 0),
    "cbrt": (np.cbrt, (-1e6, 1e6), 2e-6, 0),
    "exp": (np.exp, (-80, 80), 2e-6, 0),
    "log": (np.log, (1e-30, 1e30), 2e-6, 1e-6),
    "log2": (np.log2, (1e-30, 1e30), 2e-6, 1e-6),
    "log10": (np.log10, (1e-30, 1e30), 2e-6, 1e-6),
    "floor": (np.floor, (-1e3, 1e3), 0, 0),
    "ceil": (np.ceil, (-1e3, 1e3), 0, 0),
    "trunc": (np.trunc, (-1e3, 1e3), 0, 0),
    "round": (lambda x: np.sign(x) * np.floor(np.abs(x) + 0.5), (-1e3, 1e3), 0, 0),
    "rint": (np.rint, (-1e3, 1e3), 0, 0),
    "frac": (lambda x: x - np.trunc(x), (-1e3, 1e3), 1e-4, 1e-4),
    "degrees": (np.degrees, (-10, 10), 1e-6, 1e-6),
    "radians": (np.radians, (-1000, 1000), 1e-6, 1e-7),
    "erf": (_vec(math.erf), (-4, 4), 2e-6, 1e-6),
    "erfc": (_vec(math.erfc), (-4, 4), 5e-6, 1e-7),
    "erfinv": (_erfinv, (-0.999, 0.999), 5e-5, 5e-6),
}

BINARY = {
    "atan2": (np.arctan2, (-10, 10), 2e-6, 1e-6),
    "pow": (np.power, (0.01, 10), 5e-6, 0),
    "copysign": (np.copysign, (-10, 10), 0, 0),
}


def _unary_source():
    lines = []
    for name in UNARY:
        lines.append(f"""
@wp.kernel
def k_{name}(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = wp.{name}(x[i])
""")
    for name in BINARY:
        lines.append(f"""
@wp.kernel
def k_{name}(a: wp.array(dtype=float), b: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = wp.{name}(a[i], b[i])
""")
    lines.append("""
@wp.kernel
def k_float64(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64, ndim=2)):
    i = wp.tid()
    y[i, 0] = wp.sin(x[i])
    y[i, 1] = wp.exp(x[i])
    y[i, 2] = wp.sqrt(wp.abs(x[i]))
    y[i, 3] = wp.log(wp.abs(x[i]) + wp.float64(1.0e-300))
""")
    return "".join(lines)


@pytest.fixture(scope="module")
def math_kernels(tmp_path_factory):
    import importlib.util
    import sys
    path = tmp_path_factory.mktemp("scalar_math") / "weft_scalar_math_kernels.py"
    path.write_text("import weft as wp\n" + _unary_source())
    spec = importlib.util.spec_from_file_location("weft_scalar_math_kernels", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["weft_scalar_math_kernels"] = module
    spec.loader.exec_module(module)
    return module


def _f32_ref(fn, *args):
    with np.errstate(all="ignore"):
        return np.asarray(fn(*[a.astype(np.float64) for a in args])).astype(np.float32)


@pytest.mark.parametrize("name", sorted(UNARY))
def test_unary(wp, rng, math_kernels, name):
    fn, (lo, hi), rtol, atol = UNARY[name]
    x = np.concatenate([rng.uniform(lo, hi, 2000), HARD]).astype(np.float32)
    y = wp.zeros(len(x), dtype=float)
    wp.launch(getattr(math_kernels, f"k_{name}"), dim=len(x), inputs=[wp.array(x), y])
    got = y.numpy()
    ref = _f32_ref(fn, x)
    np.testing.assert_allclose(got[:-len(HARD)], ref[:-len(HARD)], rtol=rtol, atol=atol,
                               err_msg=f"wp.{name} on random inputs")
    # hard inputs: NaN where the reference is NaN, same infinities, close elsewhere
    g, r = got[-len(HARD):], ref[-len(HARD):]
    np.testing.assert_array_equal(np.isnan(g), np.isnan(r), err_msg=f"wp.{name} NaN pattern "
                                  f"on {HARD}: got {g}, expected {r}")
    finite = np.isfinite(r)
    np.testing.assert_array_equal(g[np.isinf(r)], r[np.isinf(r)], err_msg=f"wp.{name} inf")
    np.testing.assert_allclose(g[finite], r[finite], rtol=max(rtol, 1e-5), atol=max(atol, 1e-6),
                               err_msg=f"wp.{name} on hard inputs {HARD[finite]}")


@pytest.mark.parametrize("name", sorted(BINARY))
def test_binary(wp, rng, math_kernels, name):
    fn, (lo, hi), rtol, atol = BINARY[name]
    a = rng.uniform(lo, hi, 2000).astype(np.float32)
    b = rng.uniform(lo if name != "pow" else -3, hi if name != "pow" else 3, 2000).astype(np.float32)
    hard_a = np.array([0.0, -0.0, 0.0, 1.0, np.nan, np.inf, -2.0, 2.0, 0.0], dtype=np.float32)
    hard_b = np.array([0.0, -1.0, -0.0, np.nan, 1.0, np.inf, 3.0, 0.5, 1.0], dtype=np.float32)
    a, b = np.concatenate([a, hard_a]), np.concatenate([b, hard_b])
    y = wp.zeros(len(a), dtype=float)
    wp.launch(getattr(math_kernels, f"k_{name}"), dim=len(a), inputs=[wp.array(a), wp.array(b), y])
    np.testing.assert_allclose(y.numpy(), _f32_ref(fn, a, b), rtol=rtol, atol=atol,
                               equal_nan=True, err_msg=f"wp.{name}")


def test_float64_math_is_double_precision(wp, rng, math_kernels):
    x = rng.uniform(-20, 20, 1000)
    y = wp.zeros((1000, 4), dtype=wp.float64)
    wp.launch(math_kernels.k_float64, dim=1000, inputs=[wp.array(x, dtype=wp.float64), y])
    ref = np.stack([np.sin(x), np.exp(x), np.sqrt(np.abs(x)), np.log(np.abs(x) + 1e-300)], 1)
    np.testing.assert_allclose(y.numpy(), ref, rtol=1e-13)


@wp.kernel
def special_constants(x: wp.array(dtype=wp.float64), h: wp.array(dtype=wp.float16),
                      f: wp.array(dtype=wp.float32), d: wp.array(dtype=wp.float64)):
    i = wp.tid()
    # wp.inf / wp.nan are constants of the module: every float type converts them, on the CPU
    # and on the GPU (NVRTC has no __builtin_inf)
    h[i * 3 + 0] = wp.float16(wp.inf) * wp.float16(x[i])
    h[i * 3 + 1] = wp.float16(-wp.inf)
    h[i * 3 + 2] = wp.float16(wp.nan)
    f[i * 3 + 0] = wp.float32(wp.inf) * wp.float32(x[i])
    f[i * 3 + 1] = wp.float32(-wp.inf)
    f[i * 3 + 2] = wp.float32(wp.nan)
    d[i * 3 + 0] = wp.float64(wp.inf) * x[i]
    d[i * 3 + 1] = wp.erfinv(wp.float64(1.0)) + wp.erfcinv(wp.float64(0.0))
    d[i * 3 + 2] = wp.float64(wp.nan) + x[i]


def test_inf_and_nan_constants_on_every_float_type(wp, rng, device):
    n = 17
    x = rng.uniform(0.5, 1e300, n) * rng.choice([-1.0, 1.0], n)
    xa = wp.array(x, dtype=wp.float64)
    outs = [wp.zeros(3 * n, dtype=t) for t in (wp.float16, wp.float32, wp.float64)]
    wp.launch(special_constants, dim=n, inputs=[xa] + outs)
    h, f, d = (o.numpy().astype(np.float64).reshape(n, 3) for o in outs)
    signed_inf = np.where(x > 0, np.inf, -np.inf)
    for got in (h, f):
        np.testing.assert_array_equal(got[:, 0], signed_inf)
        np.testing.assert_array_equal(got[:, 1], -np.inf)
        assert np.isnan(got[:, 2]).all()
    np.testing.assert_array_equal(d[:, 0], signed_inf)
    np.testing.assert_array_equal(d[:, 1], np.inf)      # erfinv(1) = erfcinv(0) = +inf
    assert np.isnan(d[:, 2]).all()
