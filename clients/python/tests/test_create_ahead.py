"""Small arrays created one step ahead (weft/_create_ahead.py): a wp.zeros made again with the
same request is taken from an array the client asked for right after the previous one, with
no round trip; it holds zeros (and a zero gradient) whatever the previous one of its kind was
given; a creation refused for lack of memory gives the arrays held ahead back first."""
import numpy as np
import pytest

from weft import _fast_lane, _runtime


def _lane_runtime():
    rt = _runtime.get_runtime()
    if rt.fast_lane is None or rt.fast_lane.broken or not rt.lane_arrays:
        pytest.skip("no fast lane in this environment")
    return rt


def _device(wp, name):
    if name == "cpu":
        return "cpu"
    if not any(d.is_cuda and d.is_compute_supported for d in wp.get_cuda_devices()):
        pytest.skip("weftd has no CUDA device it can run kernels on")
    return name


@pytest.fixture(scope="module")
def scale_kernel(wp):
    @wp.kernel
    def scale_into(x: wp.array(dtype=float), s: float, out: wp.array(dtype=float)):
        i = wp.tid()
        out[i] = out[i] + s * x[i]

    return scale_into


@pytest.mark.parametrize("device_name", ["cpu", "cuda:0"])
def test_a_small_array_made_again_is_created_ahead_and_holds_zeros(wp, monkeypatch, scale_kernel,
                                                                  device_name):
    device = _device(wp, device_name)
    rt = _lane_runtime()
    creates = []
    real_call = rt.fast_lane.call
    zeros_init = _runtime.array_pb2.CreateArrayRequest.ZEROS
    monkeypatch.setattr(rt.fast_lane, "call", lambda m, r, t, *s: (
        creates.append(m) if m == _fast_lane.ARRAY_CREATE and r.init == zeros_init else None,
        real_call(m, r, t, *s))[1])
    rng = np.random.default_rng()
    n = int(rng.integers(900, 1100))
    steps = 12
    handles, kept = set(), []
    for step in range(steps):
        x0 = rng.uniform(-1e4, 1e4, n).astype(np.float32)
        x = wp.array(x0, dtype=float, device=device)
        z = wp.zeros(n, dtype=float, device=device, requires_grad=True)
        assert z._handle not in handles, "a live array's handle was handed out again"
        assert not z.numpy().any() and not z.grad.numpy().any(), f"step {step}: not zeros"
        wp.launch(scale_kernel, dim=n, inputs=[x, -2.5], outputs=[z], device=device)
        np.testing.assert_array_equal(z.numpy(), np.float32(-2.5) * x0)   # one product each
        z.grad.fill_(float(step + 1))          # the next one of its kind must not see this
        handles.add(z._handle)
        if step % 3 == 0:
            kept.append(z)                      # some stay alive, the rest are freed
    wp.synchronize()
    # the first two asked the daemon; the others were taken from arrays created ahead
    assert 1 <= len(creates) <= 2, f"{len(creates)} synchronous Creates of the zeros"
    for z in kept:
        assert z.numpy().shape == (n,) and z.grad.numpy().any()


def test_arrays_created_ahead_are_freed_with_a_refused_creation(limited_weftd, run_client):
    """2 MiB per session: an 800 KiB zeros made twice holds a third ahead (2.4 MiB would not
    fit); another 800 KiB array is then refused unless the one held ahead is given back."""
    proc = run_client(f"""
        import weft as wp
        from weft import _runtime
        wp.set_device("cpu")
        a = wp.zeros(200 * 1024, dtype=wp.float32)
        del a
        b = wp.zeros(200 * 1024, dtype=wp.float32)    # seen twice: one more created ahead
        rt = _runtime.get_runtime()
        wp.synchronize()
        print("AHEAD", len(rt.create_ahead.slots))
        c = wp.zeros(200 * 1024, dtype=wp.int32)      # 800 KiB more: fits once the slot is given back
        c.fill_(7)
        print("OK", int(c.numpy().sum()) == 7 * 200 * 1024, len(rt.create_ahead.slots))
        """, env={"WEFT_ADDRESS": limited_weftd.address})
    out = proc.stdout
    assert "AHEAD 1" in out, out + proc.stderr
    assert "OK True 0" in out, out + proc.stderr


@pytest.fixture
def limited_weftd(start_weftd):
    return start_weftd(["--max-session-memory", "2M"])
