"""Sessions and devices: a client killed with SIGKILL is reaped within 10 s (its arrays freed,
their shared-memory files gone) while the daemon keeps serving others; clean exit closes
the session; wp.init() starts a local weftd when none answers; devices as Warp shows them;
asynchronous command errors surface at the next sync with the user's file:line."""
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest


@pytest.fixture(autouse=True)
def _cpu_by_default(wp):
    """These tests are about CPU arrays (zero-copy views): make cpu the default device even
    where the daemon has a GPU (Warp's default is then cuda:0)."""
    with wp.ScopedDevice("cpu"):
        yield


HOLDER = """
import json, sys
import numpy as np
import weft as wp
import weft._runtime as rt
wp.init()
wp.set_device("cpu")
arrays = [wp.full(8 << 20, float(i), dtype=wp.float32) for i in range(3)]   # 32 MiB each
small = [wp.zeros(100) for _ in range(10)]
names = sorted({a._info.shm_name for a in arrays})   # big: slabs of their own
wp.synchronize()
print(json.dumps({"names": names, "bytes": sum(a.capacity for a in arrays + small)}),
      flush=True)
sys.stdin.readline()
"""


def wait_for(predicate, timeout_s):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    return predicate()


def test_killed_client_is_reaped_within_10_s(weftd, wp, spawn_client):
    wp.synchronize()
    mine = wp.array(np.arange(1000, dtype=np.float64))
    before = weftd.stats()
    child = spawn_client(HOLDER)
    line = child.stdout.readline()
    assert line, child.stderr.read()
    held = json.loads(line)
    during = weftd.stats()
    assert during.arrays >= before.arrays + 13
    assert during.array_bytes >= before.array_bytes + held["bytes"] - 4096
    big_slabs = [n for n in held["names"] if Path("/dev/shm" + n).exists()]
    assert big_slabs, "the holder's slabs should exist in /dev/shm while it runs"

    child.send_signal(signal.SIGKILL)
    child.wait(timeout=10)
    killed_at = time.monotonic()
    reaped = wait_for(lambda: weftd.stats().arrays <= before.arrays, 10.0)
    elapsed = time.monotonic() - killed_at
    assert reaped, f"daemon still holds the killed client's arrays after {elapsed:.1f} s"
    assert elapsed <= 10.0
    after = weftd.stats()
    assert after.array_bytes <= before.array_bytes
    assert after.sessions_reaped_total >= before.sessions_reaped_total + 1
    # the 32 MiB arrays had slabs of their own: those files are gone
    gone = wait_for(lambda: not [n for n in held["names"] if Path("/dev/shm" + n).exists()],
                    5.0)
    assert gone, f"shared-memory files left: {held['names']}"
    # and the daemon keeps serving this client
    np.testing.assert_array_equal(mine.numpy(), np.arange(1000, dtype=np.float64))
    fresh = wp.full(10, 2.0)
    np.testing.assert_array_equal(fresh.numpy(), np.full(10, 2.0, np.float32))


def test_clean_exit_closes_the_session(weftd, run_client):
    before = weftd.stats()
    run_client("""
        import weft as wp
        wp.set_device("cpu")
        a = wp.zeros(1 << 20)
        a.fill_(1.0)     # left in the batch: flushed at exit
        """)
    after = wait_for(lambda: weftd.stats().sessions <= before.sessions and weftd.stats(), 5.0)
    assert after and after.sessions <= before.sessions
    assert after.arrays <= before.arrays


def test_async_error_surfaces_at_sync_with_origin(wp):
    a = wp.zeros(8, dtype=wp.float32)
    bad = a._make_view(0, (64,), (4,))   # a view far outside the allocation
    bad.fill_(1.0)
    line = sys._getframe().f_lineno - 1
    with pytest.raises(wp.WeftError) as info:
        wp.synchronize()
    assert info.value.origin is not None
    assert info.value.origin.endswith(f"test_session.py:{line}")
    # the error is reported once; the session keeps working and nothing was written
    wp.synchronize()
    np.testing.assert_array_equal(a.numpy(), np.zeros(8, np.float32))


def test_devices_like_warp(wp):
    devices = wp.get_devices()
    assert devices and devices[0].alias == "cpu"
    cpu = wp.get_device("cpu")
    assert cpu.is_cpu and not cpu.is_cuda and str(cpu) == "cpu" and cpu == "cpu"
    assert cpu.total_memory > 0 and 0 < cpu.free_memory <= cpu.total_memory
    assert wp.is_cpu_available()
    assert wp.get_cuda_device_count() == len(wp.get_cuda_devices())
    assert wp.is_cuda_available() == (wp.get_cuda_device_count() > 0)
    assert cpu.max_shared_memory_per_block == 0
    for d in wp.get_cuda_devices():
        assert d.is_cuda and d.alias.startswith("cuda:") and d.arch >= 50
        # the opt-in maximum: at least the 48 KiB every architecture since sm_50 has
        assert d.max_shared_memory_per_block >= 48 * 1024
    preferred = wp.get_preferred_device()
    assert preferred.alias == ("cuda:0" if wp.is_cuda_available() else "cpu")
    outer = wp.get_device()          # cpu: this file's autouse scope
    for alias in [d.alias for d in devices]:
        with wp.ScopedDevice(alias):
            assert wp.get_device() == alias
            assert wp.zeros(3).device == alias
        assert wp.get_device() == outer
    with pytest.raises(ValueError, match="Invalid device"):
        wp.get_device("tpu:3")
    wp.synchronize_device("cpu")


def test_init_starts_a_local_daemon_when_none_answers(weftd, client_env, daemon_path):
    runtime_dir = tempfile.mkdtemp(prefix="weft-xdg-")
    code = """
import json, os
import numpy as np
import weft as wp
import weft._runtime as rt
wp.init()
a = wp.array(np.arange(5, dtype=np.float32))
r = rt.get_runtime()
print(json.dumps({"address": r.address, "daemon_pid": r.daemon_pid,
                  "values": a.numpy().tolist()}))
"""
    env = client_env({"WEFT_ADDRESS": None, "WEFT_TOKEN": None,
                      "XDG_RUNTIME_DIR": runtime_dir, "WEFT_DAEMON": str(daemon_path)})
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=90)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    socket_path = Path(runtime_dir) / "weft" / "weftd.sock"
    assert out["address"] == f"unix:{socket_path}"
    assert out["values"] == [0.0, 1.0, 2.0, 3.0, 4.0]
    pid = out["daemon_pid"]
    try:
        assert pid and pid != weftd.pid
        # a second client finds the running daemon instead of starting another
        proc2 = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                               text=True, timeout=90)
        assert proc2.returncode == 0, proc2.stderr
        assert json.loads(proc2.stdout.strip().splitlines()[-1])["daemon_pid"] == pid
    finally:
        if pid:
            os.kill(pid, signal.SIGTERM)
            wait_for(lambda: not Path(f"/proc/{pid}").exists()
                     or "zombie" in Path(f"/proc/{pid}/status").read_text().lower(), 10.0)


def test_an_autostarted_daemon_keeps_compiled_modules_on_disk(weftd, client_env, daemon_path, tmp_path):
    """As Warp's kernel cache: a second run, by a daemon started anew, compiles nothing."""
    runtime_dir, cache_home = tempfile.mkdtemp(prefix="weft-xdg-"), tmp_path / "cache"
    scale = float(np.random.default_rng().integers(2, 1000))
    script = tmp_path / "cached_kernel.py"
    script.write_text(f"""
import json, numpy as np
import weft as wp
import weft._runtime as rt
wp.config.verbose = True

@wp.kernel
def scale(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] * {scale}

a = wp.array(np.arange(4, dtype=np.float32))
wp.launch(scale, dim=4, inputs=[a])
print(json.dumps({{"pid": rt.get_runtime().daemon_pid, "values": a.numpy().tolist()}}))
""")
    env = client_env({"WEFT_ADDRESS": None, "WEFT_TOKEN": None, "WEFT_CACHE_DIR": None,
                      "XDG_RUNTIME_DIR": runtime_dir, "XDG_CACHE_HOME": str(cache_home),
                      "WEFT_DAEMON": str(daemon_path)})
    runs = []
    for _ in range(2):
        proc = subprocess.run([sys.executable, str(script)], env=env, capture_output=True,
                              text=True, timeout=90, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        lines = proc.stdout.strip().splitlines()
        out = json.loads(lines[-1])
        runs.append((out, [ln for ln in lines if "(compiled)" in ln]))
        assert out["values"] == [scale * i for i in range(4)]
        pid = out["pid"]
        assert pid and pid != weftd.pid
        os.kill(pid, signal.SIGTERM)             # the next run starts a daemon of its own
        wait_for(lambda: not Path(f"/proc/{pid}").exists()
                 or "zombie" in Path(f"/proc/{pid}/status").read_text().lower(), 10.0)
    (first, compiled_first), (second, compiled_second) = runs
    assert first["pid"] != second["pid"]
    assert len(compiled_first) == 1 and compiled_second == []
    cached = list((cache_home / "weft" / "modules").glob("*.wmod"))
    assert cached and (cache_home / "weft" / "modules").stat().st_mode & 0o077 == 0


def test_no_daemon_and_no_binary_is_a_clear_error(weftd, tmp_path, client_env):
    env = client_env({"WEFT_ADDRESS": None, "XDG_RUNTIME_DIR": str(tmp_path),
                      "WEFT_DAEMON": str(tmp_path / "missing-weftd"), "PATH": "/usr/bin:/bin"})
    proc = subprocess.run([sys.executable, "-c", "import weft as wp; wp.init()"], env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0
    assert "weftd" in proc.stderr
