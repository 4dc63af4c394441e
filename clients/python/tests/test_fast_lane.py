"""The fast lane (docs/protocol.md "Fast lane"): a local client's Submit and Synchronize go over
a Unix SOCK_SEQPACKET socket bound to its session, not gRPC. Checks that the client uses it,
that results and errors are the same as through gRPC, and attacks on it: a wrong secret, a
wrong session, a secret used twice, garbage, a short frame, an oversized frame, an unknown
method, a frame after the session closed, a peer that sends no hello, another Unix user holding
the secret (when the suite runs as root). After each, the daemon
keeps serving (the module's last test launches through the lane again)."""
import os
import socket
import struct
import sys
import time

import numpy as np
import pytest

import weft as wp
from weft import _fast_lane, _runtime
from weft.v1 import array_pb2, exec_pb2, session_pb2

HELLO, SUBMIT, SYNCHRONIZE = 1, 2, 3
MAX_REQUEST_BYTES = 160 << 10   # server/fast_lane.h kMaxRequestBytes


@wp.kernel
def lane_saxpy(x: wp.array(dtype=float), y: wp.array(dtype=float), a: float):
    i = wp.tid()
    y[i] = a * x[i] + y[i]


@wp.kernel
def lane_oob(data: wp.array(dtype=float), n: int):
    i = wp.tid()
    data[i + n] = 1.0


def _runtime_with_lane(wp_module):
    rt = _runtime.get_runtime()
    if os.environ.get("WEFT_FAST_LANE", "1") == "0":
        pytest.skip("WEFT_FAST_LANE=0 in this environment")
    assert rt.local, "the test daemon is on a Unix socket"
    assert rt.fast_lane is not None and not rt.fast_lane.broken, "the daemon offers a fast lane to a local client"
    return rt


def _open_session(rt):
    """A second session of this process (gRPC Open), with its fast-lane path and secret."""
    opened = rt.session_stub.Open(session_pb2.OpenSessionRequest(client_name="lane attack"),
                                  metadata=rt._base_metadata, timeout=30)
    assert opened.fast_lane_path and len(opened.fast_lane_secret) >= 32
    return opened


def _close_session(rt, session_id):
    rt.session_stub.Close(session_pb2.CloseSessionRequest(session_id=session_id),
                          metadata=rt._base_metadata, timeout=30)


def _connect(path):
    s = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    s.settimeout(10)
    s.connect(path)
    return s


def _send(s, method, body=b""):
    s.send(struct.pack("<I", method) + body)


def _reply(s):
    """(code, flags, payload) of one reply frame; None when the daemon closed the connection."""
    frame = s.recv(1 << 20)
    if not frame:
        return None
    code, flags = struct.unpack_from("<II", frame)
    return code, flags, frame[8:]


def _hello(session_id, secret):
    return session_pb2.FastLaneHello(session_id=session_id, secret=secret).SerializeToString()


def _assert_refused_and_closed(s, code_name):
    reply = _reply(s)
    assert reply is not None, "an error reply comes before the daemon closes"
    code, flags, payload = reply
    assert _fast_lane._CODE_NAMES[code] == code_name, payload
    assert flags & 2, "the reply says the connection ends"
    assert _reply(s) is None, "the daemon closed the connection"


def test_fast_lane_is_used_and_computes_like_grpc(wp, monkeypatch):
    rt = _runtime_with_lane(wp)
    calls = []
    real = rt.fast_lane.call

    def counting(method, request, response_type, *spin):
        calls.append(method)
        return real(method, request, response_type, *spin)

    monkeypatch.setattr(rt.fast_lane, "call", counting)
    rng = np.random.default_rng(5)
    n = 10_001
    x0 = rng.uniform(-1, 1, n).astype(np.float32)
    y0 = rng.uniform(-1, 1, n).astype(np.float32)
    results = []
    for lane in (rt.fast_lane, None):   # fast lane, then gRPC only
        rt.fast_lane = lane
        try:
            x = wp.array(x0, dtype=float, device="cpu")
            y = wp.array(y0, dtype=float, device="cpu")
            wp.launch(lane_saxpy, dim=n, inputs=[x, y, 1.5], device="cpu")
            wp.synchronize()
            results.append(y.numpy().copy())
        finally:
            rt.fast_lane = real.__self__
    assert SUBMIT in calls or SYNCHRONIZE in calls, "the launch and sync went through the fast lane"
    ref = 1.5 * x0.astype(np.float64) + y0.astype(np.float64)
    # float32 result of a*x + y: a few ulp of the largest term
    bound = 4 * np.finfo(np.float32).eps * (np.abs(1.5 * x0) + np.abs(y0) + 1e-30)
    assert np.all(np.abs(results[0] - ref) <= bound)
    np.testing.assert_array_equal(results[0], results[1])


def test_fast_lane_errors_are_the_grpc_errors(wp):
    rt = _runtime_with_lane(wp)
    lane = rt.fast_lane
    messages = []
    for use in (lane, None):
        rt.fast_lane = use
        try:
            data = wp.zeros(8, dtype=float, device="cpu")
            wp.launch(lane_oob, dim=4, inputs=[data, 6], device="cpu")
            with pytest.raises(wp.WeftError) as err:
                wp.synchronize()
            messages.append((str(err.value), getattr(err.value, "code", None)))
        finally:
            rt.fast_lane = lane
    assert messages[0] == messages[1]
    assert "lane_oob" in messages[0][0]
    # A Submit the daemon refuses (an empty command: nothing of the batch is queued): same
    # status and message through both transports, and the lane stays open.
    bad = exec_pb2.SubmitRequest()
    bad.commands.add().origin.line = 3
    errors = []
    with pytest.raises(Exception) as via_lane:
        lane.call(SUBMIT, bad, exec_pb2.SubmitResponse)
    with pytest.raises(Exception) as via_grpc:
        rt.call(rt.exec_stub.Submit, bad)
    for e in (via_lane.value, via_grpc.value):
        errors.append((str(e), getattr(e, "code", None)))
    assert errors[0] == errors[1]
    assert not lane.broken
    wp.synchronize()


@pytest.mark.parametrize("case", ["wrong secret", "wrong session", "secret used twice", "other session's secret"])
def test_fast_lane_hello_refused(wp, case):
    rt = _runtime_with_lane(wp)
    a = _open_session(rt)
    b = _open_session(rt)
    try:
        if case == "secret used twice":
            first = _connect(a.fast_lane_path)
            _send(first, HELLO, _hello(a.session_id, a.fast_lane_secret))
            code, _, _ = _reply(first)
            assert code == 0
            first.close()
        s = _connect(a.fast_lane_path)
        hello = {
            "wrong secret": _hello(a.session_id, bytes(len(a.fast_lane_secret))),
            "wrong session": _hello("f" * 64, a.fast_lane_secret),
            "secret used twice": _hello(a.session_id, a.fast_lane_secret),
            "other session's secret": _hello(a.session_id, b.fast_lane_secret),
        }[case]
        _send(s, HELLO, hello)
        _assert_refused_and_closed(s, "PERMISSION_DENIED")
        s.close()
    finally:
        _close_session(rt, a.session_id)
        _close_session(rt, b.session_id)


@pytest.mark.parametrize("case", ["garbage hello", "short frame", "Submit before hello", "oversized hello"])
def test_fast_lane_bad_first_frame(wp, case):
    rt = _runtime_with_lane(wp)
    a = _open_session(rt)
    try:
        s = _connect(a.fast_lane_path)
        if case == "garbage hello":
            _send(s, HELLO, b"\xff\xfe\x00garbage" * 10)
        elif case == "short frame":
            s.send(b"\x01\x00")
        elif case == "oversized hello":   # over the 1 KiB a connection may send before its hello
            _send(s, HELLO, _hello(a.session_id, a.fast_lane_secret) + b"\x00" * 2048)
        else:
            _send(s, SUBMIT, exec_pb2.SubmitRequest().SerializeToString())
        _assert_refused_and_closed(s, "INVALID_ARGUMENT")
        s.close()
        # the refused hello did not use up the secret
        s = _connect(a.fast_lane_path)
        _send(s, HELLO, _hello(a.session_id, a.fast_lane_secret))
        assert _reply(s)[0] == 0
        s.close()
    finally:
        _close_session(rt, a.session_id)


def test_fast_lane_peer_without_hello_is_dropped(wp):
    """A connection that sends nothing is closed by the daemon after its hello timeout (5 s),
    and does not use up the session's secret."""
    import time

    rt = _runtime_with_lane(wp)
    a = _open_session(rt)
    try:
        s = _connect(a.fast_lane_path)
        s.settimeout(20)
        t0 = time.monotonic()
        assert s.recv(1 << 16) == b"", "the daemon closes a silent connection"
        assert 3.0 <= time.monotonic() - t0 <= 15.0
        s.close()
        s = _connect(a.fast_lane_path)
        _send(s, HELLO, _hello(a.session_id, a.fast_lane_secret))
        assert _reply(s)[0] == 0
        s.close()
    finally:
        _close_session(rt, a.session_id)


def test_fast_lane_another_unix_user_is_refused(start_weftd):
    """A process of another uid (`nobody`; the sockets opened up deliberately) that holds a
    session's id and lane secret is refused: the lane checks the peer uid of its own
    connection. The secret stays usable by its owner."""
    import subprocess
    import sys
    import textwrap
    from pathlib import Path

    import grpc

    if os.getuid() != 0:
        pytest.skip("needs root to run a client as another user")
    daemon = start_weftd()
    os.chmod(daemon.workdir, 0o755)
    os.chmod(daemon.socket_path, 0o666)
    lane_path = str(daemon.socket_path) + ".fast"
    os.chmod(lane_path, 0o666)
    channel = grpc.insecure_channel(daemon.address)
    try:
        stub = _runtime.SessionServiceStub(channel)
        opened = stub.Open(session_pb2.OpenSessionRequest(client_name="root owner"), timeout=10)
        assert opened.fast_lane_path == lane_path
        hello = struct.pack("<I", HELLO) + _hello(opened.session_id, opened.fast_lane_secret)
        code = textwrap.dedent(f"""
            import os, socket, struct
            os.setgid(65534); os.setuid(65534)
            s = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            s.connect({lane_path!r})
            s.send({hello!r})
            frame = s.recv(1 << 16)
            print("reply", struct.unpack_from("<I", frame)[0], frame[8:].decode(), flush=True)
        """)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
        assert "reply 7 " in out.stdout, out.stdout + out.stderr   # PERMISSION_DENIED
        s = _connect(lane_path)
        _send(s, HELLO, _hello(opened.session_id, opened.fast_lane_secret))
        assert _reply(s)[0] == 0
        s.close()
        stub.Close(session_pb2.CloseSessionRequest(session_id=opened.session_id),
                   metadata=(("weft-session", opened.session_id),), timeout=10)
    finally:
        channel.close()
    assert "hello refused from unix-uid:65534" in daemon.log()


def _bound_lane(rt):
    a = _open_session(rt)
    s = _connect(a.fast_lane_path)
    _send(s, HELLO, _hello(a.session_id, a.fast_lane_secret))
    assert _reply(s)[0] == 0
    return a, s


@pytest.mark.parametrize("case", ["garbage Submit", "unknown method", "oversized frame", "after close"])
def test_fast_lane_bad_frame_after_hello(wp, case):
    rt = _runtime_with_lane(wp)
    a, s = _bound_lane(rt)
    try:
        _send(s, SYNCHRONIZE, exec_pb2.SynchronizeRequest().SerializeToString())
        code, flags, payload = _reply(s)
        assert code == 0 and not flags & 2
        exec_pb2.SynchronizeResponse.FromString(payload)
        expected = "INVALID_ARGUMENT"
        if case == "garbage Submit":
            _send(s, SUBMIT, b"\x0a\xff\xff\xff\xff\x0f" + b"\x00" * 20)
        elif case == "unknown method":
            _send(s, 77, b"")
        elif case == "oversized frame":
            s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
            size = MAX_REQUEST_BYTES + 4096
            if s.getsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF) < size + 1024:
                pytest.skip("the socket send buffer cannot hold a frame over the daemon's limit")
            _send(s, SUBMIT, b"\x00" * size)
        else:
            _close_session(rt, a.session_id)
            _send(s, SYNCHRONIZE, exec_pb2.SynchronizeRequest().SerializeToString())
            expected = "FAILED_PRECONDITION"
        _assert_refused_and_closed(s, expected)
    finally:
        s.close()
        try:
            _close_session(rt, a.session_id)
        except Exception:  # noqa: BLE001 - closed above
            pass


@wp.kernel
def lane_add(data: wp.array(dtype=float), x: float):
    i = wp.tid()
    data[i] = data[i] + x


def test_fast_lane_keeps_order_of_early_submits(wp, monkeypatch):
    """300 dependent launches, sent in early (pipelined) batches through the lane without
    waiting for their replies, then one sync: every launch ran, in order."""
    rt = _runtime_with_lane(wp)
    sent = []
    real_call, real_send = rt.fast_lane.call, rt.fast_lane.send

    def counting_call(method, request, response_type, *spin):
        sent.append((method, "call"))
        return real_call(method, request, response_type, *spin)

    def counting_send(method, request, response_type):
        sent.append((method, "send"))
        return real_send(method, request, response_type)

    real_quiet = rt.fast_lane.send_quiet

    def counting_quiet(body):          # a Submit answered only if it fails: sent, not awaited
        sent.append((SUBMIT, "send"))
        return real_quiet(body)

    monkeypatch.setattr(rt.fast_lane, "call", counting_call)
    monkeypatch.setattr(rt.fast_lane, "send", counting_send)
    monkeypatch.setattr(rt.fast_lane, "send_quiet", counting_quiet)
    monkeypatch.setattr(rt, "pipelined", True)
    data = wp.zeros(64, dtype=float, device="cpu")
    wp.synchronize()
    total = 0.0
    for k in range(300):
        wp.launch(lane_add, dim=64, inputs=[data, float(k + 1)], device="cpu")
        total += k + 1
    got = data.numpy()
    np.testing.assert_array_equal(got, np.full(64, total, dtype=np.float32))
    assert (SUBMIT, "send") in sent, f"early Submits went through the lane without waiting: {sent}"


def test_fast_lane_starts_a_slow_loop_of_launches_before_pump_first(wp, monkeypatch, wait_for):
    """Through the lane, two queued launches the older of which waited PUMP_AFTER_LANE_S go out
    as an early Submit (the device starts before PUMP_FIRST launches were queued), and they
    run before any sync point; a single launch then a sync stays one fused Submit."""
    import time

    rt = _runtime_with_lane(wp)
    if not rt.local:
        pytest.skip("needs a local session: numpy() of a CPU array is a view there")
    calls = []
    real_call, real_send = rt.fast_lane.call, rt.fast_lane.send

    def commands(request):          # Submits travel serialized (Runtime.framed_command)
        if type(request) is bytes:
            request = exec_pb2.SubmitRequest.FromString(request)
        return len(getattr(request, "commands", ()))

    def logged_call(method, request, response_type, *spin):
        calls.append((method, "call", commands(request)))
        return real_call(method, request, response_type, *spin)

    def logged_send(method, request, response_type):
        calls.append((method, "send", commands(request)))
        return real_send(method, request, response_type)

    real_quiet = rt.fast_lane.send_quiet

    def logged_quiet(body):
        calls.append((SUBMIT, "send", commands(body)))
        return real_quiet(body)

    monkeypatch.setattr(rt.fast_lane, "call", logged_call)
    monkeypatch.setattr(rt.fast_lane, "send", logged_send)
    monkeypatch.setattr(rt.fast_lane, "send_quiet", logged_quiet)
    monkeypatch.setattr(rt, "pipelined", True)
    rng = np.random.default_rng()
    values = rng.standard_normal(64).astype(np.float32)
    data = wp.array(values, dtype=float, device="cpu")
    view = data.numpy()   # synchronized; a view of the daemon's memory from here on
    calls.clear()
    steps = [float(x) for x in rng.uniform(0.5, 2.0, size=2)]
    wp.launch(lane_add, dim=64, inputs=[data, steps[0]], device="cpu")
    time.sleep(max(2 * _runtime.PUMP_AFTER_LANE_S, 0.001))
    wp.launch(lane_add, dim=64, inputs=[data, steps[1]], device="cpu")
    assert calls == [(SUBMIT, "send", 2)], calls
    expected = values.astype(np.float64) + np.float32(steps[0]) + np.float32(steps[1])
    assert wait_for(lambda: np.allclose(view, expected, rtol=1e-5, atol=1e-5), 20), \
        "the early Submit did not run before a sync point"
    wp.synchronize()
    calls.clear()
    wp.launch(lane_add, dim=64, inputs=[data, 1.0], device="cpu")
    wp.synchronize()
    assert calls == [(SUBMIT, "call", 1)], calls
    np.testing.assert_allclose(view, expected + 1.0, rtol=1e-5, atol=1e-5)


def test_fast_lane_rejected_early_submit_raises_at_the_next_sync(wp, monkeypatch):
    """An early Submit the daemon refuses (sent through the lane without waiting) is raised by
    the next synchronize, as through gRPC, and the lane stays usable."""
    import time

    rt = _runtime_with_lane(wp)
    monkeypatch.setattr(rt, "pipelined", True)
    # The refused batch is the first PUMP_FIRST commands, however slowly this machine queues them.
    monkeypatch.setattr(_runtime, "PUMP_AFTER_LANE_S", 60.0)
    data = wp.zeros(4, dtype=float, device="cpu")
    wp.synchronize()
    with rt._lock:
        rt._batch_since = time.perf_counter()
        rt._batch.append(_runtime.framed_command(exec_pb2.Command()))   # empty: refused whole
    rt._unsynchronized = True
    for _ in range(_runtime.PUMP_FIRST - 1):
        wp.launch(lane_add, dim=4, inputs=[data, 1.0], device="cpu")
    with pytest.raises(wp.WeftError) as err:
        wp.synchronize()
    assert err.value.code == "INVALID_ARGUMENT"
    wp.synchronize()
    np.testing.assert_array_equal(data.numpy(), 0.0)
    wp.launch(lane_add, dim=4, inputs=[data, 2.0], device="cpu")
    np.testing.assert_array_equal(data.numpy(), 2.0)
    assert not rt.fast_lane.broken


def test_fast_lane_keeps_serving(wp):
    """After the attacks above, this process's own lane still launches and syncs."""
    rt = _runtime_with_lane(wp)
    rng = np.random.default_rng(9)
    x0 = rng.uniform(-1, 1, 1000).astype(np.float32)
    y0 = rng.uniform(-1, 1, 1000).astype(np.float32)
    x = wp.array(x0, dtype=float, device="cpu")
    y = wp.array(y0, dtype=float, device="cpu")
    wp.launch(lane_saxpy, dim=1000, inputs=[x, y, -0.5], device="cpu")
    wp.synchronize()
    assert rt.fast_lane is not None and not rt.fast_lane.broken
    ref = -0.5 * x0.astype(np.float64) + y0.astype(np.float64)
    assert np.max(np.abs(y.numpy() - ref)) <= 4 * np.finfo(np.float32).eps * 2.0


def test_fast_lane_off_by_environment(run_client):
    out = run_client("""
        import weft as wp
        from weft import _runtime
        wp.init()
        print("lane", _runtime.get_runtime().fast_lane is None)
    """, env={"WEFT_FAST_LANE": "0"})
    assert "lane True" in out.stdout


ARRAY_CREATE, ARRAY_FREE, ARRAY_DESCRIBE, ARRAY_IMPORT_CUDA = 4, 5, 6, 7
ARRAY_FREE_UNANSWERED = 10


def test_fast_lane_carries_array_create_describe_free(wp, monkeypatch):
    """wp.zeros / wp.array / .grad / freed arrays go over the lane (no gRPC round trip), with
    the same arrays as through gRPC: Create answers with the gradient's description (no
    Describe for .grad), released arrays go in one unanswered Free frame, and are gone."""
    rt = _runtime_with_lane(wp)
    assert rt.fast_lane.unanswered_free, "the daemon's hello offers unanswered frees"
    methods, freed = [], []
    real_call, real_many = rt.fast_lane.call, rt.fast_lane.call_many
    real_free = rt.fast_lane.send_unanswered_free
    monkeypatch.setattr(rt.fast_lane, "call", lambda m, r, t, *s: (methods.append(m), real_call(m, r, t, *s))[1])
    monkeypatch.setattr(rt.fast_lane, "call_many", lambda m, rs: (methods.extend([m] * len(rs)), real_many(m, rs))[1])
    monkeypatch.setattr(rt.fast_lane, "send_unanswered_free",
                        lambda body: (freed.append(body), real_free(body))[1])
    rng = np.random.default_rng(11)
    x0 = rng.uniform(-1e3, 1e3, 1001).astype(np.float32)
    z = wp.zeros(1001, dtype=float, device="cpu", requires_grad=True)
    x = wp.array(x0, dtype=float, device="cpu")
    g = z.grad
    assert methods.count(ARRAY_CREATE) == 2 and ARRAY_DESCRIBE not in methods, methods
    described = rt.array_stub.Describe(array_pb2.DescribeArrayRequest(handle=z._info.grad_handle),
                                       metadata=rt.metadata, timeout=30).info
    assert g._info == described, "Create's gradient description is what Describe returns"
    wp.launch(lane_saxpy, dim=1001, inputs=[x, z, 2.0], device="cpu")
    np.testing.assert_array_equal(z.numpy(), 2.0 * x0)   # exact: one float32 product each
    assert not g.numpy().any()
    handles = {x._handle, z._handle}
    del x, z, g
    import gc
    gc.collect()
    wp.synchronize()
    sent = set()
    for body in freed:
        sent.update(array_pb2.FreeArrayRequest.FromString(body).handles)
    assert handles <= sent, "the freed arrays went over the lane, unanswered"
    for h in handles:   # gRPC after the lane's frees (fenced): the daemon no longer holds them
        with pytest.raises(wp.WeftError) as err:
            rt.call(rt.array_stub.Describe, array_pb2.DescribeArrayRequest(handle=h))
        assert err.value.code == "NOT_FOUND"


def test_unanswered_free_reaches_only_the_own_session(wp):
    """An unanswered Free naming another session's handle (and unknown ones) frees nothing of
    theirs, gets no reply, frees the lane's own session's handle in order, and the lane serves
    on."""
    rt = _runtime_with_lane(wp)
    from weft.v1 import types_pb2
    rng = np.random.default_rng(23)
    x0 = rng.uniform(-1e6, 1e6, 64).astype(np.float32)
    other = wp.array(x0, dtype=float, device="cpu")   # this process's session: not the lane's
    a, s = _bound_lane(rt)   # another session of this process, on a lane of its own
    try:
        meta = (("weft-session", a.session_id),) + tuple(m for m in rt._base_metadata if m[0] != "weft-session")
        own = rt.array_stub.Create(array_pb2.CreateArrayRequest(
            dtype=types_pb2.DType(scalar=types_pb2.FLOAT32), shape=[8], device="cpu"),
            metadata=meta, timeout=30).info.handle
        _send(s, ARRAY_FREE_UNANSWERED, array_pb2.FreeArrayRequest(
            handle=other._handle, handles=[other._handle, (1 << 63) + 99, 0, own]).SerializeToString())
        # the first reply on the connection answers this Describe: nothing answered the free,
        # which was served before it (the handle is gone)
        _send(s, ARRAY_DESCRIBE, array_pb2.DescribeArrayRequest(handle=own).SerializeToString())
        code, flags, payload = _reply(s)
        assert code != 0 and b"unknown array handle" in payload, payload
        _send(s, SYNCHRONIZE, exec_pb2.SynchronizeRequest().SerializeToString())
        assert _reply(s)[0] == 0, "the lane serves on"
        np.testing.assert_array_equal(other.numpy(), x0)   # still there, its bytes untouched
        assert rt.call(rt.array_stub.Describe, array_pb2.DescribeArrayRequest(
            handle=other._handle)).info.handle == other._handle
    finally:
        s.close()


def test_a_free_of_too_many_handles_is_refused_whole(wp):
    """FreeArrayRequest.handles is bounded (65536): more is refused with INVALID_ARGUMENT through
    gRPC, and nothing named in it is freed (the unanswered lane frame cannot carry that many)."""
    rt = _runtime_with_lane(wp)
    rng = np.random.default_rng()
    x0 = rng.uniform(-1e3, 1e3, 32).astype(np.float32)
    a = wp.array(x0, dtype=float, device="cpu")
    wp.synchronize()
    handles = [a._handle] + [int(h) for h in rng.integers(1, 1 << 62, 65536)]
    with pytest.raises(wp.WeftError) as err:
        rt.call(rt.array_stub.Free, array_pb2.FreeArrayRequest(handles=handles))
    assert err.value.code == "INVALID_ARGUMENT" and "65537 handles" in str(err.value), err.value
    np.testing.assert_array_equal(a.numpy(), x0)
    assert rt.call(rt.array_stub.Describe, array_pb2.DescribeArrayRequest(
        handle=a._handle)).info.handle == a._handle


def test_fast_lane_array_errors_are_the_grpc_errors(wp):
    """A bad shape, an unknown handle, another session's handle, a CUDA import on the CPU or
    with a short IPC handle: through a bound lane the same
    status and message as through gRPC, and the lane stays open."""
    rt = _runtime_with_lane(wp)
    from weft.v1 import array_pb2, types_pb2
    mine = wp.zeros(4, dtype=float, device="cpu")
    a, s = _bound_lane(rt)   # another session of this process, on a lane of its own
    try:
        cases = [
            (ARRAY_CREATE, "Create", array_pb2.CreateArrayRequest(
                dtype=types_pb2.DType(scalar=types_pb2.FLOAT32), shape=[1 << 40, 1 << 40], device="cpu")),
            (ARRAY_DESCRIBE, "Describe", array_pb2.DescribeArrayRequest(handle=mine._handle)),
            (ARRAY_FREE, "Free", array_pb2.FreeArrayRequest(handle=mine._handle)),
            (ARRAY_DESCRIBE, "Describe", array_pb2.DescribeArrayRequest(handle=(1 << 63) + 12345)),
            (ARRAY_IMPORT_CUDA, "ImportCuda", array_pb2.ImportCudaRequest(
                device="cpu", dtype=types_pb2.DType(scalar=types_pb2.FLOAT32), shape=[4],
                data=array_pb2.CudaMemoryRef(ipc_handle=b"\x01" * 64, allocation_id=1))),
            (ARRAY_IMPORT_CUDA, "ImportCuda", array_pb2.ImportCudaRequest(
                device="cuda:0", dtype=types_pb2.DType(scalar=types_pb2.FLOAT32), shape=[4],
                data=array_pb2.CudaMemoryRef(ipc_handle=b"\x01" * 63, allocation_id=1))),
        ]
        meta = (("weft-session", a.session_id),) + tuple(m for m in rt._base_metadata if m[0] != "weft-session")
        for method, name, request in cases:
            _send(s, method, request.SerializeToString())
            code, flags, payload = _reply(s)
            assert code != 0 and not flags & 2, (name, payload)
            with pytest.raises(Exception) as via_grpc:
                rt.call(lambda req, metadata, timeout: getattr(rt.array_stub, name)(req, metadata=meta, timeout=timeout),
                        request)
            via_lane = wp.WeftError(payload.decode(), _fast_lane._CODE_NAMES[code])
            assert str(via_lane) == str(via_grpc.value), name
            assert via_lane.code == via_grpc.value.code, name
        # The other session's array is untouched and still this session's.
        assert mine.numpy().shape == (4,) and not mine.numpy().any()
        _send(s, SYNCHRONIZE, exec_pb2.SynchronizeRequest().SerializeToString())
        assert _reply(s)[0] == 0
        _send(s, ARRAY_CREATE, b"\x0a\xff\xff\xff\xff\x0f" + b"\x00" * 20)   # does not parse
        _assert_refused_and_closed(s, "INVALID_ARGUMENT")
    finally:
        s.close()
        _close_session(rt, a.session_id)


GEOMETRY_CALL = 8


@wp.kernel
def lane_grid_ids(grid: wp.uint64, out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = wp.hash_grid_point_id(grid, i)


def test_fast_lane_carries_geometry_calls(wp, monkeypatch):
    """HashGrid/Mesh creates go over the lane as geometry calls, and builds, refits and
    rebuilds as commands of the lane's Submits (a refit every step costs no round trip at all),
    with the same objects as through gRPC; another session's object id and an unknown operation
    get the gRPC errors through a bound lane, and it stays open."""
    rt = _runtime_with_lane(wp)
    methods = []
    real_call = rt.fast_lane.call
    monkeypatch.setattr(rt.fast_lane, "call", lambda m, r, t, *s: (methods.append(m), real_call(m, r, t, *s))[1])
    rng = np.random.default_rng(5)
    pts = wp.array(rng.uniform(-2, 2, size=(300, 3)).astype(np.float32), dtype=wp.vec3, device="cpu")
    grid = wp.HashGrid(8, 8, 8, device="cpu")
    grid.build(pts, 0.5)
    ids = wp.zeros(300, dtype=int, device="cpu")
    wp.launch(lane_grid_ids, dim=300, inputs=[grid.id, ids], device="cpu")
    assert sorted(ids.numpy().tolist()) == list(range(300))
    tri = wp.array(np.array([0, 1, 2, 2, 1, 3], dtype=np.int32), dtype=int, device="cpu")
    mesh = wp.Mesh(points=pts, indices=tri)
    mesh.refit()
    mesh.rebuild()
    assert methods.count(GEOMETRY_CALL) == 2, methods   # the two creates; the rest in Submits
    from weft.v1 import geometry_pb2
    a, s = _bound_lane(rt)   # another session of this process, on a lane of its own
    try:
        meta = (("weft-session", a.session_id),) + tuple(m for m in rt._base_metadata if m[0] != "weft-session")
        stub = _runtime._make_stub_class(geometry_pb2.DESCRIPTOR.services_by_name["GeometryService"])(rt.channel)
        for request in (geometry_pb2.GeometryRequest(op=geometry_pb2.GeometryRequest.REFIT, id=mesh.id),
                        geometry_pb2.GeometryRequest(op=99, id=mesh.id)):
            _send(s, GEOMETRY_CALL, request.SerializeToString())
            code, flags, payload = _reply(s)
            assert code != 0 and not flags & 2, payload
            with pytest.raises(Exception) as via_grpc:
                rt.call(lambda req, metadata, timeout: stub.Call(req, metadata=meta, timeout=timeout), request)
            via_lane = wp.WeftError(payload.decode(), _fast_lane._CODE_NAMES[code])
            assert str(via_lane) == str(via_grpc.value)
        # the build's groups field through the lane: a float array, a wrong length, another
        # session's handle, an unknown handle are each refused by the daemon, not the client
        other_grid = geometry_pb2.GeometryRequest(op=geometry_pb2.GeometryRequest.CREATE_HASH_GRID,
                                                  device="cpu", dim=[4, 4, 4])
        _send(s, GEOMETRY_CALL, other_grid.SerializeToString())
        code, _, payload = _reply(s)
        assert code == 0
        gid = geometry_pb2.GeometryResponse.FromString(payload).id
        from weft.v1 import array_pb2, types_pb2
        handles = {}
        for name, scalar, n in (("float", types_pb2.FLOAT32, 300), ("short", types_pb2.INT32, 299),
                                ("points", types_pb2.FLOAT32, 300)):
            req = array_pb2.CreateArrayRequest(dtype=types_pb2.DType(scalar=scalar), shape=[n], device="cpu")
            if name == "points":
                req.dtype.elem_shape.append(3)
            _send(s, ARRAY_CREATE, req.SerializeToString())
            code, _, payload = _reply(s)
            assert code == 0, payload
            handles[name] = array_pb2.CreateArrayResponse.FromString(payload).info.handle
        for groups, match in ((handles["float"], b"expected int32"),
                              (handles["short"], b"299 group ids for 300 points"),
                              (ids._handle, b"unknown array handle"),       # this process's other session
                              ((1 << 63) + 99, b"unknown array handle")):
            req = geometry_pb2.GeometryRequest(op=geometry_pb2.GeometryRequest.BUILD_HASH_GRID, id=gid,
                                               points=handles["points"], radius=0.5, groups=groups)
            _send(s, GEOMETRY_CALL, req.SerializeToString())
            code, flags, payload = _reply(s)
            assert code != 0 and not flags & 2 and match in payload, payload
        _send(s, SYNCHRONIZE, exec_pb2.SynchronizeRequest().SerializeToString())
        assert _reply(s)[0] == 0
    finally:
        s.close()
        _close_session(rt, a.session_id)
    wp.launch(lane_grid_ids, dim=300, inputs=[grid.id, ids], device="cpu")   # still this session's
    assert sorted(ids.numpy().tolist()) == list(range(300))


def test_array_calls_fall_back_to_grpc_when_the_lane_refuses_them(wp, run_client):
    """A daemon whose lane does not serve a method ends the lane on it (unknown method): the
    client then serves the call, and every later one, through gRPC. Run in a child client, so
    this process keeps its lane."""
    out = run_client('''
        import numpy as np
        import weft as wp
        from weft import _runtime
        wp.init()
        rt = _runtime.get_runtime()
        assert rt.fast_lane is not None and not rt.fast_lane.broken
        _runtime.Runtime._LANE_ARRAY_METHODS["Create"] = (77, _runtime.array_pb2.CreateArrayResponse)
        z = wp.full(17, 2.5, dtype=float, device="cpu")
        assert rt.fast_lane.broken, "the daemon ended the lane on the unknown method"
        y = wp.zeros(17, dtype=float, device="cpu")
        wp.copy(y, z)
        wp.synchronize()
        assert (y.numpy() == np.float32(2.5)).all() and (z.numpy() == np.float32(2.5)).all()
        del z
        wp.synchronize()
        print("FELL BACK")
    ''').stdout
    assert "FELL BACK" in out, out


def test_array_calls_over_grpc_when_turned_off(wp, monkeypatch):
    """Runtime.lane_arrays False (WEFT_FAST_LANE_ARRAYS=0): array calls go through gRPC while
    Submit still uses the lane."""
    rt = _runtime_with_lane(wp)
    methods = []
    real_call = rt.fast_lane.call
    monkeypatch.setattr(rt.fast_lane, "call", lambda m, r, t, *s: (methods.append(m), real_call(m, r, t, *s))[1])
    monkeypatch.setattr(rt, "lane_arrays", False)
    z = wp.full(9, 1.25, dtype=float, device="cpu")
    wp.launch(lane_add, dim=9, inputs=[z, 0.5], device="cpu")
    np.testing.assert_array_equal(z.numpy(), np.full(9, 1.75, np.float32))
    assert ARRAY_CREATE not in methods and (SUBMIT in methods or SYNCHRONIZE in methods)


def test_fast_lane_polling_after_sync_replies(start_weftd, run_client, monkeypatch, tmp_path):
    """After a synchronizing reply the daemon's lane thread polls for the next frame a short
    while (server/fast_lane.cpp SpinReceive; WEFT_LANE_POLLERS forces it on this machine) and
    the client polls for the reply (WEFT_FAST_LANE_SPIN_US). Frames that come at once, and
    after the poll gave up, are served alike; a launch + synchronize loop computes exactly;
    a bounds error is reported with its line; garbage and an oversized frame right after a
    synchronizing reply are refused and end that connection, and the daemon keeps serving."""
    import time

    import grpc

    monkeypatch.setenv("WEFT_LANE_POLLERS", "2")
    daemon = start_weftd()
    code = """
import numpy as np
import weft as wp
from weft import _runtime
rt = _runtime.get_runtime()
assert rt.fast_lane is not None
@wp.kernel
def step(x: wp.array(dtype=wp.float64), k: wp.float64):
    i = wp.tid()
    x[i] = x[i] * k + wp.float64(1.0)
@wp.kernel
def oob(x: wp.array(dtype=wp.float64), n: int):
    i = wp.tid()
    x[i + n] = 1.0
rng = np.random.default_rng()
x0 = rng.uniform(-1e6, 1e6, 257)
x = wp.array(x0, dtype=wp.float64)
ref = x0.copy()
for j in range(300):
    k = float(rng.uniform(0.5, 1.5))
    wp.launch(step, dim=257, inputs=[x, k])
    wp.synchronize()
    ref = ref * k + 1.0
assert np.array_equal(x.numpy(), ref), np.max(np.abs(x.numpy() - ref))
wp.launch(oob, dim=4, inputs=[x, 256])
try:
    wp.synchronize()
    raise SystemExit("no bounds error")
except Exception as err:
    assert "out of bounds" in str(err) or "outside" in str(err), err
    print("error:", err)
wp.launch(step, dim=257, inputs=[x, 1.0])
wp.synchronize()
print("ok", rt.fast_lane is not None and not rt.fast_lane.broken)
"""
    script = tmp_path / "lane_poll_client.py"      # kernels need a source file
    script.write_text(code)
    code = f"import runpy; runpy.run_path({str(script)!r})"
    out = run_client(code, env={"WEFT_ADDRESS": daemon.address, "WEFT_FAST_LANE_SPIN_US": "300"})
    assert "ok True" in out.stdout, out.stdout + out.stderr
    assert "lane_poll_client.py:14" in out.stdout, out.stdout     # the bounds error's line

    channel = grpc.insecure_channel(daemon.address)
    try:
        stub = _runtime.SessionServiceStub(channel)
        for bad in (b"\x0a\xff\xff\xff\xff\x0f" + b"\x00" * 20, None):
            opened = stub.Open(session_pb2.OpenSessionRequest(client_name="poll"), timeout=10)
            s = _connect(opened.fast_lane_path)
            _send(s, HELLO, _hello(opened.session_id, opened.fast_lane_secret))
            assert _reply(s)[0] == 0
            sync = exec_pb2.SynchronizeRequest().SerializeToString()
            for pause in (0.0, 0.0, 0.002, 0.0, 0.05, 0.0):   # within and after the poll
                time.sleep(pause)
                _send(s, SYNCHRONIZE, sync)
                code_, flags, _ = _reply(s)
                assert code_ == 0 and not flags & 2
            _send(s, SYNCHRONIZE, sync)
            assert _reply(s)[0] == 0
            if bad is None:             # oversized, sent right after a synchronizing reply
                s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
                size = MAX_REQUEST_BYTES + 4096
                if s.getsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF) < size + 1024:
                    s.close()
                    continue
                bad = b"\x00" * size
            _send(s, SUBMIT, bad)
            _assert_refused_and_closed(s, "INVALID_ARGUMENT")
            s.close()
            stub.Close(session_pb2.CloseSessionRequest(session_id=opened.session_id),
                       metadata=(("weft-session", opened.session_id),), timeout=10)
    finally:
        channel.close()
    out = run_client(code, env={"WEFT_ADDRESS": daemon.address, "WEFT_FAST_LANE_SPIN_US": "0"})
    assert "ok True" in out.stdout, out.stdout + out.stderr


def test_lane_trace_reports_each_kind_of_frame(start_weftd, run_client, monkeypatch, tmp_path):
    """WEFT_LANE_TRACE: when a lane's connection ends, weftd appends one line per kind of frame
    it served, with the frame count and the median of each phase; a launch + synchronize loop
    shows as `submit+sync` frames (`submit-gpu+sync` where the default device is a GPU; with a
    ring, `submit-gpu` frames and `synchronize` ones), a bare synchronize as `synchronize`, and
    the numbers parse."""
    import re

    trace = tmp_path / "lane-trace.txt"
    monkeypatch.setenv("WEFT_LANE_TRACE", str(trace))
    daemon = start_weftd()
    code = """
import weft as wp
from weft import _runtime
assert _runtime.get_runtime().fast_lane is not None
@wp.kernel
def bump(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] + 1.0
x = wp.zeros(16, dtype=float)
wp.synchronize()
for _ in range(25):
    wp.launch(bump, dim=16, inputs=[x])
    wp.synchronize()
wp.synchronize()
assert x.numpy()[0] == 25.0
_runtime.shutdown()
print("done")
"""
    script = tmp_path / "trace_client.py"
    script.write_text(code)
    out = run_client(f"import runpy; runpy.run_path({str(script)!r})", env={"WEFT_ADDRESS": daemon.address})
    assert "done" in out.stdout, out.stdout + out.stderr
    import time

    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and "kind=submit" not in (trace.read_text() if trace.exists() else ""):
        time.sleep(0.05)
    text = trace.read_text()
    line = re.search(r"kind=submit(?:-gpu)?(?:\+sync)? frames=(\d+) median_us: before=([\d.]+) parse=([\d.]+) "
                     r"serve=([\d.]+) \(device_sync=([\d.]+) stream_wait=([\d.]+) polls=(\d+) "
                     r"gpu_launch=([\d.]+) driver_launch=([\d.]+)\) reply=([\d.]+)", text)
    assert line, text
    # On a GPU where the lane has a ring, the first launch after a sync point goes out at once
    # (`submit-gpu`) and its synchronize follows as a frame of its own.
    submits = sum(int(n) for n in re.findall(r"kind=submit[-a-z+]* frames=(\d+)", text))
    assert submits >= 25, text
    assert all(float(v) >= 0 for v in line.groups()[1:]), text
    assert float(line.group(4)) > 0, text       # the engine did run the launches
    # and how many frames' stream waits blocked on a host function (GPU streams only)
    assert re.search(r"kind=submit(?:-gpu)?(?:\+sync)? frames=\d+ .* reply=[\d.]+ blocked_frames=\d+\n", text), text
    assert "kind=synchronize" in text, text


def test_finalizers_inside_the_runtime_do_not_disturb_it(wp, monkeypatch):
    """A captured graph refers to itself (Warp's `graph.graph`), so the garbage collector
    finalizes it, at whatever allocation it runs: inside the runtime too, while the runtime
    walks its Submits in flight or its frees. Here a collector callback drops a graph, a
    daemon tape, a geometry object or an array whenever a collection starts inside the
    runtime's own code (weft/_runtime.py on the stack), late (replies arrive meanwhile), so
    their finalizers run at its allocation points during bursts of pipelined launches and
    array calls. They only queue their commands (the next batch takes them): nothing of the
    runtime changes under its own iteration, and every launch still runs, in order."""
    import gc
    import sys
    import time

    rt = _runtime_with_lane(wp)
    monkeypatch.setattr(rt, "pipelined", True)
    rng = np.random.default_rng(int.from_bytes(os.urandom(4), "little"))
    data = wp.array(rng.uniform(-1, 1, 64).astype(np.float32), dtype=float, device="cpu")
    start = data.numpy().astype(np.float64)
    pool = []
    for _ in range(60):
        with wp.ScopedCapture(device="cpu") as capture:
            wp.launch(lane_add, dim=64, inputs=[data, 0.0], device="cpu")
        tape = wp.Tape()
        with tape:
            wp.launch(lane_add, dim=64, inputs=[data, 0.0], device="cpu")
        pool += [wp.zeros(16, dtype=float, device="cpu"), wp.HashGrid(2, 2, 2, device="cpu"),
                 tape, capture.graph]
    del capture, tape
    wp.synchronize()
    runtime_file = _runtime.__file__
    dropped = []

    def drop_one(phase, info):
        if phase != "start" or not pool:
            return
        frame = sys._getframe(1)
        while frame is not None and frame.f_code.co_filename != runtime_file:
            frame = frame.f_back
        if frame is None:
            return
        time.sleep(0.0005)                    # a late finalizer: replies arrive meanwhile
        obj = pool.pop()
        if isinstance(obj, wp.Graph):
            obj.graph = None                  # no cycle left: finalized right here
        dropped.append((type(obj).__name__, frame.f_code.co_name))
        del obj

    total = 0.0
    thresholds = gc.get_threshold()
    gc.set_threshold(1, 1, 1)
    gc.callbacks.append(drop_one)
    try:
        for k in range(100):
            for _ in range(10):
                wp.launch(lane_add, dim=64, inputs=[data, float(k + 1)], device="cpu")
                total += k + 1
            wp.zeros(8, dtype=float, device="cpu")
    finally:
        gc.callbacks.remove(drop_one)
        gc.set_threshold(*thresholds)
    assert len(dropped) > 100, f"finalizers ran inside the runtime {len(dropped)} times"
    got = data.numpy().astype(np.float64)
    np.testing.assert_allclose(got, start + total, rtol=1e-6, atol=1e-3)
    assert not rt.fast_lane.broken


def test_a_synchronize_after_gpu_launches_polls_longer(wp, monkeypatch):
    """A synchronize that waits for GPU work polls for its reply for SPIN_GPU_S (CUDA's own
    synchronize spins too); any other call keeps SPIN_S; the flag is cleared by the
    synchronize. Checked on the CPU by marking the session's work as GPU work."""
    from weft import _fast_lane

    rt = _runtime_with_lane(wp)
    spins = []
    real_call = rt.fast_lane.call
    monkeypatch.setattr(rt.fast_lane, "call",
                        lambda m, r, t, *s: (spins.append((m, s)), real_call(m, r, t, *s))[1])
    monkeypatch.setattr(_fast_lane, "SPIN_GPU_S", 0.02)
    z = wp.zeros(4, dtype=float, device="cpu")
    wp.launch(lane_saxpy, dim=4, inputs=[z, z, 1.0], device="cpu")
    assert not rt.gpu_work                   # CPU launches are not GPU work
    rt.gpu_work = True
    wp.synchronize()
    assert spins and spins[-1][0] in (_fast_lane.SUBMIT, _fast_lane.SYNCHRONIZE)
    assert spins[-1][1] == (0.02,) and not rt.gpu_work
    spins.clear()
    wp.launch(lane_saxpy, dim=4, inputs=[z, z, 1.0], device="cpu")
    wp.synchronize()
    assert spins and all(s in ((), (None,)) for _, s in spins)
    monkeypatch.setattr(_fast_lane, "SPIN_GPU_S", 0.0)   # 0: a GPU wait polls as long as any
    rt.gpu_work = True
    spins.clear()
    wp.synchronize()
    assert spins[-1][1] in ((), (None,))


def test_quiet_submit_is_answered_only_when_it_fails(wp):
    """SUBMIT_QUIET (asynchronous batches): the hello's reply offers it; a batch it queues gets
    no reply (the next frame read answers the next request); a batch the daemon refuses, or one
    that asks to synchronize or run (nothing would answer it), gets its error with the quiet
    flag, in order, read on the way to the next reply; the connection stays usable."""
    from weft import _fast_lane

    rt = _runtime_with_lane(wp)
    opened = _open_session(rt)
    s = _connect(opened.fast_lane_path)
    try:
        _send(s, _fast_lane.HELLO, _hello(opened.session_id, opened.fast_lane_secret))
        code, flags, payload = _reply(s)
        assert code == 0 and b"quiet-submit" in payload.split(), payload
        bad = exec_pb2.SubmitRequest()
        bad.commands.add().origin.line = 3               # no command in it: refused whole
        sync = exec_pb2.SubmitRequest(synchronize=True)
        run = exec_pb2.SubmitRequest(run=True)
        empty = exec_pb2.SubmitRequest()
        for request in (empty, bad, sync, empty, run, bad):
            _send(s, _fast_lane.SUBMIT_QUIET, request.SerializeToString())
        _send(s, _fast_lane.SYNCHRONIZE, exec_pb2.SynchronizeRequest().SerializeToString())
        replies = []
        while True:
            code, flags, payload = _reply(s)
            replies.append((code, flags, payload))
            if not flags & _fast_lane.QUIET_REPLY_FLAG:
                break
        quiet = replies[:-1]
        assert len(quiet) == 4, replies                  # bad, sync, run, bad: in order
        assert all(code != 0 and not flags & 2 for code, flags, _ in quiet), quiet
        assert b"cannot synchronize or run" in quiet[1][2] and b"cannot synchronize or run" in quiet[2][2]
        assert quiet[0][2] == quiet[3][2]                # the same refusal as a plain Submit's
        code, flags, payload = replies[-1]
        assert code == 0 and not flags & 2, replies[-1]   # the Synchronize's own answer
        exec_pb2.SynchronizeResponse.FromString(payload)
        # the lane still serves: a plain Submit's refusal has the same message, unflagged
        _send(s, _fast_lane.SUBMIT, bad.SerializeToString())
        code, flags, payload = _reply(s)
        assert code != 0 and not flags & _fast_lane.QUIET_REPLY_FLAG and payload == quiet[0][2]
    finally:
        s.close()
        _close_session(rt, opened.session_id)


def test_quiet_submit_failure_is_raised_at_the_next_synchronize(wp, monkeypatch):
    """Through the client: an asynchronous batch the daemon refuses (sent quietly) is raised by
    the next wp.synchronize, with the message a plain Submit gets; nothing of it ran; the next
    synchronize is clean and later launches run. Also with the failures drained by polling
    (more quiet Submits than LANE_IN_FLIGHT between synchronizes)."""
    rt = _runtime_with_lane(wp)
    if not rt.fast_lane.quiet:
        pytest.skip("the daemon's lane does not offer quiet Submits")
    monkeypatch.setattr(rt, "pipelined", True)
    data = wp.zeros(8, dtype=float, device="cpu")
    wp.synchronize()
    sent = []
    real_quiet = rt.fast_lane.send_quiet
    monkeypatch.setattr(rt.fast_lane, "send_quiet", lambda body: (sent.append(body), real_quiet(body))[1])
    bad = exec_pb2.Command()
    bad.origin.line = 3
    with rt._lock:
        rt._batch.append(_runtime.framed_command(bad))   # refused whole when it goes out
        rt._batch_since = time.perf_counter()
        rt._unsynchronized = True
        rt.send_now()
    assert sent, "the batch went out as a quiet Submit"
    with pytest.raises(wp.WeftError) as err:
        wp.synchronize()
    assert err.value.code == "INVALID_ARGUMENT", err.value
    wp.synchronize()                                   # taken: nothing more to report
    np.testing.assert_array_equal(data.numpy(), 0.0)
    # many quiet Submits, each refused, then good launches: the failures are drained as the
    # client goes on (poll every LANE_IN_FLIGHT sends) and the first is raised
    for _ in range(3 * _runtime.LANE_IN_FLIGHT):
        with rt._lock:
            rt._batch.append(_runtime.framed_command(bad))
            rt._unsynchronized = True
            rt._send_batch()
    # taken by polling (as the sends poll every LANE_IN_FLIGHT), before any synchronize; the
    # replies may still be on their way when the last send polled, so poll until they are in
    deadline = time.monotonic() + 10
    while rt._deferred_error is None and rt.fast_lane.quiet_error is None and \
            time.monotonic() < deadline:
        with rt._lock:
            rt.fast_lane.poll_quiet()
            rt._take_quiet()
        time.sleep(0.001)
    assert rt._deferred_error is not None or rt.fast_lane.quiet_error is not None
    with pytest.raises(wp.WeftError):
        wp.synchronize()
    values = np.random.default_rng().uniform(0.5, 2.0, 8).astype(np.float32)
    x = wp.array(values, dtype=float, device="cpu")
    wp.launch(lane_saxpy, dim=8, inputs=[x, data, 2.0], device="cpu")
    np.testing.assert_allclose(data.numpy(), 2.0 * values.astype(np.float64), rtol=1e-6)


def _send_quiet_fills(rt, targets, value):
    """Fills of `targets` with float32 `value` sent at once as one quiet Submit (nothing
    answers it, nothing fences it yet)."""
    with rt._lock:
        for target in targets:
            rt._batch.append(_runtime.framed_command(exec_pb2.Command(fill=exec_pb2.FillCommand(
                dst=target._ref(), value=value.tobytes()))))
        rt._batch_since = time.perf_counter()
        rt._unsynchronized = True
        rt.send_now()
    assert rt._quiet_unfenced


def test_a_grpc_read_comes_after_the_quiet_frames_before_it(wp, monkeypatch):
    """A fill sent as a quiet Submit, then at once a gRPC read of the same array (the path of a
    remote or non-mapped array): the read sees the fill, every time (Runtime.order_grpc fences
    the lane first; gRPC and the lane are not ordered with each other)."""
    rt = _runtime_with_lane(wp)
    if not rt.fast_lane.quiet:
        pytest.skip("the daemon's lane does not offer quiet Submits")
    monkeypatch.setattr(rt, "pipelined", True)
    array_mod = sys.modules["weft.array"]
    rng = np.random.default_rng()
    n = int(rng.integers(50_000, 70_000))
    a = wp.zeros(n, dtype=float, device="cpu")
    wp.synchronize()
    for _ in range(20):
        value = np.float32(rng.uniform(-1e6, 1e6))
        _send_quiet_fills(rt, [a], value)
        remote = type(a._info)()
        remote.CopyFrom(a._info)
        remote.shm_name = ""                    # read as a remote client reads: through gRPC
        got = array_mod._read_bytes(rt, remote, 0, 4 * n).view(np.float32)
        np.testing.assert_array_equal(got, value)


def test_a_grpc_free_comes_after_the_quiet_frames_that_use_the_array(wp, monkeypatch):
    """Frees through gRPC (array calls off the lane, WEFT_FAST_LANE_ARRAYS=0) right after a
    quiet Submit that uses the freed array: the Submit's command still finds the array, every
    time (a free that overtook the lane's unread frame made the command fail with "unknown
    array handle": the Torch Rosenbrock loop on the H200). Each gRPC free is sent only once
    the lane was fenced, and the fills all landed."""
    rt = _runtime_with_lane(wp)
    if not rt.fast_lane.quiet:
        pytest.skip("the daemon's lane does not offer quiet Submits")
    monkeypatch.setattr(rt, "pipelined", True)
    monkeypatch.setattr(rt, "lane_arrays", False)
    sent_unfenced = []
    free = rt.array_stub.Free

    class _ObservedFree:                        # Free, with whether the lane was fenced noted
        def future(self, request, **kwargs):
            sent_unfenced.append(rt._quiet_unfenced)
            return free.future(request, **kwargs)

        def __call__(self, request, **kwargs):
            return free(request, **kwargs)

    monkeypatch.setattr(rt.array_stub, "Free", _ObservedFree())
    rng = np.random.default_rng()
    keep = wp.zeros(1000, dtype=float, device="cpu")
    for _ in range(30):
        n = int(rng.integers(100_000, 400_000))
        a = wp.zeros(n, dtype=float, device="cpu")
        wp.synchronize()
        value = np.float32(rng.uniform(-1e6, 1e6))
        _send_quiet_fills(rt, [a, keep], value)
        del a                                   # its free goes out through gRPC now
        rt.drain_frees()
        wp.synchronize()                        # raised "unknown array handle" when it overtook
        np.testing.assert_array_equal(keep.numpy(), value)
    assert sent_unfenced and not any(sent_unfenced), "a gRPC free went out before the lane was fenced"
