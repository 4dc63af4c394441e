"""Launch overhead of an empty kernel on the CPU: weft batched (N launches, one sync),
weft synchronous (launch + sync each time: one round trip), and warp-lang (N launches + sync).
"client CPU" is this process's CPU time per launch (all its threads): on a loaded machine it is
steadier than wall time, which includes waiting for a core.
Error column: the empty kernel writes nothing, so the check is that a counter kernel launched
N times in the same way counts exactly N. Ratio = warp time / weft time."""
from __future__ import annotations

import time

import numpy as np

import bench_common as bc

SOURCE = '''
@wp.kernel
def empty_kernel(a: wp.array(dtype=float)):
    pass

@wp.kernel
def count(c: wp.array(dtype=int)):
    wp.atomic_add(c, 0, 1)
'''
N = 2000


def weft_overhead():
    import weft as wp

    wp.init()
    mod = bc.load_kernels(SOURCE, "weft", "launch")
    a = wp.zeros(1, dtype=float, device="cpu")
    wp.launch(mod.empty_kernel, dim=1, inputs=[a])
    wp.synchronize()

    def batched():
        for _ in range(N):
            wp.launch(mod.empty_kernel, dim=1, inputs=[a])
        wp.synchronize()

    def synchronous():
        for _ in range(200):
            wp.launch(mod.empty_kernel, dim=1, inputs=[a])
            wp.synchronize()

    batched_s = bc.median_time(batched, repeat=3) / N
    cpu0 = time.process_time()
    batched()
    batched_cpu_s = (time.process_time() - cpu0) / N
    sync_s = bc.median_time(synchronous, repeat=3) / 200
    cpu0 = time.process_time()
    synchronous()
    sync_cpu_s = (time.process_time() - cpu0) / 200
    c = wp.zeros(1, dtype=int, device="cpu")
    for _ in range(N):
        wp.launch(mod.count, dim=1, inputs=[c])
    counted = int(c.numpy()[0])
    return batched_s, sync_s, counted, batched_cpu_s, sync_cpu_s


def warp_overhead():
    warp = bc.import_warp()
    if warp is None:
        return None, None, None
    mod = bc.load_kernels(SOURCE, "warp", "launch")
    a = warp.zeros(1, dtype=float, device="cpu")
    warp.launch(mod.empty_kernel, dim=1, inputs=[a], device="cpu")
    warp.synchronize()

    def batched():
        for _ in range(N):
            warp.launch(mod.empty_kernel, dim=1, inputs=[a], device="cpu")
        warp.synchronize()

    batched_s = bc.median_time(batched, repeat=3) / N
    cpu0 = time.process_time()
    batched()
    batched_cpu_s = (time.process_time() - cpu0) / N
    c = warp.zeros(1, dtype=int, device="cpu")
    for _ in range(N):
        warp.launch(mod.count, dim=1, inputs=[c], device="cpu")
    return batched_s, int(c.numpy()[0]), batched_cpu_s


def main():
    batched_s, sync_s, counted, batched_cpu_s, sync_cpu_s = weft_overhead()
    warp_s, warp_counted, warp_cpu_s = warp_overhead()
    rows = [["weft batched (N launches, 1 sync)", bc.fmt_time(batched_s),
             bc.fmt_time(batched_cpu_s), f"{1 / batched_s:,.0f}/s", f"{counted - N:+d}",
             bc.fmt_time(warp_s), bc.fmt_time(warp_cpu_s), bc.fmt_ratio(batched_s, warp_s)],
            ["weft launch + sync each", bc.fmt_time(sync_s), bc.fmt_time(sync_cpu_s),
             f"{1 / sync_s:,.0f}/s", "", bc.fmt_time(warp_s), bc.fmt_time(warp_cpu_s),
             bc.fmt_ratio(sync_s, warp_s)]]
    if warp_counted is not None and warp_counted != N:
        print(f"(warp counted {warp_counted} of {N})")
    bc.print_table(f"empty-kernel launch overhead, CPU, N={N}",
                   ["mode", "per launch", "client CPU", "launches", "count error",
                    "warp-lang per launch", "warp CPU", "ratio warp/weft"], rows)


if __name__ == "__main__":
    main()
    del np, time
