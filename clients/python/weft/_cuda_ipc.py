"""The client's CUDA driver access: libcuda through ctypes, CUDA IPC mappings of the daemon's
GPU slabs, and the few driver calls the client makes itself (copies through a mapping,
context synchronization, pointer queries).

weftd exports every GPU slab once with a legacy CUDA IPC handle (docs/cuda.md); ArrayInfo of a
local session carries it (cuda_ipc_handle, cuda_ipc_offset, cuda_slab_size, cuda_slab_id). This
module opens each slab once per process with cuIpcOpenMemHandle in the device's primary context
(the context Torch, CuPy and JAX use, so their kernels can use the pointer), keeps the mapping
while arrays of this process use the slab, plus up to 16 idle regular (64 MiB) slabs, which the
daemon keeps for the session's next arrays (slab ids are never reused, so an idle mapping is
never handed out for other memory); a slab of its own (a large or exported array) is closed
with its last array, and every mapping at exit. A new slab may get the handle bytes of a freed
one: an idle mapping with those bytes is closed before the new one is opened.

Nothing here is required: without a driver (or with WEFT_CUDA_IPC=0, or when the sandbox
refuses IPC), `available()` is False, `reason()` says why, and the array layer falls back to
copies through the daemon (ArrayService.Read/Write).
"""
from __future__ import annotations

import atexit
import collections
import ctypes
import os
import threading

CU_IPC_MEM_LAZY_ENABLE_PEER_ACCESS = 1
CU_POINTER_ATTRIBUTE_CONTEXT = 1
CU_POINTER_ATTRIBUTE_MEMORY_TYPE = 2
CU_POINTER_ATTRIBUTE_BUFFER_ID = 7
CU_POINTER_ATTRIBUTE_DEVICE_ORDINAL = 9
CU_MEMORYTYPE_DEVICE = 2
CU_EVENT_DEFAULT = 0
CU_EVENT_DISABLE_TIMING = 2
CU_EVENT_INTERPROCESS = 4
CU_STREAM_NON_BLOCKING = 1
CU_DEVICE_ATTRIBUTE_CAN_USE_64_BIT_STREAM_MEM_OPS = 122
CU_STREAM_WAIT_VALUE_GEQ = 0
EVENT_POOL = 4                   # interprocess events per device, used in turn
IDLE_MAPPINGS_KEPT = 16          # regular slabs with no live array kept open (reopening costs)
REGULAR_SLAB_BYTES = 64 << 20    # the daemon keeps a session's regular slabs for reuse

_lock = threading.RLock()
_lib = None
_reason = None                   # why IPC is off (None: not tried yet / on)
_contexts: dict = {}             # ordinal -> primary context (retained)
_mappings: dict = {}             # slab id -> _Mapping
_idle = collections.OrderedDict()  # slab id -> None, least recently idle first
_stats = {"opened": 0, "closed": 0, "open_failures": 0, "last_failure": ""}


class CudaError(RuntimeError):
    """A CUDA driver call the client made failed."""


class _IpcHandle(ctypes.Structure):
    _fields_ = [("reserved", ctypes.c_char * 64)]


def _load():
    """Loads libcuda and initialises it once; sets _reason when it cannot be used."""
    global _lib, _reason
    if _lib is not None or _reason is not None:
        return _lib
    if os.environ.get("WEFT_CUDA_IPC", "1") == "0":
        _reason = "WEFT_CUDA_IPC=0"
        return None
    try:
        lib = ctypes.CDLL("libcuda.so.1")
    except OSError as err:
        _reason = f"no CUDA driver in this process ({err})"
        return None
    u = ctypes.c_uint
    vp = ctypes.c_void_p
    sz = ctypes.c_size_t
    p = ctypes.POINTER
    signatures = {
        "cuInit": [u],
        "cuDeviceGet": [p(ctypes.c_int), ctypes.c_int],
        "cuDevicePrimaryCtxRetain": [p(vp), ctypes.c_int],
        "cuDevicePrimaryCtxRelease_v2": [ctypes.c_int],
        "cuCtxPushCurrent_v2": [vp],
        "cuCtxPopCurrent_v2": [p(vp)],
        "cuCtxSynchronize": [],
        "cuCtxGetCurrent": [p(vp)],
        "cuIpcOpenMemHandle_v2": [p(ctypes.c_uint64), _IpcHandle, u],
        "cuIpcCloseMemHandle": [ctypes.c_uint64],
        "cuMemcpyDtoH_v2": [vp, ctypes.c_uint64, sz],
        "cuMemcpyHtoD_v2": [ctypes.c_uint64, vp, sz],
        "cuMemcpyDtoD_v2": [ctypes.c_uint64, ctypes.c_uint64, sz],
        "cuMemcpy2D_v2": [vp],
        "cuPointerGetAttribute": [vp, ctypes.c_int, ctypes.c_uint64],
        "cuMemGetAddressRange_v2": [p(ctypes.c_uint64), p(sz), ctypes.c_uint64],
        "cuIpcGetMemHandle": [p(_IpcHandle), ctypes.c_uint64],
        "cuEventCreate": [p(vp), u],
        "cuEventDestroy_v2": [vp],
        "cuEventRecord": [vp, vp],
        "cuEventSynchronize": [vp],
        "cuEventElapsedTime": [p(ctypes.c_float), vp, vp],
        "cuGetErrorName": [ctypes.c_int, p(ctypes.c_char_p)],
        "cuIpcGetEventHandle": [p(_IpcHandle), vp],
        "cuStreamWaitEvent": [vp, vp, u],
        "cuStreamCreate": [p(vp), u],
        "cuStreamSynchronize": [vp],
        "cuIpcOpenEventHandle": [p(vp), _IpcHandle],
        "cuEventQuery": [vp],
    }
    try:
        for name, args in signatures.items():
            fn = getattr(lib, name)
            fn.argtypes = args
            fn.restype = ctypes.c_int
    except AttributeError as err:
        _reason = f"libcuda lacks {err}"
        return None
    # Stream memory operations (ordering without a round trip, weft.interop.cuda_order):
    # optional, CUDA 12+ drivers.
    for name, args in {"cuStreamWaitValue64_v2": [vp, ctypes.c_uint64, ctypes.c_uint64, u],
                       "cuStreamWriteValue64_v2": [vp, ctypes.c_uint64, ctypes.c_uint64, u],
                       "cuDeviceGetAttribute": [p(ctypes.c_int), ctypes.c_int, ctypes.c_int]}.items():
        fn = getattr(lib, name, None)
        if fn is not None:
            fn.argtypes = args
            fn.restype = ctypes.c_int
    rc = lib.cuInit(0)
    if rc != 0:
        _reason = f"cuInit failed ({_name(lib, rc)})"
        return None
    _lib = lib
    return lib


def _name(lib, rc) -> str:
    out = ctypes.c_char_p()
    if lib.cuGetErrorName(rc, ctypes.byref(out)) == 0 and out.value:
        return out.value.decode()
    return f"CUresult {rc}"


def _check(rc, what):
    if rc != 0:
        raise CudaError(f"{what}: {_name(_lib, rc)}")


def available() -> bool:
    """Whether this process can use the CUDA driver (IPC mappings may still fail per slab;
    see reason())."""
    with _lock:
        return _load() is not None and _reason is None


def reason() -> str:
    """'' when CUDA IPC works here, else why the client copies instead."""
    with _lock:
        _load()
        return _reason or ""


def disable(why: str) -> None:
    """Turns IPC off for this process (a sandbox that refuses it); later calls copy."""
    global _reason
    with _lock:
        _reason = why


def stats() -> dict:
    with _lock:
        return dict(_stats, open=len(_mappings), idle=len(_idle))


def _context(ordinal: int):
    ctx = _contexts.get(ordinal)
    if ctx is None:
        dev = ctypes.c_int()
        _check(_lib.cuDeviceGet(ctypes.byref(dev), int(ordinal)), f"cuDeviceGet({ordinal})")
        handle = ctypes.c_void_p()
        _check(_lib.cuDevicePrimaryCtxRetain(ctypes.byref(handle), dev),
               "cuDevicePrimaryCtxRetain")
        ctx = _contexts[ordinal] = handle
    return ctx


class _Scope:
    """The device's primary context made current for a few driver calls."""

    def __init__(self, ordinal: int):
        self.ordinal = ordinal

    def __enter__(self):
        _check(_lib.cuCtxPushCurrent_v2(_context(self.ordinal)), "cuCtxPushCurrent")
        return self

    def __exit__(self, *exc):
        popped = ctypes.c_void_p()
        _lib.cuCtxPopCurrent_v2(ctypes.byref(popped))


class _Mapping:
    __slots__ = ("slab_id", "ordinal", "base", "size", "users", "handle")

    def __init__(self, slab_id, ordinal, base, size, handle):
        self.slab_id = slab_id
        self.ordinal = ordinal
        self.base = base
        self.size = size
        self.users = 0
        self.handle = handle


def _close(mapping) -> None:
    try:
        with _Scope(mapping.ordinal):
            _lib.cuIpcCloseMemHandle(ctypes.c_uint64(mapping.base))
        _stats["closed"] += 1
    except CudaError:
        pass


CUDA_ERROR_ALREADY_MAPPED = 208


def slab_address(info, ordinal: int):
    """The device address of the slab of GPU ArrayInfo `info` in this process (its IPC
    mapping, opened on first use), or None when IPC is unavailable for it. The caller pairs a
    successful call with release(slab id) when its allocation goes away."""
    handle = bytes(info.cuda_ipc_handle)
    if len(handle) != 64 or not info.cuda_slab_size:
        return None
    with _lock:
        if _load() is None or _reason is not None:
            return None
        slab_id = int(info.cuda_slab_id)
        mapping = _mappings.get(slab_id)
        if mapping is None:
            mapping = _open(slab_id, handle, ordinal, int(info.cuda_slab_size))
            if mapping is None:
                return None
        mapping.users += 1
        _idle.pop(slab_id, None)
        return mapping.base


def _open(slab_id, handle, ordinal, size):
    # The driver hands out the same handle bytes for a new allocation that took the place of a
    # freed one, and refuses a second open of a handle (ALREADY_MAPPED). A mapping of this
    # process with the same handle and no live array is such a freed slab: close it first. One
    # with live arrays is the same memory (a live slab is never freed under them): share it.
    for other in _mappings.copy().values():   # a copy: finalizers may release meanwhile
        if other.handle == handle and other.ordinal == ordinal:
            if other.users > 0 and other.size == size:
                _mappings[slab_id] = other
                return other
            _forget(other)
    raw = _IpcHandle()
    ctypes.memmove(ctypes.addressof(raw), handle, 64)
    ptr = ctypes.c_uint64()
    try:
        with _Scope(ordinal):
            rc = _lib.cuIpcOpenMemHandle_v2(ctypes.byref(ptr), raw,
                                            CU_IPC_MEM_LAZY_ENABLE_PEER_ACCESS)
    except CudaError as err:
        disable(f"no usable CUDA context here ({err})")
        return None
    if rc != 0:
        _stats["open_failures"] += 1
        _stats["last_failure"] = _name(_lib, rc)
        if rc != CUDA_ERROR_ALREADY_MAPPED:
            # A sandbox refusing IPC fails every open the same way: turn it off once.
            disable(f"cuIpcOpenMemHandle failed ({_name(_lib, rc)})")
        return None
    mapping = _mappings[slab_id] = _Mapping(slab_id, ordinal, int(ptr.value), size, handle)
    _stats["opened"] += 1
    return mapping


def _forget(mapping) -> None:
    """Closes `mapping` and drops every slab id that names it."""
    # Over a copy: an array finalizer may run at any allocation here and release a mapping.
    for key in [k for k, m in _mappings.copy().items() if m is mapping]:
        del _mappings[key]
        _idle.pop(key, None)
    _close(mapping)


def release(slab_id: int) -> None:
    """An allocation of slab `slab_id` that used its mapping (slab_address) went away."""
    with _lock:
        mapping = _mappings.get(int(slab_id))
        if mapping is None or mapping.users <= 0:
            return
        mapping.users -= 1
        if mapping.users:
            return
        if mapping.size != REGULAR_SLAB_BYTES:
            _forget(mapping)    # a slab of one array: the daemon frees it with that array
            return
        _idle[int(slab_id)] = None
        while len(_idle) > IDLE_MAPPINGS_KEPT:
            old_id, _ = _idle.popitem(last=False)
            old = _mappings.get(old_id)
            if old is not None and old.users == 0:
                _forget(old)


def copy_to_host(ordinal: int, dst_address: int, src_device: int, nbytes: int) -> None:
    with _lock, _Scope(ordinal):
        _check(_lib.cuMemcpyDtoH_v2(ctypes.c_void_p(dst_address), ctypes.c_uint64(src_device),
                                    nbytes), "cuMemcpyDtoH")


def copy_from_host(ordinal: int, dst_device: int, src_address: int, nbytes: int) -> None:
    """Host -> device, finished (visible to other processes) when it returns."""
    with _lock, _Scope(ordinal):
        _check(_lib.cuMemcpyHtoD_v2(ctypes.c_uint64(dst_device), ctypes.c_void_p(src_address),
                                    nbytes), "cuMemcpyHtoD")
        _check(_lib.cuCtxSynchronize(), "cuCtxSynchronize")


def copy_device(ordinal: int, dst_device: int, src_device: int, nbytes: int) -> None:
    """Device -> device in this process's context, finished when it returns."""
    with _lock, _Scope(ordinal):
        _check(_lib.cuMemcpyDtoD_v2(ctypes.c_uint64(dst_device), ctypes.c_uint64(src_device),
                                    nbytes), "cuMemcpyDtoD")
        _check(_lib.cuCtxSynchronize(), "cuCtxSynchronize")


def synchronize(ordinal: int) -> None:
    """Waits for every stream of this process on the device (Torch's, CuPy's, ...)."""
    with _lock:
        if _load() is None:
            return
        with _Scope(ordinal):
            _check(_lib.cuCtxSynchronize(), "cuCtxSynchronize")


def _pointer_attribute(address: int, attribute: int, ctype):
    """cuPointerGetAttribute of a pointer of this process as a Python int, or None (no driver,
    or the driver does not know the address)."""
    with _lock:
        if _load() is None:
            return None
        value = ctype()
        if _lib.cuPointerGetAttribute(ctypes.byref(value), attribute, ctypes.c_uint64(address)) != 0:
            return None
        return int(value.value)


def pointer_device(address: int):
    """The CUDA device ordinal of a device pointer of this process, or None (host memory, or
    no driver)."""
    if _pointer_attribute(address, CU_POINTER_ATTRIBUTE_MEMORY_TYPE, ctypes.c_uint) is None:
        return None
    return _pointer_attribute(address, CU_POINTER_ATTRIBUTE_DEVICE_ORDINAL, ctypes.c_int)


_exported = collections.OrderedDict()   # (ordinal, buffer id) -> (base, size, handle bytes)
EXPORTED_KEPT = 256


def export_allocation(ordinal: int, address: int):
    """(base, size, buffer id, 64 handle bytes) of the CUDA allocation (cudaMalloc block) of
    this process that holds device address `address`: what weftd needs to import it
    (ArrayService.ImportCuda). The buffer id is unique for the life of this process, so a block
    freed and allocated again is a new identity even if the driver reuses its handle bytes;
    an allocation exported before is known by its buffer id alone (one driver call).
    Raises CudaError where the memory cannot be exported (not cudaMalloc memory: VMM or
    stream-ordered pools, managed or host memory)."""
    with _lock:
        if _load() is None:
            raise CudaError(f"no CUDA driver ({_reason})")
        buffer_id = ctypes.c_uint64()
        pointer = ctypes.c_uint64(address)
        if _lib.cuPointerGetAttribute(ctypes.byref(buffer_id), CU_POINTER_ATTRIBUTE_BUFFER_ID,
                                      pointer) == 0:
            known = _exported.get((ordinal, buffer_id.value))
            if known is not None and known[0] <= address < known[0] + known[1]:
                _exported.move_to_end((ordinal, buffer_id.value))
                return known[0], known[1], int(buffer_id.value), known[2]
        base = ctypes.c_uint64()
        size = ctypes.c_size_t()
        with _Scope(ordinal):
            _check(_lib.cuMemGetAddressRange_v2(ctypes.byref(base), ctypes.byref(size), pointer),
                   "cuMemGetAddressRange")
            _check(_lib.cuPointerGetAttribute(ctypes.byref(buffer_id),
                                              CU_POINTER_ATTRIBUTE_BUFFER_ID, pointer),
                   "cuPointerGetAttribute(BUFFER_ID)")
            key = (ordinal, buffer_id.value)
            known = _exported.get(key)
            if known is None or known[0] != base.value or known[1] != size.value:
                h = _IpcHandle()
                _check(_lib.cuIpcGetMemHandle(ctypes.byref(h), base), "cuIpcGetMemHandle")
                known = _exported[key] = (int(base.value), int(size.value),
                                          ctypes.string_at(ctypes.addressof(h), 64))
                if len(_exported) > EXPORTED_KEPT:
                    _exported.popitem(last=False)
            else:
                _exported.move_to_end(key)
        return known[0], known[1], int(buffer_id.value), known[2]


def buffer_id(address: int):
    """The buffer id of the CUDA allocation of this process that holds device address
    `address` (unique for the life of the process: a segment freed and allocated again has a
    new one), or None where the driver does not know the address (one driver call)."""
    return _pointer_attribute(address, CU_POINTER_ATTRIBUTE_BUFFER_ID, ctypes.c_uint64)


class IpcEvent:
    """An interprocess event of this process (cudaEventInterprocess | DisableTiming) on one
    device and its IPC handle bytes (taken once: weftd opens each handle once per session)."""
    __slots__ = ("ordinal", "event", "handle")

    def __init__(self, ordinal, event, handle):
        self.ordinal = ordinal
        self.event = event
        self.handle = handle


_events: dict = {}               # ordinal -> [IpcEvent], EVENT_POOL of them
_event_turn: dict = {}           # ordinal -> index of the next event to use
_proxy_streams: dict = {}        # ordinal -> this process's stream that stands for weft's


def next_event(ordinal: int) -> IpcEvent:
    """The next event of the device's small pool (created on first use, kept for the life of
    the process: weftd may hold them open until the session ends). Each use records it again;
    a use never overlaps the previous use of the same event because every ordering round
    ends with a Submit that returns after weftd ran it (docs/interop.md, "Ordering")."""
    with _lock:
        if _load() is None:
            raise CudaError(f"no CUDA driver ({_reason})")
        pool = _events.get(ordinal)
        if pool is None:
            pool = []
            with _Scope(ordinal):
                for _ in range(EVENT_POOL):
                    ev = ctypes.c_void_p()
                    _check(_lib.cuEventCreate(ctypes.byref(ev), CU_EVENT_INTERPROCESS |
                                              CU_EVENT_DISABLE_TIMING), "cuEventCreate")
                    h = _IpcHandle()
                    _check(_lib.cuIpcGetEventHandle(ctypes.byref(h), ev), "cuIpcGetEventHandle")
                    pool.append(IpcEvent(ordinal, ev, ctypes.string_at(ctypes.addressof(h), 64)))
            _events[ordinal] = pool
        turn = _event_turn.get(ordinal, 0)
        _event_turn[ordinal] = (turn + 1) % len(pool)
        return pool[turn]


def create_ipc_event(ordinal: int) -> IpcEvent:
    """A new interprocess event of this process on device `ordinal` (wp.Event with
    interprocess=True): not from the ordering pool, it lives as long as its wp.Event."""
    with _lock:
        if _load() is None:
            raise CudaError(f"no CUDA driver ({_reason})")
        with _Scope(ordinal):
            ev = ctypes.c_void_p()
            _check(_lib.cuEventCreate(ctypes.byref(ev), CU_EVENT_INTERPROCESS |
                                      CU_EVENT_DISABLE_TIMING), "cuEventCreate")
            h = _IpcHandle()
            rc = _lib.cuIpcGetEventHandle(ctypes.byref(h), ev)
            if rc != 0:
                _lib.cuEventDestroy_v2(ev)
                _check(rc, "cuIpcGetEventHandle")
        return IpcEvent(ordinal, ev, ctypes.string_at(ctypes.addressof(h), 64))


def open_ipc_event(ordinal: int, handle: bytes) -> IpcEvent:
    """The event another process made interprocess, opened in this process from its 64-byte
    handle (wp.event_from_ipc_handle)."""
    if len(handle) != 64:
        raise ValueError(f"an IPC event handle is 64 bytes, not {len(handle)}")
    with _lock:
        if _load() is None:
            raise CudaError(f"no CUDA driver ({_reason})")
        raw = _IpcHandle()
        ctypes.memmove(ctypes.addressof(raw), bytes(handle), 64)
        with _Scope(ordinal):
            ev = ctypes.c_void_p()
            _check(_lib.cuIpcOpenEventHandle(ctypes.byref(ev), raw), "cuIpcOpenEventHandle")
        return IpcEvent(ordinal, ev, bytes(handle))


def destroy_event(event: IpcEvent) -> None:
    """Destroys this process's event (the daemon's opened copy of it lives on until the
    session that opened it ends)."""
    with _lock:
        if _lib is None or not event.event:
            return
        with _Scope(event.ordinal):
            _lib.cuEventDestroy_v2(event.event)
        event.event = None


def synchronize_event(event: IpcEvent) -> None:
    """Waits on the host until the work before the event's latest record (by any process) is
    done."""
    with _lock, _Scope(event.ordinal):
        _check(_lib.cuEventSynchronize(event.event), "cuEventSynchronize")


def event_is_done(event: IpcEvent) -> bool:
    with _lock, _Scope(event.ordinal):
        rc = _lib.cuEventQuery(event.event)
    if rc == CUDA_ERROR_NOT_READY:
        return False
    _check(rc, "cuEventQuery")
    return True


def record_event(event: IpcEvent, stream: int) -> None:
    """Records `event` on this process's CUDA stream `stream` (0: the legacy default stream)."""
    with _lock, _Scope(event.ordinal):
        _check(_lib.cuEventRecord(event.event, ctypes.c_void_p(stream or None)), "cuEventRecord")


def wait_event(stream: int, event: IpcEvent) -> None:
    """Makes this process's CUDA stream `stream` wait (on the GPU) for the latest record of
    `event`, made by weftd: no host wait."""
    with _lock, _Scope(event.ordinal):
        _check(_lib.cuStreamWaitEvent(ctypes.c_void_p(stream or None), event.event, 0),
               "cuStreamWaitEvent")


def proxy_stream(ordinal: int) -> int:
    """A stream of this process on the device that stands for weft's session stream (it is
    made to wait for weft's work before it is handed out, e.g. as the
    `__cuda_array_interface__` "stream"). Blocking, as the streams Warp creates: it also
    orders with this process's legacy default stream."""
    with _lock:
        s = _proxy_streams.get(ordinal)
        if s is None:
            if _load() is None:
                raise CudaError(f"no CUDA driver ({_reason})")
            h = ctypes.c_void_p()
            with _Scope(ordinal):
                _check(_lib.cuStreamCreate(ctypes.byref(h), 0), "cuStreamCreate")
            s = _proxy_streams[ordinal] = int(h.value)
        return s


_mem_ops: dict = {}              # ordinal -> whether stream memory operations work here


def stream_mem_ops(ordinal: int) -> bool:
    """Whether this process can queue 64-bit stream memory operations (cuStreamWaitValue64 /
    cuStreamWriteValue64) on device `ordinal`."""
    with _lock:
        known = _mem_ops.get(ordinal)
        if known is not None:
            return known
        ok = False
        if _load() is not None and all(hasattr(_lib, name) for name in (
                "cuStreamWaitValue64_v2", "cuStreamWriteValue64_v2", "cuDeviceGetAttribute")):
            dev, value = ctypes.c_int(), ctypes.c_int()
            ok = (_lib.cuDeviceGet(ctypes.byref(dev), int(ordinal)) == 0 and
                  _lib.cuDeviceGetAttribute(ctypes.byref(value),
                                            CU_DEVICE_ATTRIBUTE_CAN_USE_64_BIT_STREAM_MEM_OPS,
                                            dev) == 0 and value.value != 0)
        _mem_ops[ordinal] = ok
        return ok


CUDA_ERROR_INVALID_CONTEXT = 201


_CURRENT = ctypes.c_void_p()          # _stream_op's cuCtxGetCurrent result (under _lock)
_CURRENT_REF = ctypes.byref(_CURRENT)


def _stream_op(fn, what, ordinal, stream, address, value, flags):
    # A stream of its own names its context: queued from whatever context is current (Torch
    # and CuPy keep the device's primary context current), pushed only when the driver asks.
    # The legacy default stream (0) is the current context's: always pushed.
    if stream:
        rc = fn(stream, address, value, flags)
    else:
        _lib.cuCtxGetCurrent(_CURRENT_REF)          # under _lock: one buffer for every call
        ctx = _contexts.get(ordinal) or _context(ordinal)
        rc = fn(None, address, value, flags) if _CURRENT.value == ctx.value \
            else CUDA_ERROR_INVALID_CONTEXT
    if rc == CUDA_ERROR_INVALID_CONTEXT:
        with _Scope(ordinal):
            rc = fn(stream or None, address, value, flags)
    _check(rc, what)


# weft._stream_ops (clients/python/native/stream_ops.c): per device, (op, the driver's
# cuStreamWriteValue64_v2, cuStreamWaitValue64_v2 and cuCtxGetCurrent addresses, the device's
# primary context) for the stream memory operations in C; False when not looked up yet, None
# when not built or WEFT_NATIVE_STREAM_OPS=0.
_native_ops: dict = {}


def _native_op(ordinal: int):
    entry = _native_ops.get(ordinal, False)
    if entry is False:
        from . import _native  # noqa: PLC0415

        module = _native.optional("_stream_ops", "WEFT_NATIVE_STREAM_OPS")
        entry = None
        if module is not None and _load() is not None:
            with _lock:
                fns = [getattr(_lib, name, None) for name in
                       ("cuStreamWriteValue64_v2", "cuStreamWaitValue64_v2", "cuCtxGetCurrent")]
                address = [ctypes.cast(fn, ctypes.c_void_p).value if fn is not None else None
                           for fn in fns]
                ctx = _context(ordinal).value
            if all(address) and ctx:
                entry = (module.op, address[0], address[1], address[2], ctx)
        _native_ops[ordinal] = entry
    return entry


def write_value(ordinal: int, stream: int, address: int, value: int) -> None:
    """Queues on this process's stream `stream`: write the 64-bit `value` at device `address`
    after the work queued before it."""
    native = _native_ops.get(ordinal, False)
    if native is False:
        native = _native_op(ordinal)
    if native is not None:
        rc = native[0](native[1], native[3], native[4], stream, address, value, 0)
        if rc == 0:
            return
        if rc != CUDA_ERROR_INVALID_CONTEXT:
            _check(rc, "cuStreamWriteValue64")
    elif stream and _lib.cuStreamWriteValue64_v2(stream, address, value, 0) == 0:
        return                   # a stream of its own names its context: no lock, no push
    with _lock:
        _stream_op(_lib.cuStreamWriteValue64_v2, "cuStreamWriteValue64", ordinal, stream,
                   address, value, 0)


def wait_value(ordinal: int, stream: int, address: int, value: int) -> None:
    """Queues on this process's stream `stream`: wait (on the GPU) until the 64-bit word at
    device `address` holds at least `value`."""
    native = _native_ops.get(ordinal, False)
    if native is False:
        native = _native_op(ordinal)
    if native is not None:
        rc = native[0](native[2], native[3], native[4], stream, address, value,
                       CU_STREAM_WAIT_VALUE_GEQ)
        if rc == 0:
            return
        if rc != CUDA_ERROR_INVALID_CONTEXT:
            _check(rc, "cuStreamWaitValue64")
    elif stream and _lib.cuStreamWaitValue64_v2(stream, address, value, CU_STREAM_WAIT_VALUE_GEQ) == 0:
        return                   # a stream of its own names its context: no lock, no push
    with _lock:
        _stream_op(_lib.cuStreamWaitValue64_v2, "cuStreamWaitValue64", ordinal, stream,
                   address, value, CU_STREAM_WAIT_VALUE_GEQ)


CUDA_ERROR_NOT_READY = 600


def stream_is_blocking(ordinal: int, stream: int) -> bool:
    """Whether this process's CUDA stream `stream` synchronizes with the legacy default stream
    (the default stream itself: True)."""
    if not stream:
        return True
    if _load() is None:
        raise CudaError(f"no CUDA driver ({_reason})")
    flags = ctypes.c_uint()
    with _lock, _Scope(ordinal):
        _check(_lib.cuStreamGetFlags(ctypes.c_void_p(stream), ctypes.byref(flags)), "cuStreamGetFlags")
    return not (flags.value & CU_STREAM_NON_BLOCKING)


def stream_is_idle(ordinal: int, stream: int) -> bool:
    """Whether the work queued so far on this process's CUDA stream `stream` is done."""
    if _load() is None:
        raise CudaError(f"no CUDA driver ({_reason})")
    with _lock, _Scope(ordinal):
        rc = _lib.cuStreamQuery(ctypes.c_void_p(stream or None))
    if rc == CUDA_ERROR_NOT_READY:
        return False
    _check(rc, "cuStreamQuery")
    return True


def synchronize_stream(ordinal: int, stream: int) -> None:
    with _lock, _Scope(ordinal):
        _check(_lib.cuStreamSynchronize(ctypes.c_void_p(stream or None)), "cuStreamSynchronize")


@atexit.register
def _close_all() -> None:
    with _lock:
        if _lib is None:
            return
        for mapping in {id(m): m for m in _mappings.values()}.values():
            _close(mapping)
        _mappings.clear()
        _idle.clear()
