"""Cold and warm module compile time: weft (daemon compile with an empty cache entry = cold;
the same module from a client with an empty process cache = warm, a daemon memory-cache hit;
the daemon's own compile_ms and cache_hit flags are shown) against warp-lang on the CPU (cold:
empty kernel cache dir; warm: the module reloaded from Warp's disk cache).
Ratio = warp time / weft time (higher is better for weft)."""
from __future__ import annotations

import time
import uuid

import bench_common as bc

SOURCE = '''
SALT = {salt}

@wp.func
def smooth(x: float):
    return x * x * (3.0 - 2.0 * x)

@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i] + float(SALT) * 0.0

@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), f: wp.array(dtype=wp.vec3),
              w: wp.array(dtype=float), gravity: wp.vec3, dt: float):
    tid = wp.tid()
    v1 = v[tid] + (f[tid] * w[tid] + gravity) * dt
    x[tid] = x[tid] + v1 * dt
    v[tid] = v1

@wp.kernel
def shade(img: wp.array2d(dtype=float), t: float):
    i, j = wp.tid()
    u = float(i) / 64.0
    v = float(j) / 64.0
    s = wp.sin(u * 6.0 + t) * wp.cos(v * 4.0 - t)
    img[i, j] = smooth(wp.clamp(s * 0.5 + 0.5, 0.0, 1.0))
'''


def weft_times():
    import weft as wp
    from weft._kernel import module as module_mod

    wp.init()
    mod = bc.load_kernels(SOURCE.format(salt=uuid.uuid4().int % 1000000), "weft", "compile")
    t = time.perf_counter()
    cold = wp.load_module(mod, device="cpu")
    cold_s = time.perf_counter() - t
    # warm: forget what this process knows; the daemon's memory cache answers
    module_mod._compiled.clear()
    for k in module_mod.all_kernels(mod.__name__):
        k._compiled.clear()
    t = time.perf_counter()
    warm = wp.load_module(mod, device="cpu")
    warm_s = time.perf_counter() - t
    return cold_s, warm_s, cold, warm


def warp_times():
    warp = bc.import_warp()
    if warp is None:
        return None, None
    mod = bc.load_kernels(SOURCE.format(salt=uuid.uuid4().int % 1000000), "warp", "compile")
    t = time.perf_counter()
    warp.load_module(mod, device="cpu")
    cold_s = time.perf_counter() - t
    warp.get_module(mod.__name__).unload()
    t = time.perf_counter()
    warp.load_module(mod, device="cpu")
    warm_s = time.perf_counter() - t
    return cold_s, warm_s


def main():
    cold_s, warm_s, cold, warm = weft_times()
    warp_cold, warp_warm = warp_times()
    rows = [
        ["cold (compile)", bc.fmt_time(cold_s), f"{cold.compile_ms:.1f} ms", str(cold.cache_hit),
         bc.fmt_time(warp_cold), bc.fmt_ratio(cold_s, warp_cold)],
        ["warm (cache)", bc.fmt_time(warm_s), f"{warm.compile_ms:.1f} ms", str(warm.cache_hit),
         bc.fmt_time(warp_warm), bc.fmt_ratio(warm_s, warp_warm)],
    ]
    bc.print_table("module compile, 3 kernels + 1 func, CPU (client-observed wall time)",
                   ["case", "weft", "daemon compile_ms", "daemon cache_hit", "warp-lang",
                    "ratio warp/weft"], rows)


if __name__ == "__main__":
    main()
