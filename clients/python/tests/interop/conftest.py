"""Fixtures of the interop tests: fresh random data (seed printed; WEFT_TEST_SEED replays),
frameworks imported or the test skipped with the reason, and `run_example` which runs one of
the example programs in examples/ (Warp's interoperability documentation, unchanged but for the
import) in a child client on a given default device and returns its stdout."""
from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parent / "examples"


@pytest.fixture
def rng(request):
    seed = int(os.environ.get("WEFT_TEST_SEED", "0")) or int.from_bytes(os.urandom(4), "little")
    print(f"{request.node.nodeid}: WEFT_TEST_SEED={seed}")
    return np.random.default_rng(seed)


@pytest.fixture(autouse=True)
def _cpu_by_default(wp):
    with wp.ScopedDevice("cpu"):
        yield


@pytest.fixture
def torch():
    return pytest.importorskip("torch", reason="PyTorch is not installed")


@pytest.fixture
def tcuda(wp, cuda, torch):
    """"cuda:0" for tests of Torch GPU memory: Torch on CUDA and CUDA IPC usable by this client
    (else skipped with the reason). Files narrow it further by overriding it."""
    if not torch.cuda.is_available():
        pytest.skip("Torch has no CUDA device")
    from weft import _cuda_ipc

    if not _cuda_ipc.available():
        pytest.skip(f"CUDA IPC is not available in this client: {_cuda_ipc.reason()}")
    return cuda


@pytest.fixture
def tordered(tcuda):
    """tcuda, with launches on framework memory ordered on the GPU (stream memory operations
    or events; else skipped with the reason)."""
    from weft import _runtime
    from weft.interop import cuda_order

    if not cuda_order.enabled(_runtime.get_runtime(), {0}):
        pytest.skip(f"GPU ordering is off: {cuda_order.refused()}")
    return tcuda


@pytest.fixture
def jgpu(wp, cuda):
    """(jax, JAX's first CUDA device, weft's cuda:0) with that device JAX's default, or skipped
    with the reason (no JAX, no CUDA backend in JAX, no CUDA IPC in this client)."""
    jax = pytest.importorskip("jax", reason="JAX is not installed")
    try:
        gpus = jax.devices("gpu")
    except RuntimeError as err:
        pytest.skip(f"JAX has no CUDA device here ({err})")
    if not gpus:
        pytest.skip("JAX has no CUDA device here")
    from weft import _cuda_ipc

    if not _cuda_ipc.available():
        pytest.skip(f"CUDA IPC is not available in this client: {_cuda_ipc.reason()}")
    with jax.default_device(gpus[0]):
        yield jax, gpus[0], cuda


@pytest.fixture
def jax():
    """JAX with float64 enabled, its arrays placed on the CPU (these are the CPU paths, also
    on machines where JAX has a GPU)."""
    jax = pytest.importorskip("jax", reason="JAX is not installed")
    jax.config.update("jax_enable_x64", True)
    with jax.default_device(jax.devices("cpu")[0]):
        yield jax


@pytest.fixture
def paddle():
    """Paddle, or the test skipped with the reason: not installed, or installed but failing to
    import (a broken or incompatible install raises ImportError, which importorskip would let
    through as an error). Warnings of the import (Paddle warns that ccache is missing) are
    ignored, as importorskip ignores them."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import paddle  # noqa: PLC0415
    except ImportError as err:
        pytest.skip(f"Paddle is not importable ({type(err).__name__}: {err})")
    return paddle


@pytest.fixture
def cuda(wp):
    if not any(d.is_cuda and d.is_compute_supported for d in wp.get_cuda_devices()):
        pytest.skip("weftd has no CUDA device it can run kernels on")
    return wp.get_cuda_device(0)


@pytest.fixture
def run_example(weftd, client_env):
    """run_example(name, device="cpu", timeout=600) -> stdout of examples/<name>.py, run as
    __main__ in a child client whose default weft device is `device`."""

    def run(name: str, device: str = "cpu", timeout: float = 600) -> str:
        path = EXAMPLES / f"{name}.py"
        code = ("import runpy, weft\n"
                f"weft.set_device({device!r})\n"
                f"runpy.run_path({str(path)!r}, run_name='__main__')\n")
        env = {"JAX_PLATFORMS": "cpu"} if device == "cpu" else None
        proc = subprocess.run([sys.executable, "-c", code], env=client_env(env),
                              capture_output=True, text=True, timeout=timeout)
        assert proc.returncode == 0, (f"example {name} failed ({proc.returncode}):\n"
                                      f"stdout:\n{proc.stdout[-4000:]}\n"
                                      f"stderr:\n{proc.stderr[-4000:]}")
        return proc.stdout

    return run


@pytest.fixture
def descriptors_follow_the_tensor(wp, torch):
    """check(t, values, device): after a loop of from_torch(t, return_ctype=True), the
    descriptor remembered on tensor `t` (made from `values` on `device`) follows every change
    of the tensor: a gradient set on the remembered array and removed, a resize, a re-pointed
    storage, another dtype asked for, a gradient asked for."""
    def check(t, values, device):
        first = wp.from_torch(t, return_ctype=True)
        remembered = first._weft_value               # the conversion the later ones follow
        g = wp.zeros(len(values), dtype=float, device=device)
        remembered.grad = g                          # the descriptor must now carry it
        d = wp.from_torch(t, return_ctype=True)
        assert d.grad == g.ptr and d.data == t.data_ptr()
        remembered.grad = None
        assert wp.from_torch(t, return_ctype=True).grad == 0
        t.resize_(1000)
        d = wp.from_torch(t, return_ctype=True)
        assert d.shape[0] == 1000 and d.data == t.data_ptr()
        t.set_(torch.tensor(values[:7], device=device))
        d = wp.from_torch(t, return_ctype=True)
        assert d.shape[0] == 7 and d.data == t.data_ptr() and d.data != first.data
        u = torch.tensor(values.reshape(len(values) // 2, 2), device=device)
        wp.from_torch(u, return_ctype=True), wp.from_torch(u, return_ctype=True)
        d = wp.from_torch(u, dtype=wp.vec2, return_ctype=True)
        assert d.ndim == 1 and d.shape[0] == len(values) // 2
        t.requires_grad_(True)
        d = wp.from_torch(t, return_ctype=True)
        assert d.grad != 0 and d.grad == t.grad.data_ptr()

    return check
