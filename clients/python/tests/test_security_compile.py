"""Compile time is bounded (issue 7, finding 9): clang runs in a child process (weft-cc) that the
daemon kills at --compile-time-limit. A pathological kernel (hundreds of vector statements:
clang's optimizer is superlinear on them) gets a clear RESOURCE_EXHAUSTED naming the flag
within the limit (plus the daemon's own parsing and code generation); meanwhile other sessions
are served (arrays, and a small module compiles); afterwards no compiler process is left and
the daemon keeps serving."""
import threading
import time
from pathlib import Path

import grpc
import numpy as np

LIMIT_S = 2.0
HEAVY = 3000


def pathological_kernel(n: int) -> str:
    """A kernel of n chained vec3 statements; the CPU compile grows faster than linearly with n
    (on the 2-core CI machine, 2026-11-24: 900 statements 1.9 s, 1800 5.1 s, 3600 17 s), so the
    tests use HEAVY statements, several times a 2 s limit."""
    lines = ["v0 = wp.vec3(x[i], x[i] * 2.0, 1.0)"]
    for k in range(1, n):
        lines.append(f"v{k} = wp.cross(v{k - 1}, wp.vec3(1.0, {k}.0, 2.0)) * 0.5 + v{k - 1}")
    lines.append(f"y[i] = wp.length(v{n - 1})")
    body = "\n    ".join(lines)
    return f'''
import weft as wp

@wp.kernel
def heavy(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    {body}
'''


def children(pid: int) -> list[int]:
    """Child processes of `pid` (the compiler processes it runs)."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            found += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return found


def no_verify_cuda(monkeypatch):
    """--verify-cuda (added to test daemons built with NVRTC) also compiles every module with
    NVRTC, in the daemon and without a time limit (docs/security.md, Known limits)."""
    monkeypatch.setenv("WEFT_TEST_VERIFY_CUDA", "0")


def test_compile_time_limit_stops_a_pathological_kernel_and_others_are_served(start_weftd, run_client,
                                                                            client_env, tmp_path,
                                                                            wait_for, monkeypatch):
    no_verify_cuda(monkeypatch)
    daemon = start_weftd(["--compile-time-limit", str(LIMIT_S)])
    heavy = tmp_path / "heavy.py"
    heavy.write_text(pathological_kernel(HEAVY))
    light = tmp_path / "light.py"
    light.write_text('''
import weft as wp

@wp.kernel
def double(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] * 2.0
''')
    env = {"WEFT_ADDRESS": daemon.address, "PYTHONPATH": f"{tmp_path}:" + client_env(None)["PYTHONPATH"]}
    result = {}

    def compile_heavy():
        start = time.monotonic()
        result["heavy"] = run_client('''
            import time
            import weft as wp
            import heavy
            wp.init()
            try:
                wp.load_module(heavy, device="cpu")
                print("COMPILED")
            except Exception as error:   # the error the user sees
                print("ERROR", type(error).__name__, error)
        ''', env=env, timeout=300)
        result["heavy_s"] = time.monotonic() - start

    worker = threading.Thread(target=compile_heavy)
    worker.start()
    # while it compiles: another session's arrays and a small compile answer promptly
    assert wait_for(lambda: children(daemon.pid), 30.0, 0.02), "the compile never started a compiler process"
    with daemon.raw_session("bystander") as bystander:
        for _ in range(10):
            start = time.monotonic()
            values = np.arange(256, dtype=np.float32)
            np.testing.assert_array_equal(bystander.read_array(bystander.create_array(values).handle), values)
            assert time.monotonic() - start < 2.0
    start = time.monotonic()
    run_client('''
        import numpy as np
        import weft as wp
        import light
        wp.init()
        a = wp.array(np.arange(8, dtype=np.float32), device="cpu")
        wp.launch(light.double, dim=8, inputs=[a], device="cpu")
        assert (a.numpy() == np.arange(8) * 2).all()
    ''', env=env, timeout=120)
    light_s = time.monotonic() - start
    worker.join(timeout=300)
    out = result["heavy"].stdout
    assert "COMPILED" not in out, "the pathological kernel compiled within the limit: make it heavier"
    assert "ERROR" in out and "compile time limit" in out and "--compile-time-limit" in out, out
    assert "RESOURCE_EXHAUSTED" in out or "ResourceExhausted" in out or "resource" in out.lower(), out
    # the limit plus parsing, code generation and a client start; far less than the minutes
    # clang would take
    assert result["heavy_s"] < LIMIT_S + 30, result["heavy_s"]
    assert light_s < 60, light_s
    assert wait_for(lambda: not children(daemon.pid), 5.0), f"compiler processes left: {children(daemon.pid)}"
    with daemon.raw_session("after") as after:   # still serving
        assert after.session_id


def test_sigterm_stops_the_daemon_during_a_long_compile(start_weftd, spawn_client, client_env, tmp_path,
                                                       wait_for, monkeypatch):
    """A compile that would take minutes (the limit set far above it) does not hold the daemon
    past its stop bound: SIGTERM kills the compiler process and weftd exits 0 within 5 s."""
    no_verify_cuda(monkeypatch)
    daemon = start_weftd(["--compile-time-limit", "600"])
    (tmp_path / "heavy.py").write_text(pathological_kernel(HEAVY))
    env = {"WEFT_ADDRESS": daemon.address, "PYTHONPATH": f"{tmp_path}:" + client_env(None)["PYTHONPATH"]}
    child = spawn_client('''
        import weft as wp
        import heavy
        wp.init()
        try:
            wp.load_module(heavy, device="cpu")
            print("COMPILED", flush=True)
        except Exception as error:
            print("ERROR", error, flush=True)
    ''', env=env)
    assert wait_for(lambda: children(daemon.pid), 60.0, 0.02), "the compile never started a compiler process"
    compiler = children(daemon.pid)
    time.sleep(0.5)
    start = time.monotonic()
    assert daemon.stop() == 0
    assert time.monotonic() - start < 5.0, f"weftd took {time.monotonic() - start:.1f} s to stop"
    for pid in compiler:
        assert not Path(f"/proc/{pid}").exists() or "Z" in Path(f"/proc/{pid}/stat").read_text().split()[2], \
            f"compiler process {pid} outlived the daemon"
    out, _ = child.communicate(timeout=30)
    assert "COMPILED" not in out, out


def test_nvrtc_compile_time_limit_stops_a_slow_cuda_compile(needs_nvrtc, start_weftd, run_client, client_env,
                                                          tmp_path, wait_for, monkeypatch):
    """NVRTC runs in the compiler child too (weft-cc --nvrtc): a compile for sm_90 of a kernel
    NVRTC takes far over the limit (400 chained vec3 statements: 120 took 7 s on an idle
    2-core machine, and the time grows faster than the count) is stopped at
    the limit with an error naming the architecture and the flag, on a machine without a GPU;
    no compiler process is left, and a small CUDA compile and the daemon go on."""
    limit_s = 5.0   # a small CUDA compile (NVRTC, forward and adjoint) fits on a loaded machine
    no_verify_cuda(monkeypatch)
    daemon = start_weftd(["--compile-time-limit", str(limit_s)])
    (tmp_path / "slow_cuda.py").write_text(pathological_kernel(400))
    (tmp_path / "small_cuda.py").write_text('''
import weft as wp

@wp.kernel
def double(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] * 2.0
''')
    env = {"WEFT_ADDRESS": daemon.address, "PYTHONPATH": f"{tmp_path}:" + client_env(None)["PYTHONPATH"]}
    start = time.monotonic()
    out = run_client('''
        import weft as wp
        import slow_cuda
        wp.init()
        try:
            wp.compile(slow_cuda.heavy, device="cuda", arch=90)
            print("COMPILED")
        except Exception as error:   # the error the user sees
            print("ERROR", type(error).__name__, error)
    ''', env=env, timeout=300).stdout
    took = time.monotonic() - start
    assert "COMPILED" not in out, "NVRTC compiled the slow kernel within the limit: make it heavier"
    assert "ERROR" in out and "CUDA sm_90 (NVRTC)" in out and "--compile-time-limit" in out, out
    assert took < limit_s + 30, took
    assert wait_for(lambda: not children(daemon.pid), 5.0), f"compiler processes left: {children(daemon.pid)}"
    out = run_client('''
        import weft as wp
        import small_cuda
        wp.init()
        report = wp.compile(small_cuda.double, device="cuda", arch=90)
        print("REGISTERS", report.kernel("double").registers)
    ''', env=env, timeout=120).stdout
    assert "REGISTERS" in out, out
    with daemon.raw_session("after") as after:   # still serving
        assert after.session_id
