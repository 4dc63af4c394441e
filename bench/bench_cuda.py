"""weft on a GPU next to warp-lang on the same GPU in the same run.

Rows (each for weft and Warp, same kernel source):
- empty launch, batched (N launches, one sync) and with a sync after each;
- 3-argument launch (three arrays), batched and with a sync each;
- saxpy (y = a*x + y) and particle integration (x += v*dt, v += g*dt on vec3) at 1e6, 1e7,
  1e8 elements: time per launch (R launches, one sync), the rate in GB/s of bytes the kernel
  must move, that rate in % of the device-to-device copy rate (Torch's `copy_` of a 1e8-float
  array when Torch is there, else Warp's wp.copy), and the kernel-time ratio (Warp time / weft
  time: >= 1.0 means weft is as fast or faster); "saxpy lean" is the same saxpy declared
  @wp.kernel(grid_stride=False) in both libraries (one index per thread, no loop);
- cold compile (a kernel never seen: compile + load + first launch + sync);
- warm module load from a second client process (the module compiled by the first one:
  weft's daemon holds it; Warp's comes from its kernel cache on disk);
- error: the max relative error of saxpy and integration results (first 1e6 elements) against
  a float64 reference computed from the same inputs.
The table is printed last. Usage: python3 bench/bench_cuda.py [--sizes 1e6,1e7,1e8]
[--daemon-args=--device-hosts]
(WEFT_DAEMON: the weftd to start; warp-lang imported from PYTHONPATH, e.g. /tmp/wp).
"""
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
def empty_kernel():
    pass

@wp.kernel
def three_args(a: wp.array(dtype=float), b: wp.array(dtype=float), c: wp.array(dtype=float)):
    pass

@wp.kernel
def init_random(x: wp.array(dtype=float), seed: int, scale: float):
    i = wp.tid()
    state = wp.rand_init(seed, i)
    x[i] = (wp.randf(state) - 0.5) * scale

@wp.kernel
def init_vec3(x: wp.array(dtype=wp.vec3), seed: int, scale: float):
    i = wp.tid()
    state = wp.rand_init(seed, i)
    x[i] = wp.vec3(wp.randf(state) - 0.5, wp.randf(state) - 0.5, wp.randf(state) - 0.5) * scale

@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]

@wp.kernel(grid_stride=False)
def saxpy_lean(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]

@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), g: wp.vec3, dt: float):
    i = wp.tid()
    vi = v[i] + g * dt
    v[i] = vi
    x[i] = x[i] + vi * dt
'''

COLD_SOURCE = '''
@wp.kernel
def cold_{tag}(x: wp.array(dtype=float), s: float):
    i = wp.tid()
    x[i] = wp.sin(x[i]) * s + float({salt})
'''

WARM_CHILD = '''
import os, sys, time
sys.path.insert(0, {client!r})
lib = {lib!r}
if lib == "warp":
    import warp as wp
    wp.config.kernel_cache_dir = {cache!r}
    wp.config.quiet = True
    wp.init()
else:
    import weft as wp
import importlib.util
spec = importlib.util.spec_from_file_location("warm_mod_" + lib, {path!r})
mod = importlib.util.module_from_spec(spec)
spec.loader.exec_module(mod)
x = wp.zeros(1024, dtype=float, device="cuda:0")
wp.synchronize()
t = time.perf_counter()
wp.launch(mod.warm_kernel, dim=1024, inputs=[x, 2.0], device="cuda:0")
wp.synchronize()
print("WARM", time.perf_counter() - t)
'''

WARM_SOURCE = '''
@wp.kernel
def warm_kernel(x: wp.array(dtype=float), s: float):
    i = wp.tid()
    x[i] = wp.cos(x[i]) * s + 0.25
'''


def timed(lib, fn, reps: int) -> float:
    lib.synchronize()
    t = time.perf_counter()
    for _ in range(reps):
        fn()
    lib.synchronize()
    return (time.perf_counter() - t) / reps


def best_of(lib, fn, reps: int, rounds: int = 3) -> float:
    return min(timed(lib, fn, reps) for _ in range(rounds))


def launch_rows(lib, mod, n_launch: int):
    dev = "cuda:0"
    a = lib.zeros(1, dtype=float, device=dev)
    b = lib.zeros(1, dtype=float, device=dev)
    c = lib.zeros(1, dtype=float, device=dev)
    lib.launch(mod.empty_kernel, dim=1, inputs=[], device=dev)
    lib.launch(mod.three_args, dim=1, inputs=[a, b, c], device=dev)
    lib.synchronize()

    def empty():
        lib.launch(mod.empty_kernel, dim=1, inputs=[], device=dev)

    def empty_sync():
        lib.launch(mod.empty_kernel, dim=1, inputs=[], device=dev)
        lib.synchronize()

    def three():
        lib.launch(mod.three_args, dim=1, inputs=[a, b, c], device=dev)

    def three_sync():
        lib.launch(mod.three_args, dim=1, inputs=[a, b, c], device=dev)
        lib.synchronize()

    return {
        "empty launch, batched": best_of(lib, empty, n_launch),
        "empty launch, sync each": best_of(lib, empty_sync, n_launch // 4),
        "3-arg launch, batched": best_of(lib, three, n_launch),
        "3-arg launch, sync each": best_of(lib, three_sync, n_launch // 4),
    }


def reps_for(n: int) -> int:
    """Launches per timed round at size n: about 2 GB of saxpy traffic, 5 to 200."""
    return max(5, min(200, int(2e9 // (n * 12))))


def saxpy_inputs(lib, mod, n: int, dev: str = "cuda:0", alpha: float = 1.7):
    """(x, y, x0, y0, err): random x and y of n floats made on the device, one saxpy
    y = alpha x + y run on them, the first min(n, 1e6) inputs in float64 and the max relative
    error of that saxpy against them."""
    x = lib.empty(n, dtype=float, device=dev)
    y = lib.empty(n, dtype=float, device=dev)
    lib.launch(mod.init_random, dim=n, inputs=[x, 1, 4.0], device=dev)
    lib.launch(mod.init_random, dim=n, inputs=[y, 2, 4.0], device=dev)
    m = min(n, 1_000_000)
    x0 = x[:m].numpy().astype(np.float64)
    y0 = y[:m].numpy().astype(np.float64)
    lib.launch(mod.saxpy, dim=n, inputs=[x, y, alpha], device=dev)
    ref = alpha * x0 + y0
    got = y[:m].numpy().astype(np.float64)
    err = float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1e-3)))
    return x, y, x0, y0, err


def kernel_rows(lib, mod, sizes):
    """{(name, n): (seconds per launch, max rel error vs float64 of the first 1e6)}"""
    dev = "cuda:0"
    out = {}
    for n in sizes:
        alpha = 1.7
        x, y, x0, y0, err = saxpy_inputs(lib, mod, n, dev, alpha)
        m = len(x0)
        ref = alpha * x0 + y0
        reps = reps_for(n)
        t = best_of(lib, lambda: lib.launch(mod.saxpy, dim=n, inputs=[x, y, alpha],
                                            device=dev), reps)
        out[("saxpy", n)] = (t, err)
        # the same with the lean entry (@wp.kernel(grid_stride=False), both libraries)
        lib.launch(mod.init_random, dim=n, inputs=[y, 2, 4.0], device=dev)
        lib.launch(mod.saxpy_lean, dim=n, inputs=[x, y, alpha], device=dev)
        got = y[:m].numpy().astype(np.float64)
        lerr = float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), 1e-3)))
        t = best_of(lib, lambda: lib.launch(mod.saxpy_lean, dim=n, inputs=[x, y, alpha],
                                            device=dev), reps)
        out[("saxpy lean", n)] = (t, lerr)
        del x, y
        px = lib.empty(n, dtype=lib.vec3, device=dev)
        pv = lib.empty(n, dtype=lib.vec3, device=dev)
        lib.launch(mod.init_vec3, dim=n, inputs=[px, 3, 10.0], device=dev)
        lib.launch(mod.init_vec3, dim=n, inputs=[pv, 4, 2.0], device=dev)
        g = lib.vec3(0.0, -9.8, 0.0)
        dt = 1.0 / 60.0
        px0 = px[:m].numpy().astype(np.float64)
        pv0 = pv[:m].numpy().astype(np.float64)
        lib.launch(mod.integrate, dim=n, inputs=[px, pv, g, dt], device=dev)
        v_ref = pv0 + np.array([0.0, -9.8, 0.0]) * np.float64(np.float32(dt))
        x_ref = px0 + v_ref * np.float64(np.float32(dt))
        gx = px[:m].numpy().astype(np.float64)
        ierr = float(np.max(np.abs(gx - x_ref) / np.maximum(np.abs(x_ref), 1e-3)))
        t = best_of(lib, lambda: lib.launch(mod.integrate, dim=n, inputs=[px, pv, g, dt],
                                            device=dev), reps)
        out[("integrate", n)] = (t, ierr)
        del px, pv
        lib.synchronize()
    return out


def cold_compile(lib, tag: str) -> float:
    salt = int.from_bytes(os.urandom(3), "little")
    mod = bc.load_kernels(COLD_SOURCE.format(tag=tag, salt=salt), lib.__name__, f"cold_{tag}")
    x = lib.zeros(1024, dtype=float, device="cuda:0")
    lib.synchronize()
    t = time.perf_counter()
    lib.launch(getattr(mod, f"cold_{tag}"), dim=1024, inputs=[x, 1.5], device="cuda:0")
    lib.synchronize()
    return time.perf_counter() - t


def warm_second_client(lib, libname: str, warp_cache: str | None) -> float | None:
    """Compiles warm_kernel here, then times the first launch of the same module (same file)
    in a second client process."""
    workdir = Path(tempfile.mkdtemp(prefix=f"bench-warm-{libname}-"))
    path = workdir / f"warm_{libname}.py"
    path.write_text(f"import {'warp' if libname == 'warp' else 'weft'} as wp\n" + WARM_SOURCE)
    import importlib.util  # noqa: PLC0415

    spec = importlib.util.spec_from_file_location(f"warm_mod_{libname}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    x = lib.zeros(1024, dtype=float, device="cuda:0")
    lib.launch(mod.warm_kernel, dim=1024, inputs=[x, 2.0], device="cuda:0")
    lib.synchronize()
    code = WARM_CHILD.format(client=str(HERE.parent / "clients" / "python"), lib=libname,
                             cache=warp_cache or "", path=str(path))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    for line in proc.stdout.splitlines():
        if line.startswith("WARM "):
            return float(line.split()[1])
    print(f"({libname} warm child failed: {proc.returncode} {proc.stderr[-800:]})")
    return None


TRANSFER_CHILD = '''
import sys, time, numpy as np
sys.path.insert(0, {client!r})
import weft as wp
from weft import _cuda_ipc
n = 10_000_000
host = np.random.default_rng(5).random(n, dtype=np.float32)
a = wp.empty(n, dtype=float, device="cuda:0")
path = "ipc" if a.ptr is not None else "copy (" + (_cuda_ipc.reason() or "no IPC") + ")"
best_r = best_w = 1e9
for _ in range(3):
    t = time.perf_counter(); a.assign(host); wp.synchronize(); best_w = min(best_w, time.perf_counter() - t)
    t = time.perf_counter(); back = a.numpy(); best_r = min(best_r, time.perf_counter() - t)
assert np.array_equal(back, host)
print("XFER", path, best_w, best_r)
'''


def transfers():
    """{path: (write s, read s)} of 40 MB host<->GPU in a child client, IPC on and off."""
    out = {}
    for env_value in ("1", "0"):
        code = TRANSFER_CHILD.format(client=str(HERE.parent / "clients" / "python"))
        env = dict(os.environ, WEFT_CUDA_IPC=env_value)
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=300, env=env)
        for line in proc.stdout.splitlines():
            if line.startswith("XFER "):
                parts = line.split()
                out[" ".join(parts[1:-2])] = (float(parts[-2]), float(parts[-1]))
        if proc.returncode:
            print(f"(transfer child failed: {proc.stderr[-600:]})")
    return out


def copy_rate(warp) -> tuple:
    """(bytes/s of a device-to-device copy of 1e8 floats, what measured it)."""
    n = 100_000_000
    try:
        import torch  # noqa: PLC0415

        if torch.cuda.is_available():
            src = torch.rand(n, device="cuda")
            dst = torch.empty_like(src)
            dst.copy_(src)
            torch.cuda.synchronize()
            best = None
            for _ in range(3):
                t = time.perf_counter()
                for _ in range(10):
                    dst.copy_(src)
                torch.cuda.synchronize()
                dt = (time.perf_counter() - t) / 10
                best = dt if best is None else min(best, dt)
            del src, dst
            torch.cuda.empty_cache()
            return 2 * 4 * n / best, "torch copy_"
    except ImportError:
        pass
    if warp is not None:
        src = warp.zeros(n, dtype=float, device="cuda:0")
        dst = warp.zeros(n, dtype=float, device="cuda:0")
        t = best_of(warp, lambda: warp.copy(dst, src), 10)
        return 2 * 4 * n / t, "warp copy"
    return None, "n/a"


def weft_coarsened_launches():
    """Stats.gpu_coarsened_launches of the bench's weftd (None when it has no such field)."""
    from weft import _runtime  # noqa: PLC0415
    from weft.v1 import session_pb2  # noqa: PLC0415

    rt = _runtime.get_runtime()
    stats = rt.call(rt.session_stub.Stats, session_pb2.StatsRequest())
    return stats.gpu_coarsened_launches if hasattr(stats, "gpu_coarsened_launches") else None


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--sizes", default="1e6,1e7,1e8")
    parser.add_argument("--launches", type=int, default=2000)
    parser.add_argument("--daemon-args", default="",
                        help="more weftd flags, space separated (e.g. --device-hosts: the sessions "
                             "then run in the process of their device)")
    args = parser.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]

    daemon = bc.BenchDaemon(extra_args=tuple(args.daemon_args.split()))
    os.environ["WEFT_ADDRESS"] = daemon.address
    results = {}
    notes = []
    xfer = {}
    try:
        import weft  # noqa: PLC0415
        from weft import _cuda_ipc  # noqa: PLC0415

        weft.init()
        if not weft.is_cuda_available():
            raise SystemExit("weftd has no CUDA device: nothing to compare")
        probe = weft.zeros(1, device="cuda:0")
        from weft import _runtime  # noqa: PLC0415

        rt = _runtime.get_runtime()
        if rt.host_device:
            notes.append(f"weft sessions run in the device host of {rt.host_device} "
                         f"(weftd {args.daemon_args.strip()}; pid {rt.daemon_pid})")
        notes.append("weft client CUDA IPC: " + ("on" if probe.ptr is not None else
                                                 f"off ({_cuda_ipc.reason()})"))
        warp = None
        warp_cache = tempfile.mkdtemp(prefix="warp-cache-")
        os.environ["WEFT_BENCH_WARP_CACHE"] = warp_cache
        try:
            import warp  # noqa: PLC0415

            warp.config.kernel_cache_dir = warp_cache
            warp.config.quiet = True
            warp.init()
            notes.append(f"warp-lang {warp.config.version}")
        except Exception as err:  # noqa: BLE001
            warp = None
            notes.append(f"warp-lang not available: {err}")
        libs = [("weft", weft)] + ([("warp", warp)] if warp is not None else [])
        rate, rate_src = copy_rate(warp)
        notes.append(f"device-to-device copy rate: "
                     f"{rate / 1e9:.0f} GB/s ({rate_src})" if rate else "copy rate: n/a")
        for name, lib in libs:
            results[name] = {}
            steps = [("cold", lambda: {"cold": cold_compile(lib, name)}),
                     ("launch", lambda: launch_rows(lib, mod, args.launches)),
                     ("kernels", lambda: {"kernels": kernel_rows(lib, mod, sizes)}),
                     ("warm", lambda: {"warm": warm_second_client(lib, name, warp_cache)})]
            mod = bc.load_kernels(SOURCE, lib.__name__, "cuda")
            for step, fn in steps:
                try:
                    results[name].update(fn())
                except Exception as err:  # noqa: BLE001 - the table shows n/a, the note why
                    notes.append(f"{name} {step} failed: {type(err).__name__}: "
                                 f"{str(err)[:300]}")
                    try:
                        lib.synchronize()
                    except Exception:  # noqa: BLE001
                        pass
            print(f"{name}: done", flush=True)
        coarsened = weft_coarsened_launches()
        if coarsened is not None:
            notes.append(f"weft launches that ran a coarsened entry (docs/cuda.md, \"Coarsened "
                         f"launches\"): {coarsened}")
        try:
            xfer = transfers()
        except Exception as err:  # noqa: BLE001
            xfer = {}
            notes.append(f"transfers failed: {err}")
    finally:
        daemon.stop()

    weft_r = results.get("weft", {})
    warp_r = results.get("warp", {})
    rows = []
    for key in ("empty launch, batched", "empty launch, sync each", "3-arg launch, batched",
                "3-arg launch, sync each"):
        a, b = weft_r.get(key), warp_r.get(key)
        rows.append([key, bc.fmt_time(a), bc.fmt_time(b), bc.fmt_ratio(a, b), "", "", "", ""])
    bytes_per = {"saxpy": 12, "saxpy lean": 12, "integrate": 48}
    for (kname, n), (t, err) in sorted(weft_r.get("kernels", {}).items()):
        wt = warp_r.get("kernels", {}).get((kname, n))
        gbs = bytes_per[kname] * n / t
        wgbs = bytes_per[kname] * n / wt[0] if wt else None
        pct = f"{100 * gbs / rate:.0f}%" if rate else "n/a"
        wpct = f"{100 * wgbs / rate:.0f}%" if rate and wgbs else "n/a"
        rows.append([f"{kname} {n:.0e}", bc.fmt_time(t), bc.fmt_time(wt[0] if wt else None),
                     bc.fmt_ratio(t, wt[0] if wt else None), f"{gbs / 1e9:.0f} GB/s {pct}",
                     f"{wgbs / 1e9:.0f} GB/s {wpct}" if wgbs else "n/a", f"{err:.1e}",
                     f"{wt[1]:.1e}" if wt else "n/a"])
    for key, label in (("cold", "cold compile+load+launch"), ("warm", "warm load, 2nd client")):
        a, b = weft_r.get(key), warp_r.get(key)
        rows.append([label, bc.fmt_time(a), bc.fmt_time(b), bc.fmt_ratio(a, b), "", "", "", ""])
    for path, (w, r) in xfer.items():
        rows.append([f"40 MB assign / numpy(), {path}", f"{bc.fmt_time(w)} / {bc.fmt_time(r)}",
                     "", "", f"{0.04 / w:.1f} / {0.04 / r:.1f} GB/s", "", "", ""])
    for note in notes:
        print(note)
    bc.print_table("weft vs warp-lang on cuda:0 (ratio = Warp time / weft time; >= 1.0: weft "
                   "as fast or faster)",
                   ["case", "weft", "warp", "ratio", "weft rate (% of copy)",
                    "warp rate (% of copy)", "weft err", "warp err"], rows)


if __name__ == "__main__":
    main()
