"""Compile time with lazy adjoints, for one real module of five kernels (spring forces with vec3
math and atomics, particle integration, a quaternion transform, a func-heavy energy, an atomic
loss): what a forward-only program pays (wp.load_module: the daemon compiles the forward
variant only) against the first tape.backward(), which makes the daemon build the forward+backward
variant on demand, and a warm backward for comparison.

Each trial is a fresh Python process talking to a fresh weftd with an empty --cache-dir, so every
compile is a real one (the daemon's Stats module_cache_misses are recorded to prove it). Both
tape modes are measured: "daemon" (the default: the daemon's tape compiles the adjoint variant
inside the BACKWARD command) and "client" (WEFT_TAPE=client: the client sends a CompileRequest
with enable_backward, then adjoint launches).

Checks, every trial: the forward loss against a float64 NumPy reference of the whole chain, and
the gradient with respect to the initial positions against a float64 central difference of that
reference along a random direction. Writes out/bench/lazy_adjoint.md; exit status 1 on a failed
check. Daemon: $WEFT_DAEMON, else <repo>/build/bin/weftd, else the newest build-*/bin/weftd."""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(REPO_ROOT / "clients" / "python"))

import bench_common as bc  # noqa: E402

SOURCE = '''
@wp.func
def spring_force(xa: wp.vec3, xb: wp.vec3, rest: float, k: float):
    d = xb - xa
    l = wp.length(d)
    return d * (k * (l - rest) / l)

@wp.kernel
def springs(x: wp.array(dtype=wp.vec3), i0: wp.array(dtype=int), i1: wp.array(dtype=int),
            rest: wp.array(dtype=float), k: float, f: wp.array(dtype=wp.vec3)):
    t = wp.tid()
    a = i0[t]
    b = i1[t]
    fs = spring_force(x[a], x[b], rest[t], k)
    wp.atomic_add(f, a, fs)
    wp.atomic_sub(f, b, fs)

@wp.kernel
def integrate(x: wp.array(dtype=wp.vec3), v: wp.array(dtype=wp.vec3), f: wp.array(dtype=wp.vec3),
              w: wp.array(dtype=float), gravity: wp.vec3, dt: float,
              x_out: wp.array(dtype=wp.vec3), v_out: wp.array(dtype=wp.vec3)):
    tid = wp.tid()
    v1 = v[tid] + (f[tid] * w[tid] + gravity) * dt
    x_out[tid] = x[tid] + v1 * dt
    v_out[tid] = v1

@wp.kernel
def transform_points(x: wp.array(dtype=wp.vec3), q: wp.quat, p: wp.vec3,
                     y: wp.array(dtype=wp.vec3)):
    tid = wp.tid()
    y[tid] = wp.quat_rotate(q, x[tid]) + p

@wp.func
def softplus(a: float):
    return wp.log(1.0 + wp.exp(a))

@wp.func
def bump(a: float, b: float):
    s = wp.sin(a) * wp.cos(b)
    return s * s + 0.5 * wp.tanh(a - b)

@wp.func
def shape_term(y: wp.vec3):
    return softplus(y[0]) + bump(y[1], y[2]) + wp.sqrt(wp.dot(y, y) + 1.0)

@wp.kernel
def energy(y: wp.array(dtype=wp.vec3), e: wp.array(dtype=float)):
    tid = wp.tid()
    e[tid] = shape_term(y[tid])

@wp.kernel
def loss_kernel(y: wp.array(dtype=wp.vec3), e: wp.array(dtype=float), loss: wp.array(dtype=float)):
    tid = wp.tid()
    wp.atomic_add(loss, 0, 0.5 * wp.dot(y[tid], y[tid]) + e[tid])
'''

N = 256
K_SPRING = 4.0
DT = 0.01
GRAVITY = np.array([0.0, -9.8, 0.0])
AXIS_ANGLE = (np.array([0.3, 0.8, -0.5]), 0.7)
OFFSET = np.array([0.2, -0.1, 0.4])


def problem(seed: int = 7) -> dict:
    rng = np.random.default_rng(seed)
    i0 = np.arange(N - 1, dtype=np.int32)
    i1 = i0 + 1
    axis = AXIS_ANGLE[0] / np.linalg.norm(AXIS_ANGLE[0])
    half = 0.5 * AXIS_ANGLE[1]
    q = np.concatenate([axis * np.sin(half), [np.cos(half)]])   # Warp's (x, y, z, w)
    return dict(x=rng.standard_normal((N, 3)).astype(np.float32),
                v=(0.3 * rng.standard_normal((N, 3))).astype(np.float32),
                w=rng.uniform(0.5, 2.0, N).astype(np.float32),
                i0=i0, i1=i1, rest=rng.uniform(0.5, 1.5, N - 1).astype(np.float32),
                q=q.astype(np.float32), direction=rng.standard_normal((N, 3)))


def reference_loss(x: np.ndarray, p: dict) -> float:
    """The whole chain in float64."""
    x = x.astype(np.float64)
    f = np.zeros_like(x)
    d = x[p["i1"]] - x[p["i0"]]
    length = np.linalg.norm(d, axis=1, keepdims=True)
    fs = d * (K_SPRING * (length - p["rest"][:, None]) / length)
    np.add.at(f, p["i0"], fs)
    np.add.at(f, p["i1"], -fs)
    v1 = p["v"] + (f * p["w"][:, None] + GRAVITY) * DT
    x1 = x + v1 * DT
    q = p["q"].astype(np.float64)
    u, s = q[:3], q[3]
    rot = (2.0 * s * s - 1.0) * x1 + 2.0 * s * np.cross(u, x1) + 2.0 * (x1 @ u)[:, None] * u
    y = rot + OFFSET
    e = (np.log1p(np.exp(y[:, 0])) + (np.sin(y[:, 1]) * np.cos(y[:, 2])) ** 2
         + 0.5 * np.tanh(y[:, 1] - y[:, 2]) + np.sqrt(np.sum(y * y, axis=1) + 1.0))
    return float(np.sum(0.5 * np.sum(y * y, axis=1) + e))


# ------------------------------------------------------------------------------------------
# One trial (a fresh process + a fresh daemon)

def trial(mode: str) -> dict:
    daemon = bc.BenchDaemon()
    os.environ["WEFT_ADDRESS"] = daemon.address
    if mode == "client":
        os.environ["WEFT_TAPE"] = "client"
    result: dict = {"mode": mode, "failures": []}
    try:
        import weft as wp  # noqa: PLC0415
        from weft import _runtime  # noqa: PLC0415
        from weft._kernel import module as module_mod  # noqa: PLC0415

        wp.init()
        rt = _runtime.get_runtime()

        def misses() -> int:
            return int(rt.call(rt.session_stub.Stats, _runtime.session_pb2.StatsRequest())
                       .module_cache_misses)

        def compile_ms_seen() -> dict:
            return {k: v.compile_ms for k, v in module_mod._compiled.items()}

        mod = bc.load_kernels(SOURCE, "weft", f"lazy_adjoint_{mode}")
        p = problem()
        m0, seen0 = misses(), compile_ms_seen()
        t = time.perf_counter()
        wp.load_module(mod, device="cpu")
        result["forward_wall_s"] = time.perf_counter() - t
        seen1 = compile_ms_seen()
        new = [v for k, v in seen1.items() if k not in seen0]
        result["forward_compile_ms"] = sum(new)
        result["forward_requests"] = len(new)
        m1 = misses()
        result["forward_builds"] = m1 - m0

        dev = "cpu"
        x = wp.array(p["x"], dtype=wp.vec3, device=dev, requires_grad=True)
        v = wp.array(p["v"], dtype=wp.vec3, device=dev, requires_grad=True)
        w = wp.array(p["w"], dtype=float, device=dev)
        i0 = wp.array(p["i0"], dtype=int, device=dev)
        i1 = wp.array(p["i1"], dtype=int, device=dev)
        rest = wp.array(p["rest"], dtype=float, device=dev)
        f = wp.zeros(N, dtype=wp.vec3, device=dev, requires_grad=True)
        x1 = wp.zeros(N, dtype=wp.vec3, device=dev, requires_grad=True)
        v1 = wp.zeros(N, dtype=wp.vec3, device=dev, requires_grad=True)
        y = wp.zeros(N, dtype=wp.vec3, device=dev, requires_grad=True)
        e = wp.zeros(N, dtype=float, device=dev, requires_grad=True)
        loss = wp.zeros(1, dtype=float, device=dev, requires_grad=True)
        q = wp.quat(*[float(c) for c in p["q"]])
        offset = wp.vec3(*[float(c) for c in OFFSET])
        gravity = wp.vec3(*[float(c) for c in GRAVITY])

        tape = wp.Tape()
        t = time.perf_counter()
        with tape:
            wp.launch(mod.springs, dim=N - 1, inputs=[x, i0, i1, rest, K_SPRING, f], device=dev)
            wp.launch(mod.integrate, dim=N, inputs=[x, v, f, w, gravity, DT, x1, v1], device=dev)
            wp.launch(mod.transform_points, dim=N, inputs=[x1, q, offset, y], device=dev)
            wp.launch(mod.energy, dim=N, inputs=[y, e], device=dev)
            wp.launch(mod.loss_kernel, dim=N, inputs=[y, e, loss], device=dev)
        wp.synchronize()
        result["forward_run_s"] = time.perf_counter() - t
        m2 = misses()
        result["forward_run_builds"] = m2 - m1

        seen2 = compile_ms_seen()
        t = time.perf_counter()
        tape.backward(loss=loss)
        wp.synchronize()
        result["backward_first_s"] = time.perf_counter() - t
        seen3 = compile_ms_seen()
        new = [v for k, v in seen3.items() if k not in seen2]
        result["backward_compile_ms"] = sum(new)     # CompileRequests of the client tape
        result["backward_requests"] = len(new)
        m3 = misses()
        result["backward_builds"] = m3 - m2
        grad_x = x.grad.numpy().astype(np.float64)

        tape.zero()
        t = time.perf_counter()
        tape.backward(loss=loss)
        wp.synchronize()
        result["backward_warm_s"] = time.perf_counter() - t
        result["backward_warm_builds"] = misses() - m3
        grad_x2 = x.grad.numpy().astype(np.float64)

        # checks
        got_loss = float(loss.numpy()[0])
        ref_loss = reference_loss(p["x"], p)
        if not abs(got_loss - ref_loss) <= 1e-4 * abs(ref_loss):
            result["failures"].append(f"loss {got_loss} vs float64 reference {ref_loss}")
        d = p["direction"]
        h = 1e-5
        fd = (reference_loss(p["x"] + h * d, p) - reference_loss(p["x"] - h * d, p)) / (2 * h)
        ad = float(np.sum(grad_x * d))
        if not abs(ad - fd) <= 1e-3 * max(abs(fd), 1.0):
            result["failures"].append(f"d(loss)/dx along a random direction: {ad} vs float64 "
                                      f"central difference {fd}")
        if not np.allclose(grad_x, grad_x2, rtol=1e-6, atol=1e-6):
            result["failures"].append("second backward (after tape.zero) gave another gradient")
        result["loss"], result["loss_ref"], result["dir_grad"], result["dir_fd"] = (
            got_loss, ref_loss, ad, fd)
    except Exception as err:  # noqa: BLE001 - reported as the trial's failure
        result["failures"].append(f"{type(err).__name__}: {err}")
    finally:
        code, _ = daemon.stop(keep=bool(result["failures"]))
        if code != 0:
            result["failures"].append(f"weftd exited with {code} (log {daemon.log_path})")
        if result["failures"]:
            result["daemon_log"] = daemon.log()[-1500:]
    return result


# ------------------------------------------------------------------------------------------
# The driver

def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--modes", default="daemon,client")
    parser.add_argument("--trial", help=argparse.SUPPRESS)
    parser.add_argument("--out", default=str(REPO_ROOT / "out" / "bench" / "lazy_adjoint.md"))
    args = parser.parse_args()
    if args.trial:
        print("RESULT " + json.dumps(trial(args.trial)), flush=True)
        return 0

    results: dict = {}
    failures: list = []
    for mode in args.modes.split(","):
        results[mode] = []
        for i in range(args.trials):
            proc = subprocess.run([sys.executable, __file__, "--trial", mode],
                                  capture_output=True, text=True, timeout=600)
            lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
            if not lines:
                failures.append(f"{mode} trial {i}: no result (exit {proc.returncode}):\n"
                                f"{proc.stdout[-1500:]}{proc.stderr[-3000:]}")
                continue
            r = json.loads(lines[-1][len("RESULT "):])
            results[mode].append(r)
            failures += [f"{mode} trial {i}: {f}" for f in r["failures"]]
            if r["failures"] and r.get("daemon_log"):
                failures.append(f"{mode} trial {i} weftd log tail:\n{r['daemon_log']}")
            print(f"{mode} trial {i}: " + ", ".join(
                f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                for k, v in r.items() if k not in ("mode", "failures", "daemon_log")), flush=True)

    header = ["tape mode", "fwd requests/builds", "fwd compile_ms (sum)", "fwd wall",
              "per fwd build", "1st backward wall", "bwd requests/builds", "bwd compile_ms",
              "per adjoint build", "warm backward", "lazy adjoint cost"]
    rows = []

    def med(rs, key):
        vals = [r[key] for r in rs if key in r]
        return statistics.median(vals) if vals else None

    for mode, rs in results.items():
        rs = [r for r in rs if "backward_warm_s" in r]
        if not rs:
            rows.append([mode] + ["failed"] * (len(header) - 1))
            continue
        fwd_ms, fwd_wall = med(rs, "forward_compile_ms"), med(rs, "forward_wall_s")
        fwd_builds, bwd_builds = med(rs, "forward_builds"), med(rs, "backward_builds")
        b1, bw = med(rs, "backward_first_s"), med(rs, "backward_warm_s")
        rows.append([mode, f"{med(rs, 'forward_requests'):.0f}/{fwd_builds:.0f}", f"{fwd_ms:.0f} ms",
                     bc.fmt_time(fwd_wall), f"{fwd_ms / max(fwd_builds, 1):.0f} ms",
                     bc.fmt_time(b1), f"{med(rs, 'backward_requests'):.0f}/{bwd_builds:.0f}",
                     f"{med(rs, 'backward_compile_ms'):.0f} ms",
                     bc.fmt_time((b1 - bw) / max(bwd_builds, 1)), bc.fmt_time(bw),
                     bc.fmt_time(b1 - bw)])
    bc.print_table(f"Lazy adjoint compile, module of 5 kernels (median of {args.trials} fresh "
                   "daemons, empty --cache-dir each)", header, rows)
    write_markdown(Path(args.out), header, rows, failures, args.trials)
    if failures:
        print("\nFAILED:\n  " + "\n  ".join(failures))
        return 1
    print(f"\nall checks passed; wrote {args.out}")
    return 0


def write_markdown(path: Path, header, rows, failures, trials) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [
        "# Lazy adjoints: compile time for one real module",
        "",
        f"Generated by bench/bench_lazy_adjoint.py on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, "
        f"{os.cpu_count()} CPU(s). Module: springs (func + vec3 + atomics), integrate, "
        "transform_points (quat_rotate), energy (three nested funcs: log/exp/sin/cos/tanh/sqrt), "
        f"loss_kernel (atomic_add); {N} particles. Median of {trials} trials, each a fresh "
        "process and a fresh weftd with an empty --cache-dir (every compile is a real build; "
        "'builds' = the daemon's Stats module_cache_misses during that step).",
        "",
        "- forward compile: `wp.load_module(module)`: what a forward-only program pays "
        "(the daemon's CompileResponse.compile_ms summed over the requests, and wall time).",
        "- first backward: the first `tape.backward()` (plus synchronize), which makes the daemon "
        "build the forward+backward variant; warm backward: the same after `tape.zero()`. "
        "lazy adjoint cost = first - warm.",
        "- The daemon has no option to build forward+backward eagerly (the store ignores an "
        "`enable_backward` module option; only an adjoint launch / tape BACKWARD calls "
        "ModuleStore::WithBackward), so eager is not measured: an eager program would pay about "
        "forward + adjoint builds up front.",
        "- per fwd build = compile_ms / builds; per adjoint build = (first - warm backward) / "
        "builds of that step (in client mode that step also holds the forward-only rebuilds its "
        "enable_backward CompileRequests cause).",
        "- 5 builds where one would do: the Python client sends one CompileRequest per kernel, "
        "and each ModuleSource lists the module's functions with that kernel first, so the same "
        "5-kernel module gets 5 cache keys and is built 5 times (and its adjoint variant 5 times, "
        "once per module id). The per-build columns give the cost of one module.",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "|".join("---" for _ in header) + "|",
    ]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    lines += ["", "Checks (loss vs float64 NumPy chain, directional gradient vs float64 central "
              "difference, warm backward = first): " +
              ("all passed" if not failures else "FAILED:\n\n```\n" + "\n".join(failures) + "\n```"),
              ""]
    path.write_text("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
