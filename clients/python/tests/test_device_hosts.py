"""A weftd started with --device-hosts runs the checked sessions of local clients in one process
per device (a device host, server/session_hosts.h): the sessions of every local principal on
that device share its process and its one GPU context, and a fault or crash there ends that
process only. These tests attack it: the sessions of one device share one host and compute
right; the host's end (SIGKILL here: what a GPU fault that the driver keeps, or a crash of
weft's own code, leads to) costs the sessions of that device alone, whose clients get a clear
error and then work in a new host, while a session of another device and a remote session in
the daemon keep their arrays; device names a client sends are checked; a device host runs no
unchecked kernels even when asked directly; another Unix user shares the host but reaches no
array of the first."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import grpc
import numpy as np
import pytest
from test_session_hosts import _alive as _session_hosts_alive
from test_session_hosts import _daemon_stats, _zombie

# Holds random arrays on its device in the daemon's host for it, reports, waits for a line on
# stdin, then checks them and computes once more (reporting the error of a lost session).
HOLDER = '''
import sys
import time
import numpy as np
import weft as wp
import weft._runtime as runtime


@wp.kernel
def scale(a: wp.array(dtype=wp.float64), b: wp.array(dtype=wp.float64), s: wp.float64):
    i = wp.tid()
    b[i] = a[i] * s


device = sys.argv[1]
rng = np.random.default_rng()
values = rng.standard_normal(4096) * 10.0 ** rng.uniform(-30, 30, 4096)   # huge and tiny
a = wp.array(values, dtype=wp.float64, device=device)
b = wp.zeros(4096, dtype=wp.float64, device=device)
s = float(rng.uniform(0.5, 2.0))
wp.launch(scale, dim=4096, inputs=[a, b, s], device=device)
rt = runtime.get_runtime()
exact = np.max(np.abs(b.numpy() - values * s) / np.abs(values * s))
print("READY", rt.hosted, rt.host_device, rt.daemon_pid, f"{exact:.3g}", flush=True)
sys.stdin.readline()
try:
    # Through the host (a CPU array's memory stays mapped here after its process ended).
    b.zero_()
    wp.launch(scale, dim=4096, inputs=[a, b, s], device=device)
    wp.synchronize()
    kept = bool(np.allclose(b.numpy(), values * s, rtol=1e-15, atol=0))
    print("KEPT", kept, runtime.get_runtime() is rt, flush=True)
except Exception as exc:
    print("LOST", str(exc).replace("\\n", " "), flush=True)
t = time.perf_counter()
c = wp.array(values, dtype=wp.float64, device=device)
d = wp.zeros(4096, dtype=wp.float64, device=device)
wp.launch(scale, dim=4096, inputs=[c, d, s], device=device)
ok = np.allclose(d.numpy(), values * s, rtol=1e-15, atol=0)
now = runtime.get_runtime()
print("AFTER", ok, now.hosted, now.daemon_pid, f"{1e3 * (time.perf_counter() - t):.1f}", flush=True)
'''


class _Holder:
    """A HOLDER child process on `device` against `address`."""

    def __init__(self, tmp_path, client_env, address: str, device: str, env: dict | None = None):
        script = tmp_path / "holder.py"
        script.write_text(HOLDER)
        extra = {"WEFT_ADDRESS": address}
        extra.update(env or {})
        self.proc = subprocess.Popen([sys.executable, str(script), device], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env=client_env(extra))
        line = self.proc.stdout.readline().split()
        assert line[:1] == ["READY"], (line, self._stderr())
        self.hosted = line[1] == "True"
        self.host_device = line[2]
        self.pid = int(line[3])
        self.error = float(line[4])

    def _stderr(self) -> str:
        return self.proc.stderr.read() if self.proc.poll() is not None else ""

    def go(self) -> list[str]:
        self.proc.stdin.write("go\n")
        self.proc.stdin.flush()
        first = self.proc.stdout.readline().rstrip("\n")
        after = self.proc.stdout.readline().split()
        assert after[:1] == ["AFTER"], (first, after, self._stderr())
        self.proc.wait(timeout=60)
        return [first, after]

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()


def _alive(pid: int) -> bool:
    return _session_hosts_alive(pid) and not _zombie(pid)


def _open(daemon, device: str = "", target: str | None = None, unchecked: bool = False):
    from weft import _runtime
    from weft.v1 import session_pb2

    channel = grpc.insecure_channel(target or daemon.grpc_target)
    try:
        return _runtime.SessionServiceStub(channel).Open(
            session_pb2.OpenSessionRequest(client_name="pytest", device=device, unchecked=unchecked),
            metadata=daemon.metadata(), timeout=60)
    finally:
        channel.close()


def _gpus(daemon) -> list[str]:
    """The daemon's GPUs that compute: the cuda:N a session may be opened on (each Open starts
    that device's host)."""
    gpus = []
    for i in range(16):
        try:
            gpus.append(_open(daemon, f"cuda:{i}").session_device)
        except grpc.RpcError as err:
            assert err.code() == grpc.StatusCode.INVALID_ARGUMENT, err
            break
    return gpus


def test_the_sessions_of_a_device_share_its_process(start_weftd, client_env, tmp_path):
    """weftd with device-hosts (from its config file): two client processes on the CPU get their
    sessions in one device host (not the daemon),
    compute right against float64 on huge and tiny values, and the daemon's stats count the host
    and add its sessions and arrays; a session that names no device lands in the same host
    where there is no GPU, in the first GPU's otherwise."""
    config = tmp_path / "weftd.toml"          # the config file's key, as an operator writes it
    config.write_text("device-hosts = true\n")
    daemon = start_weftd(["--config", str(config)])
    gpus = _gpus(daemon)
    # Without a GPU a session that names no device is the CPU's; with one, it is the first GPU's.
    first = _Holder(tmp_path, client_env, daemon.address, "cpu", {"WEFT_SESSION_DEVICE": "cpu"})
    second = _Holder(tmp_path, client_env, daemon.address, "cpu",
                     {"WEFT_SESSION_DEVICE": "cpu" if gpus else None})
    try:
        assert first.hosted and second.hosted
        assert first.host_device == second.host_device == "cpu"
        assert first.pid == second.pid != daemon.pid and _alive(first.pid)
        assert first.error <= 1e-15 and second.error <= 1e-15
        stats = _daemon_stats(daemon)
        # The daemon's stats add its device hosts': the two sessions and their four arrays.
        assert stats.session_hosts == 1 + len(gpus) and stats.sessions == 2, stats
        assert stats.arrays >= 4 and stats.array_bytes >= 4 * 4096 * 8, stats
        default = _open(daemon, "")
        assert default.session_device == (gpus[0] if gpus else "cpu")
        assert (default.session_host == _open(daemon, "cpu").session_host) == (not gpus)
        for holder in (first, second):
            kept, after = holder.go()
            assert kept.split() == ["KEPT", "True", "True"], kept
            assert after[1:3] == ["True", "True"] and int(after[3]) == first.pid, after
    finally:
        first.kill()
        second.kill()


def test_a_device_host_ending_costs_only_its_device(start_weftd, client_env, tmp_path, wait_for):
    """Two sessions share the CPU's device host; it is killed (SIGKILL: a crash). Both clients
    get the error that names the device and --device-hosts and says their arrays are gone, and
    their next calls work in a new host (timed); a remote session in the daemon keeps its array
    and the daemon serves on. On a machine with a GPU, a session on cuda:0 (another device host)
    keeps its arrays through it, and the same is then done to the GPU's host with the CPU
    session as the bystander."""
    daemon = start_weftd(["--device-hosts"], also_tcp=True)
    from weft import _runtime
    from weft.v1 import session_pb2

    channel = grpc.insecure_channel(daemon.tcp_target)
    token = (("authorization", f"Bearer {daemon.token}"),)
    remote = _runtime.SessionServiceStub(channel).Open(
        session_pb2.OpenSessionRequest(client_name="remote"), metadata=token, timeout=30)
    assert remote.session_id and not remote.session_host and remote.daemon_pid == daemon.pid
    values = np.random.default_rng().standard_normal(257).astype(np.float32)
    from weft.v1 import array_pb2, types_pb2

    remote_md = token + (("weft-session", remote.session_id),)
    arrays = _runtime.ArrayServiceStub(channel)
    handle = arrays.Create(array_pb2.CreateArrayRequest(
        dtype=types_pb2.DType(scalar=types_pb2.FLOAT32, type_name="float32"), shape=[257],
        device="cpu", init=array_pb2.CreateArrayRequest.DATA, value=values.tobytes()),
        metadata=remote_md, timeout=10).info.handle

    devices = ["cpu"] + _gpus(daemon)
    try:
        for victim in devices:
            others = [d for d in devices if d != victim]
            holders = [_Holder(tmp_path, client_env, daemon.address, victim,
                               {"WEFT_SESSION_DEVICE": victim}) for _ in range(2)]
            bystanders = [_Holder(tmp_path, client_env, daemon.address, d, {"WEFT_SESSION_DEVICE": d})
                          for d in others]
            try:
                host = holders[0].pid
                assert holders[1].pid == host and all(b.pid != host for b in bystanders)
                os.kill(host, signal.SIGKILL)
                wait_for(lambda: not _alive(host), 10)
                for holder in holders:
                    lost, after = holder.go()
                    print(victim, lost, after)
                    assert lost.startswith("LOST "), lost
                    assert f"the sessions of {victim}" in lost and "--device-hosts" in lost, lost
                    assert "the next weft call opens a new session" in lost, lost
                    assert after[1:3] == ["True", "True"] and int(after[3]) != host, after
                for bystander in bystanders:
                    kept, after = bystander.go()
                    assert kept.split() == ["KEPT", "True", "True"], kept
                    assert int(after[3]) == bystander.pid and _alive(bystander.pid), after
            finally:
                for h in holders + bystanders:
                    h.kill()
        chunks = arrays.Read(array_pb2.ReadArrayRequest(handle=handle), metadata=remote_md, timeout=10)
        assert np.array_equal(np.frombuffer(b"".join(c.data for c in chunks), np.float32), values)
        assert _alive(daemon.pid)
    finally:
        channel.close()


@pytest.mark.parametrize("asked", ["cuda:99", "cuda:-1", "cuda:0x0", "CPU", "cpu ", "cuda:",
                                   "cpu\x00cuda:0", "'; rm -rf /", "c" * 100_000])
def test_session_device_names_are_checked(start_weftd, asked):
    """A device name a client sends is one of the daemon's devices or the Open is refused with
    INVALID_ARGUMENT, before any process starts; a name that is not printable or is long is not
    shown back. The daemon serves the next Open."""
    daemon = start_weftd(["--device-hosts"])
    with pytest.raises(grpc.RpcError) as refused:
        _open(daemon, asked)
    assert refused.value.code() == grpc.StatusCode.INVALID_ARGUMENT, refused.value
    details = refused.value.details()
    assert details.startswith("session device ") and len(details) < 200, details
    if len(asked) > 32 or any(not 0x21 <= ord(c) <= 0x7e for c in asked) or "'" in asked:
        assert asked not in details, details
    assert _daemon_stats(daemon).session_hosts_started_total == 0
    assert _open(daemon, "cpu").session_host


def test_sessions_opened_on_cuda_go_to_the_gpus_in_turn(start_weftd):
    """"cuda" names no GPU: the daemon gives such sessions its GPUs in turn (one host each), and
    an empty name the first GPU; without a GPU, "cuda" is refused and an empty name is the CPU."""
    daemon = start_weftd(["--device-hosts"])
    gpus = _gpus(daemon)
    if not gpus:
        with pytest.raises(grpc.RpcError) as refused:
            _open(daemon, "cuda")
        assert refused.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "no GPU" in refused.value.details()
        assert _open(daemon, "").session_device == "cpu"
        return
    turns = [_open(daemon, "cuda") for _ in range(2 * len(gpus))]
    assert sorted(t.session_device for t in turns) == sorted(gpus * 2)
    hosts = {t.session_device: t.session_host for t in turns}
    assert len(set(hosts.values())) == len(gpus)
    assert all(t.session_host == hosts[t.session_device] for t in turns)
    assert _open(daemon, "").session_device == gpus[0]


def test_a_device_host_runs_no_unchecked_kernels(start_weftd, client_env, tmp_path):
    """On a daemon that allows unchecked sessions and runs device hosts, an unchecked session
    still gets a process of its own; a client that goes to the device host's socket directly and
    asks for an unchecked session there gets a checked one: a kernel with bounds checks off is
    refused, and a kernel writing out of bounds fails with the bounds error."""
    daemon = start_weftd(["--device-hosts", "--allow-unchecked"])
    device_host = _open(daemon, "cpu").session_host
    own = _open(daemon, "cpu", unchecked=True)
    assert own.session_host and own.session_host != device_host and not own.session_device
    script = tmp_path / "direct.py"
    script.write_text('''
import numpy as np
import weft as wp

wp.set_module_options({"bounds_checks": False})


@wp.kernel
def wild(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i * 1000000] = 1.0


a = wp.zeros(16, dtype=float, device="cpu")
try:
    wp.launch(wild, dim=16, inputs=[a], device="cpu")
    wp.synchronize()
    print("RAN")
except Exception as exc:
    print("REFUSED", exc)
''')
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                          env=client_env({"WEFT_ADDRESS": "unix:" + device_host, "WEFT_UNCHECKED": "1"}))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("REFUSED"), proc.stdout
    assert "bounds" in proc.stdout, proc.stdout


def test_an_unchecked_request_without_allow_unchecked_goes_to_the_device_host(start_weftd):
    """Without --allow-unchecked an unchecked request is an ordinary, checked session: under
    --device-hosts it goes to its device's host like any other, and starts no process of its own."""
    daemon = start_weftd(["--device-hosts"])
    checked = _open(daemon, "cpu")
    asked = _open(daemon, "cpu", unchecked=True)
    assert asked.session_host == checked.session_host and asked.session_device == "cpu"
    assert _daemon_stats(daemon).session_hosts_started_total == 1


OTHER_USER_PROBE = """
import sys
import grpc

# Opens a session at the device host (bytes in, bytes out: no weft import), then asks for the
# first user's array with its own session and with the first user's session id.
target, open_body, describe_body, foreign_session = sys.argv[1:5]
channel = grpc.insecure_channel("unix:" + target)
opened = channel.unary_unary("/weft.v1.SessionService/Open")(bytes.fromhex(open_body), timeout=20)
# OpenSessionResponse field 1 is the session id (a short string: tag, length, bytes).
assert opened[0] == 0x0A
own = opened[2:2 + opened[1]].decode()
print("OPENED", own)
for label, session in (("own", own), ("foreign", foreign_session)):
    try:
        channel.unary_unary("/weft.v1.ArrayService/Describe")(
            bytes.fromhex(describe_body), metadata=(("weft-session", session),), timeout=20)
        print("DESCRIBED", label)
    except grpc.RpcError as err:
        print("REFUSED", label, err.code().name, err.details())
channel.close()
"""


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="needs root: a client is run as another Unix user (uid 65534)")
def test_another_user_shares_the_device_host_but_not_its_arrays(start_weftd, tmp_path):
    """A device host serves every local principal of its device, so another Unix user (uid
    65534, who can reach the socket because an operator opened it to everyone) opens a session
    in the same process; its session cannot name the first user's array, and naming the first
    user's session is refused: sessions stay bound to their principal inside a shared host."""
    import shutil
    import tempfile

    from test_session_hosts import _python_for_another_user
    from weft.v1 import array_pb2, session_pb2

    daemon = start_weftd(["--device-hosts"])
    host = _open(daemon, "cpu").session_host
    public = Path(tempfile.mkdtemp(prefix="weft-other-user-"))
    try:
        with daemon.raw_session("first user", target="unix:" + host) as first:
            info = first.create_array(np.random.default_rng().standard_normal(64).astype(np.float32))
            os.chmod(public, 0o755)
            os.chmod(host, 0o666)
            link = public / "host.sock"
            try:
                os.link(host, link)
            except OSError as err:
                pytest.skip(f"cannot link the socket where another user can reach it: {err}")
            python = _python_for_another_user()
            if python is None:
                pytest.skip("no Python with grpc that another user may run on this machine")
            proc = subprocess.run(
                [python[0], "-c", OTHER_USER_PROBE, str(link),
                 session_pb2.OpenSessionRequest(client_name="another user").SerializeToString().hex(),
                 array_pb2.DescribeArrayRequest(handle=info.handle).SerializeToString().hex(),
                 first.session_id],
                user=65534, group=65534, extra_groups=[], capture_output=True, text=True, timeout=60,
                env={"PATH": "/usr/bin:/bin", "HOME": str(public), "PYTHONPATH": python[1]})
            assert proc.returncode == 0, proc.stderr
            lines = proc.stdout.splitlines()
            assert lines[0].startswith("OPENED ") and lines[0].split()[1] != first.session_id, lines
            assert lines[1].startswith("REFUSED own NOT_FOUND"), lines
            assert lines[2].startswith("REFUSED foreign PERMISSION_DENIED"), lines
            assert np.array_equal(first.read_array(info.handle).size, 64)
    finally:
        shutil.rmtree(public, ignore_errors=True)


def test_device_hosts_end_with_the_daemon(start_weftd, wait_for):
    """A daemon killed outright takes its device hosts along (each checks its parent on a
    timer); one stopped normally stops them."""
    daemon = start_weftd(["--device-hosts"])
    opened = _open(daemon, "cpu")
    pid = _open(daemon, "cpu", target="unix:" + opened.session_host).daemon_pid
    assert pid != daemon.pid and _alive(pid)
    os.kill(daemon.pid, signal.SIGKILL)
    daemon.proc.wait(timeout=10)
    wait_for(lambda: not _alive(pid), 10)
    from test_session_hosts import _Exited

    daemon.proc = _Exited()


@pytest.mark.parametrize("flags", [["--host-device", "cuda:x"], ["--host-device", "gpu"],
                                   ["--host-device", "cpu", "--host-principal", "unix-uid:0"]])
def test_host_flags_are_checked(daemon_path, flags):
    """The flags the daemon gives a device host are checked like any other: a device that is not
    cpu or cuda:N, or a device host that also names a principal, stops weftd with exit code 2."""
    proc = subprocess.run([str(daemon_path), "--listen", "unix:/nonexistent/w.sock"] + flags,
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "--host-device" in proc.stderr, proc.stderr


EXPORTER = '''
import sys
import numpy as np
import weft as wp

a = wp.array(np.arange(64, dtype=np.float32), dtype=float, device="cpu")
print(a.ipc_handle().decode(), flush=True)
sys.stdin.readline()
'''

IMPORTER = '''
import sys
import numpy as np
import weft as wp

try:
    b = wp.from_ipc_handle(sys.argv[1].encode(), dtype=wp.float32, shape=(64,))
    print("OPENED", np.array_equal(b.numpy(), np.arange(64, dtype=np.float32)))
except Exception as exc:
    print("REFUSED", exc)
'''


def test_exports_open_in_sessions_of_the_same_device_host(start_weftd, client_env, tmp_path):
    """An array exported with ipc_handle() opens in another session of the same device host;
    a session in another device's host does not hold it and gets the clear error for a token
    that names nothing (needs a GPU, for a second host)."""
    daemon = start_weftd(["--device-hosts"])
    gpus = _gpus(daemon)
    if not gpus:
        pytest.skip("needs a GPU: every session of a machine without one is in the CPU's host")
    exporter_file, importer_file = tmp_path / "exporter.py", tmp_path / "importer.py"
    exporter_file.write_text(EXPORTER)
    importer_file.write_text(IMPORTER)
    env = {"WEFT_ADDRESS": daemon.address, "WEFT_SESSION_DEVICE": gpus[0]}
    exporter = subprocess.Popen([sys.executable, str(exporter_file)], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True, env=client_env(env))
    try:
        token = exporter.stdout.readline().strip()
        assert token, "the exporter printed no token"
        results = {}
        for device in (gpus[0], "cpu"):
            proc = subprocess.run([sys.executable, str(importer_file), token], capture_output=True,
                                  text=True, timeout=120,
                                  env=client_env({**env, "WEFT_SESSION_DEVICE": device}))
            assert proc.returncode == 0, proc.stderr
            results[device] = proc.stdout.strip()
        assert results[gpus[0]] == "OPENED True", results
        assert results["cpu"].startswith("REFUSED") and "IPC token" in results["cpu"], results
    finally:
        exporter.kill()
        exporter.wait()


def test_a_session_opened_as_its_device_host_dies_gets_a_new_one(start_weftd, wait_for):
    """A device host killed just before a client opens a session: the daemon may still name the
    dead host's socket (it reaps on a timer), whose connect then fails; the client asks the
    daemon again and gets a new host, whose session works."""
    from weft import _runtime

    daemon = start_weftd(["--device-hosts"])
    first = _runtime.Runtime(address=daemon.address)
    old, device = first.daemon_pid, first.host_device    # the first GPU's host, else the CPU's
    assert first.hosted and device in ("cpu", "cuda:0") and old != daemon.pid
    first.close()
    for _ in range(3):
        os.kill(old, signal.SIGKILL)
        rt = _runtime.Runtime(address=daemon.address)   # at once: the reaper runs every 100 ms
        try:
            assert rt.hosted and rt.host_device == device
            assert rt.daemon_pid != old and _alive(rt.daemon_pid), (rt.daemon_pid, old)
            assert rt.devices()[0].name == "cpu"
        finally:
            rt.close()
        old = rt.daemon_pid


def test_isolation_wins_over_device_hosts(start_weftd):
    """With --isolate-sessions and --device-hosts both, every local session gets a process of
    its own (a session host, no device named), not the device's shared host."""
    daemon = start_weftd(["--device-hosts", "--isolate-sessions"])
    first, second = _open(daemon, "cpu"), _open(daemon, "cpu")
    assert first.session_host and second.session_host and first.session_host != second.session_host
    assert not first.session_device and not second.session_device
