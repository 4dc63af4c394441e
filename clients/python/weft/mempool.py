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


def _no_access(target_device, peer_device) -> bool:
    """No device pair has client-side pool or peer access; the names are still checked."""
    get_device(target_device), get_device(peer_device)
    return False


is_mempool_access_supported = is_mempool_access_enabled = _no_access
is_peer_access_supported = is_peer_access_enabled = _no_access


def set_mempool_access_enabled(target_device, peer_device, enable: bool) -> None:
    _pair(target_device, peer_device, "Memory pool access", enable)


def set_peer_access_enabled(target_device, peer_device, enable: bool) -> None:
    _pair(target_device, peer_device, "Peer access", enable)


class _Scoped:
    """Warp's scoped setters: `setter(*devices, enable)` inside the block, the setting read by
    `getter(*devices)` restored after it."""

    getter = setter = None

    def __init__(self, *args):
        *devices, self.enable = args
        self.devices = [get_device(d) for d in devices]

    def __enter__(self):
        self.saved = type(self).getter(*self.devices)
        type(self).setter(*self.devices, self.enable)
        return self

    def __exit__(self, *exc):
        type(self).setter(*self.devices, self.saved)


class ScopedMempool(_Scoped):
    """with wp.ScopedMempool(device, enable): (enable=True raises as set_mempool_enabled)."""
    getter, setter = staticmethod(is_mempool_enabled), staticmethod(set_mempool_enabled)


class ScopedMempoolAccess(_Scoped):
    """with wp.ScopedMempoolAccess(target_device, peer_device, enable):"""
    getter, setter = staticmethod(is_mempool_access_enabled), staticmethod(set_mempool_access_enabled)


class ScopedPeerAccess(_Scoped):
    """with wp.ScopedPeerAccess(target_device, peer_device, enable):"""
    getter, setter = staticmethod(is_peer_access_enabled), staticmethod(set_peer_access_enabled)
