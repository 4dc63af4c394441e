"""GPU arrays through the daemon (skipped with the reason when it has no CUDA device it can run
kernels on): creation, fills of slices, copies between cpu and cuda, clone/to, numpy() copies,
assign; the client's CUDA IPC mapping (ptr, __cuda_array_interface__ v3, DLPack kDLCUDA) and
the copy fallback when IPC is off (WEFT_CUDA_IPC=0); streams and events (Warp's attributes,
host waits refused inside a capture, events between captured graphs)."""
import numpy as np
import pytest


@pytest.fixture
def cuda(wp):
    if not any(d.is_cuda and d.is_compute_supported for d in wp.get_cuda_devices()):
        pytest.skip("weftd has no CUDA device it can run kernels on")
    return wp.get_cuda_device(0)


@pytest.fixture
def ipc(wp, cuda):
    """The client's CUDA IPC state; skips tests that need the zero-copy path where it is off."""
    from weft import _cuda_ipc

    a = wp.zeros(1, device=cuda)
    if a.ptr is None:
        pytest.skip(f"CUDA IPC is not available in this client: {_cuda_ipc.reason()}")
    print(f"CUDA IPC: on ({_cuda_ipc.stats()})")
    return _cuda_ipc


def test_cuda_is_the_default_device(wp, cuda):
    assert wp.get_preferred_device() == cuda and cuda.alias == "cuda:0"
    a = wp.zeros(4, device=cuda)
    assert a.device.is_cuda
    with pytest.raises(AttributeError):
        a.__array_interface__


@pytest.mark.parametrize("name", ["float32", "float64", "int32", "uint8", "float16"])
def test_cuda_round_trip(wp, cuda, name):
    rng = np.random.default_rng(20)
    dtype = getattr(wp, name)
    values = (rng.standard_normal((33, 7)) * 50).astype(wp.dtype_to_numpy(dtype))
    a = wp.array(values, dtype=dtype, device=cuda)
    assert a.device == "cuda:0"
    np.testing.assert_array_equal(a.numpy(), values)
    a[3:9, 2:5].fill_(1)
    values[3:9, 2:5] = 1
    np.testing.assert_array_equal(a.numpy(), values)
    np.testing.assert_array_equal(a[::3, 1].numpy(), values[::3, 1])


def test_cuda_cpu_copies(wp, cuda):
    rng = np.random.default_rng(21)
    ref = rng.standard_normal((100, 3)).astype(np.float32)
    host = wp.array(ref, dtype=wp.vec3, device="cpu")
    dev = host.to(cuda)
    assert dev.device.is_cuda
    np.testing.assert_array_equal(dev.numpy(), ref)
    back = wp.zeros_like(host)
    wp.copy(back, dev, dest_offset=10, src_offset=20, count=30)
    expected = np.zeros_like(ref)
    expected[10:40] = ref[20:50]
    np.testing.assert_array_equal(back.numpy(), expected)
    clone = wp.clone(dev, device="cpu")
    np.testing.assert_array_equal(clone.numpy(), ref)


def test_cuda_assign_and_large_read(wp, cuda):
    rng = np.random.default_rng(22)
    ref = rng.random(24 << 20, dtype=np.float32)   # 96 MiB: a slab of its own, many chunks
    a = wp.empty(ref.size, dtype=wp.float32, device=cuda)
    a.assign(ref)
    np.testing.assert_array_equal(a.numpy(), ref)
    a[5:10].assign(np.arange(5, dtype=np.float32))
    ref[5:10] = np.arange(5)
    np.testing.assert_array_equal(a[:16].numpy(), ref[:16])
    big = wp.array(ref, device=cuda)               # initial data above the inline limit
    np.testing.assert_array_equal(big.numpy(), ref)


def test_cuda_array_interface(wp, cuda, ipc):
    rng = np.random.default_rng(23)
    values = rng.standard_normal((64, 3)).astype(np.float32)
    a = wp.array(values, dtype=wp.vec3, device=cuda)
    cai = a.__cuda_array_interface__
    assert cai["version"] == 3 and cai["typestr"] == "<f4" and cai["shape"] == (64, 3)
    assert cai["strides"] is None
    # a stream of this process that waits for weft's queued work (interprocess events), or
    # None where weft finished its work first (docs/interop.md, "Ordering")
    assert cai["stream"] is None or cai["stream"] == ipc.proxy_stream(a.device.ordinal)
    assert cai["data"] == (a.ptr, False)
    view = a[1::2]
    vcai = view.__cuda_array_interface__
    assert vcai["data"][0] == a.ptr + 12 and vcai["strides"] == (24, 4)
    assert vcai["shape"] == (32, 3)
    # the same slab is mapped once: a second array of the session lands in the same mapping
    opened = ipc.stats()["opened"]
    b = wp.zeros(16, device=cuda)
    assert b.ptr is not None and ipc.stats()["opened"] == opened


def test_cuda_dlpack_capsule(wp, cuda):
    a = wp.zeros(8, dtype=wp.vec2, device=cuda)
    assert a.__dlpack_device__() == (2, cuda.ordinal)
    if a.ptr is None:              # absent, so consumers fall back to __array__ (a copy)
        with pytest.raises(AttributeError, match="CUDA IPC"):
            a.__dlpack__()
        return
    capsule = a.__dlpack__(stream=None)
    assert type(capsule).__name__ == "PyCapsule"
    del capsule                        # unconsumed: its destructor runs the deleter


def test_cuda_slab_reuse_reopens_mappings(wp, cuda, ipc):
    """Dedicated slabs (arrays above 16 MiB) go back to the driver when freed; the next one
    may get the same IPC handle bytes. The client closes the stale mapping and maps anew
    (never reads through the old one), and IPC stays on."""
    for k in range(6):
        a = wp.full(5 << 20, float(k), dtype=wp.float32, device=cuda)   # 20 MiB
        assert a.ptr is not None, ipc.stats()
        np.testing.assert_array_equal(a[:8].numpy(), float(k))
        np.testing.assert_array_equal(a.numpy()[-8:], float(k))
        del a
        wp.synchronize()
    assert ipc.reason() == "", ipc.stats()
    print(ipc.stats())


def test_cuda_numpy_paths_agree(wp, cuda, run_client):
    """numpy()/assign through the IPC mapping (when on) and through the daemon (IPC off in a
    child client) give the same bytes; the child says which path it ran."""
    rng = np.random.default_rng(24)
    values = rng.standard_normal(3000).astype(np.float64)
    a = wp.array(values, device=cuda)
    token = a.ipc_handle().decode()
    code = f"""
import numpy as np, weft as wp
from weft import _cuda_ipc
b = wp.from_ipc_handle({token!r}.encode())
print("path", "ipc" if b.ptr is not None else "copy:" + _cuda_ipc.reason())
assert b.ptr is None and not hasattr(b, "__cuda_array_interface__")
v = b.numpy()
print("sum", repr(float(v.sum())))
b[10:20].assign(np.full(10, 7.0))
wp.synchronize()
"""
    out = run_client(code, env={"WEFT_CUDA_IPC": "0"}).stdout
    assert "path copy:WEFT_CUDA_IPC=0" in out
    assert f"sum {float(values.sum())!r}" in out
    values[10:20] = 7.0
    np.testing.assert_array_equal(a.numpy(), values)


def test_streams_and_events(wp, cuda):
    s = wp.get_stream(cuda)
    assert s == wp.Stream(cuda) and s.device == cuda
    start = wp.Event(cuda, enable_timing=True)
    end = wp.Event(cuda, enable_timing=True)
    a = wp.zeros(1 << 20, device=cuda)
    wp.record_event(start)
    for _ in range(10):
        a.fill_(3.0)
    s.record_event(end)
    wp.synchronize_event(end)
    elapsed = wp.get_event_elapsed_time(start, end)
    assert elapsed > 0.0
    plain = wp.record_event(wp.Event(cuda))
    plain.synchronize()
    assert plain.query()
    with wp.ScopedStream(s):
        assert wp.get_stream() is s
    s.wait_event(plain)
    wp.synchronize_stream(s)
    wp.synchronize_device(cuda)
    np.testing.assert_array_equal(a.numpy()[:4], 3.0)
    with pytest.raises(RuntimeError, match="enable_timing"):
        wp.get_event_elapsed_time(plain, end)


def test_streams_are_cuda_only(wp):
    with pytest.raises(RuntimeError, match="CUDA objects"):
        wp.Stream("cpu")
    with pytest.raises(RuntimeError, match="CUDA objects"):
        wp.Event("cpu")


def test_stream_attributes_as_warp(wp, cuda):
    assert wp.Stream(cuda).priority == 0
    assert wp.Stream(cuda, priority=-100).priority == -1      # Warp's two levels, clamped
    assert wp.Stream(cuda, priority=100).priority == 0
    with pytest.raises(TypeError, match="priority must be an integer"):
        wp.Stream(cuda, priority=0.5)
    assert wp.Stream(cuda).is_blocking and cuda.stream.is_blocking and cuda.null_stream.is_blocking
    assert cuda.has_stream and not wp.get_device("cpu").has_stream
    stream, event = wp.Stream(cuda), wp.Event(cuda)
    assert event.is_complete                                     # never recorded
    a = wp.zeros(1 << 16, dtype=float, device=cuda)
    with wp.ScopedStream(stream):
        a.fill_(2.0)
        stream.record_event(event)
        wp.synchronize_stream(stream)
        assert stream.is_complete and event.is_complete
    a.fill_(3.0)                                              # a loop polling for completion ends
    polls = 0
    while not stream.is_complete:
        polls += 1
        assert polls < 3
    b = wp.empty_like(a)
    wp.copy(b, a, stream=stream)
    np.testing.assert_array_equal(b.numpy(), 3.0)
    with pytest.raises(TypeError, match="must be a wp.Stream"):
        wp.copy(b, a, stream="cuda:0")


def test_host_waits_inside_a_capture_are_refused(wp, cuda):
    with wp.ScopedDevice(cuda):
        for wait, what in ((wp.synchronize, "device"), (wp.synchronize_device, "device"),
                           (wp.synchronize_stream, "stream"),
                           (lambda: wp.synchronize_event(wp.Event(cuda)), "event")):
            with pytest.raises(RuntimeError, match=f"Cannot synchronize {what}"):
                with wp.ScopedCapture():
                    wait()
        # an event recorded inside one graph and waited on in another: in order on one stream
        a = wp.zeros(1024, dtype=float, device=cuda)
        event = wp.Event()
        with wp.ScopedCapture() as first:
            a.fill_(1.0)
            wp.record_event(event, external=True)
        with wp.ScopedCapture() as second:
            wp.wait_event(event, external=True)
            a.fill_(4.0)
        wp.capture_launch(first.graph, stream=wp.Stream(cuda))
        wp.capture_launch(second.graph, stream=wp.Stream(cuda))
        np.testing.assert_array_equal(a.numpy(), 4.0)
