"""Warp's memory-pool and peer-access API against weft (weft/mempool.py): no device has
memory-pool support (weftd sub-allocates GPU memory from its own slabs) and no device pair has
client-side pool or peer access, so queries answer False, enabling raises as Warp does for a
device without the support (RuntimeError on CUDA devices, ValueError where a CPU is named),
disabling is accepted, and unknown device names are refused. CUDA cases skip without a GPU."""
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


def test_cuda_devices_have_no_memory_pools(wp):
    gpu = _cuda(wp)
    assert wp.is_mempool_supported(gpu) is False and wp.is_mempool_enabled(gpu) is False
    with pytest.raises(RuntimeError, match="does not support memory pools"):
        wp.set_mempool_enabled(gpu, True)
    with pytest.raises(RuntimeError, match="does not support memory pools"):
        wp.get_mempool_release_threshold(gpu)
    with pytest.raises(RuntimeError, match="does not support memory pools"):
        with wp.ScopedMempool(gpu, True):
            pass
    with wp.ScopedMempool(gpu, False):           # Warp's IPC idiom: allocate outside pools
        a = wp.full(8, 2.0, dtype=float, device=gpu)
    assert a.numpy().tolist() == [2.0] * 8


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


def test_peer_access_between_gpus_is_the_daemons(wp):
    gpu = _cuda(wp)
    assert wp.is_peer_access_supported(gpu, gpu) is False
    assert wp.is_peer_access_enabled(gpu, gpu) is False
    with pytest.raises(RuntimeError, match="weftd copies between GPUs itself"):
        wp.set_peer_access_enabled(gpu, gpu, True)
    with pytest.raises(ValueError):
        wp.set_mempool_access_enabled(gpu, "cpu", True)


def test_unknown_devices_are_refused(wp):
    for call in (lambda: wp.is_mempool_supported("cuda:99"),
                 lambda: wp.is_peer_access_supported("cpu", "tpu:0"),
                 lambda: wp.set_mempool_enabled("nonsense\n", False),
                 lambda: wp.ScopedMempool("cuda:99", False)):
        with pytest.raises((ValueError, RuntimeError)):
            call()
