"""What array bounds checks cost: the same kernels (saxpy, a 2D 5-point stencil, a gather with
random indices) compiled twice by one weftd started with --allow-unchecked, once as is and once
with wp.set_module_options({"bounds_checks": False}, module), timed on the CPU at 1e5..1e7
elements (median of launch + synchronize). Each result is checked against a float64 NumPy
reference, checked and unchecked outputs must be identical, and a one-past-the-end read must fail
in the checked module and not in the unchecked one (proof the option reached the compiler).
Writes out/bench/bounds_checks.md. Exit status 1 when any check fails.

The daemon: $WEFT_DAEMON, else <repo>/build/bin/weftd, else the newest <repo>/build-*/bin/weftd;
it listens on a temp Unix socket with a temp --cache-dir and is stopped at the end."""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO_ROOT / "clients" / "python"))

import bench_common as bc  # noqa: E402



# ------------------------------------------------------------------------------------------
# The daemon

Daemon = bc.BenchDaemon   # bench_lazy_adjoint imports it from here


# ------------------------------------------------------------------------------------------
# Kernels

SOURCE = '''
@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a * x[i] + y[i]

@wp.kernel
def stencil(u: wp.array2d(dtype=float), out: wp.array2d(dtype=float)):
    i, j = wp.tid()
    ni = u.shape[0]
    nj = u.shape[1]
    im = wp.max(i - 1, 0)
    ip = wp.min(i + 1, ni - 1)
    jm = wp.max(j - 1, 0)
    jp = wp.min(j + 1, nj - 1)
    out[i, j] = 0.25 * (u[im, j] + u[ip, j] + u[i, jm] + u[i, jp]) - u[i, j]

@wp.kernel
def gather(x: wp.array(dtype=float), idx: wp.array(dtype=wp.int32), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = 2.0 * x[idx[i]] + 1.0

@wp.kernel
def probe(x: wp.array(dtype=float), at: int, out: wp.array(dtype=float)):
    out[0] = x[at]
'''


def stencil_reference(u: np.ndarray) -> np.ndarray:
    u = u.astype(np.float64)
    p = np.pad(u, 1, mode="edge")
    return 0.25 * (p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:]) - u


def normwise_error(got: np.ndarray, ref: np.ndarray) -> float:
    """max |got - ref| / max |ref| (relative to the result's scale)."""
    scale = float(np.max(np.abs(ref))) or 1.0
    return float(np.max(np.abs(got.astype(np.float64) - ref))) / scale


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="1e5,1e6,1e7")
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--out", default=str(REPO_ROOT / "out" / "bench" / "bounds_checks.md"))
    args = parser.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]

    daemon = Daemon(["--allow-unchecked"])
    os.environ["WEFT_ADDRESS"] = daemon.address
    os.environ["WEFT_UNCHECKED"] = "1"   # an unchecked session (in a process of its own)
    failures: list[str] = []
    rows: list[list] = []
    try:
        import weft as wp  # noqa: PLC0415

        wp.init()
        checked = bc.load_kernels(SOURCE, "weft", "bounds_checked")
        unchecked = bc.load_kernels(SOURCE, "weft", "bounds_unchecked")
        wp.set_module_options({"bounds_checks": False}, unchecked)
        t = time.perf_counter()
        wp.load_module(checked, device="cpu")
        wp.load_module(unchecked, device="cpu")
        print(f"weftd {daemon.binary}; both modules compiled in {time.perf_counter() - t:.2f} s")

        # The option reached the compiler: one-past-the-end fails only when checked.
        x = wp.array(np.arange(1000, dtype=np.float32), dtype=float, device="cpu")
        o = wp.zeros(1, dtype=float, device="cpu")
        try:
            wp.launch(checked.probe, dim=1, inputs=[x, 1000, o], device="cpu")
            wp.synchronize()
            failures.append("checked probe: reading x[1000] of a 1000-element array did not fail")
        except Exception as err:  # noqa: BLE001
            print(f"checked module, x[n]: rejected as expected ({str(err).splitlines()[0][:100]})")
        try:
            wp.launch(unchecked.probe, dim=1, inputs=[x, 999, o], device="cpu")
            wp.synchronize()
            if o.numpy()[0] != 999.0:
                failures.append(f"unchecked probe read {o.numpy()[0]} instead of 999")
            wp.launch(unchecked.probe, dim=1, inputs=[x, 1000, o], device="cpu")
            wp.synchronize()
            print("unchecked module, x[n]: not checked (bounds_checks=false is in effect)")
        except Exception as err:  # noqa: BLE001
            failures.append(f"unchecked probe: x[1000] was still checked, the option did not reach "
                            f"the compiler: {str(err).splitlines()[0]}")

        rng = np.random.default_rng(1234)
        for n in sizes:
            cases = []
            xs = rng.standard_normal(n).astype(np.float32)
            ys = rng.standard_normal(n).astype(np.float32)
            a = 1.75
            xw, yw = wp.array(xs, dtype=float, device="cpu"), wp.array(ys, dtype=float, device="cpu")
            cases.append(("saxpy", n, lambda m, out: ((m.saxpy, n, [xw, yw, a, out])),
                          a * xs.astype(np.float64) + ys, (n,)))
            side = int(round(n ** 0.5))
            us = rng.standard_normal((side, side)).astype(np.float32)
            uw = wp.array(us, dtype=float, device="cpu")
            cases.append(("stencil2d", side * side, lambda m, out: (m.stencil, (side, side), [uw, out]),
                          stencil_reference(us), (side, side)))
            idx = rng.integers(0, n, size=n, dtype=np.int32)
            iw = wp.array(idx, dtype=wp.int32, device="cpu")
            cases.append(("gather", n, lambda m, out: (m.gather, n, [xw, iw, out]),
                          2.0 * xs.astype(np.float64)[idx] + 1.0, (n,)))
            for name, count, make, ref, shape in cases:
                results, runs = {}, {}
                for label, module in (("checked", checked), ("unchecked", unchecked)):
                    out = wp.zeros(shape, dtype=float, device="cpu")
                    kernel, dim, inputs = make(module, out)

                    def run(kernel=kernel, dim=dim, inputs=inputs):
                        wp.launch(kernel, dim=dim, inputs=inputs, device="cpu")
                        wp.synchronize()

                    run()   # warm-up (and the result we check)
                    results[label] = out.numpy().copy()
                    runs[label] = run
                # interleaved rounds, alternating which goes first, so drift and other users of
                # the machine hit both sides alike
                samples = {"checked": [], "unchecked": []}
                for r in range(args.repeat):
                    order = ("checked", "unchecked") if r % 2 == 0 else ("unchecked", "checked")
                    for label in order:
                        samples[label].append(bc.median_time(runs[label], repeat=3))
                times = {k: statistics.median(v) for k, v in samples.items()}
                errs = {k: normwise_error(v, ref) for k, v in results.items()}
                for k, e in errs.items():
                    if not e < 1e-5:
                        failures.append(f"{name} n={count} {k}: normwise error {e:.2e} >= 1e-5")
                if not np.array_equal(results["checked"], results["unchecked"]):
                    failures.append(f"{name} n={count}: checked and unchecked results differ")
                overhead = (times["checked"] / times["unchecked"] - 1.0) * 100.0
                rows.append([name, f"{side}x{side}" if name == "stencil2d" else f"{count:.0e}", f"{times['checked'] * 1e3:.3f}",
                             f"{times['unchecked'] * 1e3:.3f}", f"{overhead:+.1f}%",
                             f"{max(errs.values()):.1e}"])
                print(f"  {name:9s} n={count:>9d}  checked {times['checked'] * 1e3:8.3f} ms  "
                      f"unchecked {times['unchecked'] * 1e3:8.3f} ms  {overhead:+6.1f}%", flush=True)
    finally:
        code, _ = daemon.stop(keep=bool(failures))
    if code != 0:
        failures.append(f"weftd exited with {code} at stop (log: {daemon.log_path})")

    header = ["kernel", "n", "checked ms", "unchecked ms", "overhead", "max err vs f64"]
    bc.print_table("Bounds checks on vs off (CPU, median of launch + synchronize)", header, rows)
    write_markdown(Path(args.out), header, rows, failures, daemon.binary)
    if failures:
        print("\nFAILED:\n  " + "\n  ".join(failures))
        return 1
    print(f"\nall checks passed; wrote {args.out}")
    return 0


def write_markdown(path: Path, header, rows, failures, binary) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [
        "# Bounds checks: what they cost",
        "",
        f"Generated by bench/bench_bounds_checks.py on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
        f"{os.cpu_count()} CPU(s), weftd `{binary}` started with `--allow-unchecked`; the unchecked "
        "module sets `wp.set_module_options({\"bounds_checks\": False}, module)`. "
        "Times: median over interleaved rounds (checked and unchecked alternating) of the median of 3 runs of `wp.launch` + `wp.synchronize` on the CPU (launch overhead "
        "included). overhead = checked / unchecked - 1. Error: max |weft - ref| / max |ref| "
        "against a float64 NumPy reference (checked and unchecked outputs are also required to be "
        "bit-identical).",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "|".join("---" for _ in header) + "|",
    ]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    lines += ["", "Checks: " + ("all passed" if not failures else "FAILED: " + "; ".join(failures)), ""]
    path.write_text("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
