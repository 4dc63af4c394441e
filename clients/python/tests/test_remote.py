"""Remote-style clients over TCP with a token (issue 2, must show): a 256 MiB array written
and read back correctly in chunks (random data, compared); array operations without shared
memory; a wrong or missing token is refused with UNAUTHENTICATED."""
import grpc
import pytest

from weft._runtime import SessionServiceStub
from weft.v1 import session_pb2


def tcp_env(daemon, token="from-daemon"):
    return {"WEFT_ADDRESS": daemon.address,
            "WEFT_TOKEN": daemon.token if token == "from-daemon" else token}


def test_256_mib_round_trip_over_tcp(tcp_weftd, run_client):
    proc = run_client("""
        import time
        import numpy as np
        import weft as wp
        import weft._runtime as rt
        wp.init()
        assert not rt.get_runtime().local
        n = (256 << 20) // 4
        data = np.random.default_rng(13).random(n, dtype=np.float32)
        t0 = time.perf_counter()
        a = wp.array(data, dtype=wp.float32, device="cpu")
        t1 = time.perf_counter()
        assert a._info.shm_name == "", "a remote session must not see shared-memory names"
        back = a.numpy()
        t2 = time.perf_counter()
        assert back.shape == data.shape and back.dtype == np.float32
        assert np.array_equal(back, data)
        # overwrite a middle range in place (Write of a view) and read a strided view back
        patch = np.random.default_rng(14).random(3 << 20, dtype=np.float32)
        a[1 << 20:(1 << 20) + patch.size].assign(patch)
        data[1 << 20:(1 << 20) + patch.size] = patch
        assert np.array_equal(a[::4096].numpy(), data[::4096])
        assert np.array_equal(a.numpy(), data)
        print(f"write {(t1 - t0) * 1e3:.0f} ms, read {(t2 - t1) * 1e3:.0f} ms")
        """, env=tcp_env(tcp_weftd), timeout=300)
    assert "read" in proc.stdout


def test_array_api_over_tcp(tcp_weftd, run_client):
    run_client("""
        import numpy as np
        import weft as wp
        rng = np.random.default_rng(15)
        ref = rng.standard_normal((8, 5))
        a = wp.array(ref)
        a[2:4].fill_(1.5)
        ref[2:4] = 1.5
        a[:, 1].zero_()
        ref[:, 1] = 0
        assert np.array_equal(a.numpy(), ref)
        assert np.array_equal(np.asarray(a), ref)
        try:
            a.__array_interface__
            raise SystemExit("remote arrays must not expose __array_interface__")
        except AttributeError:
            pass
        v = wp.array([(1, 2, 3), (4, 5, 6)], dtype=wp.vec3)
        assert v.numpy().tolist() == [[1, 2, 3], [4, 5, 6]]
        c = wp.clone(a)
        wp.copy(c, wp.zeros_like(a), count=5)
        ref2 = ref.copy().reshape(-1)
        ref2[:5] = 0
        assert np.array_equal(c.numpy().reshape(-1), ref2)
        assert wp.full(3, 7, dtype=wp.int64).numpy().tolist() == [7, 7, 7]
        b = wp.zeros(4)
        token = b.ipc_handle()
        assert token
        """, env=tcp_env(tcp_weftd))


@pytest.mark.parametrize("token", ["wrong-token", None])
def test_wrong_or_missing_token_is_refused(tcp_weftd, run_client, token):
    proc = run_client("""
        import weft as wp
        try:
            wp.init()
        except wp.WeftError as err:
            print("CODE", err.code)
            raise SystemExit(0)
        raise SystemExit("a wrong token was accepted")
        """, env=tcp_env(tcp_weftd, token))
    assert "CODE UNAUTHENTICATED" in proc.stdout


def test_wrong_token_raw(tcp_weftd):
    with grpc.insecure_channel(tcp_weftd.grpc_target) as channel:
        stub = SessionServiceStub(channel)
        for metadata in ((("authorization", "Bearer nope"),), (),
                         (("authorization", tcp_weftd.token),)):
            with pytest.raises(grpc.RpcError) as info:
                stub.Open(session_pb2.OpenSessionRequest(client_name="intruder"),
                          metadata=metadata, timeout=10)
            assert info.value.code() == grpc.StatusCode.UNAUTHENTICATED
        opened = stub.Open(session_pb2.OpenSessionRequest(client_name="pytest"),
                           metadata=tcp_weftd.metadata(), timeout=10)
        assert opened.session_id and not opened.local
        # a valid session id with a wrong token is still refused
        with pytest.raises(grpc.RpcError) as info:
            stub.Stats(session_pb2.StatsRequest(),
                       metadata=(("authorization", "Bearer nope"),
                                 ("weft-session", opened.session_id)), timeout=10)
        assert info.value.code() == grpc.StatusCode.UNAUTHENTICATED
        stub.Close(session_pb2.CloseSessionRequest(session_id=opened.session_id),
                   metadata=tcp_weftd.metadata(opened.session_id), timeout=10)
