"""Unchecked sessions run in processes of their own (session hosts, server/session_hosts.h): a
weftd started with --allow-unchecked sends a session opened unchecked to a weftd it starts for
that session alone. These tests attack it: an unchecked kernel that writes far out of bounds
crashes its host and nothing else (another session's array on the daemon stays readable and the
daemon keeps serving), the crashed client's next call opens a new session by itself, a host
serves one session and only its principal (another Unix user who reaches its socket is
refused), hosts are bounded per principal, a host's socket has the daemon socket's mode and
group, a remote client gets no host, a host ends with its session, without one and
with its daemon, and a session that asks for unchecked kernels where they are not allowed stays
checked."""
import os
import time
from pathlib import Path

import grpc
import numpy as np
import pytest

CRASHER = '''
import time
import numpy as np
import weft as wp
import weft._runtime as runtime

wp.set_module_options({"bounds_checks": False})


@wp.kernel
def wild(a: wp.array(dtype=float), n: int):
    i = wp.tid()
    a[i * n] = 1.0


@wp.kernel
def add_one(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] + 1.0


a = wp.array(np.arange(16, dtype=np.float32), dtype=float, device="cpu")
first = runtime.get_runtime()
print("HOSTED", first.hosted, first.daemon_pid, first.address)
wp.launch(add_one, dim=16, inputs=[a], device="cpu")
print("BEFORE", a.numpy().tolist() == list(range(1, 17)))
t = time.perf_counter()
try:
    wp.launch(wild, dim=4096, inputs=[a, 1 << 26], device="cpu")
    wp.synchronize()
    print("CRASH none")
except Exception as exc:
    print("CRASH", exc)
b = wp.array(np.arange(8, dtype=np.float32), dtype=float, device="cpu")
wp.launch(add_one, dim=8, inputs=[b], device="cpu")
ok = b.numpy().tolist() == list(range(1, 9))
second = runtime.get_runtime()
print("AFTER", ok, second.hosted, second.daemon_pid != first.daemon_pid,
      f"{1e3 * (time.perf_counter() - t):.1f} ms")
try:
    wp.launch(add_one, dim=16, inputs=[a], device="cpu")
    wp.synchronize()
    print("OLD usable")
except Exception as exc:
    print("OLD", exc)
'''


def _run_file(tmp_path, client_env, code: str, address: str) -> str:
    """Runs `code` as a script file (kernels need their source in a file) against `address`."""
    import subprocess
    import sys

    script = tmp_path / f"client_{time.monotonic_ns()}.py"
    script.write_text(code)
    proc = subprocess.run([sys.executable, str(script)], env=client_env({"WEFT_ADDRESS": address}),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"client failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _stat_fields(pid: int) -> list[str]:
    """/proc/<pid>/stat after the command name (state, parent pid, ...); [] once it is gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return []


def _host_pids(daemon_pid: int) -> list[int]:
    """The session hosts the daemon started (its children named weftd)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        fields = _stat_fields(int(entry.name))
        try:
            if fields and int(fields[1]) == daemon_pid and "weftd" in (entry / "comm").read_text():
                pids.append(int(entry.name))
        except OSError:
            continue
    return pids


def test_an_unchecked_crash_ends_its_own_process_only(start_weftd, client_env, tmp_path, wait_for):
    daemon = start_weftd(["--allow-unchecked"])
    with daemon.raw_session("bystander") as bystander:
        values = np.random.default_rng().standard_normal(1000).astype(np.float32)
        held = bystander.create_array(values)
        out = _run_file(tmp_path, client_env, CRASHER, daemon.address)
        print(out)
        assert "HOSTED True" in out and f"host-{daemon.pid}-" in out, out
        assert "BEFORE True" in out, out
        assert "CRASH " in out and "CRASH none" not in out, out
        assert "session host pid" in out and "the next weft call opens a new session" in out, out
        assert "AFTER True True True" in out, out          # a new host, by itself
        assert "OLD " in out and "unknown array handle" in out, out   # an array of the ended session
        # The daemon and the other session were never touched.
        assert _alive(daemon.pid)
        assert np.array_equal(bystander.read_array(held.handle), values)
        stats = daemon.stats()
        assert stats.session_hosts_started_total >= 2
        assert "ended with signal" in daemon.log()
    wait_for(lambda: daemon.stats().session_hosts == 0, 10)
    assert not list(Path(daemon.socket_path).parent.glob("host-*.sock"))
    assert not [f for f in os.listdir("/dev/shm") if f.startswith("weft-") and
                not _alive(int(f.split("-")[1]))]


def _open_unchecked(daemon):
    from weft.v1 import session_pb2
    from weft import _runtime

    channel = grpc.insecure_channel(daemon.grpc_target)
    stub = _runtime.SessionServiceStub(channel)
    reply = stub.Open(session_pb2.OpenSessionRequest(client_name="raw unchecked", unchecked=True),
                      timeout=90)
    channel.close()
    return reply


def test_a_host_serves_one_session_and_ends_with_it(start_weftd, wait_for):
    daemon = start_weftd(["--allow-unchecked", "--max-session-hosts", "1"])
    # An operator opened the daemon's socket to its group: a host's socket follows it.
    os.chmod(daemon.socket_path, 0o660)
    reply = _open_unchecked(daemon)
    assert reply.session_host and not reply.session_id
    assert os.stat(reply.session_host).st_mode & 0o777 == 0o660
    assert os.stat(reply.session_host).st_gid == os.stat(daemon.socket_path).st_gid
    target = "unix:" + reply.session_host
    # The principal's one host is taken: another unchecked session is refused until it ends.
    with pytest.raises(grpc.RpcError) as refused:
        _open_unchecked(daemon)
    assert refused.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert "--max-session-hosts 1" in refused.value.details()
    hosts = _host_pids(daemon.pid)
    assert len(hosts) == 1
    with daemon.raw_session("in the host", target=target) as session:
        assert session.opened.session_id and session.opened.daemon_pid == hosts[0]
        with pytest.raises(grpc.RpcError) as second:
            daemon.raw_session("second in the host", target=target)
        assert second.value.code() == grpc.StatusCode.FAILED_PRECONDITION
        assert "serves one session" in second.value.details()
        values = np.random.default_rng().standard_normal(64).astype(np.float32)
        info = session.create_array(values)
        assert np.array_equal(session.read_array(info.handle), values)
        # Checked sessions stay on the daemon itself.
        with daemon.raw_session("checked") as checked:
            assert checked.opened.session_id and not checked.opened.session_host
            assert checked.opened.daemon_pid == daemon.pid
    # Its session closed: the host ends, its sockets go, and the slot is free again.
    wait_for(lambda: not _alive(hosts[0]) or not _host_pids(daemon.pid), 10)
    wait_for(lambda: daemon.stats().session_hosts == 0, 10)
    assert not Path(reply.session_host).exists()
    assert _open_unchecked(daemon).session_host


def test_a_host_without_a_session_ends(start_weftd, wait_for):
    daemon = start_weftd(["--allow-unchecked", "--attach-timeout", "1"])
    reply = _open_unchecked(daemon)
    hosts = _host_pids(daemon.pid)
    assert len(hosts) == 1
    wait_for(lambda: daemon.stats().session_hosts == 0, 15)
    assert not _alive(hosts[0]) and not Path(reply.session_host).exists()


@pytest.mark.parametrize("isolate", [False, True])
def test_unchecked_is_refused_where_not_allowed(start_weftd, client_env, tmp_path, isolate):
    """Without --allow-unchecked an unchecked request opens an ordinary session: the bounds
    check still fires (no crash). With --isolate-sessions the session runs in a session host,
    which inherits the daemon's refusal: checked all the same."""
    daemon = start_weftd(["--isolate-sessions"] if isolate else [])
    reply = _open_unchecked(daemon)
    if isolate:
        assert reply.session_host and not reply.session_id
    else:
        assert reply.session_id and not reply.session_host and reply.daemon_pid == daemon.pid
    out = _run_file(tmp_path, client_env, '''
import numpy as np
import weft as wp
import weft._runtime as runtime
wp.set_module_options({"bounds_checks": False})

@wp.kernel
def past_end(a: wp.array(dtype=float)):
    a[wp.tid() + 100] = 1.0

a = wp.zeros(4, dtype=float, device="cpu")
print("HOSTED", runtime.get_runtime().hosted)
try:
    wp.launch(past_end, dim=1, inputs=[a], device="cpu")
    wp.synchronize()
    print("CHECK none")
except Exception as exc:
    print("CHECK", exc)
''', daemon.address)
    assert f"HOSTED {isolate}" in out and "out of bounds" in out.lower(), out


def test_remote_clients_get_no_host(start_weftd, wait_for):
    """A TCP client (which could not reach a host's Unix socket) asking for an unchecked
    session gets an ordinary, checked one from the daemon; a local client of the same daemon
    gets a host. (That a host refuses another local user: test_a_host_refuses_another_user.)"""
    daemon = start_weftd(["--allow-unchecked"], also_tcp=True)
    from weft.v1 import session_pb2
    from weft import _runtime

    channel = grpc.insecure_channel(daemon.tcp_target)
    stub = _runtime.SessionServiceStub(channel)
    reply = stub.Open(session_pb2.OpenSessionRequest(client_name="tcp unchecked", unchecked=True),
                      metadata=(("authorization", f"Bearer {daemon.token}"),), timeout=30)
    channel.close()
    # A remote client gets no host (it could not reach a Unix socket): an ordinary session.
    assert reply.session_id and not reply.session_host
    local = _open_unchecked(daemon)
    assert local.session_host
    with daemon.raw_session("in the host", target="unix:" + local.session_host) as session:
        assert session.opened.session_id
    wait_for(lambda: daemon.stats().session_hosts == 0, 10)


OTHER_USER_CLIENT = """
import sys
import grpc

# Opens a session on each target with the serialized OpenSessionRequest given, as whoever
# runs this (bytes in, bytes out: no weft import).
body = bytes.fromhex(sys.argv[1])
for target in sys.argv[2:]:
    channel = grpc.insecure_channel("unix:" + target)
    try:
        channel.unary_unary("/weft.v1.SessionService/Open")(body, timeout=20)
        print("OPENED", target)
    except grpc.RpcError as err:
        print("REFUSED", target, err.code().name, err.details())
    channel.close()
"""


def _reachable_by_others(path) -> bool:
    """Whether any user can reach `path`: every directory on the way searchable by others and
    the file itself readable by them."""
    resolved = Path(path).resolve()
    try:
        return all(os.stat(d).st_mode & 0o001 for d in resolved.parents) and \
            bool(os.stat(resolved).st_mode & 0o004)
    except OSError:
        return False


def _python_for_another_user():
    """(interpreter, PYTHONPATH) another user can run with grpc importable: this Python when
    others can reach it, else the system's interpreter of the same version (grpc's extension
    is built for it); None when there is none."""
    import sys

    import grpc as grpc_module

    packages = str(Path(grpc_module.__file__).resolve().parent.parent)
    if not _reachable_by_others(Path(packages) / "grpc" / "__init__.py"):
        return None
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    for candidate in (sys.executable, f"/usr/bin/python{version}", f"/usr/local/bin/python{version}"):
        if os.path.exists(candidate) and _reachable_by_others(candidate):
            return str(Path(candidate).resolve()), packages
    return None


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="needs root: a client is run as another Unix user (uid 65534)")
def test_a_host_refuses_another_user(start_weftd, wait_for):
    """A session host serves its one principal only. Another Unix user (uid 65534) who can reach
    the host's socket (an operator opened it, and its directory, to everyone) is refused with
    PERMISSION_DENIED, while the same client reaches the daemon's own socket, opened the same
    way, and gets a session there; the host's one session is still free for its principal."""
    import shutil
    import subprocess
    import tempfile

    from weft.v1 import session_pb2

    daemon = start_weftd(["--allow-unchecked"])
    host = _open_unchecked(daemon).session_host
    assert host
    public = Path(tempfile.mkdtemp(prefix="weft-other-user-"))
    try:
        os.chmod(public, 0o755)
        links = {}
        for name, path in (("host", host), ("daemon", str(daemon.socket_path))):
            os.chmod(path, 0o666)
            links[name] = public / f"{name}.sock"
            try:
                os.link(path, links[name])    # the same socket, on a path everyone can walk
            except OSError as err:
                pytest.skip(f"cannot link the socket where another user can reach it: {err}")
        python = _python_for_another_user()
        if python is None:
            pytest.skip("no Python with grpc that another user may run on this machine")
        body = session_pb2.OpenSessionRequest(client_name="another user", unchecked=True)
        proc = subprocess.run(
            [python[0], "-c", OTHER_USER_CLIENT, body.SerializeToString().hex(),
             str(links["host"]), str(links["daemon"])],
            user=65534, group=65534, extra_groups=[], capture_output=True, text=True, timeout=60,
            env={"PATH": "/usr/bin:/bin", "HOME": str(public), "PYTHONPATH": python[1]})
        assert proc.returncode == 0, proc.stderr
        lines = proc.stdout.splitlines()
        assert lines[0].startswith(f"REFUSED {links['host']} PERMISSION_DENIED"), proc.stdout
        assert "session host of another principal" in lines[0], proc.stdout
        assert lines[1].startswith(f"OPENED {links['daemon']}"), proc.stdout
    finally:
        shutil.rmtree(public, ignore_errors=True)
    # The refused user took nothing: the host's principal still gets its one session.
    with daemon.raw_session("the host's principal", target="unix:" + host) as session:
        assert session.opened.session_id
    wait_for(lambda: daemon.stats().session_hosts == 0, 10)


def test_hosts_end_with_the_daemon(start_weftd, wait_for):
    """A daemon killed outright (no chance to stop its hosts) takes its hosts along: each
    checks on a timer that the daemon which started it is still its parent."""
    import signal

    daemon = start_weftd(["--allow-unchecked"])
    _open_unchecked(daemon)
    _open_unchecked(daemon)
    hosts = _host_pids(daemon.pid)
    assert len(hosts) == 2
    os.kill(daemon.pid, signal.SIGKILL)
    daemon.proc.wait(timeout=10)
    wait_for(lambda: not any(_alive(pid) and not _zombie(pid) for pid in hosts), 10)
    # Let the fixture's check pass: the daemon is gone, and so are the hosts and their slabs.
    daemon.proc = _Exited()


class _Exited:
    """Stands in for a daemon process the test already killed (the fixture stops and checks it)."""

    returncode = 0

    def poll(self):
        return 0

    def wait(self, timeout=None):
        return 0

    def send_signal(self, sig):
        pass

    def kill(self):
        pass


def _zombie(pid: int) -> bool:
    return _stat_fields(pid)[:1] == ["Z"]


BYSTANDER = '''
import sys
import numpy as np
import weft as wp
import weft._runtime as runtime

values = np.random.default_rng().standard_normal(1000).astype(np.float32)
devices = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])   # on a GPU too, in the host
held = [wp.array(values, dtype=float, device=d) for d in devices]
rt = runtime.get_runtime()
print("READY", rt.hosted, rt.daemon_pid, flush=True)
sys.stdin.readline()
print("KEPT", all(np.array_equal(h.numpy(), values) for h in held), runtime.get_runtime() is rt,
      flush=True)
'''

KILLED = '''
import os
import signal
import numpy as np
import weft as wp
import weft._runtime as runtime


@wp.kernel
def add_one(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] + 1.0


a = wp.array(np.arange(16, dtype=np.float32), dtype=float, device="cpu")
first = runtime.get_runtime()
print("HOSTED", first.hosted, first.unchecked, first.daemon_pid, flush=True)
wp.launch(add_one, dim=16, inputs=[a], device="cpu")
print("BEFORE", a.numpy().tolist() == list(range(1, 17)))
os.kill(first.daemon_pid, signal.SIGKILL)     # the session's own process dies (a crash)
try:
    wp.launch(add_one, dim=16, inputs=[a], device="cpu")
    wp.synchronize()
    print("LOST none")
except Exception as exc:
    print("LOST", exc)
b = wp.array(np.arange(8, dtype=np.float32), dtype=float, device="cpu")
wp.launch(add_one, dim=8, inputs=[b], device="cpu")
second = runtime.get_runtime()
print("AFTER", b.numpy().tolist() == list(range(1, 9)), second.hosted, second.daemon_pid != first.daemon_pid)
'''


def _daemon_stats(daemon):
    """SessionService.Stats without opening a session (an Open would start a host here)."""
    from weft.v1 import session_pb2
    from weft import _runtime

    channel = grpc.insecure_channel(daemon.grpc_target)
    try:
        return _runtime.SessionServiceStub(channel).Stats(session_pb2.StatsRequest(),
                                                          metadata=daemon.metadata(), timeout=10)
    finally:
        channel.close()


def test_isolated_sessions_each_run_in_a_process_of_their_own(start_weftd, client_env, tmp_path,
                                                              wait_for):
    """weftd with isolate-sessions (here from its config file; no allow-unchecked): every local
    session, checked ones included, runs in a session host. One session's process dying (SIGKILL here: what a fault
    or a crash of weft's own code would do) costs that session only: its client gets the clear
    error, its next call opens a new session in a new host, another client's session (in its own
    host) keeps its array, and the daemon keeps serving; a TCP client gets an ordinary session."""
    import subprocess
    import sys

    config = tmp_path / "weftd.toml"          # the config file's key, as an operator writes it
    config.write_text("isolate-sessions = true\nmax-session-hosts = 3\n")
    daemon = start_weftd(["--config", str(config)], also_tcp=True)
    script = tmp_path / "bystander.py"
    script.write_text(BYSTANDER)
    bystander = subprocess.Popen([sys.executable, str(script)], stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                 env=client_env({"WEFT_ADDRESS": daemon.address}))
    try:
        ready = bystander.stdout.readline().split()
        assert ready[:2] == ["READY", "True"], (ready, bystander.stderr.read() if bystander.poll() else "")
        bystander_host = int(ready[2])
        assert bystander_host != daemon.pid and bystander_host in _host_pids(daemon.pid)
        out = _run_file(tmp_path, client_env, KILLED, daemon.address)
        print(out)
        assert "HOSTED True False" in out, out
        assert "BEFORE True" in out, out
        assert "LOST " in out and "LOST none" not in out, out
        assert "session host pid" in out and "--isolate-sessions" in out, out
        assert "the next weft call opens a new session" in out, out
        assert "AFTER True True True" in out, out
        bystander.stdin.write("go\n")
        bystander.stdin.flush()
        kept = bystander.stdout.readline().split()
        assert kept == ["KEPT", "True", "True"], (kept, bystander.stderr.read())
        assert _alive(daemon.pid) and _alive(bystander_host)
        stats = _daemon_stats(daemon)
        assert stats.session_hosts_started_total >= 3 and stats.sessions == 0, stats
    finally:
        bystander.kill()
        bystander.wait()
    wait_for(lambda: _daemon_stats(daemon).session_hosts == 0, 15)
    # A remote client cannot reach a host's socket: the daemon serves it itself.
    from weft.v1 import session_pb2
    from weft import _runtime

    channel = grpc.insecure_channel(daemon.tcp_target)
    try:
        reply = _runtime.SessionServiceStub(channel).Open(
            session_pb2.OpenSessionRequest(client_name="remote"),
            metadata=(("authorization", f"Bearer {daemon.token}"),), timeout=30)
    finally:
        channel.close()
    assert reply.session_id and not reply.session_host and reply.daemon_pid == daemon.pid
