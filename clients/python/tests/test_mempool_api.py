"""Warp's memory-pool and peer-access API against weft (weft/mempool.py): a CUDA device's pool
is the session's memory in weftd (support, the per-device switch, Warp's capture-allocation
error with it off, the release threshold's rules, usage of this process's arrays), the CPU has
no pools (ValueError), a GPU reaches its own memory and no other's, and unknown device names are
refused. CUDA cases skip without a GPU."""
import numpy as np
import pytest


def _cuda(wp):
    cuda = [d for d in wp.get_cuda_devices() if d.is_compute_supported]
    if not cuda:
        pytest.skip("no GPU the daemon computes on")
    return cuda[0]


def test_cpu_has_no_memory_pools(wp):
    cpu = wp.get_device("cpu")
    assert wp.is_mempool_supported(cpu) is False and cpu.is_mempool_supported is False
    assert wp.is_mempool_enabled(cpu) is False
    for call in (lambda: wp.set_mempool_enabled(cpu, True),
                 lambda: wp.set_mempool_release_threshold(cpu, 42000),
                 lambda: wp.get_mempool_release_threshold(cpu),
                 lambda: wp.get_mempool_used_mem_current(cpu),
                 lambda: wp.get_mempool_used_mem_high(cpu)):
        with pytest.raises(ValueError, match="only supported on CUDA devices"):
            call()
    wp.set_mempool_enabled(cpu, False)          # disabling is accepted
    with wp.ScopedMempool(cpu, False):
        a = wp.full(8, 3.0, dtype=float, device=cpu)
    assert a.numpy().tolist() == [3.0] * 8


def test_cuda_devices_have_pools_that_answer_for_the_session(wp):
    gpu = _cuda(wp)
    assert wp.is_mempool_supported(gpu) is True and gpu.is_mempool_supported is True
    assert wp.is_mempool_enabled(gpu) is True                 # Warp's default
    with wp.ScopedMempool(gpu, False):
        assert wp.is_mempool_enabled(gpu) is False
        a = wp.full(8, 2.0, dtype=float, device=gpu)          # outside a capture: allocated
    assert wp.is_mempool_enabled(gpu) is True
    assert a.numpy().tolist() == [2.0] * 8

    saved = wp.get_mempool_release_threshold(gpu)
    wp.set_mempool_release_threshold(gpu, 42000)
    assert wp.get_mempool_release_threshold(gpu) == 42000
    wp.set_mempool_release_threshold(gpu, 0.5)
    assert wp.get_mempool_release_threshold(gpu) == int(0.5 * gpu.total_memory)
    wp.set_mempool_release_threshold(gpu, -3)
    assert wp.get_mempool_release_threshold(gpu) == 0
    wp.set_mempool_release_threshold(gpu, saved)


def test_pool_usage_counts_the_arrays_this_process_holds(wp):
    import gc
    gpu = _cuda(wp)
    gc.collect()
    before, high_before = wp.get_mempool_used_mem_current(gpu), wp.get_mempool_used_mem_high(gpu)
    assert high_before >= before >= 0
    n = int(np.random.default_rng().integers(200_000, 300_000))
    a = wp.empty(n, dtype=wp.float32, device=gpu)
    held = wp.get_mempool_used_mem_current(gpu)
    assert held >= before + 4 * n
    assert wp.get_mempool_used_mem_high(gpu) >= held
    del a
    gc.collect()
    assert wp.get_mempool_used_mem_current(gpu) == held - 4 * n
    assert wp.get_mempool_used_mem_high(gpu) >= held       # the high-water mark stays


def test_allocating_during_a_capture_needs_the_pool_on(wp):
    gpu = _cuda(wp)
    with wp.ScopedMempool(gpu, False):
        wp.capture_begin(device=gpu)
        try:
            with pytest.raises(RuntimeError, match="memory pools are not enabled on device"):
                wp.zeros(16, dtype=float, device=gpu)
        finally:
            graph = wp.capture_end(device=gpu)
    wp.capture_launch(graph)
    with wp.ScopedMempool(gpu, True):
        wp.capture_begin(device=gpu)
        try:
            b = wp.full(16, 5.0, dtype=float, device=gpu)
        finally:
            graph = wp.capture_end(device=gpu)
    wp.capture_launch(graph)
    assert b.numpy().tolist() == [5.0] * 16


def test_peer_and_pool_access_between_devices(wp):
    assert wp.is_peer_access_supported("cpu", "cpu") is False
    assert wp.is_mempool_access_enabled("cpu", "cpu") is False
    with pytest.raises(ValueError, match="only supported between CUDA devices"):
        wp.set_mempool_access_enabled("cpu", "cpu", True)
    with pytest.raises(ValueError, match="only supported between CUDA devices"):
        wp.set_peer_access_enabled("cpu", "cpu", True)
    wp.set_peer_access_enabled("cpu", "cpu", False)
    wp.set_mempool_access_enabled("cpu", "cpu", False)
    with wp.ScopedPeerAccess("cpu", "cpu", False), wp.ScopedMempoolAccess("cpu", "cpu", False):
        pass


def test_a_gpu_reaches_its_own_memory_and_no_other(wp):
    gpu = _cuda(wp)
    assert wp.is_peer_access_supported(gpu, gpu) is True
    assert wp.is_peer_access_enabled(gpu, gpu) is True
    assert wp.is_mempool_access_enabled(gpu, gpu) is True
    wp.set_peer_access_enabled(gpu, gpu, True)            # no-ops, as in Warp
    wp.set_mempool_access_enabled(gpu, gpu, False)
    with pytest.raises(ValueError):
        wp.set_mempool_access_enabled(gpu, "cpu", True)
    others = [d for d in wp.get_cuda_devices() if d.is_compute_supported and d.alias != gpu.alias]
    for other in others:
        assert wp.is_peer_access_supported(gpu, other) is False
        with pytest.raises(RuntimeError, match="weftd copies between GPUs itself"):
            wp.set_peer_access_enabled(gpu, other, True)


def test_unknown_devices_are_refused(wp):
    for call in (lambda: wp.is_mempool_supported("cuda:99"),
                 lambda: wp.is_peer_access_supported("cpu", "tpu:0"),
                 lambda: wp.set_mempool_enabled("nonsense\n", False),
                 lambda: wp.ScopedMempool("cuda:99", False)):
        with pytest.raises((ValueError, RuntimeError)):
            call()
