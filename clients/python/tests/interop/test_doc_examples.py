"""The examples of Warp's interoperability documentation, unchanged but for the import, run as
child clients (examples/): the Torch optimizations (wp.from_torch + Adam, wp.to_torch + Adam,
the Rosenbrock torch.autograd.Function with adjoint=True converging to (1, 1)) and jax_kernel
inside jax.jit; the short ones (saxpy with NumPy and Torch inputs) run inline. Each result is
checked against a float64 NumPy reference or the known optimum."""
import re

import numpy as np
import pytest

import weft as wp


@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


def test_saxpy_with_numpy_inputs(wp):
    n = 1000
    x = np.arange(n, dtype=np.float32)
    y = np.ones(n, dtype=np.float32)

    wp.launch(saxpy, dim=n, inputs=[x, y, 1.0], device="cpu")

    expected = np.arange(n, dtype=np.float64) * 1.0 + 1.0
    np.testing.assert_allclose(y, expected, rtol=1e-6)       # float32 arithmetic, exact ints


def test_saxpy_with_torch_inputs(wp, torch):
    n = 1000
    device = "cpu"
    x = torch.arange(n, dtype=torch.float32, device=device)
    y = torch.ones(n, dtype=torch.float32, device=device)

    wp.launch(saxpy, dim=n, inputs=[x, y, 1.0], device=device)

    expected = np.arange(n, dtype=np.float64) + 1.0
    np.testing.assert_allclose(y.numpy(), expected, rtol=1e-6)


def _losses(stdout):
    return [float(v) for v in re.findall(r"loss: ([-+0-9.eE]+)", stdout)]


@pytest.mark.parametrize("name", ["torch_from_torch_adam", "torch_to_torch_adam"])
def test_adam_optimization_examples(run_example, torch, name):
    losses = _losses(run_example(name))
    assert len(losses) == 500
    # sum of squares of 100 standard-normal 2-d points: ~200 at the start; Adam (lr 0.1)
    # drives every coordinate to 0 within 500 steps
    assert losses[0] > 10.0
    assert losses[-1] < 1e-2 * losses[0]
    assert losses[-1] < 0.5


# 10,000 Adam steps of the documented example, each two launches and a few round trips to the
# daemon (array creations, imports): minutes, past a suite's default per-test timeout.
@pytest.mark.timeout(900)
def test_rosenbrock_autograd_function_converges_to_1_1(run_example, torch):
    out = run_example("torch_rosenbrock", timeout=900)
    values = [float(v) for v in re.findall(r"[-+]?[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?",
                                           out.strip().splitlines()[-1])]
    assert len(values) == 2, out
    np.testing.assert_allclose(values, [1.0, 1.0], atol=0.05)


def test_jax_kernel_triple_example(run_example, jax):
    out = run_example("jax_kernel_triple").replace("float32", "")
    values = [float(v) for v in re.findall(r"[-+]?[0-9]+\.?[0-9]*", out)]
    np.testing.assert_allclose(values, 3.0 * np.arange(64, dtype=np.float64))


def test_jax_kernel_sincos_example(run_example, jax):
    out = run_example("jax_kernel_sincos").replace("float32", "")
    values = [float(v) for v in re.findall(r"[-+]?[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?", out)]
    assert len(values) == 64, out
    angles = np.linspace(0, 2 * np.pi, 32, dtype=np.float64)
    # float32 angles and sin/cos, printed by JAX with 8 significant digits
    np.testing.assert_allclose(values[:32], np.sin(angles), atol=2e-6)
    np.testing.assert_allclose(values[32:], np.cos(angles), atol=2e-6)
