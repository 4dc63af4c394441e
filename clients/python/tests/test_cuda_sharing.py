"""GPU arrays shared between client processes and with frameworks (skipped with the reason when
the daemon has no CUDA device it can run kernels on, or the framework is missing):
ipc_handle/from_ipc_handle of GPU arrays between two client processes, each seeing the other's
writes (kernels in the daemon, and direct writes through the CUDA IPC mapping when the client
has one); CuPy and Torch seeing a daemon array at the same device pointer, both ways."""
import textwrap

import numpy as np
import pytest


@pytest.fixture
def cuda(wp):
    if not any(d.is_cuda and d.is_compute_supported for d in wp.get_cuda_devices()):
        pytest.skip("weftd has no CUDA device it can run kernels on")
    return wp.get_cuda_device(0)


def _ipc_or_skip(a):
    from weft import _cuda_ipc

    if a.ptr is None:
        pytest.skip(f"CUDA IPC is not available in this client: {_cuda_ipc.reason()}")


CHILD = """
import sys, numpy as np, weft as wp

@wp.kernel
def add(x: wp.array(dtype=float), v: float):
    i = wp.tid()
    x[i] = x[i] + v

b = wp.from_ipc_handle(sys.stdin.readline().strip().encode())
print("device", b.device, "ptr", "ipc" if b.ptr is not None else "none", flush=True)
print("first", float(b.numpy()[0]), flush=True)
wp.launch(add, dim=b.shape[0], inputs=[b, 10.0], device=b.device)
wp.synchronize()
print("launched", flush=True)
sys.stdin.readline()                 # the parent wrote through its side
print("sum", repr(float(b.numpy().astype(np.float64).sum())), flush=True)
direct = b.ptr is not None
if direct:
    from weft import _cuda_ipc
    ones = np.ones(4, dtype=np.float32)
    _cuda_ipc.copy_from_host(b.device.ordinal, b.ptr, ones.ctypes.data, ones.nbytes)
else:
    b[:4].assign(np.ones(4, dtype=np.float32))
    wp.synchronize()
print("wrote", "direct" if direct else "daemon", flush=True)
sys.stdin.readline()
"""


def test_two_clients_share_a_gpu_array(wp, cuda, spawn_client, tmp_path):
    n = 4096
    rng = np.random.default_rng(31)
    values = rng.standard_normal(n).astype(np.float32)
    a = wp.array(values, device=cuda)
    token = a.ipc_handle().decode()
    path = tmp_path / "child.py"
    path.write_text(textwrap.dedent(CHILD))
    child = spawn_client(f"import runpy; runpy.run_path({str(path)!r}, run_name='__main__')")
    child.stdin.write(token + "\n")
    child.stdin.flush()
    lines = [child.stdout.readline().strip() for _ in range(3)]
    print(lines)
    assert lines[0].startswith("device cuda:0")
    assert lines[1] == f"first {float(values[0])}"
    assert lines[2] == "launched"
    # the child's kernel wrote the daemon's memory: seen here
    expected = values.astype(np.float64) + 10.0
    np.testing.assert_allclose(a.numpy(), expected, rtol=1e-6)
    # a write from this side (assign: through the IPC mapping when there is one)
    a[100:200].assign(np.full(100, -1.0, dtype=np.float32))
    wp.synchronize()
    expected[100:200] = -1.0
    child.stdin.write("go\n")
    child.stdin.flush()
    line = child.stdout.readline().strip()
    assert line.startswith("sum ")
    np.testing.assert_allclose(float(line.split()[1]), expected.astype(np.float32).sum(dtype=np.float64),
                               rtol=1e-5)
    wrote = child.stdout.readline().strip()
    print(wrote)
    assert wrote.startswith("wrote")
    expected[:4] = 1.0
    np.testing.assert_allclose(a.numpy(), expected, rtol=1e-6)
    child.stdin.write("done\n")
    child.stdin.flush()
    assert child.wait(timeout=60) == 0


def test_cupy_sees_the_same_device_pointer(wp, cuda):
    cp = pytest.importorskip("cupy", reason="CuPy is not installed")
    rng = np.random.default_rng(32)
    values = rng.standard_normal(1000).astype(np.float32)
    a = wp.array(values, device=cuda)
    _ipc_or_skip(a)
    c = cp.asarray(a)
    assert c.data.ptr == a.__cuda_array_interface__["data"][0] == a.ptr
    np.testing.assert_array_equal(cp.asnumpy(c), values)
    c *= 2.0                                  # CuPy writes the daemon's memory
    cp.cuda.Device(0).synchronize()
    np.testing.assert_array_equal(a.numpy(), values * 2.0)
    v = a[::2]
    cv = cp.asarray(v)
    assert cv.data.ptr == a.ptr and cv.strides == (8,)
    np.testing.assert_array_equal(cp.asnumpy(cv), values[::2] * 2.0)


def test_torch_sees_the_same_device_pointer(wp, cuda):
    torch = pytest.importorskip("torch", reason="PyTorch is not installed")
    if not torch.cuda.is_available():
        pytest.skip("Torch has no CUDA device")
    rng = np.random.default_rng(33)
    values = rng.standard_normal((50, 3)).astype(np.float32)
    a = wp.array(values, dtype=wp.vec3, device=cuda)
    _ipc_or_skip(a)
    t1 = torch.as_tensor(a, device="cuda")
    t2 = torch.from_dlpack(a)
    t3 = wp.to_torch(a)
    for t in (t1, t2, t3):
        assert t.data_ptr() == a.ptr and tuple(t.shape) == (50, 3)
    np.testing.assert_array_equal(t2.cpu().numpy(), values)
    t2.add_(1.0)
    torch.cuda.synchronize()
    np.testing.assert_array_equal(a.numpy(), values + 1.0)
    back = wp.from_torch(t2, dtype=wp.vec3)
    assert back.ptr == a.ptr


def test_ipc_off_falls_back_to_copies(wp, cuda, run_client):
    """Without CUDA IPC (WEFT_CUDA_IPC=0, as in a sandbox that refuses it) GPU arrays have no
    pointer, __cuda_array_interface__ or __dlpack__; cupy.asarray goes through __array__ and
    wp.to_torch copies (both correct)."""
    code = """
import numpy as np, weft as wp
a = wp.array(np.arange(10, dtype=np.float32), device="cuda:0")
assert a.ptr is None and not hasattr(a, "__cuda_array_interface__")
try:
    import cupy as cp
    c = cp.asarray(a)
    assert (cp.asnumpy(c) == np.arange(10)).all()
    print("cupy copy ok")
except ImportError:
    print("cupy missing")
try:
    import torch
    if torch.cuda.is_available():
        t = wp.to_torch(a)                 # a copy on Torch's cuda:0
        assert t.device.type == "cuda" and (t.cpu().numpy() == np.arange(10)).all()
    t2 = torch.as_tensor(np.asarray(a))    # Torch takes no __array__: through NumPy
    assert (t2.numpy() == np.arange(10)).all()
    print("torch copy ok")
except ImportError:
    print("torch missing")
"""
    out = run_client(code, env={"WEFT_CUDA_IPC": "0"}).stdout
    print(out)
    assert "copy ok" in out or "missing" in out
