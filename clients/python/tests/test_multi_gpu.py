"""Two GPUs or more (skipped with the reason otherwise): kernels on every GPU against a float64
reference, copies between GPUs bit-exact on random bit patterns (NaN payloads, subnormals,
infinities; contiguous and strided views, both directions), and a kernel fault on cuda:0
(bounds checks off under --allow-unchecked, so the session runs in a process of its own, a
session host) seen from a session working on cuda:1 in the daemon itself: cuda:1 is untouched
(its arrays and results kept), although the driver keeps such an error for every context of
the faulting process; the faulting client gets a clear error and its next session computes on
both GPUs; the CPU keeps serving."""
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import weft as wp

CLIENT_DIR = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


@wp.kernel
def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@pytest.fixture
def gpus(wp):
    names = [d.alias for d in wp.get_cuda_devices() if d.is_compute_supported]
    if len(names) < 2:
        pytest.skip(f"weftd computes on {len(names)} GPU(s); these tests need two")
    return names


@pytest.fixture
def rng():
    seed = int(os.environ.get("WEFT_TEST_SEED", "0")) or int.from_bytes(os.urandom(4), "little")
    print(f"WEFT_TEST_SEED={seed}")
    return np.random.default_rng(seed)


def test_saxpy_on_every_gpu(wp, gpus, rng):
    n = 300_007
    for gpu in gpus:
        x0 = rng.standard_normal(n).astype(np.float32) * np.float32(1e3)
        y0 = rng.standard_normal(n).astype(np.float32)
        x = wp.array(x0, dtype=float, device=gpu)
        y = wp.array(y0, dtype=float, device=gpu)
        wp.launch(saxpy, dim=n, inputs=[0.75, x, y], device=gpu)
        ref = 0.75 * x0.astype(np.float64) + y0
        # one float32 rounding of a*x and one of the sum: 2 float32 ulp of the larger term, per element
        bound = 2 * np.spacing(np.maximum(np.abs(ref), np.abs(0.75 * x0)).astype(np.float32)).astype(np.float64)
        err = np.abs(y.numpy().astype(np.float64) - ref)
        assert np.all(err <= bound), f"{gpu}: worst error {err.max()} at {err.argmax()}, bound there {bound[err.argmax()]}"


def _bits(rng, n):
    return rng.integers(0, 2**32, size=n, dtype=np.uint64).astype(np.uint32)


def test_copies_between_gpus_are_bit_exact(wp, gpus, rng):
    g0, g1 = gpus[0], gpus[1]
    n = (1 << 20) + 5
    a0, b0 = _bits(rng, n), _bits(rng, n)
    a = wp.array(a0, dtype=wp.uint32, device=g0)
    b = wp.array(b0, dtype=wp.uint32, device=g1)
    f = wp.array(a0.view(np.float32), dtype=float, device=g0)
    g = wp.empty(n, dtype=float, device=g1)

    wp.copy(g, f)  # floats with NaN payloads and subnormals: the bits, not the values
    assert np.array_equal(g.numpy().view(np.uint32), a0)

    wp.copy(b, a, dest_offset=7, src_offset=100, count=5000)
    expect = b0.copy()
    expect[7:5007] = a0[100:5100]
    assert np.array_equal(b.numpy(), expect)

    # strided source on one GPU, strided destination on the other
    k = 4000
    wp.copy(b[1:2 * k:2], a[0:3 * k:3])
    expect[1:2 * k:2] = a0[0:3 * k:3]
    assert np.array_equal(b.numpy(), expect)
    wp.copy(a[5:5 + 5 * k:5], b[0:k])
    a_expect = a0.copy()
    a_expect[5:5 + 5 * k:5] = expect[0:k]
    assert np.array_equal(a.numpy(), a_expect)


VICTIM = '''
import os, sys, time
import numpy as np
import weft as wp

@wp.kernel
def add_one(a: wp.array(dtype=float)):
    a[wp.tid()] = a[wp.tid()] + 1.0

wp.init()
data = np.random.default_rng(5).standard_normal(4096).astype(np.float32)
keep = wp.array(data, dtype=float, device="cuda:1")
wp.launch(add_one, dim=4096, inputs=[keep], device="cuda:1")
wp.synchronize()
open(sys.argv[1], "w").write("ready")
while not os.path.exists(sys.argv[2]):
    time.sleep(0.05)
try:
    wp.launch(add_one, dim=4096, inputs=[keep], device="cuda:1")
    print("VICTIM kept:", np.array_equal(keep.numpy(), data + np.float32(1) + np.float32(1)))
except Exception as exc:
    print("VICTIM error:", exc)
'''

FAULTER = '''
import numpy as np
import weft as wp

wp.set_module_options({"bounds_checks": False})

@wp.kernel
def wild(a: wp.array(dtype=float), n: int):
    i = wp.tid()
    a[i * n] = 1.0

wp.init()
a = wp.zeros(16, dtype=float, device="cuda:0")
try:
    wp.launch(wild, dim=1024, inputs=[a, 1 << 28], device="cuda:0")
    wp.synchronize()
    print("FAULTER no error")
except Exception as exc:
    print("FAULTER error:", exc)
try:
    b = wp.array(np.arange(8, dtype=np.float32), dtype=float, device="cuda:1")
    print("FAULTER cuda:1 after:", np.array_equal(b.numpy(), np.arange(8)))
except Exception as exc:
    print("FAULTER cuda:1 refused:", exc)
c = wp.array(np.arange(8, dtype=np.float32), dtype=float, device="cpu")
print("FAULTER cpu after:", np.array_equal(c.numpy(), np.arange(8)))
'''


def test_fault_on_one_gpu_leaves_the_other_untouched(wp, gpus, start_weftd, tmp_path):
    daemon = start_weftd(["--allow-unchecked"])
    env = dict(os.environ)
    env["WEFT_ADDRESS"] = daemon.address
    env["PYTHONPATH"] = os.pathsep.join([CLIENT_DIR] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    (tmp_path / "victim.py").write_text(VICTIM)
    (tmp_path / "faulter.py").write_text(FAULTER)
    ready, go = tmp_path / "ready", tmp_path / "go"
    victim = subprocess.Popen([sys.executable, str(tmp_path / "victim.py"), str(ready), str(go)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        for _ in range(1200):
            if ready.exists() or victim.poll() is not None:
                break
            time.sleep(0.05)
        assert ready.exists(), victim.communicate(timeout=5)[0]
        faulter = subprocess.run([sys.executable, str(tmp_path / "faulter.py")], env=env, capture_output=True,
                                 text=True, timeout=120)
        go.write_text("go")
        victim_out = victim.communicate(timeout=120)[0]
    finally:
        if victim.poll() is None:
            victim.kill()
    out = faulter.stdout + faulter.stderr
    print(out)
    print(victim_out)
    assert "FAULTER error:" in out and "these arrays are lost" in out, out
    assert "FAULTER cpu after: True" in out, out
    assert "FAULTER cuda:1 after: True" in out, out   # in the client's next session
    assert "VICTIM kept: True" in victim_out, victim_out
    assert daemon.stats().gpu_resets == 0
    print("cuda:1 was untouched by the fault on cuda:0 (the fault ended the faulting session's own process)")
