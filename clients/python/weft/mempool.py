"""Warp's memory-pool and peer-access API (wp.is_mempool_supported, wp.set_mempool_enabled,
wp.ScopedMempool, wp.is_peer_access_supported, ...) against weft.

weftd allocates GPU memory from its own slabs, sub-allocated per session (docs/cuda.md), never
from CUDA's stream-ordered memory pools, and copies between GPUs itself (peer copies where the
GPUs allow them, staged otherwise); a client never maps another GPU's memory. So no device has
memory-pool support and no device pair has client-side pool or peer access: the queries answer
False and the setters behave as Warp's do for a device without that support (enabling raises
RuntimeError on a CUDA device and ValueError where a CPU is named; disabling is accepted), so a
Warp program that checks support before enabling runs unchanged. Unknown device names raise, as
everywhere.
"""
from __future__ import annotations

from .device import get_device

__all__ = ["is_mempool_supported", "is_mempool_enabled", "set_mempool_enabled",
           "get_mempool_release_threshold", "set_mempool_release_threshold",
           "get_mempool_used_mem_current", "get_mempool_used_mem_high",
           "is_mempool_access_supported", "is_mempool_access_enabled", "set_mempool_access_enabled",
           "is_peer_access_supported", "is_peer_access_enabled", "set_peer_access_enabled",
           "ScopedMempool", "ScopedMempoolAccess", "ScopedPeerAccess"]


def _pool_device(device):
    """The CUDA device `device` names; ValueError for the CPU, RuntimeError (no pools) otherwise."""
    d = get_device(device)
    if not d.is_cuda:
        raise ValueError("Memory pools are only supported on CUDA devices")
    raise RuntimeError(f"Device {d} does not support memory pools (weftd allocates GPU memory "
                       "from its own slabs, docs/cuda.md)")


def is_mempool_supported(device=None) -> bool:
    return bool(get_device(device).is_mempool_supported)


def is_mempool_enabled(device=None) -> bool:
    get_device(device)
    return False


def set_mempool_enabled(device, enable: bool) -> None:
    d = get_device(device)
    if enable:
        _pool_device(d)


def get_mempool_release_threshold(device=None) -> int:
    _pool_device(device)


def set_mempool_release_threshold(device, threshold) -> None:
    _pool_device(device)


def get_mempool_used_mem_current(device=None) -> int:
    _pool_device(device)


def get_mempool_used_mem_high(device=None) -> int:
    _pool_device(device)


def _pair(target_device, peer_device, what: str, enable: bool) -> None:
    t, p = get_device(target_device), get_device(peer_device)
    if not enable:
        return
    if not (t.is_cuda and p.is_cuda):
        raise ValueError(f"{what} is only supported between CUDA devices")
    raise RuntimeError(f"{what} from {p} to {t} is not supported for weft clients: weftd copies "
                       "between GPUs itself (docs/cuda.md)")


def is_mempool_access_supported(target_device, peer_device) -> bool:
    get_device(target_device), get_device(peer_device)
    return False


def is_mempool_access_enabled(target_device, peer_device) -> bool:
    get_device(target_device), get_device(peer_device)
    return False


def set_mempool_access_enabled(target_device, peer_device, enable: bool) -> None:
    _pair(target_device, peer_device, "Memory pool access", enable)


def is_peer_access_supported(target_device, peer_device) -> bool:
    get_device(target_device), get_device(peer_device)
    return False


def is_peer_access_enabled(target_device, peer_device) -> bool:
    get_device(target_device), get_device(peer_device)
    return False


def set_peer_access_enabled(target_device, peer_device, enable: bool) -> None:
    _pair(target_device, peer_device, "Peer access", enable)


class ScopedMempool:
    """Warp's context manager: the pool setting of `device` inside the block (enable=True raises
    as set_mempool_enabled does)."""

    def __init__(self, device, enable: bool):
        self.device = get_device(device)
        self.enable = enable

    def __enter__(self):
        self.saved = is_mempool_enabled(self.device)
        set_mempool_enabled(self.device, self.enable)
        return self

    def __exit__(self, *exc):
        set_mempool_enabled(self.device, self.saved)


class ScopedMempoolAccess:
    def __init__(self, target_device, peer_device, enable: bool):
        self.target, self.peer, self.enable = get_device(target_device), get_device(peer_device), enable

    def __enter__(self):
        self.saved = is_mempool_access_enabled(self.target, self.peer)
        set_mempool_access_enabled(self.target, self.peer, self.enable)
        return self

    def __exit__(self, *exc):
        set_mempool_access_enabled(self.target, self.peer, self.saved)


class ScopedPeerAccess:
    def __init__(self, target_device, peer_device, enable: bool):
        self.target, self.peer, self.enable = get_device(target_device), get_device(peer_device), enable

    def __enter__(self):
        self.saved = is_peer_access_enabled(self.target, self.peer)
        set_peer_access_enabled(self.target, self.peer, self.enable)
        return self

    def __exit__(self, *exc):
        set_peer_access_enabled(self.target, self.peer, self.saved)
