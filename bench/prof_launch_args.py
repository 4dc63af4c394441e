"""Where a launch + synchronize goes by argument kind, on cuda:0: an empty kernel, one array,
three arrays, three scalars (1-element arrays, dim=1). Per case and round: the median launch +
synchronize over 2000 iterations, split into the launch call and the synchronize call, how many
launches went out at once (Runtime.eager_sends), and the time per launch of 2000 batched
launches. Run with WEFT_LANE_EAGER=0 for the same without the launch sent at once.

Usage: python3 bench/prof_launch_args.py (WEFT_DAEMON / WEFT_ADDRESS: the weftd)."""
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "clients" / "python"))
import bench_common as bc  # noqa: E402
import weft as wp  # noqa: E402
from prof_launch_sync import SOURCE  # noqa: E402  (the empty and 3-array kernels)
from weft import _runtime  # noqa: E402

mod = bc.load_kernels(SOURCE + '''
@wp.kernel
def one_arg(a: wp.array(dtype=float)):
    pass

@wp.kernel
def three_scalars(a: float, b: float, c: float):
    pass
''', "weft", "prof_args")
empty_kernel, three_args, one_arg, three_scalars = mod.empty_kernel, mod.three_args, mod.one_arg, mod.three_scalars

dev = "cuda:0"
a = wp.zeros(1, dtype=float, device=dev); b = wp.zeros(1, dtype=float, device=dev); c = wp.zeros(1, dtype=float, device=dev)
cases = {"empty": (empty_kernel, []), "1 array": (one_arg, [a]), "3 arrays": (three_args, [a, b, c]),
         "3 scalars": (three_scalars, [1.0, 2.0, 3.0])}
rt = _runtime.get_runtime()
for rnd in range(2):
    for name, (k, inputs) in cases.items():
        wp.launch(k, dim=1, inputs=inputs, device=dev); wp.synchronize()
        tot, lc, sc = [], [], []
        e0 = rt.eager_sends
        for i in range(2000):
            t = time.perf_counter()
            wp.launch(k, dim=1, inputs=inputs, device=dev)
            t1 = time.perf_counter()
            wp.synchronize()
            t2 = time.perf_counter()
            tot.append(t2 - t); lc.append(t1 - t); sc.append(t2 - t1)
        bt = time.perf_counter()
        for i in range(2000):
            wp.launch(k, dim=1, inputs=inputs, device=dev)
        wp.synchronize()
        batched = (time.perf_counter() - bt) / 2000
        print(f"round {rnd} {name:10s} sync-each {statistics.median(tot)*1e6:6.1f} us (launch {statistics.median(lc)*1e6:5.1f}, sync {statistics.median(sc)*1e6:5.1f}) eager {rt.eager_sends - e0} batched {batched*1e6:5.1f} us")
