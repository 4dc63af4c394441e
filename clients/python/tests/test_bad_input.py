"""Bad input gets a clear error and changes nothing (issue 2, must show): unknown handles,
wrong dtype/shape, negative or absurd sizes, out-of-range views, writes of the wrong byte
count, requests without a session. Requests are made by hand with bare gRPC stubs, as a
buggy or hostile client would; each case checks the status code class, that the message
says something, and that the daemon's arrays and the bytes of a canary array are unchanged."""
import grpc
import numpy as np
import pytest

from weft.v1 import array_pb2, exec_pb2, session_pb2, types_pb2

FLOAT32 = 11
REFUSED = {grpc.StatusCode.INVALID_ARGUMENT, grpc.StatusCode.OUT_OF_RANGE,
           grpc.StatusCode.NOT_FOUND, grpc.StatusCode.RESOURCE_EXHAUSTED,
           grpc.StatusCode.FAILED_PRECONDITION}
NO_SESSION = {grpc.StatusCode.UNAUTHENTICATED, grpc.StatusCode.FAILED_PRECONDITION,
              grpc.StatusCode.PERMISSION_DENIED, grpc.StatusCode.INVALID_ARGUMENT}


def f32(shape):
    return types_pb2.DType(scalar=FLOAT32, type_name="float32"), list(shape)


@pytest.fixture
def raw(weftd):
    with weftd.raw_session("pytest bad input") as session:
        yield session


@pytest.fixture
def canary(raw):
    """A 64-float array of known values in the raw session, and a checker."""
    values = np.random.default_rng(12).standard_normal(64).astype(np.float32)
    dtype, shape = f32([64])
    info = raw.arrays.Create(array_pb2.CreateArrayRequest(
        dtype=dtype, shape=shape, device="cpu", init=array_pb2.CreateArrayRequest.DATA,
        value=values.tobytes()), metadata=raw.metadata, timeout=10).info

    def unchanged():
        chunks = raw.arrays.Read(array_pb2.ReadArrayRequest(handle=info.handle),
                                 metadata=raw.metadata, timeout=10)
        data = b"".join(c.data for c in chunks)
        np.testing.assert_array_equal(np.frombuffer(data, np.float32), values)

    return info, unchanged


def expect_refused(call, codes=REFUSED):
    with pytest.raises(grpc.RpcError) as info:
        call()
    assert info.value.code() in codes, f"{info.value.code()}: {info.value.details()}"
    assert info.value.details(), "the error must say what was wrong"
    return info.value


def totals(weftd):
    stats = weftd.stats()
    return stats.arrays, stats.array_bytes


def sync_error(raw):
    response = raw.exec.Synchronize(exec_pb2.SynchronizeRequest(), metadata=raw.metadata,
                                    timeout=30)
    return response


def test_unknown_handle(weftd, raw, canary):
    info, unchanged = canary
    before = totals(weftd)
    bogus = info.handle + 987654321
    md = raw.metadata
    expect_refused(lambda: raw.arrays.Describe(array_pb2.DescribeArrayRequest(handle=bogus),
                                               metadata=md, timeout=10))
    expect_refused(lambda: raw.arrays.Free(array_pb2.FreeArrayRequest(handle=bogus),
                                           metadata=md, timeout=10))
    expect_refused(lambda: list(raw.arrays.Read(array_pb2.ReadArrayRequest(handle=bogus),
                                                metadata=md, timeout=10)))
    expect_refused(lambda: raw.arrays.Export(array_pb2.ExportArrayRequest(handle=bogus),
                                             metadata=md, timeout=10))
    expect_refused(lambda: raw.arrays.Write(iter([array_pb2.WriteArrayRequest(
        handle=bogus, chunk=array_pb2.ArrayChunk(byte_offset=0, data=b"\0" * 4))]),
        metadata=md, timeout=10))
    fill = exec_pb2.Command(fill=exec_pb2.FillCommand(
        dst=types_pb2.ArrayRef(handle=bogus, shape=[64], strides=[4]), value=b"\0\0\x80\x3f"))
    try:
        raw.exec.Submit(exec_pb2.SubmitRequest(commands=[fill]), metadata=md, timeout=10)
        response = sync_error(raw)
        assert response.error, "a fill of an unknown handle must be reported at sync"
    except grpc.RpcError as err:   # refusing the whole batch up front is fine too
        assert err.code() in REFUSED and err.details()
    assert totals(weftd) == before
    unchanged()


def test_wrong_dtype_and_shape(weftd, raw, canary):
    _, unchanged = canary
    before = totals(weftd)
    md = raw.metadata
    cases = [
        types_pb2.DType(scalar=0),                                    # unspecified scalar
        types_pb2.DType(scalar=99),                                   # no such scalar
        types_pb2.DType(scalar=FLOAT32, elem_shape=[0]),              # empty vector
        types_pb2.DType(scalar=FLOAT32, elem_shape=[2, 2, 2]),        # 3-d element
    ]
    for dtype in cases:
        expect_refused(lambda d=dtype: raw.arrays.Create(array_pb2.CreateArrayRequest(
            dtype=d, shape=[4], device="cpu"), metadata=md, timeout=10))
    dtype, _ = f32([1])
    expect_refused(lambda: raw.arrays.Create(array_pb2.CreateArrayRequest(
        dtype=dtype, shape=[1, 1, 1, 1, 1], device="cpu"), metadata=md, timeout=10))
    expect_refused(lambda: raw.arrays.Create(array_pb2.CreateArrayRequest(
        dtype=dtype, shape=[4], device="tpu:7"), metadata=md, timeout=10),
        REFUSED | {grpc.StatusCode.UNAVAILABLE})
    # a FILL value of the wrong element size
    expect_refused(lambda: raw.arrays.Create(array_pb2.CreateArrayRequest(
        dtype=dtype, shape=[4], device="cpu", init=array_pb2.CreateArrayRequest.FILL,
        value=b"\x01\x02\x03"), metadata=md, timeout=10))
    assert totals(weftd) == before
    unchanged()


def test_negative_and_absurd_sizes(weftd, raw, canary):
    _, unchanged = canary
    before = totals(weftd)
    dtype, _ = f32([1])
    md = raw.metadata
    for shape in ([-1], [4, -3], [1 << 62], [1 << 40, 1 << 40], [1 << 31, 1 << 31, 1 << 31]):
        expect_refused(lambda s=shape: raw.arrays.Create(array_pb2.CreateArrayRequest(
            dtype=dtype, shape=s, device="cpu"), metadata=md, timeout=30))
    assert totals(weftd) == before
    unchanged()


def test_out_of_range_views_and_reads(weftd, raw, canary):
    info, unchanged = canary
    before = totals(weftd)
    md = raw.metadata
    one = np.float32(1.0).tobytes()
    bad_refs = [
        types_pb2.ArrayRef(handle=info.handle, byte_offset=0, shape=[65], strides=[4]),
        types_pb2.ArrayRef(handle=info.handle, byte_offset=4 * 60, shape=[8], strides=[4]),
        types_pb2.ArrayRef(handle=info.handle, byte_offset=1 << 40, shape=[1], strides=[4]),
        types_pb2.ArrayRef(handle=info.handle, byte_offset=0, shape=[8], strides=[4096]),
        types_pb2.ArrayRef(handle=info.handle, byte_offset=0, shape=[-2], strides=[4]),
    ]
    for ref in bad_refs:
        cmd = exec_pb2.Command(fill=exec_pb2.FillCommand(dst=ref, value=one))
        try:
            raw.exec.Submit(exec_pb2.SubmitRequest(commands=[cmd]), metadata=md, timeout=10)
            assert sync_error(raw).error, f"out-of-range view {ref} must be reported"
        except grpc.RpcError as err:
            assert err.code() in REFUSED and err.details()
    # a copy whose source lies outside its allocation
    src = types_pb2.ArrayRef(handle=info.handle, byte_offset=128, shape=[64], strides=[4])
    dst = types_pb2.ArrayRef(handle=info.handle, byte_offset=0, shape=[64], strides=[4])
    cmd = exec_pb2.Command(copy=exec_pb2.CopyCommand(dst=dst, src=src))
    try:
        raw.exec.Submit(exec_pb2.SubmitRequest(commands=[cmd]), metadata=md, timeout=10)
        assert sync_error(raw).error
    except grpc.RpcError as err:
        assert err.code() in REFUSED
    # reads past the end
    expect_refused(lambda: list(raw.arrays.Read(array_pb2.ReadArrayRequest(
        handle=info.handle, byte_offset=256, byte_count=4), metadata=md, timeout=10)))
    expect_refused(lambda: list(raw.arrays.Read(array_pb2.ReadArrayRequest(
        handle=info.handle, byte_offset=200, byte_count=100), metadata=md, timeout=10)))
    # the session still works after the errors were reported
    assert not sync_error(raw).error
    assert totals(weftd) == before
    unchanged()


def test_write_of_the_wrong_byte_count(weftd, raw, canary):
    info, unchanged = canary
    before = totals(weftd)
    md = raw.metadata
    too_long = array_pb2.WriteArrayRequest(handle=info.handle, chunk=array_pb2.ArrayChunk(
        byte_offset=0, data=b"\xff" * 260))
    expect_refused(lambda: raw.arrays.Write(iter([too_long]), metadata=md, timeout=10))
    past_end = array_pb2.WriteArrayRequest(handle=info.handle, chunk=array_pb2.ArrayChunk(
        byte_offset=254, data=b"\xff" * 4))
    expect_refused(lambda: raw.arrays.Write(iter([past_end]), metadata=md, timeout=10))
    dtype, _ = f32([1])
    for size in (0, 255, 257):
        expect_refused(lambda n=size: raw.arrays.Create(array_pb2.CreateArrayRequest(
            dtype=dtype, shape=[64], device="cpu", init=array_pb2.CreateArrayRequest.DATA,
            value=b"\x01" * n), metadata=md, timeout=10))
    assert totals(weftd) == before
    unchanged()


def test_requests_without_a_session(weftd, raw, canary):
    info, unchanged = canary
    before = totals(weftd)
    dtype, _ = f32([1])
    create = array_pb2.CreateArrayRequest(dtype=dtype, shape=[4], device="cpu")
    for metadata in ((), (("weft-session", "no-such-session"),)):
        expect_refused(lambda m=metadata: raw.arrays.Create(create, metadata=m, timeout=10),
                       NO_SESSION)
        expect_refused(lambda m=metadata: raw.arrays.Describe(
            array_pb2.DescribeArrayRequest(handle=info.handle), metadata=m, timeout=10),
            NO_SESSION | {grpc.StatusCode.NOT_FOUND})
        expect_refused(lambda m=metadata: raw.exec.Synchronize(
            exec_pb2.SynchronizeRequest(), metadata=m, timeout=10), NO_SESSION)
    assert totals(weftd) == before
    unchanged()


def test_another_sessions_handle_is_not_reachable(weftd, raw, canary, wp):
    info, unchanged = canary
    with weftd.raw_session("pytest intruder") as other:
        expect_refused(lambda: raw.arrays.Describe(
            array_pb2.DescribeArrayRequest(handle=info.handle), metadata=other.metadata,
            timeout=10))
        expect_refused(lambda: other.arrays.Write(iter([array_pb2.WriteArrayRequest(
            handle=info.handle, chunk=array_pb2.ArrayChunk(byte_offset=0, data=b"\0" * 4))]),
            metadata=other.metadata, timeout=10))
        expect_refused(lambda: other.arrays.Free(array_pb2.FreeArrayRequest(handle=info.handle),
                                                 metadata=other.metadata, timeout=10))
    unchanged()


def test_client_errors_are_weft_errors(wp):
    with pytest.raises(wp.WeftError) as info:
        wp.from_ipc_handle(b"definitely-not-a-token", dtype=wp.float32, shape=(4,))
    assert isinstance(info.value, RuntimeError)
    assert info.value.code in ("NOT_FOUND", "INVALID_ARGUMENT", "PERMISSION_DENIED")
    with pytest.raises(wp.WeftError):
        wp.zeros(1 << 62, dtype=wp.float64)
    with pytest.raises((ValueError, wp.WeftError)):
        wp.zeros(4, device="cuda:99")


def test_session_close_message_is_not_needed_for_stats(weftd):
    stats = weftd.stats()
    assert isinstance(stats, session_pb2.StatsResponse) and stats.sessions >= 1
