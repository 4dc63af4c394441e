"""Framework GPU memory into weft: a Torch/CuPy/JAX (or any `__cuda_array_interface__` or
CUDA DLPack) array of this process used by a weft launch or wp.from_torch/from_dlpack/from_jax.

Imported in place where it can be (local session, CUDA driver in this process, cudaMalloc
memory): the client finds the array's base allocation (cuMemGetAddressRange), its buffer id
(unique for the life of the process) and its legacy IPC handle (cuIpcGetMemHandle, cached per
allocation), and weftd opens the handle (ArrayService.ImportCuda, cached per session by handle
bytes and buffer id) and returns an array handle that kernels use in place. The weft array
keeps a reference to the framework object for as long as it (or any view of it) lives, so the
framework cannot free or hand out that block meanwhile; a block freed and allocated again has a
new buffer id, so weftd never reads it through an old mapping (docs/interop.md). The imported
array of a Torch tensor is remembered on the tensor (keyed by its pointer, layout, dtype and
gradient pointer), so converting the same tensor again costs no round trip. The remembered
import does not hold the gradient's memory (each array handed out does): a training loop's new
gradient, which Torch places in a block an earlier one freed, finds it again, checked by buffer
id against a segment freed and allocated again.

Where import is impossible (remote session, IPC off, VMM or pool memory the driver cannot
export, negative strides) the data is copied into a weft GPU array (device to device through
this process's IPC mapping of the weft slab; through the host where IPC is not available) and,
for launches, copied back after the kernel ran.
"""
from __future__ import annotations

import collections
import ctypes
import weakref

import numpy as np

from .. import _cuda_ipc, _runtime
from ..errors import WeftError
from . import external, memory

_KDL_CUDA = 2
_import_refused = ""     # why weftd cannot open this process's IPC handles ("" = it can)


def import_refused() -> str:
    """'' while weftd imports this process's GPU memory, else why it cannot (copies instead)."""
    return _import_refused


class _Source:
    """Pointer, layout and device of a foreign GPU array, and what keeps it alive."""

    def __init__(self, ptr, np_dtype, shape, strides, keep, ordinal, scalar=None):
        self.ptr = int(ptr)
        self.np_dtype = np.dtype(np_dtype)
        # the weft scalar type where NumPy has none (bfloat16: np_dtype holds its bits)
        self.scalar = scalar
        self.shape = tuple(int(s) for s in shape)
        if strides is None:
            strides, step = [], self.np_dtype.itemsize
            for n in reversed(self.shape):
                strides.append(step)
                step *= max(n, 1)
            strides = tuple(reversed(strides))
        self.strides = tuple(int(s) for s in strides)
        self.keep = keep
        self.ordinal = ordinal

    @property
    def contiguous(self) -> bool:
        step = self.np_dtype.itemsize
        for n, s in zip(reversed(self.shape), reversed(self.strides)):
            if n > 1 and s != step:
                return False
            step *= n
        return True

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64)) * self.np_dtype.itemsize


def _from_interface(obj, what) -> _Source:
    iface = external.cuda_interface(obj)
    if iface.get("mask") is not None:
        raise external.InteropError(f"{what}: masked CUDA arrays are not supported")
    ptr = int(iface["data"][0])
    ordinal = None
    if external.is_torch_tensor(obj):
        ordinal = obj.device.index if obj.device.index is not None else 0
    elif ptr:
        ordinal = _cuda_ipc.pointer_device(ptr)
    return _Source(ptr, iface["typestr"], iface["shape"], iface.get("strides"), obj, ordinal)


class _DLTensorView(ctypes.Structure):
    _fields_ = [("data", ctypes.c_void_p), ("device_type", ctypes.c_int32),
                ("device_id", ctypes.c_int32), ("ndim", ctypes.c_int32),
                ("code", ctypes.c_uint8), ("bits", ctypes.c_uint8), ("lanes", ctypes.c_uint16),
                ("shape", ctypes.POINTER(ctypes.c_int64)),
                ("strides", ctypes.POINTER(ctypes.c_int64)), ("byte_offset", ctypes.c_uint64)]


_DL_CODES = {0: "i", 1: "u", 2: "f", 6: "b"}


_USED_NAME = b"used_dltensor"   # a capsule keeps the name pointer: this bytes object lives on


class _Capsule:
    """A consumed "dltensor" capsule: calls the producer's deleter when collected."""

    def __init__(self, capsule):
        get = ctypes.pythonapi["PyCapsule_GetPointer"]       # own function objects: other
        # modules set other argtypes on the shared attributes
        get.restype = ctypes.c_void_p
        get.argtypes = [ctypes.py_object, ctypes.c_char_p]
        self.address = get(capsule, b"dltensor")
        rename = ctypes.pythonapi["PyCapsule_SetName"]
        rename.restype = ctypes.c_int
        rename.argtypes = [ctypes.py_object, ctypes.c_char_p]
        rename(capsule, _USED_NAME)
        self.tensor = _DLTensorView.from_address(self.address)

    def __del__(self):
        # DLManagedTensor: DLTensor (48 bytes on 64-bit), manager_ctx, deleter
        deleter_at = self.address + ctypes.sizeof(_DLTensorView) + ctypes.sizeof(ctypes.c_void_p)
        deleter = ctypes.c_void_p.from_address(deleter_at).value
        if deleter:
            ctypes.CFUNCTYPE(None, ctypes.c_void_p)(deleter)(self.address)


def _from_dlpack(source, what) -> _Source:
    try:
        capsule = source.__dlpack__(stream=None)
    except TypeError:
        capsule = source.__dlpack__()
    if type(capsule).__name__ != "PyCapsule":
        raise external.InteropError(f"{what}: __dlpack__ did not return a capsule")
    try:
        held = _Capsule(capsule)
    except (ValueError, SystemError):
        raise external.InteropError(f"{what}: only legacy ('dltensor') CUDA capsules are "
                                    f"imported") from None
    t = held.tensor
    if t.device_type != _KDL_CUDA:
        raise external.InteropError(f"{what}: DLPack device type {t.device_type} is not CUDA")
    scalar = None
    if int(t.code) == 4 and int(t.bits) == 16 and t.lanes == 1:     # kDLBfloat: bfloat16
        from .. import types  # noqa: PLC0415
        scalar, np_dtype = types.bfloat16, np.dtype(np.uint16)
    else:
        kind = _DL_CODES.get(int(t.code))
        if kind is None or t.lanes != 1 or int(t.bits) not in (8, 16, 32, 64):
            raise external.InteropError(f"{what}: unsupported DLPack dtype (code {t.code}, "
                                        f"{t.bits} bits, {t.lanes} lanes)")
        np_dtype = np.dtype("?") if kind == "b" else np.dtype(f"{kind}{t.bits // 8}")
    shape = [int(t.shape[i]) for i in range(t.ndim)]
    strides = ([int(t.strides[i]) * np_dtype.itemsize for i in range(t.ndim)]
               if t.strides else None)
    return _Source(int(t.data or 0) + int(t.byte_offset), np_dtype, shape, strides, held,
                   int(t.device_id), scalar)


def _source_dtype(src: _Source, dtype, what: str):
    """The dtype asked for, or the source's own scalar type where NumPy has none (bfloat16,
    whose bits only alias bfloat16: DLPackDtypeError for anything else, as Warp's rule)."""
    if src.scalar is None:
        return dtype
    if dtype is None:
        return src.scalar
    from ..array import _canonical_dtype  # noqa: PLC0415
    from .dlpack import DLPackDtypeError  # noqa: PLC0415

    if getattr(_canonical_dtype(dtype), "_wp_scalar_type_", None) is not src.scalar:
        raise DLPackDtypeError(f"{what}: incompatible data types: DLPack bfloat16 and "
                               f"{getattr(dtype, '__name__', dtype)}")
    return dtype


def numeric_interface(obj) -> bool:
    """Whether `obj` has a readable CUDA Array Interface of a NumPy numeric type (JAX gives
    bfloat16 arrays none, or a void typestr: those go through DLPack)."""
    try:
        iface = obj.__cuda_array_interface__
        return np.dtype(iface["typestr"]).kind in "biuf"
    except Exception:  # noqa: BLE001 - any failure to read it: not usable
        return False


def source_of(obj, what) -> _Source:
    """The GPU memory of a foreign array (CUDA Array Interface first, then DLPack)."""
    if external.is_torch_tensor(obj) or numeric_interface(obj):
        return _from_interface(obj, what)
    if hasattr(obj, "__dlpack__"):
        return _from_dlpack(obj, what)
    try:
        getattr(obj, "__cuda_array_interface__")
        has_interface = True
    except AttributeError:
        has_interface = False
    except Exception:  # noqa: BLE001 - read again below for its error
        has_interface = True
    if has_interface:
        return _from_interface(obj, what)     # an interface weft cannot use: its error
    raise external.InteropError(f"{what}: {type(obj).__name__} has neither "
                                f"__cuda_array_interface__ nor __dlpack__")


def _check_device(src: _Source, device: str, what: str) -> int:
    ordinal = int(device.split(":")[1]) if ":" in device else 0
    if src.ordinal is not None and int(src.ordinal) != ordinal:
        raise external.InteropError(f"{what}: the array lives on cuda:{src.ordinal} but the "
                                    f"target is cuda:{ordinal}")
    return ordinal


def _host_copy(src: _Source, ordinal: int) -> np.ndarray:
    """The source's elements in host memory (through the driver, after the framework's work
    on the device finished)."""
    low = sum(min(0, (n - 1) * s) for n, s in zip(src.shape, src.strides) if n > 0)
    high = sum(max(0, (n - 1) * s) for n, s in zip(src.shape, src.strides) if n > 0)
    span = high - low + src.np_dtype.itemsize if src.nbytes else 0
    raw = np.empty(max(span, 0), dtype=np.uint8)
    if span:
        if not _cuda_ipc.available() and _cuda_ipc._load() is None:
            raise external.InteropError("reading framework GPU memory needs the CUDA driver in "
                                        f"this process ({_cuda_ipc.reason()})")
        _cuda_ipc.synchronize(ordinal)
        _cuda_ipc.copy_to_host(ordinal, raw.ctypes.data, src.ptr + low, span)
    if not src.nbytes:
        return np.empty(src.shape, dtype=src.np_dtype)
    return np.ndarray(src.shape, dtype=src.np_dtype, buffer=raw, offset=-low,
                      strides=src.strides)


def copy_in(obj, dtype, device: str, what: str, requires_grad=False, cast_ok=False):
    """(weft GPU array holding a copy of `obj`, _Source). Device-to-device through the IPC
    mapping when there is one, else through the host."""
    from ..array import array, empty  # noqa: PLC0415

    src = source_of(obj, what)
    ordinal = _check_device(src, device, what)
    dtype = _source_dtype(src, dtype, what)
    fake = np.lib.stride_tricks.as_strided(np.zeros(1, dtype=src.np_dtype), shape=src.shape,
                                           strides=src.strides, writeable=False)
    wdtype, shape, strides = external.resolve_layout(fake, dtype, what, cast_ok=cast_ok)
    same_scalar = external._scalar_compatible(src.np_dtype, wdtype._wp_scalar_type_)
    out = empty(shape, dtype=wdtype, device=f"cuda:{ordinal}", requires_grad=requires_grad)
    if out.size == 0:
        return out, src
    target = out.ptr if same_scalar and src.contiguous else None
    if target is not None:
        out._alloc.runtime.synchronize_if_needed()
        _cuda_ipc.synchronize(ordinal)           # the framework's writes are done
        _cuda_ipc.copy_device(ordinal, target, src.ptr, src.nbytes)
        return out, src
    host = _host_copy(src, ordinal)
    np_target = np.dtype(wdtype._wp_scalar_type_._np_dtype_)
    host = np.ascontiguousarray(host)
    host = host.view(np_target) if same_scalar else host.astype(np_target)
    out.assign(host.reshape(tuple(shape) + tuple(wdtype._shape_)))
    return out, src


# Imports whose arrays died, by what they import (device, dtype, shape, and the buffer id and
# offset of the data and of the gradient): their daemon handles are kept instead of freed, so
# a framework that hands out the same block again (Torch's caching allocator: a new gradient
# or `ones_like` each training step) gets it back without a round trip. The buffer id is
# unique for the life of the process, so a block freed and allocated again never matches; at
# most PARKED_IMPORTS per session, the oldest freed first.
PARKED_IMPORTS = 16


def _parked(rt) -> dict:
    pool = rt.__dict__.get("_weft_parked_imports")
    if pool is None:
        pool = rt.__dict__["_weft_parked_imports"] = collections.OrderedDict()
    return pool


class _Recycle:
    """Parks a dead imported allocation's handle (see PARKED_IMPORTS)."""

    __slots__ = ("rt", "key")

    def __init__(self, rt, key):
        self.rt = rt
        self.key = key

    def __call__(self, info) -> None:
        pool = _parked(self.rt)
        old = pool.pop(self.key, None)
        if old is not None:
            self.rt.free_later(old.handle)
        pool[self.key] = info
        while len(pool) > PARKED_IMPORTS:
            _, evicted = pool.popitem(last=False)
            self.rt.free_later(evicted.handle)


def _free_unheld(rt) -> None:
    """Frees every daemon import of this session that does not hold its framework memory: the
    parked ones and the tensors' remembered imports of gradients (_UNHELD)."""
    pool = _parked(rt)
    for info in pool.values():
        rt.free_later(info.handle)
    pool.clear()
    for a in list(_UNHELD):
        if a._alloc.runtime is rt:
            cache = a.__dict__.get("_weft_cache")
            if cache is not None:
                _forget(cache, a)
    rt.drain_frees()


def import_memory(src: _Source, wdtype, shape, strides, ordinal: int, what: str,
                  grad_src: "_Source | None" = None):
    """A weft array over `src`'s memory, opened by weftd through CUDA IPC (None where that
    cannot be done: the caller copies instead). `grad_src` (same layout) becomes the array's
    gradient, the same memory on both sides."""
    from ..array import _contiguous_strides, _dtype_proto, _elem_size, array  # noqa: PLC0415

    global _import_refused
    rt = _runtime.get_runtime()
    if not rt.local or not src.ptr or not _cuda_ipc.available() or _import_refused:
        return None
    elem = _elem_size(wdtype)
    low, span = external._span(shape, strides, elem)
    if low < 0 or span == 0 or span % elem:
        return None
    parts = []
    for part in (src, grad_src):
        if part is None:
            continue
        try:
            base, size, buffer_id, handle = _cuda_ipc.export_allocation(ordinal, part.ptr)
        except _cuda_ipc.CudaError:
            return None                     # not cudaMalloc memory: copied instead
        offset = part.ptr - base
        if offset < 0 or offset + span > size:
            return None
        parts.append((handle, buffer_id, offset))
    contiguous = tuple(strides) == _contiguous_strides(tuple(shape), elem)
    flat_shape = tuple(shape) if contiguous else (span // elem,)
    # what the import is: the blocks by identity (buffer ids are never reused in a process)
    key = (ordinal, wdtype, flat_shape, tuple((b, o) for _, b, o in parts))
    info = _parked(rt).pop(key, None)       # the same block imported before, handle kept
    if info is None:
        refs = [_runtime.array_pb2.CudaMemoryRef(ipc_handle=h, allocation_id=b, byte_offset=o)
                for h, b, o in parts]
        request = _runtime.array_pb2.ImportCudaRequest(
            device=f"cuda:{ordinal}", dtype=_dtype_proto(wdtype), shape=list(flat_shape),
            data=refs[0])
        if len(refs) > 1:
            request.grad.CopyFrom(refs[1])
        rt.drain_frees()
        try:
            try:
                info = rt.array_call("ImportCuda", request).info
            except WeftError as err:
                if err.code != "FAILED_PRECONDITION":
                    raise
                # weftd still maps the segment this handle named before (an import kept
                # without its memory, parked or remembered on a tensor): those go, then again
                _free_unheld(rt)
                info = rt.array_call("ImportCuda", request).info
        except WeftError as err:
            if "could not be opened" not in str(err):
                raise
            # the daemon cannot open this process's handles (a sandbox, another PID
            # namespace): copies from now on, as without IPC
            _import_refused = str(err)
            return None
    out = array._from_info(info, wdtype)
    out._alloc.recycle = _Recycle(rt, key)
    out._alloc.keep = src.keep              # the framework memory lives as long as the array
    out._alloc._cuda = src.ptr              # its address in this process
    memory.mark_shared(out._alloc)          # launches order with the framework
    if not contiguous:
        out = out._make_view(0, shape, strides)
    if grad_src is not None:
        ginfo = type(info)()
        ginfo.CopyFrom(info)
        ginfo.handle = info.grad_handle
        ginfo.grad_handle = 0
        g = array._from_info(ginfo, wdtype, owned=False)   # released with the array
        g._alloc.parent = out._alloc
        g._alloc.keep = grad_src.keep
        g._alloc._cuda = grad_src.ptr
        out.__dict__["_weft_grad_block"] = parts[1][1]   # the gradient segment's buffer id
        memory.mark_shared(g._alloc)
        if not contiguous:
            g = g._make_view(0, shape, strides)
        out._grad = g
        out._requires_grad = True
    return out


def _view_object(a, **replaced):
    """A new array object viewing what `a` views (its state, `replaced` set), a view of `a`;
    the launch's cached wire reference is computed once on `a` and inherited."""
    if "_weft_launch_ref" not in a.__dict__:
        from .._kernel.launch import _array_arg  # noqa: PLC0415

        _array_arg(a)
    v = type(a).__new__(type(a))
    state = dict(a.__dict__)
    state.pop("_is_read", None)
    state.pop("_weft_cache", None)
    state["_view_of"] = a
    state.update(replaced)
    v.__dict__.update(state)
    return v


def _fresh(a, grad=None):
    """A new array object over imported array `a` (each conversion returns its own object,
    as in Warp; they share the allocation, the gradient, the framework reference and the
    launch's cached wire reference). With `grad` (the Torch gradient tensor this conversion
    maps), the object's gradient holds that tensor's memory: `a`, remembered on the tensor,
    does not (import_torch)."""
    base_grad = a.__dict__.get("_grad")
    if grad is None or base_grad is None:
        return _view_object(a)
    return _view_object(a, _grad=_grad_holding(base_grad, grad.untyped_storage()))


def _grad_holding(base, keep):
    """A view of imported gradient array `base` over an allocation object of its own that
    holds `keep` (the framework memory it maps) as long as the view, any view of it or any
    export of it (DLPack capsules hold the allocation object) lives."""
    from ..array import _Allocation  # noqa: PLC0415

    alloc = base._alloc
    own = _Allocation(alloc.runtime, alloc.info, owned=False, parent=alloc)
    own.keep = keep
    own._cuda = alloc._cuda
    memory.mark_shared(own)
    return _view_object(base, _alloc=own)


_TORCH_IMPORTS_KEPT = 8      # imported arrays remembered per tensor (dtypes/gradients differ)

# Imports remembered on tensors (import_torch) that do not hold their gradient's memory: their
# daemon arrays may map a segment Torch has since freed. An import the daemon refuses as a
# failed precondition (it still maps the handle's old segment for arrays of the session) frees
# them and the parked ones, then asks again.
_UNHELD = weakref.WeakSet()


def _grad_block_current(a, g) -> bool:
    """Whether gradient tensor `g` lies in the allocation (segment) whose block remembered
    import `a` mapped as its gradient: the buffer id at `g`'s address is the one recorded at
    import (a segment freed and allocated again at the same address has a new one)."""
    block = a.__dict__.get("_weft_grad_block")
    return block is not None and _cuda_ipc.buffer_id(g.data_ptr()) == block


def _forget(cache, a) -> None:
    """Removes remembered import `a` from tensor cache `cache`; its daemon array is freed
    (not parked: it may map a segment that is gone)."""
    for k in [k for k, v in cache.items() if v is a]:
        del cache[k]
    a._alloc.recycle = None
    _UNHELD.discard(a)


def _fast_key(t, dtype, g):
    """What a conversion of `t` asks for, from cheap facts only (the cache's first look-up,
    before the layout is resolved): None when `dtype` cannot be a key."""
    key = (t.data_ptr(), t.shape, t.stride(), t.dtype, t.device, dtype,
           None if g is None else (g.data_ptr(), g.shape, g.stride(), g.dtype, g.device))
    try:
        hash(key)
    except TypeError:
        return None
    return key


def import_torch(t, dtype, what, requires_grad=False, grad=None):
    """A weft array over CUDA tensor `t`'s memory, imported by CUDA IPC (None where that cannot
    be done). With `requires_grad` the array's gradient is `grad` (default `t.grad`, zeros put
    there first when the tensor has none, as Warp does): the same memory on both sides. The
    imported array is remembered on the tensor, keyed by pointer, layout and gradient pointer:
    converting the same tensor again costs no round trip."""
    from .torch import _dtype_map  # noqa: PLC0415

    rt = _runtime.get_runtime()
    if not rt.local or not _cuda_ipc.available() or t.is_sparse:
        return None
    scalar = _dtype_map().get(t.dtype)
    if scalar is None:
        return None
    g = None
    if requires_grad:
        g = grad if grad is not None else t.grad
        if g is None:
            import torch  # noqa: PLC0415

            with torch.no_grad():
                t.grad = torch.zeros_like(t)
            g = t.grad
        if g.device != t.device or g.dtype != t.dtype or g.shape != t.shape or \
                g.stride() != t.stride():
            return None
    # The same conversion again (a training loop): no layout work, no round trip.
    cache = t.__dict__.get("_weft_imports")
    fast = _fast_key(t, dtype, g)
    if cache is not None and fast is not None:
        hit = cache.get(fast)
        if hit is not None and hit._alloc.runtime is rt:
            if g is None:
                return _fresh(hit)
            if _grad_block_current(hit, g):
                return _fresh(hit, g)
            _forget(cache, hit)
    np_dtype = np.dtype(scalar._np_dtype_)
    strides = tuple(s * np_dtype.itemsize for s in t.stride())
    try:
        wdtype, shape, wstrides = external.resolve_parts(np_dtype, tuple(t.shape), strides,
                                                         dtype, what, cast_ok=True)
    except external.InteropError:
        return None
    if not external._scalar_compatible(np_dtype, wdtype._wp_scalar_type_):
        return None
    # keyed by what the array is (resolved dtype), not by how it was asked for
    key = (t.data_ptr(), tuple(t.shape), strides, wdtype, g.data_ptr() if g is not None else None)
    if cache is not None:
        hit = cache.get(key)
        if hit is not None and hit._alloc.runtime is rt:
            if g is None or _grad_block_current(hit, g):
                if fast is not None:
                    cache[fast] = hit
                return _fresh(hit, g)
            _forget(cache, hit)
    ordinal = t.device.index if t.device.index is not None else 0
    try:
        if external.find_cuda_in_place(t, dtype, f"cuda:{ordinal}", what) is not None:
            return None                 # weft's own memory: used in place by the caller
    except external.InteropError:
        pass
    src = _Source(t.data_ptr(), np_dtype, t.shape, strides, t.untyped_storage(), ordinal)
    gsrc = None if g is None else _Source(g.data_ptr(), np_dtype, g.shape, strides,
                                          g.untyped_storage(), ordinal)
    a = import_memory(src, wdtype, shape, wstrides, ordinal, what, gsrc)
    if a is None:
        return None
    if cache is None:
        cache = t.__dict__["_weft_imports"] = {}
    while len(cache) >= _TORCH_IMPORTS_KEPT - 1:
        cache.pop(next(iter(cache)))
    cache[key] = a
    if fast is not None:
        cache[fast] = a
    if g is None:
        return _fresh(a)
    # The remembered import does not hold the gradient's memory (each conversion's array
    # does, _fresh): after `zero_grad()` Torch may hand the freed block out again as the next
    # gradient, which then finds this import (its segment checked by buffer id).
    a._grad._alloc.keep = None
    a.__dict__["_weft_cache"] = cache
    _UNHELD.add(a)
    return _fresh(a, g)


def import_object(obj, dtype, device: str, what: str):
    """A weft array over foreign GPU array `obj` (CUDA Array Interface or DLPack), imported by
    CUDA IPC, or None (the caller copies)."""
    if not _runtime.get_runtime().local or not _cuda_ipc.available():
        return None
    src = source_of(obj, what)
    ordinal = _check_device(src, device, what)
    dtype = _source_dtype(src, dtype, what)
    fake = np.lib.stride_tricks.as_strided(np.zeros(1, dtype=src.np_dtype), shape=src.shape,
                                           strides=src.strides, writeable=False)
    try:
        wdtype, shape, strides = external.resolve_layout(fake, dtype, what, cast_ok=True)
    except external.InteropError:
        return None
    if not external._scalar_compatible(src.np_dtype, wdtype._wp_scalar_type_):
        return None
    return import_memory(src, wdtype, shape, strides, ordinal, what)


def array_from_interface(obj, dtype, device: str, what: str):
    """wp.array(obj) of a foreign GPU array (an object with __cuda_array_interface__: CuPy,
    Numba, Torch, ...), as Warp wraps it: the same memory (weft memory found in place, other
    memory imported by CUDA IPC; a Torch tensor through adopt_torch), or, where neither can be,
    a copy on `device` ("cuda:N")."""
    if external.is_torch_tensor(obj):
        out, _ = adopt_torch(obj, dtype, device, what)
        return out
    found = external.find_cuda_in_place(obj, dtype, device, what)
    if found is not None:
        return found
    out = import_object(obj, dtype, device, what)
    if out is not None:
        return out
    out, _ = copy_in(obj, dtype, device, what)
    return out


class CopyBack:
    """After a launch: the weft temporary's contents written back into the framework array."""

    def __init__(self, src: _Source, temp):
        self.src = src
        self.temp = temp

    def apply(self) -> None:
        src, temp = self.src, self.temp
        ordinal = int(temp.device.ordinal)
        same = external._scalar_compatible(src.np_dtype, temp.dtype._wp_scalar_type_)
        if same and src.contiguous and temp.ptr is not None:
            _cuda_ipc.copy_device(ordinal, src.ptr, temp.ptr, src.nbytes)
            return
        values = np.asarray(temp.numpy())
        host = np.ascontiguousarray(values.reshape(src.shape).astype(src.np_dtype, copy=False))
        if src.contiguous:
            _cuda_ipc.copy_from_host(ordinal, src.ptr, host.ctypes.data, host.nbytes)
            return
        # a strided framework array: element rows through the host, one copy per element
        itemsize = src.np_dtype.itemsize
        flat = host.reshape(-1)
        for k, index in enumerate(np.ndindex(*src.shape)):
            offset = sum(i * s for i, s in zip(index, src.strides))
            _cuda_ipc.copy_from_host(ordinal, src.ptr + offset,
                                     flat[k:k + 1].ctypes.data, itemsize)


def adopt_torch(t, dtype, device: str, what: str, requires_grad=False):
    """A weft GPU array for CUDA tensor `t`: in place when its memory is weft's, else a copy
    into a new weft array and, where IPC works and the tensor owns its storage, `t` re-pointed
    at that array's memory (one copy; zero-copy afterwards)."""
    _check_device(_Source(t.data_ptr(), "u1", (0,), None, None, t.device.index or 0), device,
                  what)
    imported = import_torch(t, dtype, what)
    if imported is not None:
        return imported, None
    found = external.find_cuda_in_place(t, dtype, device, what)
    if found is not None:
        memory.mark_shared(found._alloc)
        return found, None
    out, src = copy_in(t, dtype, device, what, requires_grad=requires_grad)
    if out.ptr is not None and t._base is None and not t.is_inference() and t.is_contiguous() \
            and out.size:
        import torch  # noqa: PLC0415

        moved = torch.utils.dlpack.from_dlpack(out)
        if moved.dtype != t.dtype:
            moved = moved.view(t.dtype)
        moved = moved.reshape(t.shape)
        try:
            with torch.no_grad():
                t.data = moved
            memory.mark_shared(out._alloc)
            return out, None
        except RuntimeError:
            pass
    return out, src
