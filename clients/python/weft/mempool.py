"""Warp's memory-pool and peer-access API (wp.is_mempool_supported, wp.set_mempool_enabled,
wp.ScopedMempool, wp.get_mempool_used_mem_current, wp.is_peer_access_supported, ...) against weft.

A CUDA device's memory pool is, for a weft client, its session's GPU memory in weftd: the daemon
sub-allocates it from slabs the session owns (docs/cuda.md), allocations and frees are ordered
on the session's stream, and an array can be made while a graph is being captured (its zeroing
or fill is captured, as Warp's pooled allocations are). So every CUDA device the daemon computes
on reports pool support, and the pool API answers for the session:
- is_mempool_enabled / set_mempool_enabled / ScopedMempool keep Warp's per-device switch
  (default wp.config.enable_mempools_at_init, True). With it off, allocating during a graph
  capture raises Warp's error; elsewhere allocations are the same.
- get/set_mempool_release_threshold keep the value with Warp's rules (negative -> 0, a fraction
  in (0, 1] of the device's memory); weftd returns a session's empty slabs to the driver under
  its own bound (docs/cuda.md), which the value does not change.
- get_mempool_used_mem_current / _high: bytes of the arrays this client process created on the
  device and still holds (live now / the most at any time; their gradient buffers are not
  counted), counted where the daemon allocates them.
A device always reaches its own memory (peer and pool access to itself: True, setting it is a
no-op); between two GPUs weftd copies itself (peer copies where the GPUs allow them, staged
otherwise) and a client never maps another GPU's memory, so no pair of different devices has
client-side peer or pool access. The CPU has no pools (ValueError, as in Warp); unknown device
names raise, as everywhere.
"""
from __future__ import annotations

import threading

from . import config as _config
from .device import get_device

__all__ = ["is_mempool_supported", "is_mempool_enabled", "set_mempool_enabled",
           "get_mempool_release_threshold", "set_mempool_release_threshold",
           "get_mempool_used_mem_current", "get_mempool_used_mem_high",
           "is_mempool_access_supported", "is_mempool_access_enabled", "set_mempool_access_enabled",
           "is_peer_access_supported", "is_peer_access_enabled", "set_peer_access_enabled",
           "ScopedMempool", "ScopedMempoolAccess", "ScopedPeerAccess"]

_lock = threading.Lock()
_enabled: dict = {}       # device alias -> the pool switch (absent: enable_mempools_at_init)
_threshold: dict = {}     # device alias -> release threshold, bytes
_used: dict = {}          # device alias -> bytes of live arrays this process holds there
_high: dict = {}          # device alias -> the most _used has been


def _pool_device(device):
    """The CUDA device `device` names; ValueError for the CPU, RuntimeError without pools."""
    d = get_device(device)
    if not d.is_cuda:
        raise ValueError("Memory pools are only supported on CUDA devices")
    if not d.is_mempool_supported:
        raise RuntimeError(f"Device {d} does not support memory pools")
    return d


def note_allocated(alias: str, nbytes: int) -> None:
    """An array of `nbytes` the daemon allocated for this process on device `alias`."""
    with _lock:
        used = _used.get(alias, 0) + nbytes
        _used[alias] = used
        if used > _high.get(alias, 0):
            _high[alias] = used


def note_freed(alias: str, nbytes: int) -> None:
    with _lock:
        _used[alias] = max(_used.get(alias, 0) - nbytes, 0)


def is_mempool_supported(device=None) -> bool:
    return bool(get_device(device).is_mempool_supported)


def is_mempool_enabled(device=None) -> bool:
    d = get_device(device)
    if not (d.is_cuda and d.is_mempool_supported):
        return False
    return bool(_enabled.get(d.alias, _config.enable_mempools_at_init))


def set_mempool_enabled(device, enable: bool) -> None:
    """Disabling is accepted on any device (as in Warp); enabling needs a pool."""
    d = _pool_device(device) if enable else get_device(device)
    if d.is_cuda:
        _enabled[d.alias] = bool(enable)


def capture_allocation_error(device, nbytes: int):
    """Warp's error for an allocation during a graph capture on a device whose pool is off
    (None when the allocation may go ahead)."""
    if device.is_cuda and not is_mempool_enabled(device):
        return RuntimeError(
            f"Failed to allocate {nbytes} bytes on device '{device}':  Failed to allocate memory "
            f"during graph capture because memory pools are not enabled on device '{device}'.  "
            f"Try calling wp.set_mempool_enabled('{device}', True) before capture begins.")
    return None


def get_mempool_release_threshold(device=None) -> int:
    d = _pool_device(device)
    return int(_threshold.get(d.alias, 0))


def set_mempool_release_threshold(device, threshold) -> None:
    d = _pool_device(device)
    if threshold < 0:
        threshold = 0
    elif 0 < threshold <= 1:
        threshold = int(threshold * d.total_memory)
    _threshold[d.alias] = int(threshold)


def get_mempool_used_mem_current(device=None) -> int:
    d = _pool_device(device)
    with _lock:
        return int(_used.get(d.alias, 0))


def get_mempool_used_mem_high(device=None) -> int:
    d = _pool_device(device)
    with _lock:
        return int(_high.get(d.alias, 0))


def _pair(target_device, peer_device, what: str, enable: bool) -> None:
    t, p = get_device(target_device), get_device(peer_device)
    if not enable:
        return
    if not (t.is_cuda and p.is_cuda):
        raise ValueError(f"{what} is only supported between CUDA devices")
    if t.alias == p.alias and t.is_mempool_supported:
        return      # a device reaches its own memory: a no-op, as in Warp
    raise RuntimeError(f"{what} from {p} to {t} is not supported for weft clients: weftd copies "
                       "between GPUs itself (docs/cuda.md)")


def _access(target_device, peer_device) -> bool:
    """Only a CUDA device the daemon computes on reaches its own memory; the names are checked."""
    t, p = get_device(target_device), get_device(peer_device)
    return t.alias == p.alias and t.is_cuda and bool(t.is_mempool_supported)


is_mempool_access_supported = is_mempool_access_enabled = _access
is_peer_access_supported = is_peer_access_enabled = _access


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
    """with wp.ScopedMempool(device, enable): the pool switch inside the block, restored after."""
    getter, setter = staticmethod(is_mempool_enabled), staticmethod(set_mempool_enabled)


class ScopedMempoolAccess(_Scoped):
    """with wp.ScopedMempoolAccess(target_device, peer_device, enable):"""
    getter, setter = staticmethod(is_mempool_access_enabled), staticmethod(set_mempool_access_enabled)


class ScopedPeerAccess(_Scoped):
    """with wp.ScopedPeerAccess(target_device, peer_device, enable):"""
    getter, setter = staticmethod(is_peer_access_enabled), staticmethod(set_peer_access_enabled)
