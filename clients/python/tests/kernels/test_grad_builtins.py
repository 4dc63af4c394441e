"""Autodiff, per differentiable builtin: the gradient the daemon computes (tape backward of a
float64 kernel) against float64 central finite differences of the same kernel, on fresh
random inputs and the hard cases of issue 4 (sqrt near 0, acos/asin near +-1, atan2 near the
origin, normalize/length near the zero vector, pow with negative bases, inverse/determinant
near singular, slerp of nearly identical rotations, exp/log at extreme magnitudes).
Each test prints its worst relative error (run with -s for the gradient-check table)."""
import importlib.util
import sys

import numpy as np
import pytest

import weft as wp

HELPERS = '''
import weft as wp

@wp.func
def v3(x: wp.array2d(dtype=wp.float64), i: int, o: int):
    return wp.vec3d(x[i, o], x[i, o + 1], x[i, o + 2])

@wp.func
def q4(x: wp.array2d(dtype=wp.float64), i: int, o: int):
    return wp.normalize(wp.quatd(x[i, o], x[i, o + 1], x[i, o + 2], x[i, o + 3]))

@wp.func
def m3(x: wp.array2d(dtype=wp.float64), i: int):
    return wp.mat33d(x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5], x[i, 6], x[i, 7], x[i, 8])

@wp.func
def wvec():
    return wp.vec3d(wp.float64(0.3), wp.float64(-0.7), wp.float64(0.45))
'''

F = "wp.float64"
# name: (k inputs per row, expression of x (array2d float64) and i, sampler(rng, n) -> (n, k),
#        hard rows (list of k-tuples), rtol)
CASES = {
    "sin": (1, "wp.sin(x[i, 0])", lambda r, n: r.uniform(-6, 6, (n, 1)), [(0.0,), (1e-8,)], 1e-6),
    "cos": (1, "wp.cos(x[i, 0])", lambda r, n: r.uniform(-6, 6, (n, 1)), [(0.0,), (3.14159,)], 1e-6),
    "tan": (1, "wp.tan(x[i, 0])", lambda r, n: r.uniform(-1.4, 1.4, (n, 1)), [(1.5,)], 1e-6),
    "asin": (1, "wp.asin(x[i, 0])", lambda r, n: r.uniform(-0.99, 0.99, (n, 1)),
             [(0.999999,), (-0.999999,), (0.0,)], 1e-4),
    "acos": (1, "wp.acos(x[i, 0])", lambda r, n: r.uniform(-0.99, 0.99, (n, 1)),
             [(0.999999,), (-0.999999,)], 1e-4),
    "atan": (1, "wp.atan(x[i, 0])", lambda r, n: r.uniform(-50, 50, (n, 1)), [(0.0,), (1e8,)], 1e-6),
    "sinh": (1, "wp.sinh(x[i, 0])", lambda r, n: r.uniform(-5, 5, (n, 1)), [(0.0,)], 1e-6),
    "cosh": (1, "wp.cosh(x[i, 0])", lambda r, n: r.uniform(-5, 5, (n, 1)), [(0.0,)], 1e-6),
    "tanh": (1, "wp.tanh(x[i, 0])", lambda r, n: r.uniform(-5, 5, (n, 1)), [(0.0,), (15.0,)], 1e-6),
    "sqrt": (1, "wp.sqrt(x[i, 0])", lambda r, n: r.uniform(0.01, 100, (n, 1)),
             [(1e-8,), (1e-12,)], 1e-4),
    "cbrt": (1, "wp.cbrt(x[i, 0])", lambda r, n: r.uniform(0.01, 100, (n, 1)), [(-8.0,), (1e-9,)], 1e-4),
    "exp": (1, "wp.exp(x[i, 0])", lambda r, n: r.uniform(-20, 20, (n, 1)), [(700.0,), (-700.0,)], 1e-6),
    "log": (1, "wp.log(x[i, 0])", lambda r, n: r.uniform(0.01, 100, (n, 1)), [(1e-300,), (1e300,)], 1e-6),
    "log2": (1, "wp.log2(x[i, 0])", lambda r, n: r.uniform(0.01, 100, (n, 1)), [(1e-200,)], 1e-6),
    "log10": (1, "wp.log10(x[i, 0])", lambda r, n: r.uniform(0.01, 100, (n, 1)), [(1e200,)], 1e-6),
    "erf": (1, "wp.erf(x[i, 0])", lambda r, n: r.uniform(-3, 3, (n, 1)), [(0.0,)], 1e-6),
    "abs": (1, "wp.abs(x[i, 0])", lambda r, n: r.uniform(-5, 5, (n, 1)), [], 1e-6),
    "pow": (2, "wp.pow(x[i, 0], x[i, 1])", lambda r, n: np.stack([r.uniform(0.1, 5, n),
                                                                   r.uniform(-3, 3, n)], 1),
            [(1e-6, 2.5)], 1e-5),
    "atan2": (2, "wp.atan2(x[i, 0], x[i, 1])", lambda r, n: r.uniform(-5, 5, (n, 2)),
              [(1e-7, 1e-7), (-1e-7, 2e-7), (1e-7, -1e-7)], 1e-4),
    "mul_div": (2, "x[i, 0] * x[i, 1] / (x[i, 1] * x[i, 1] + " + F + "(1.0))",
                lambda r, n: r.uniform(-5, 5, (n, 2)), [], 1e-6),
    "min_max": (2, "wp.min(x[i, 0], x[i, 1]) * " + F + "(2.0) + wp.max(x[i, 0], x[i, 1])",
                lambda r, n: r.uniform(-5, 5, (n, 2)), [], 1e-6),
    "clamp": (1, "wp.clamp(x[i, 0], " + F + "(-1.0), " + F + "(1.0))",
              lambda r, n: r.uniform(-3, 3, (n, 1)), [], 1e-6),
    "length": (3, "wp.length(v3(x, i, 0))", lambda r, n: r.standard_normal((n, 3)),
               [(1e-6, 2e-6, -1e-6), (1e-150, 1e-150, 1e-150)], 1e-5),
    "length_sq": (3, "wp.length_sq(v3(x, i, 0))", lambda r, n: r.standard_normal((n, 3)), [], 1e-6),
    "normalize": (3, "wp.dot(wp.normalize(v3(x, i, 0)), wvec())",
                  lambda r, n: r.standard_normal((n, 3)), [(1e-5, -2e-5, 3e-5)], 1e-4),
    "dot": (6, "wp.dot(v3(x, i, 0), v3(x, i, 3))", lambda r, n: r.standard_normal((n, 6)), [], 1e-6),
    "cross": (6, "wp.dot(wp.cross(v3(x, i, 0), v3(x, i, 3)), wvec())",
              lambda r, n: r.standard_normal((n, 6)), [], 1e-6),
    "determinant": (9, "wp.determinant(m3(x, i))",
                    lambda r, n: r.standard_normal((n, 9)),
                    [(1, 2, 3, 2, 4, 6.000001, 0, 1, 1)], 1e-5),
    "inverse": (9, "wp.ddot(wp.inverse(m3(x, i)), wp.outer(wvec(), wvec()))",
                lambda r, n: (r.standard_normal((n, 3, 3)) + 3 * np.eye(3)).reshape(n, 9),
                [(1, 2, 3, 2, 4, 6.001, 0, 1, 1)], 1e-4),
    "quat_rotate": (7, "wp.dot(wp.quat_rotate(q4(x, i, 0), v3(x, i, 4)), wvec())",
                    lambda r, n: r.standard_normal((n, 7)), [], 1e-5),
    "quat_slerp": (8, "wp.dot(wp.quat_slerp(q4(x, i, 0), q4(x, i, 4), " + F + "(0.3)), "
                      "wp.quatd(" + F + "(0.1), " + F + "(0.2), " + F + "(-0.3), " + F + "(0.4)))",
                   lambda r, n: r.standard_normal((n, 8)),
                   [(0.1, 0.2, 0.3, 0.9, 0.1, 0.2, 0.3, 0.9000001)], 1e-3),
    "transform_point": (10, "wp.dot(wp.transform_point(wp.transformation(v3(x, i, 0), q4(x, i, 3)), "
                            "v3(x, i, 7)), wvec())",
                        lambda r, n: r.standard_normal((n, 10)), [], 1e-5),
}


def _source():
    parts = [HELPERS]
    for name, (k, expr, _s, _h, _t) in CASES.items():
        parts.append(f'''
@wp.kernel
def grad_{name}(x: wp.array2d(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] = {expr}
''')
    return "".join(parts)


@pytest.fixture(scope="module")
def grad_kernels(tmp_path_factory):
    path = tmp_path_factory.mktemp("grad") / "weft_grad_builtin_kernels.py"
    path.write_text(_source())
    spec = importlib.util.spec_from_file_location("weft_grad_builtin_kernels", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["weft_grad_builtin_kernels"] = module
    spec.loader.exec_module(module)
    return module


def _forward(wp, kernel, x):
    y = wp.zeros(len(x), dtype=wp.float64)
    wp.launch(kernel, dim=len(x), inputs=[wp.array(x, dtype=wp.float64)], outputs=[y])
    return y.numpy()


def _finite_difference(wp, kernel, x):
    """Central differences with one Richardson step: (4 D(h/2) - D(h)) / 3, error O(h^4).
    h is relative (1e-7 |x|, at least 1e-7) and, for components near 0, a fraction of the
    component, so no step crosses a singularity (sqrt at 1e-12, asin at 0.999999)."""
    grads = np.zeros_like(x)
    for c in range(x.shape[1]):
        ax = np.abs(x[:, c])
        h = np.where(ax >= 1e-3, 1e-7 * np.maximum(ax, 1.0), np.where(ax > 0, 1e-3 * ax, 1e-8))

        def central(step):
            xp, xm = x.copy(), x.copy()
            xp[:, c] += step
            xm[:, c] -= step
            return (_forward(wp, kernel, xp) - _forward(wp, kernel, xm)) / (2 * step)

        grads[:, c] = (4 * central(h / 2) - central(h)) / 3
    return grads


def _tape_gradient(wp, kernel, x):
    xa = wp.array(x, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(len(x), dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(kernel, dim=len(x), inputs=[xa], outputs=[y])
    tape.backward(grads={y: np.ones(len(x))})
    return xa.grad.numpy()


@pytest.mark.parametrize("name", sorted(CASES))
def test_gradient_matches_finite_differences(wp, rng, grad_kernels, name):
    k, _expr, sampler, hard, rtol = CASES[name]
    x = sampler(rng, 64).astype(np.float64)
    if hard:
        x = np.concatenate([x, np.array(hard, dtype=np.float64).reshape(-1, k)])
    kernel = getattr(grad_kernels, f"grad_{name}")
    got = _tape_gradient(wp, kernel, x)
    ref = _finite_difference(wp, kernel, x)
    scale = np.maximum(np.abs(ref), 1.0)
    rel = np.abs(got - ref) / scale
    worst = float(np.nanmax(rel)) if rel.size else 0.0
    print(f"\ngradcheck {name:16s} worst relative error {worst:.2e} (tolerance {rtol:.0e})")
    assert np.all(np.isfinite(got)), f"{name}: non-finite gradients {got[~np.isfinite(got)]}"
    np.testing.assert_allclose(got, ref, rtol=rtol, atol=rtol, err_msg=f"gradient of {name}")


def test_abs_subgradient_at_zero_is_one(wp, grad_kernels):
    # Warp's convention: d|x|/dx at 0 is +1 (documented subgradient)
    got = _tape_gradient(wp, grad_kernels.grad_abs, np.array([[0.0], [-0.0], [2.0], [-2.0]]))
    np.testing.assert_array_equal(got[:, 0], [1.0, 1.0, 1.0, -1.0])


def test_pow_with_negative_base(wp, grad_kernels):
    # integer exponents of negative bases: d/dx x^n = n x^(n-1) is defined and finite
    x = np.array([[-2.0, 2.0], [-1.5, 3.0], [-0.5, 4.0]])
    got = _tape_gradient(wp, grad_kernels.grad_pow, x)
    np.testing.assert_allclose(got[:, 0], x[:, 1] * x[:, 0] ** (x[:, 1] - 1), rtol=1e-12)


def test_zero_vector_gradients_are_finite(wp, grad_kernels):
    zero = np.zeros((1, 3))
    for name in ("length", "normalize"):
        got = _tape_gradient(wp, getattr(grad_kernels, f"grad_{name}"), zero)
        assert np.all(np.isfinite(got)), f"{name} at the zero vector: {got}"


def test_long_atomic_add_reduction(wp, rng):
    n = 100_000
    x = rng.standard_normal(n)
    xa = wp.array(x, dtype=wp.float64, requires_grad=True)
    total = wp.zeros(1, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(sum_squares, dim=n, inputs=[xa, total])
    tape.backward(loss=total)
    np.testing.assert_allclose(total.numpy()[0], (x * x).sum(), rtol=1e-10)
    np.testing.assert_allclose(xa.grad.numpy(), 2 * x, rtol=1e-14)


@wp.kernel
def sum_squares(x: wp.array(dtype=wp.float64), total: wp.array(dtype=wp.float64)):
    i = wp.tid()
    wp.atomic_add(total, 0, x[i] * x[i])
