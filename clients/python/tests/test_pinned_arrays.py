"""Pinned host arrays (Warp's `pinned=True`): a CPU array in a slab of its own that weftd
page-locks for its GPUs (cuMemHostRegister, portable), so copies between it and a GPU are DMA.
`array.pinned` follows Warp (requested and on the CPU; *_like and clone take the source's);
ArrayInfo.page_locked says whether weftd could page-lock it (never without a GPU). Tests: the
flag everywhere, data round trips on fresh random data, the gradient, many create/free cycles
(each registration undone before the memory is reused), sizes a client makes absurd; on a GPU
machine the memory is page-locked and copies both ways (contiguous and strided) are exact."""
import numpy as np
import pytest

import weft as wp


def _page_locked(a) -> bool:
    return bool(a._info.page_locked)


def _has_gpu(wp) -> bool:
    return any(d.is_cuda and d.is_compute_supported for d in wp.get_cuda_devices())


def test_pinned_follows_warp_on_the_cpu(wp):
    rng = np.random.default_rng()
    host = rng.standard_normal(1000).astype(np.float32)
    a = wp.array(host, dtype=float, device="cpu", pinned=True)
    b = wp.array(host, dtype=float, device="cpu")
    assert a.pinned and not b.pinned
    assert a._info.pinned and not b._info.pinned
    np.testing.assert_array_equal(a.numpy(), host)
    assert wp.zeros_like(a).pinned and not wp.zeros_like(b).pinned
    assert not wp.zeros_like(a, pinned=False).pinned and wp.empty_like(b, pinned=True).pinned
    assert wp.ones_like(a).pinned and wp.full_like(a, 2.0).pinned
    c = wp.clone(a)
    assert c.pinned
    np.testing.assert_array_equal(c.numpy(), host)
    for factory in (wp.zeros, wp.empty, wp.ones):
        assert factory(16, dtype=float, device="cpu", pinned=True).pinned
    assert wp.full(16, 3.0, dtype=float, device="cpu", pinned=True).pinned
    assert a[10:20].pinned                                   # views keep it
    assert _page_locked(a) == _has_gpu(wp)                   # only a GPU can page-lock it


def test_pinned_arrays_with_gradients(wp):
    rng = np.random.default_rng()
    host = rng.uniform(-1e6, 1e6, size=(64, 3)).astype(np.float32)
    a = wp.array(host, dtype=wp.vec3, device="cpu", pinned=True, requires_grad=True)
    assert a.pinned and a.grad is not None and a.grad.pinned
    assert a.grad._info.pinned
    np.testing.assert_array_equal(a.grad.numpy(), np.zeros((64, 3), dtype=np.float32))
    np.testing.assert_array_equal(a.numpy(), host)


def test_pinned_means_nothing_on_a_gpu_array(wp):
    if not _has_gpu(wp):
        pytest.skip("weftd has no CUDA device it can run kernels on")
    g = wp.zeros(8, dtype=float, device="cuda:0", pinned=True)
    assert not g.pinned and not g._info.pinned


def test_many_pinned_arrays_come_and_go(wp):
    rng = np.random.default_rng()
    for i in range(40):
        n = int(rng.integers(1, 200_000))
        host = rng.integers(-2**31, 2**31 - 1, size=n, dtype=np.int64).astype(np.int32)
        a = wp.array(host, dtype=wp.int32, device="cpu", pinned=True)
        np.testing.assert_array_equal(a.numpy(), host)
        del a
    empty = wp.zeros(0, dtype=float, device="cpu", pinned=True)   # nothing to page-lock
    assert empty.pinned and not _page_locked(empty)


def test_absurd_pinned_sizes_are_refused_like_any_array(wp):
    with pytest.raises(Exception, match="absurdly large|more than"):
        wp.zeros((1 << 40, 1 << 40), dtype=float, device="cpu", pinned=True)
    a = wp.full(4, 7.0, dtype=float, device="cpu", pinned=True)   # still serving
    np.testing.assert_array_equal(a.numpy(), np.full(4, 7.0, dtype=np.float32))


def test_pinned_copies_to_and_from_a_gpu(wp):
    if not _has_gpu(wp):
        pytest.skip("weftd has no CUDA device it can run kernels on")
    rng = np.random.default_rng()
    n = 1 << 20
    host = (rng.standard_normal(n) * np.exp(rng.uniform(-30, 30, n))).astype(np.float32)
    pinned = wp.array(host, dtype=float, device="cpu", pinned=True)
    assert _page_locked(pinned), "weftd did not page-lock a pinned array on a GPU machine"
    back = wp.zeros_like(pinned)
    assert back.pinned and _page_locked(back)
    dev = wp.zeros(n, dtype=float, device="cuda:0")
    wp.copy(dev, pinned)
    wp.copy(back, dev)
    wp.synchronize_device("cuda:0")
    np.testing.assert_array_equal(back.numpy(), host)
    # strided views on either side, with offsets and counts
    strided = wp.zeros(n // 2, dtype=float, device="cuda:0")
    wp.copy(strided, pinned[::2])
    np.testing.assert_array_equal(strided.numpy(), host[::2])
    wp.copy(back, dev, dest_offset=5, src_offset=11, count=1000)
    np.testing.assert_array_equal(back.numpy()[5:1005], host[11:1011])
