"""Kernel time for saxpy and particle integration (semi-implicit Euler, wp.vec3) at 1e3..1e7
elements on the CPU: weft (all cores in the daemon) vs warp-lang (one thread), median of
several launch+sync runs; throughput in elements/s; normwise relative error (max|err|/max|ref|)
of one launch against a float64 NumPy reference. Ratio = warp time / weft time (higher is better for weft)."""
from __future__ import annotations

import sys

import numpy as np

import bench_common as bc

SOURCE = '''
@wp.kernel
def saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]

@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), f: wp.array(dtype=wp.vec3),
              w: wp.array(dtype=float), gravity: wp.vec3, dt: float):
    tid = wp.tid()
    v1 = v[tid] + (f[tid] * w[tid] + gravity) * dt
    x[tid] = x[tid] + v1 * dt
    v[tid] = v1
'''
SIZES = [10 ** k for k in range(3, 8)]
A = 1.5
DT = 0.01
G = (0.0, -9.8, 0.0)


def _rel_err(got, ref):
    """Normwise relative error max|got - ref| / max|ref| (elementwise relative error is
    meaningless where a*x + y cancels to ~0)."""
    return float(np.max(np.abs(got - ref)) / max(float(np.max(np.abs(ref))), 1e-30))


def run(lib, mod, n, rng):
    """(saxpy seconds, saxpy error, integrate seconds, integrate error) for one library."""
    x = rng.standard_normal(n).astype(np.float32)
    y = rng.standard_normal(n).astype(np.float32)
    xa = lib.array(x, dtype=float, device="cpu")
    ya = lib.array(y, dtype=float, device="cpu")
    lib.launch(mod.saxpy, dim=n, inputs=[xa, ya, A], device="cpu")
    saxpy_err = _rel_err(ya.numpy(), A * x.astype(np.float64) + y)

    def saxpy():
        lib.launch(mod.saxpy, dim=n, inputs=[xa, ya, A], device="cpu")
        lib.synchronize()

    repeat = 20 if n <= 10 ** 5 else 5
    saxpy_s = bc.median_time(saxpy, repeat=repeat)

    p = rng.standard_normal((n, 3)).astype(np.float32)
    v = rng.standard_normal((n, 3)).astype(np.float32)
    f = rng.standard_normal((n, 3)).astype(np.float32)
    w = rng.uniform(0.5, 2, n).astype(np.float32)
    pa, va = lib.array(p, dtype=lib.vec3, device="cpu"), lib.array(v, dtype=lib.vec3, device="cpu")
    fa, wa = lib.array(f, dtype=lib.vec3, device="cpu"), lib.array(w, dtype=float, device="cpu")
    args = [pa, va, fa, wa, lib.vec3(*G), DT]
    lib.launch(mod.integrate, dim=n, inputs=args, device="cpu")
    v1 = v.astype(np.float64) + (f.astype(np.float64) * w[:, None] + np.array(G)) * DT
    p1 = p.astype(np.float64) + v1 * DT
    integ_err = max(_rel_err(pa.numpy(), p1), _rel_err(va.numpy(), v1))

    def integrate():
        lib.launch(mod.integrate, dim=n, inputs=args, device="cpu")
        lib.synchronize()

    integ_s = bc.median_time(integrate, repeat=repeat)
    return saxpy_s, saxpy_err, integ_s, integ_err


def main():
    import weft

    weft.init()
    weft_mod = bc.load_kernels(SOURCE, "weft", "kernels")
    warp = bc.import_warp()
    warp_mod = bc.load_kernels(SOURCE, "warp", "kernels") if warp is not None else None
    rng = np.random.default_rng(0)
    sizes = SIZES if "--quick" not in sys.argv else SIZES[:3]
    saxpy_rows, integ_rows = [], []
    for n in sizes:
        s_t, s_e, i_t, i_e = run(weft, weft_mod, n, rng)
        ws_t = wi_t = None
        ws_e = wi_e = None
        if warp is not None:
            ws_t, ws_e, wi_t, wi_e = run(warp, warp_mod, n, rng)
        saxpy_rows.append([f"{n:.0e}", bc.fmt_time(s_t), f"{n / s_t / 1e6:,.1f} M/s",
                           f"{s_e:.1e}", bc.fmt_time(ws_t),
                           "n/a" if ws_e is None else f"{ws_e:.1e}", bc.fmt_ratio(s_t, ws_t)])
        integ_rows.append([f"{n:.0e}", bc.fmt_time(i_t), f"{n / i_t / 1e6:,.1f} M/s",
                           f"{i_e:.1e}", bc.fmt_time(wi_t),
                           "n/a" if wi_e is None else f"{wi_e:.1e}", bc.fmt_ratio(i_t, wi_t)])
    header = ["n", "weft", "throughput", "weft rel err", "warp-lang", "warp rel err",
              "ratio warp/weft"]
    bc.print_table("saxpy y = a*x + y, float32, CPU (launch + sync)", header, saxpy_rows)
    bc.print_table("particle integration (semi-implicit Euler, vec3), CPU (launch + sync)",
                   header, integ_rows)


if __name__ == "__main__":
    main()
