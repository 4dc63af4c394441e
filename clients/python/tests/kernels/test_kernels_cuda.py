"""Kernels on cuda:0 (skipped with the reason when the daemon computes on no GPU): saxpy and a
vec3 integration step against float64 references on random data, Warp's block_dim/max_blocks
launch options, out-of-bounds errors reported at the next sync exactly as on the CPU (kernel,
array, index, shape, file:line), tape backward on the GPU, and fault containment: a kernel
that faults (an illegal address with bounds checks off under --allow-unchecked) runs in its
session's own process (a session host), gives that session a clear error ("these arrays are
lost"), and the client's next call works on the GPU again in a new session; another session
on the same GPU, in the daemon itself, never sees the fault. The test prints the time from the
error to the first good result on the GPU."""
import inspect

import numpy as np
import pytest

import weft as wp


@wp.kernel
def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel(grid_stride=False)
def saxpy_lean(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), g: wp.vec3, dt: float):
    i = wp.tid()
    vi = v[i] + g * dt
    v[i] = vi
    x[i] = x[i] + vi * dt


@wp.kernel
def oob(data: wp.array(dtype=float), n: int):
    i = wp.tid()
    data[i + n] = 7.0


@wp.kernel
def square_sum(x: wp.array(dtype=float), loss: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(loss, 0, x[i] * x[i])


@pytest.fixture
def gpu(wp):
    if not wp.is_cuda_available():
        pytest.skip("weftd has no CUDA device")
    dev = wp.get_cuda_device(0)
    if not dev.is_compute_supported:
        pytest.skip("weftd lists cuda:0 but cannot compute on it")
    return dev.alias


def test_saxpy_matches_float64(wp, gpu, rng):
    n = 100_003
    x0 = rng.standard_normal(n).astype(np.float32)
    y0 = rng.standard_normal(n).astype(np.float32)
    x = wp.array(x0, dtype=float, device=gpu)
    y = wp.array(y0, dtype=float, device=gpu)
    wp.launch(saxpy, dim=n, inputs=[1.5, x, y], device=gpu)
    ref = 1.5 * x0.astype(np.float64) + y0
    np.testing.assert_allclose(y.numpy(), ref, rtol=1e-6, atol=1e-6)


def test_integrate_vec3_matches_float64(wp, gpu, rng):
    n = 4097
    x0 = rng.standard_normal((n, 3)).astype(np.float32)
    v0 = rng.standard_normal((n, 3)).astype(np.float32)
    x = wp.array(x0, dtype=wp.vec3, device=gpu)
    v = wp.array(v0, dtype=wp.vec3, device=gpu)
    wp.launch(integrate, dim=n, inputs=[x, v, wp.vec3(0.0, -9.8, 0.0), 0.01], device=gpu)
    dt = np.float64(np.float32(0.01))
    vr = v0 + np.array([0.0, -9.8, 0.0]) * dt
    np.testing.assert_allclose(v.numpy(), vr, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(x.numpy(), x0 + vr * dt, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("block_dim,max_blocks", [(32, 0), (1024, 0), (64, 3), (256, 1)])
def test_block_dim_and_max_blocks(wp, gpu, rng, block_dim, max_blocks):
    n = 10_007
    x0 = rng.standard_normal(n).astype(np.float32)
    x = wp.array(x0, dtype=float, device=gpu)
    y = wp.zeros(n, dtype=float, device=gpu)
    wp.launch(saxpy, dim=n, inputs=[2.0, x, y], device=gpu, block_dim=block_dim, max_blocks=max_blocks)
    np.testing.assert_allclose(y.numpy(), 2.0 * x0.astype(np.float64), rtol=1e-6)


def test_max_blocks_forward_and_adjoint_stride_over_every_index(wp, gpu, rng):
    """A default kernel's GPU entries run one index per thread; a launch capped by max_blocks
    runs the module's grid-stride variant (built on first use), forward and, from a tape,
    adjoint, and reaches every index: values and gradients against float64."""
    n = 5_003
    x0 = rng.standard_normal(n).astype(np.float32) * np.float32(1e3)
    y0 = rng.standard_normal(n).astype(np.float32) * np.float32(1e-3)
    g0 = rng.standard_normal(n).astype(np.float32)
    x = wp.array(x0, dtype=float, device=gpu, requires_grad=True)
    y = wp.array(y0, dtype=float, device=gpu, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(saxpy, dim=n, inputs=[-1.5, x, y], device=gpu, max_blocks=2, block_dim=64)
    np.testing.assert_allclose(y.numpy(), -1.5 * x0.astype(np.float64) + y0, rtol=1e-6, atol=1e-9)
    tape.backward(grads={y: wp.array(g0, dtype=float, device=gpu)})
    np.testing.assert_allclose(x.grad.numpy(), -1.5 * g0.astype(np.float64), rtol=1e-6)
    # the same kernel without a cap, right after: the lean entry, still every index
    z = wp.zeros(n, dtype=float, device=gpu)
    wp.launch(saxpy, dim=n, inputs=[2.0, x, z], device=gpu)
    np.testing.assert_allclose(z.numpy(), 2.0 * x0.astype(np.float64), rtol=1e-6)


@pytest.mark.parametrize("n,block_dim", [(1, 256), (100_003, 256), (65_537, 32), (1 << 20, 1024)])
def test_lean_kernels_cover_every_index(wp, gpu, rng, n, block_dim):
    """grid_stride=False: one index per thread; the runtime's grid covers the launch exactly."""
    x0 = rng.standard_normal(n).astype(np.float32) * np.float32(1e20)
    y0 = rng.standard_normal(n).astype(np.float32) * np.float32(1e-20)
    x = wp.array(x0, dtype=float, device=gpu)
    y = wp.array(y0, dtype=float, device=gpu)
    wp.launch(saxpy_lean, dim=n, inputs=[-0.5, x, y], device=gpu, block_dim=block_dim)
    ref = -0.5 * x0.astype(np.float64) + y0.astype(np.float64)
    np.testing.assert_allclose(y.numpy(), ref, rtol=1e-6)


def test_lean_kernels_refuse_max_blocks(wp, gpu, monkeypatch):
    x = wp.zeros(1000, dtype=float, device=gpu)
    with pytest.raises(RuntimeError, match=r"max_blocks=4, but it was compiled without a grid-stride loop"):
        wp.launch(saxpy_lean, dim=1000, inputs=[1.0, x, x], device=gpu, max_blocks=4)
    with pytest.raises(RuntimeError, match=r"max_blocks=4, but it was compiled without a grid-stride loop"):
        wp.launch(saxpy_lean, dim=1000, inputs=[1.0, x, x], device=gpu, max_blocks=4, record_cmd=True)
    # a client that skips its own check is refused by the daemon (at the next sync)
    import weft._kernel.module as module_mod

    monkeypatch.setattr(module_mod, "grid_stride_of", lambda kernel: True)
    with pytest.raises(RuntimeError, match=r"kernel 'saxpy_lean' was launched with max_blocks=4, but it was "
                                           r"compiled without a grid-stride loop"):
        wp.launch(saxpy_lean, dim=1000, inputs=[1.0, x, x], device=gpu, max_blocks=4)
        wp.synchronize_device(gpu)
    monkeypatch.undo()
    # the session goes on
    wp.launch(saxpy_lean, dim=1000, inputs=[1.0, x, x], device=gpu)
    wp.synchronize_device(gpu)


def test_out_of_bounds_is_reported_like_the_cpu(wp, gpu):
    messages = {}
    for device in ("cpu", gpu):
        data = wp.zeros(8, dtype=float, device=device)
        wp.launch(oob, dim=8, inputs=[data, 4], device=device)
        with pytest.raises(wp.WeftError) as info:
            wp.synchronize()
        messages[device] = str(info.value)
    lines, start = inspect.getsourcelines(oob.func)
    line = start + next(k for k, t in enumerate(lines) if "data[i + n]" in t)
    for text in messages.values():
        assert f"test_kernels_cuda.py:{line}" in text and "kernel 'oob'" in text, text
        assert "array 'data' of shape (8,)" in text, text
    # the same words on both devices, bar the thread that hit it first
    assert messages["cpu"].split("index")[0] == messages[gpu].split("index")[0]
    # the session goes on
    z = wp.zeros(4, dtype=float, device=gpu)
    wp.launch(saxpy, dim=4, inputs=[1.0, wp.full(4, 2.0, dtype=float, device=gpu), z], device=gpu)
    np.testing.assert_array_equal(z.numpy(), 2.0)


def test_tid_indexed_arrays_shorter_than_the_launch_stay_checked(wp, gpu, rng):
    """A launch whose x[i] and y[i] (i = wp.tid()) arrays all cover it runs the kernel's
    trusted-index variant (those checks proven, docs/cuda.md): the same results as float64,
    views included. An array one element short of the launch, a strided view as long as the
    launch, and a short array passed as the loss of a backward pass keep their checks: the
    access past the end is reported as ever, on the same line."""
    n = 100_003
    x0 = rng.standard_normal(n).astype(np.float32)
    y0 = rng.standard_normal(n + 7).astype(np.float32)
    x = wp.array(x0, dtype=float, device=gpu)
    for variant, name in ((saxpy, "saxpy"), (saxpy_lean, "saxpy_lean")):
        y = wp.array(y0, dtype=float, device=gpu)
        wp.launch(variant, dim=n, inputs=[1.5, x, y], device=gpu)
        want = y0.astype(np.float64)
        want[:n] += 1.5 * x0.astype(np.float64)
        np.testing.assert_allclose(y.numpy(), want, rtol=2e-7, atol=1e-6)
        # a view that covers the launch exactly: in range
        yv = wp.array(y0, dtype=float, device=gpu)[7:]
        wp.launch(variant, dim=n, inputs=[1.5, x, yv], device=gpu)
        np.testing.assert_allclose(yv.numpy(), y0[7:].astype(np.float64) + 1.5 * x0, rtol=2e-7, atol=1e-6)
        # one element short: the check stays, and reports the first index past the end
        short = wp.array(y0[: n - 1], dtype=float, device=gpu)
        wp.launch(variant, dim=n, inputs=[1.5, x, short], device=gpu)
        with pytest.raises(wp.WeftError) as info:
            wp.synchronize()
        text = str(info.value)
        assert f"kernel '{name}'" in text and f"of shape ({n - 1},)" in text, text
        assert f"index [{n - 1}]" in text, text
        # a strided view of n // 2 + 1 elements under a launch of n threads: checked as well
        strided = wp.array(y0, dtype=float, device=gpu)[::2]
        wp.launch(variant, dim=n, inputs=[1.5, x, strided], device=gpu)
        with pytest.raises(wp.WeftError):
            wp.synchronize()
    # the session goes on
    z = wp.zeros(4, dtype=float, device=gpu)
    wp.launch(saxpy, dim=4, inputs=[1.0, wp.full(4, 2.0, dtype=float, device=gpu), z], device=gpu)
    np.testing.assert_array_equal(z.numpy(), 2.0)


def test_tape_backward_on_gpu(wp, gpu, rng):
    x0 = rng.standard_normal(1000).astype(np.float32)
    x = wp.array(x0, dtype=float, device=gpu, requires_grad=True)
    loss = wp.zeros(1, dtype=float, device=gpu, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square_sum, dim=1000, inputs=[x, loss], device=gpu)
    tape.backward(loss=loss)
    np.testing.assert_allclose(loss.numpy()[0], np.sum(x0.astype(np.float64) ** 2), rtol=1e-4)
    np.testing.assert_allclose(x.grad.numpy(), 2.0 * x0.astype(np.float64), rtol=1e-6)
    tape.zero()
    np.testing.assert_array_equal(x.grad.numpy(), 0.0)


FAULT_VICTIM = '''
import os, sys, time
import numpy as np
import weft as wp

@wp.kernel
def add_one(a: wp.array(dtype=float)):
    a[wp.tid()] = a[wp.tid()] + 1.0

wp.init()
keep = wp.array(np.arange(16, dtype=np.float32), dtype=float, device="cuda:0")
wp.launch(add_one, dim=16, inputs=[keep], device="cuda:0")
wp.synchronize()
open(sys.argv[1], "w").write("ready")
while not os.path.exists(sys.argv[2]):
    time.sleep(0.05)
try:
    wp.launch(add_one, dim=16, inputs=[keep], device="cuda:0")
    wp.synchronize()
    print("VICTIM no error")
except Exception as exc:
    print("VICTIM error:", exc)
try:
    fresh = wp.array(np.arange(16, dtype=np.float32), dtype=float, device="cuda:0")
    wp.launch(add_one, dim=16, inputs=[fresh], device="cuda:0")
    print("VICTIM after:", np.array_equal(fresh.numpy(), np.arange(16) + 1))
except Exception as exc:
    print("VICTIM refused:", exc)
'''

FAULTER = '''
import time
import numpy as np
import weft as wp
import weft._runtime as runtime

wp.set_module_options({"bounds_checks": False})

@wp.kernel
def wild(a: wp.array(dtype=float), n: int):
    i = wp.tid()
    a[i * n] = 1.0

@wp.kernel
def add_one(a: wp.array(dtype=float)):
    a[wp.tid()] = a[wp.tid()] + 1.0

wp.init()
first = runtime.get_runtime()
print("FAULTER hosted:", first.hosted)
a = wp.zeros(16, dtype=float, device="cuda:0")
t = time.perf_counter()
try:
    wp.launch(wild, dim=1024, inputs=[a, 1 << 28], device="cuda:0")
    wp.synchronize()
    print("FAULTER no error")
except Exception as exc:
    print("FAULTER error:", exc)
t_error = time.perf_counter()
print(f"FAULTER error after {1e3 * (t_error - t):.1f} ms")
try:
    b = wp.array(np.arange(8, dtype=np.float32), dtype=float, device="cuda:0")
    wp.launch(add_one, dim=8, inputs=[b], device="cuda:0")
    print("FAULTER gpu after:", np.array_equal(b.numpy(), np.arange(8) + 1),
          "new session:", runtime.get_runtime() is not first)
    print(f"FAULTER recovered in {1e3 * (time.perf_counter() - t_error):.1f} ms")
except Exception as exc:
    print("FAULTER gpu refused:", exc)
c = wp.array(np.ones(8, dtype=np.float32), dtype=float, device="cpu")
print("FAULTER cpu after:", np.array_equal(c.numpy(), np.ones(8)))
'''


def test_faulting_kernel_costs_only_its_own_session(wp, gpu, start_weftd, run_script, tmp_path):
    import subprocess
    import sys
    import time

    daemon = start_weftd(["--allow-unchecked"])
    ready, go = tmp_path / "ready", tmp_path / "go"
    victim_path = tmp_path / "victim.py"
    victim_path.write_text(FAULT_VICTIM)
    env = dict(__import__("os").environ)
    env["WEFT_ADDRESS"] = daemon.address
    env["PYTHONPATH"] = __import__("os").path.dirname(__import__("os").path.dirname(wp.__file__))
    victim = subprocess.Popen([sys.executable, str(victim_path), str(ready), str(go)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        for _ in range(600):
            if ready.exists() or victim.poll() is not None:
                break
            time.sleep(0.05)
        assert ready.exists(), victim.communicate(timeout=5)[0]
        out = run_script(FAULTER, env={"WEFT_ADDRESS": daemon.address}).stdout
        go.write_text("go")
        victim_out = victim.communicate(timeout=60)[0]
    finally:
        if victim.poll() is None:
            victim.kill()
    print(out)
    print(victim_out)
    # The unchecked session ran in a session host: the fault cost that process only.
    assert "FAULTER hosted: True" in out, out
    assert "FAULTER error:" in out and "these arrays are lost" in out, out
    assert "FAULTER gpu after: True" in out, out
    assert "FAULTER cpu after: True" in out, out
    # The checked session on the same GPU, in the daemon itself, never saw it.
    assert "VICTIM no error" in victim_out and "VICTIM after: True" in victim_out, victim_out
    stats = daemon.stats()
    assert stats.gpu_resets == 0 and stats.session_hosts_started_total >= 1
    recovered = [line for line in out.splitlines() if line.startswith("FAULTER recovered in")]
    print(f"cuda:0 usable again for the faulting client: {recovered}; the daemon's GPU untouched")
    # the daemon still serves: a new client works on the CPU and on the GPU
    check = run_script('''
import numpy as np
import weft as wp
wp.init()
a = wp.array(np.arange(4, dtype=np.float32), dtype=float, device="cpu")
print("NEW cpu:", np.array_equal(a.numpy(), np.arange(4)), "cuda:0 computes:", wp.get_cuda_device(0).is_compute_supported)
''', env={"WEFT_ADDRESS": daemon.address}).stdout
    assert "NEW cpu: True" in check, check
    assert "cuda:0 computes: True" in check, check


@wp.kernel
def visit_once(x: wp.array(dtype=float), seen: wp.array(dtype=int), tids: wp.array(dtype=int),
               count: wp.array(dtype=int)):
    i = wp.tid()
    if wp.abs(x[i]) >= 0.0:
        wp.atomic_add(seen, i, 1)
    tids[i] = i
    wp.atomic_add(count, 0, 1)


@wp.kernel
def horner(x: wp.array(dtype=float), out: wp.array(dtype=float), k: int):
    i = wp.tid()
    v = x[i]
    acc = float(0.0)
    for j in range(k):
        acc = acc * v + float(j + 1)
    if v < 0.0:
        acc = -acc
    out[i] = acc


@wp.kernel
def gather_add(x: wp.array(dtype=float), idx: wp.array(dtype=int), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = x[i] + x[idx[i]]


@wp.kernel
def double_first(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = 2.0 * x[i]


def _coarsened(weftd) -> int:
    return weftd.stats().gpu_coarsened_launches


def test_coarsened_launches_run_every_logical_thread_once(wp, gpu, weftd, rng):
    """A large 1-D launch proven in range runs the kernel's coarsened entry (several logical
    threads per GPU thread, the later ones' loads prefetched; docs/cuda.md "Coarsened
    launches"), counted in Stats.gpu_coarsened_launches. Every logical thread runs exactly once
    with its own wp.tid(), the tail of a size that is no multiple of the factor included; saxpy
    on magnitudes from 1e-30 to 1e30 and a loop with a branch match float64; an access that
    fails its check in a coarsened launch is reported as ever (kernel, index, shape, line)."""
    n = (1 << 23) + 3
    before = _coarsened(weftd)
    x0 = (rng.standard_normal(n) * 10.0 ** rng.uniform(-30, 30, n)).astype(np.float32)
    x = wp.array(x0, dtype=float, device=gpu)
    seen = wp.zeros(n, dtype=int, device=gpu)
    tids = wp.full(n, -1, dtype=int, device=gpu)
    count = wp.zeros(1, dtype=int, device=gpu)
    wp.launch(visit_once, dim=n, inputs=[x, seen, tids, count], device=gpu)
    assert count.numpy()[0] == n
    np.testing.assert_array_equal(seen.numpy(), 1)
    np.testing.assert_array_equal(tids.numpy(), np.arange(n))

    y0 = (rng.standard_normal(n) * 10.0 ** rng.uniform(-30, 30, n)).astype(np.float32)
    y = wp.array(y0, dtype=float, device=gpu)
    wp.launch(saxpy_lean, dim=n, inputs=[0.75, x, y], device=gpu)
    ref = 0.75 * x0.astype(np.float64) + y0.astype(np.float64)
    got = y.numpy().astype(np.float64)
    # float32 rounding of a*x and of the sum: within 2 ulp of the larger operand
    scale = np.maximum(np.abs(0.75 * x0.astype(np.float64)), np.abs(y0.astype(np.float64)))
    assert np.all(np.abs(got - ref) <= 2.5e-7 * scale + 1e-37)

    u0 = rng.uniform(-1.5, 1.5, n).astype(np.float32)
    u = wp.array(u0, dtype=float, device=gpu)
    out = wp.zeros(n, dtype=float, device=gpu)
    wp.launch(horner, dim=n, inputs=[u, out, 6], device=gpu)
    v = u0.astype(np.float64)
    acc = np.zeros(n)
    for j in range(6):
        acc = acc * v + (j + 1)
    acc = np.where(v < 0.0, -acc, acc)
    np.testing.assert_allclose(out.numpy(), acc, rtol=2e-5, atol=2e-5)
    after = _coarsened(weftd)
    assert after - before >= 3, (before, after)

    # a gather whose index is out of range in the last quarter of the launch
    idx0 = rng.integers(0, n, n).astype(np.int32)
    idx0[n - 2] = n + 10
    idx = wp.array(idx0, dtype=int, device=gpu)
    wp.launch(gather_add, dim=n, inputs=[x, idx, out], device=gpu)
    lines, start = inspect.getsourcelines(gather_add.func)
    line = start + next(k for k, t in enumerate(lines) if "x[idx[i]]" in t)
    with pytest.raises(wp.WeftError) as info:
        wp.synchronize()
    text = str(info.value)
    assert "kernel 'gather_add'" in text and f"index [{n + 10}]" in text and f"of shape ({n},)" in text, text
    assert f"test_kernels_cuda.py:{line}" in text, text
    assert _coarsened(weftd) > after
    # the session goes on
    wp.launch(visit_once, dim=n, inputs=[x, seen, tids, count], device=gpu)
    assert count.numpy()[0] == 2 * n


def test_small_and_2d_launches_are_not_coarsened(wp, gpu, weftd, rng):
    """Below the threshold (the coarsened grid would not fill the GPU twice) and for a launch of
    two dimensions of a kernel that has a coarsened entry (1-D arrays of as many elements as the
    launch has threads, loaded at i = wp.tid(), the launch's first coordinate), the plain entry
    runs: the counter does not move, results match."""
    x0 = rng.standard_normal(1 << 16).astype(np.float32)
    y0 = rng.standard_normal(1 << 16).astype(np.float32)
    before = _coarsened(weftd)
    x = wp.array(x0, dtype=float, device=gpu)
    y = wp.array(y0, dtype=float, device=gpu)
    wp.launch(saxpy_lean, dim=x0.size, inputs=[2.0, x, y], device=gpu)
    np.testing.assert_allclose(y.numpy(), 2.0 * x0.astype(np.float64) + y0, rtol=1e-6, atol=1e-6)
    rows, cols = 4000, 1000                     # 4e6 threads: past the threshold of any GPU here
    a0 = rng.standard_normal(rows * cols).astype(np.float32)
    b0 = rng.standard_normal(rows * cols).astype(np.float32)
    a = wp.array(a0, dtype=float, device=gpu)
    b = wp.array(b0, dtype=float, device=gpu)
    wp.launch(double_first, dim=(rows, cols), inputs=[a, b], device=gpu)
    want = b0.copy()
    want[:rows] = 2.0 * a0[:rows]               # i runs over the first coordinate only
    np.testing.assert_array_equal(b.numpy(), want)
    assert _coarsened(weftd) == before
    # the same kernel launched 1-D over as many threads does take it (so the above could fail)
    wp.launch(double_first, dim=rows * cols, inputs=[a, b], device=gpu)
    np.testing.assert_array_equal(b.numpy(), 2.0 * a0)
    assert _coarsened(weftd) == before + 1


@wp.kernel
def bump_then_add(v: wp.array(dtype=wp.vec3), x: wp.array(dtype=wp.vec3), g: wp.vec3, dt: float):
    i = wp.tid()
    vi = v[i] + g * dt
    v[i] = vi
    x[i] = x[i] + vi * dt      # loaded after v's store: the trusted entry prefetches x[i]


@pytest.mark.parametrize("alias", [False, True])
def test_loads_after_a_store_prefetched_keep_program_order(wp, gpu, rng, alias):
    """The trusted entry of a kernel that loads x[i] after storing v[i] prefetches x[i] first
    (docs/cuda.md, "Loads after a store"): a hint, so results are those of program order even
    when x and v are the same array (the load then sees the store), on magnitudes from 1e-30 to
    1e30, for a 1-D launch not a multiple of the block and for a 2-D one (no prefetch there).
    Bit-exact against the same float32 operations in NumPy (no FMA contraction without
    fast_math), and within 2 ulps of the operands against float64."""
    n = 1_000_003
    mags = 10.0 ** rng.uniform(-30, 30, (n, 3))
    v0 = (rng.standard_normal((n, 3)) * mags).astype(np.float32)
    x0 = (rng.standard_normal((n, 3)) * mags[::-1]).astype(np.float32)
    g = np.array([1e-3, -9.8, 2.5e4], dtype=np.float32)
    dt = np.float32(1.0 / 64.0)

    def expected(v_in, x_in):
        vi = v_in + g * dt                              # float32, as the kernel
        xi = (vi if alias else x_in) + vi * dt
        return vi, xi

    def check(got_v, got_x, v_in, x_in):
        vi, xi = expected(v_in, x_in)
        if not alias:
            np.testing.assert_array_equal(got_v, vi)
        np.testing.assert_array_equal(got_x, xi)
        v64 = v_in.astype(np.float64) + g.astype(np.float64) * np.float64(dt)
        base = v64 if alias else x_in.astype(np.float64)
        x64 = base + v64 * np.float64(dt)
        eps = np.finfo(np.float32).eps
        bound = 2 * eps * (np.abs(base) + np.abs(v64 * np.float64(dt)) + np.abs(g * dt)) + 1e-44
        assert np.all(np.abs(got_x - x64) <= bound)

    v = wp.array(v0, dtype=wp.vec3, device=gpu)
    x = v if alias else wp.array(x0, dtype=wp.vec3, device=gpu)
    wp.launch(bump_then_add, dim=n, inputs=[v, x, wp.vec3(*g), float(dt)], device=gpu)
    check(v.numpy(), x.numpy(), v0, x0)
    # a 2-D launch, (rows, 1): i = wp.tid() is the first coordinate, rows past it untouched
    rows = 100_001
    v2 = wp.array(v0, dtype=wp.vec3, device=gpu)
    x2 = v2 if alias else wp.array(x0, dtype=wp.vec3, device=gpu)
    wp.launch(bump_then_add, dim=(rows, 1), inputs=[v2, x2, wp.vec3(*g), float(dt)], device=gpu)
    got_v, got_x = v2.numpy(), x2.numpy()
    check(got_v[:rows], got_x[:rows], v0[:rows], x0[:rows])
    np.testing.assert_array_equal(got_v[rows:], v0[rows:])
    if not alias:
        np.testing.assert_array_equal(got_x[rows:], x0[rows:])
