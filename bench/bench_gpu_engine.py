"""GPU engine benchmark (cuda:0 of a daemon this script starts): device-to-device copy rate,
saxpy and particle integration at 1e8 elements (time per launch, effective bandwidth, % of the
copy rate, max error against a float64 reference on a sample), empty-kernel launch overhead
(batched and with a synchronize each), cold module compile+load and warm load from a second
client process, and after a faulting kernel (when the daemon allows unchecked kernels: this
script's session then runs in a session host) the time to the error and from the error to the
next result on the GPU, in the new session the client opens. warp-lang is not run here (its GPU build is not on the machine this
runs on); the reference column quotes Warp 1.19's numbers measured on the lent H100 (issue 9).
Usage: WEFT_DAEMON=build/bin/weftd python bench/bench_gpu_engine.py [--n 100000000]"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))

import bench_common as bc  # noqa: E402

SOURCE = '''
@wp.kernel
def saxpy(a: float, x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = a * x[i] + y[i]

@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), g: wp.vec3, dt: float):
    i = wp.tid()
    vi = v[i] + g * dt
    v[i] = vi
    x[i] = x[i] + vi * dt

@wp.kernel
def empty_kernel(a: wp.array(dtype=float)):
    pass

@wp.kernel
def copy_kernel(dst: wp.array(dtype=float), src: wp.array(dtype=float)):
    i = wp.tid()
    dst[i] = src[i]

@wp.kernel
def fault(a: wp.array(dtype=float), n: int):
    i = wp.tid()
    a[i * n] = 1.0
'''

WARM_CLIENT = '''
import importlib.util, sys, time
sys.path.insert(0, sys.argv[1])
import weft as wp
from weft._kernel import module as m
wp.init()
spec = importlib.util.spec_from_file_location("bench_gpu_kernels", sys.argv[2])
mod = importlib.util.module_from_spec(spec)
sys.modules["bench_gpu_kernels"] = mod
spec.loader.exec_module(mod)
t = time.perf_counter()
m.compile_kernel(mod.saxpy, "cuda:0")
print((time.perf_counter() - t) * 1e3)
'''


def load_file_module(path: Path):
    """The kernels of `path` as module bench_gpu_kernels (the same file and module name in
    every client: the same module for the daemon)."""
    import importlib.util  # noqa: PLC0415
    spec = importlib.util.spec_from_file_location("bench_gpu_kernels", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_gpu_kernels"] = mod
    spec.loader.exec_module(mod)
    return mod


def start_daemon(tmp: Path, unchecked: bool):
    sock = tmp / "w.sock"
    args = [os.environ.get("WEFT_DAEMON", str(HERE.parent / "build" / "bin" / "weftd")),
            "--listen", f"unix:{sock}", "--cache-dir", str(tmp / "cache")]
    if unchecked:   # the session runs unchecked, in a process of its own (a session host)
        args.append("--allow-unchecked")
        os.environ["WEFT_UNCHECKED"] = "1"
    log = open(tmp / "weftd.log", "w")
    proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT)
    for _ in range(300):
        if sock.exists():
            break
        time.sleep(0.05)
    os.environ["WEFT_ADDRESS"] = f"unix:{sock}"
    return proc


def timed(fn, n):
    fn()
    import weft as wp
    wp.synchronize()
    t = time.perf_counter()
    for _ in range(n):
        fn()
    wp.synchronize()
    return (time.perf_counter() - t) / n


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=100_000_000)
    ap.add_argument("--no-fault", action="store_true")
    opts = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="weft-gpu-bench-"))
    daemon = start_daemon(tmp, unchecked=not opts.no_fault)
    try:
        return run(opts, tmp)
    finally:
        daemon.terminate()
        daemon.wait(timeout=30)


def run(opts, tmp: Path) -> int:
    import weft as wp

    wp.init()
    os.environ.pop("WEFT_UNCHECKED", None)   # this session only: the warm-load client is checked
    if not wp.is_cuda_available() or not wp.get_cuda_device(0).is_compute_supported:
        print("bench_gpu_engine: the daemon has no GPU it computes on; nothing to measure")
        return 0
    dev = wp.get_cuda_device(0)
    print(f"device: {dev.name} ({dev.alias}, sm_{dev.arch})")
    src_path = tmp / "bench_gpu_kernels.py"
    src_path.write_text("import weft as wp\n" + SOURCE)
    rows = []

    # cold compile + load (fresh cache dir): the first compile of the module for cuda:0
    mod = load_file_module(src_path)
    from weft._kernel import module as m
    t = time.perf_counter()
    m.compile_kernel(mod.saxpy, "cuda:0")
    cold_ms = (time.perf_counter() - t) * 1e3
    # module load on the GPU happens at the first launch
    a1 = wp.zeros(1, dtype=float, device="cuda:0")
    t = time.perf_counter()
    wp.launch(mod.saxpy, dim=1, inputs=[1.0, a1, a1], device="cuda:0")
    wp.synchronize()
    first_launch_ms = (time.perf_counter() - t) * 1e3
    warm = subprocess.run([sys.executable, "-c", WARM_CLIENT, str(HERE.parent / "clients" / "python"),
                           str(src_path)], capture_output=True, text=True, env=dict(os.environ))
    try:
        warm_ms = float(warm.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        warm_ms = float("nan")
        print(warm.stdout, warm.stderr)
    rows.append(["cold compile (NVRTC) + cache", f"{cold_ms:.1f} ms", "750 ms", ""])
    rows.append(["first launch (module load) + sync", f"{first_launch_ms:.1f} ms", "", ""])
    rows.append(["warm load, second client", f"{warm_ms:.2f} ms", "137 ms", "target <= 5 ms"])

    # launch overhead
    e = wp.zeros(1, dtype=float, device="cuda:0")
    wp.launch(mod.empty_kernel, dim=1, inputs=[e], device="cuda:0")
    wp.synchronize()
    N = 2000

    def batched():
        for _ in range(N):
            wp.launch(mod.empty_kernel, dim=1, inputs=[e], device="cuda:0")
        wp.synchronize()

    def each():
        for _ in range(200):
            wp.launch(mod.empty_kernel, dim=1, inputs=[e], device="cuda:0")
            wp.synchronize()
    b = bc.median_time(batched, repeat=3) / N
    s = bc.median_time(each, repeat=3) / 200
    ecpu = wp.zeros(1, dtype=float, device="cpu")

    def each_cpu():
        for _ in range(200):
            wp.launch(mod.empty_kernel, dim=1, inputs=[ecpu], device="cpu")
            wp.synchronize()
    each_cpu()
    sc = bc.median_time(each_cpu, repeat=3) / 200
    rows.append(["empty launch, batched", bc.fmt_time(b), "16.9 us", ""])
    rows.append(["empty launch + synchronize", bc.fmt_time(s), "20.4 us",
                 f"the same on the cpu device: {bc.fmt_time(sc)} (the round trip)"])

    n = opts.n
    rng = np.random.default_rng(7)
    # device-to-device copy rate
    x = wp.array(rng.random(n, dtype=np.float32), dtype=float, device="cuda:0")
    y0 = rng.random(n, dtype=np.float32)
    y = wp.array(y0, dtype=float, device="cuda:0")
    c = wp.empty(n, dtype=float, device="cuda:0")
    tc = timed(lambda: wp.copy(c, x), 20)
    tk = timed(lambda: wp.launch(mod.copy_kernel, dim=n, inputs=[c, x], device="cuda:0"), 20)
    copy_rate = 2 * 4 * n / min(tc, tk)
    rows.append([f"d2d copy {n:.0e} float32 (wp.copy)", f"{tc * 1e3:.3f} ms", "", f"{2 * 4 * n / tc / 1e12:.2f} TB/s"])
    rows.append([f"d2d copy {n:.0e} float32 (kernel)", f"{tk * 1e3:.3f} ms", "2.9 TB/s",
                 f"{2 * 4 * n / tk / 1e12:.2f} TB/s; the faster of the two is the copy rate below"])

    # saxpy
    reps = 20
    ts = timed(lambda: wp.launch(mod.saxpy, dim=n, inputs=[2.0, x, y], device="cuda:0"), reps)
    bw = 3 * 4 * n / ts
    got = y.numpy()
    xs = x.numpy()
    idx = rng.integers(0, n, 100_000)
    ref = y0[idx].astype(np.float64)
    for _ in range(reps + 1):
        ref = 2.0 * xs[idx].astype(np.float64) + ref
    err = float(np.max(np.abs(got[idx] - ref) / np.maximum(1, np.abs(ref))))
    rows.append([f"saxpy {n:.0e}", f"{ts * 1e3:.3f} ms", "87% of copy",
                 f"{bw / 1e12:.2f} TB/s = {100 * bw / copy_rate:.0f}% of copy, rel err {err:.1e}"])
    if not opts.no_fault:   # the daemon allows unchecked kernels: the same without bounds checks
        umod = bc.load_kernels(SOURCE, "weft", "unchecked")
        wp.set_module_options({"bounds_checks": False}, module=umod)
        tu = timed(lambda: wp.launch(umod.saxpy, dim=n, inputs=[2.0, x, y], device="cuda:0"), reps)
        rows.append([f"saxpy {n:.0e}, bounds checks off", f"{tu * 1e3:.3f} ms", "",
                     f"{3 * 4 * n / tu / 1e12:.2f} TB/s = {100 * 3 * 4 * n / tu / copy_rate:.0f}% of copy"])

    # particle integration (vec3 position + velocity)
    m3 = n
    xp0 = rng.standard_normal((m3, 3)).astype(np.float32)
    vp0 = rng.standard_normal((m3, 3)).astype(np.float32)
    del x, y, c
    xp = wp.array(xp0, dtype=wp.vec3, device="cuda:0")
    vp = wp.array(vp0, dtype=wp.vec3, device="cuda:0")
    g = wp.vec3(0.0, -9.8, 0.0)
    steps = 10
    ti = timed(lambda: wp.launch(mod.integrate, dim=m3, inputs=[xp, vp, g, 0.001], device="cuda:0"), steps)
    bwi = 4 * 12 * m3 / ti
    sel = rng.integers(0, m3, 100_000)
    xr, vr = xp0[sel].astype(np.float64), vp0[sel].astype(np.float64)
    gr = np.array([0.0, -9.8, 0.0])
    for _ in range(steps + 1):
        vr = vr + gr * np.float64(np.float32(0.001))
        xr = xr + vr * np.float64(np.float32(0.001))
    erri = float(np.max(np.abs(xp.numpy()[sel] - xr)))
    rows.append([f"integrate {m3:.0e} vec3", f"{ti * 1e3:.3f} ms", "82% of copy",
                 f"{bwi / 1e12:.2f} TB/s = {100 * bwi / copy_rate:.0f}% of copy, abs err {erri:.1e}"])
    del xp, vp

    # fault recovery
    if not opts.no_fault:
        fmod = bc.load_kernels(SOURCE, "weft", "fault")
        wp.set_module_options({"bounds_checks": False}, module=fmod)
        fa = wp.zeros(16, dtype=float, device="cuda:0")
        t = time.perf_counter()
        err_text = ""
        try:
            wp.launch(fmod.fault, dim=1024, inputs=[fa, 1 << 28], device="cuda:0")
            wp.synchronize()
        except Exception as exc:  # noqa: BLE001
            err_text = str(exc)
        fault_ms = (time.perf_counter() - t) * 1e3
        t = time.perf_counter()
        ok_after = False
        after_text = ""
        try:
            z = wp.array(np.arange(8, dtype=np.float32), dtype=float, device="cuda:0")
            wp.launch(mod.saxpy, dim=8, inputs=[1.0, z, z], device="cuda:0")
            ok_after = bool(np.array_equal(z.numpy(), 2 * np.arange(8, dtype=np.float32)))
        except Exception as exc:  # noqa: BLE001
            after_text = str(exc)
        recover_ms = (time.perf_counter() - t) * 1e3
        print("fault error:", err_text)
        print("after the fault:", "cuda:0 works" if ok_after else after_text)
        rows.append(["fault -> error at sync", f"{fault_ms:.1f} ms", "",
                     "the session host ended; the daemon's own GPU context untouched"])
        rows.append(["error -> next GPU result (new session host)", f"{recover_ms:.1f} ms", "",
                     "array + launch + read back in a new session" if ok_after else f"refused: {after_text[:80]}"])
    bc.print_table("weft on " + dev.name + " (cuda:0); Warp 1.19 column: issue 9's H100 numbers",
                   ["what", "weft", "warp 1.19 (H100)", "notes"], rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
