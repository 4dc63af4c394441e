"""Weft memory behind foreign host pointers, and memory shared with frameworks.

A local client sees each CPU array's bytes at an address in a mapped shared-memory slab. Every
allocation whose slab address leaves the array layer (numpy() views, `.ptr`, DLPack, to_torch)
is noted here with its address range, so that an address a framework hands back (a Torch tensor
made by to_torch, a NumPy view of a weft array, a DLPack capsule of one) resolves to the
allocation that owns it and is used in place instead of being copied. Entries hold the
allocation weakly: memory only resolves while its allocation is alive, and any foreign object
still pointing at it keeps it alive (through the NumPy view it was made from).

`mark_shared` records allocations a framework (Torch, JAX, a DLPack consumer) can read and
write at any time: launches and tape backward passes that touch them complete before they
return (see docs/interop.md, "Ordering").
"""
from __future__ import annotations

import bisect
import threading
import weakref

import numpy as np

# Re-entrant: a weakref callback (forget) may run inside a locked region when the garbage
# collector frees an allocation there.
_lock = threading.RLock()
_spaces: dict = {}           # "cpu" / "cuda:N" -> (sorted start addresses, {start: (end, weakref)})
_shared = weakref.WeakSet()  # allocations a framework holds (launches touching them synchronize)


def note_range(alloc, space: str, start: int, nbytes: int) -> None:
    """Records that `alloc` is seen at [start, start+nbytes) in address space `space`."""
    end = start + int(nbytes)
    with _lock:
        starts, entries = _spaces.setdefault(space, ([], {}))

    def forget(ref, start=start, lock=_lock, bisect_left=bisect.bisect_left):
        # what it uses is bound now: at interpreter exit the module's globals may already be
        # None when the last allocations die
        with lock:
            entry = entries.get(start)
            if entry is not None and entry[1] is ref:
                del entries[start]
                i = bisect_left(starts, start)
                if i < len(starts) and starts[i] == start:
                    del starts[i]

    ref = weakref.ref(alloc, forget)
    with _lock:
        if start not in entries:
            bisect.insort(starts, start)
        entries[start] = (end, ref)


def note_mapped(alloc, mapping) -> None:
    """Called by the array layer when `alloc`'s slab mapping is first handed out."""
    info = alloc.info
    note_range(alloc, "cpu", mapping.address + int(info.shm_offset), int(info.byte_size))


def find(address: int, nbytes: int, space: str = "cpu"):
    """(allocation, byte offset in it) of live weft memory holding [address, address+nbytes)
    in address space `space`, else None."""
    registry = _spaces.get(space)
    if registry is None:
        return None
    starts, entries = registry
    with _lock:
        i = bisect.bisect_right(starts, address) - 1
        if i < 0:
            return None
        entry = entries.get(starts[i])
        if entry is None:
            return None
        start = starts[i]
        end, ref = entry
    if address + max(nbytes, 0) > end:
        return None
    alloc = ref()
    if alloc is None:
        return None
    return alloc, address - start


def mark_shared(alloc) -> None:
    if alloc is not None:
        _shared.add(alloc)
        try:
            alloc.framework_shared = True      # touches_shared's test, an attribute read
        except AttributeError:
            pass


def any_shared() -> bool:
    return len(_shared) > 0


def touches_shared(values) -> bool:
    """Whether any weft array among `values` lives in memory a framework holds."""
    if not _shared:
        return False
    for value in values:
        alloc = getattr(value, "_alloc", None)
        if alloc is not None and getattr(alloc, "framework_shared", False):
            return True
        grad = getattr(value, "_grad", None)
        galloc = getattr(grad, "_alloc", None)
        if galloc is not None and getattr(galloc, "framework_shared", False):
            return True
    return False


_array_class = None
_devices: dict = {}


def _device(name: str):
    device = _devices.get(name)
    if device is None:
        from ..device import get_device  # noqa: PLC0415

        device = _devices[name] = get_device(name)
    return device


def array_over(alloc, byte_offset: int, shape, strides, dtype):
    """A weft array viewing `alloc` at `byte_offset` (bytes) with byte `strides`; checked
    against the allocation's size."""
    global _array_class
    if _array_class is None:
        from ..array import array  # noqa: PLC0415

        _array_class = array
    from .external import elem_bytes  # noqa: PLC0415

    info = alloc.info
    shape = tuple(int(s) for s in shape)
    strides = tuple(int(s) for s in strides)
    elem = elem_bytes(dtype)
    size = 1
    for n in shape:
        size *= n
    if any(s < 0 for s in strides):
        raise ValueError("negative strides cannot view weft memory in place")
    span = (sum((n - 1) * s for n, s in zip(shape, strides)) + elem) if size else 0
    if byte_offset < 0 or byte_offset + span > int(info.byte_size):
        raise ValueError(f"a view of {span} bytes at offset {byte_offset} exceeds the "
                         f"allocation ({info.byte_size} bytes)")
    out = _array_class.__new__(_array_class)
    out._alloc = alloc
    out._info = info
    out._handle = info.handle
    out._byte_offset = int(byte_offset)
    out.dtype = dtype
    out.shape = shape
    out.strides = strides
    out.ndim = len(shape)
    out.size = size
    out.device = _device(info.device)
    out.pinned = False
    out._requires_grad = False
    out._grad = None
    return out


_grad_infos = weakref.WeakKeyDictionary()   # _Allocation -> ArrayInfo of its daemon gradient


def grad_view(a):
    """`a.grad`, without a Describe round trip when the gradient of `a`'s allocation was
    described before (conversions make new array objects over the same allocation)."""
    if a._grad is not None:
        return a._grad
    info = a._info
    if info is None or not info.grad_handle:
        return None
    ginfo = _grad_infos.get(a._alloc)
    if ginfo is None or ginfo.handle != info.grad_handle:
        return a.grad                   # described once, kept in _grad_infos
    from ..array import _Allocation  # noqa: PLC0415

    galloc = _Allocation(a._alloc.runtime, ginfo, owned=False, parent=a._alloc)
    g = array_over(galloc, a._byte_offset, a.shape, a.strides, a.dtype)
    a._grad = g
    return g


def set_now(a, values=None) -> None:
    """Writes zeros (or `values`) into weft array `a` before returning: a framework that
    shares the memory (a gradient handed to Torch or Paddle) may read it at once. A local
    CPU array is written through its slab; any other goes through the daemon and waits."""
    if a._alloc.runtime.local and a._info.shm_name:
        view = a.numpy()
        view[...] = 0 if values is None else np.asarray(values).reshape(view.shape)
        return
    if values is None:
        a.zero_()
    else:
        a.assign(values)
    a._alloc.runtime.synchronize()
