"""PyTorch interop: wp.from_torch / wp.to_torch, gradients, device, dtype and stream helpers.

Memory (CPU; see docs/interop.md for the full rules):
- `to_torch(a)` of a local CPU array is zero-copy: the tensor is `torch.from_numpy` of the
  array's shared-memory view, so Torch and weftd read and write the same bytes.
- `from_torch(t)` of a tensor whose memory is already a weft slab (made by to_torch, or a view
  of one) returns a weft array over that memory. Any other CPU tensor lives in this process,
  where the daemon cannot see it: its storage is moved into a new weft slab once (one copy)
  and the tensor is re-pointed at the slab (`t.data = ...`, so the tensor object, its autograd
  identity and the optimizers holding it are unchanged). From then on both sides share the
  memory and later from_torch calls are zero-copy. Tensors that are views of another tensor
  are copied instead (re-pointing a view would cut it off from its base): a snapshot that
  later Torch writes do not reach.
- Gradients are mapped both ways through the same mechanism: the weft array's `.grad` and the
  tensor's `.grad` are one weft allocation (a tensor `.grad` that lives elsewhere is moved into
  a slab the same way).
"""
from __future__ import annotations

import numpy as np

from . import external, memory
from .._runtime import get_runtime as _get_runtime

_FROM_TORCH: dict = {}


def _torch():
    import torch  # noqa: PLC0415

    return torch


def _dtype_map() -> dict:
    if not _FROM_TORCH:
        torch = _torch()
        from .. import types  # noqa: PLC0415

        pairs = [("float16", types.float16), ("float32", types.float32),
                 ("float64", types.float64), ("int8", types.int8), ("int16", types.int16),
                 ("int32", types.int32), ("int64", types.int64), ("uint8", types.uint8),
                 ("uint16", types.uint16), ("uint32", types.uint32), ("uint64", types.uint64),
                 ("bool", types.bool), ("bfloat16", types.bfloat16)]
        for name, weft_type in pairs:
            torch_type = getattr(torch, name, None)
            if torch_type is not None:
                _FROM_TORCH[torch_type] = weft_type
    return _FROM_TORCH


def dtype_from_torch(torch_dtype):
    """The weft scalar dtype of a Torch dtype (TypeError for complex, float8, ...)."""
    weft_type = _dtype_map().get(torch_dtype)
    if weft_type is None:
        raise TypeError(f"Invalid or unsupported data type: {torch_dtype} (weft arrays hold "
                        f"bool, int8..int64, uint8..uint64, float16, bfloat16, float32, float64)")
    return weft_type


def dtype_to_torch(weft_dtype):
    """The Torch dtype of a weft dtype (of its scalar components for vectors and matrices)."""
    from .. import types  # noqa: PLC0415
    from ..array import _canonical_dtype  # noqa: PLC0415

    dtype = _canonical_dtype(weft_dtype)
    scalar = dtype._wp_scalar_type_ if types.is_dtype(dtype) else None
    for torch_type, weft_type in _dtype_map().items():
        if weft_type is scalar:
            return torch_type
    raise TypeError(f"Cannot convert {weft_dtype} to a Torch type")


def device_from_torch(torch_device):
    """The weft Device of a Torch device ("cpu", "cuda", "cuda:N" or a torch.device)."""
    from ..device import get_device  # noqa: PLC0415

    torch = _torch()
    dev = torch.device(torch_device) if not isinstance(torch_device, torch.device) \
        else torch_device
    if dev.type == "cuda":
        index = dev.index if dev.index is not None else torch.cuda.current_device()
        return get_device(f"cuda:{index}")
    if dev.type == "cpu":
        return get_device("cpu")
    raise RuntimeError(f"Torch device {dev} has no weft counterpart (weft has cpu and cuda:N)")


def device_to_torch(device):
    """The Torch device string ("cpu", "cuda:N") of a weft device."""
    return external.framework_device(device, "cuda", "Torch")


def _check_tensor(t, what):
    torch = _torch()
    if not isinstance(t, torch.Tensor):
        raise TypeError(f"{what} expects a torch.Tensor, got {type(t).__name__}")


def _adopt_tensor(t, dtype, what, requires_grad=False, other_refs=0):
    """A weft array over `t`'s memory: in place when it is a weft slab, else after moving the
    tensor's storage into a new slab (created with a daemon-side gradient when
    `requires_grad`); views, tensors whose storage others share and tensors Torch will not
    re-point get a copy. `other_refs`: references to the storage the caller holds (a NumPy
    view of it)."""
    weft_scalar = _dtype_map().get(t.dtype) if t.device.type == "cpu" else None
    if weft_scalar is not None and t.numel():
        # hot path: the tensor's own layout, no NumPy view
        np_dtype = np.dtype(weft_scalar._np_dtype_)
        wdtype, shape, strides = external.resolve_parts(
            np_dtype, tuple(t.shape), tuple(s * np_dtype.itemsize for s in t.stride()), dtype,
            what)
        found = external.find_at(t.data_ptr(), wdtype, shape, strides)
        if found is not None:
            memory.mark_shared(found._alloc)
            return found
    exclusive = _storage_exclusive(t, other_refs)   # before the NumPy view below shares it too
    view = external.host_view(t, what)
    wdtype, shape, strides = external.resolve_layout(view, dtype, what)
    found = external.find_in_place(view, wdtype, shape, strides)
    if found is not None:
        memory.mark_shared(found._alloc)
        return found
    out, _ = external.weft_array(view, dtype=wdtype, device="cpu", what=what,
                                 requires_grad=requires_grad)
    if t._base is None and not t.is_inference() and exclusive:
        moved = _tensor_over(out, t.dtype, tuple(t.shape))
        if moved is not None:
            torch = _torch()
            try:
                with torch.no_grad():
                    t.data = moved
                return out
            except RuntimeError:
                pass                    # Torch refused: the array stays a copy
    if t.device.type == "cpu" and not t.is_inference():
        out._mirror = TensorMirror(t)   # a copy: launches keep it and the tensor in step
    return out


class TensorMirror:
    """The CPU tensor a weft array copied because its storage could not move (a view, storage
    other tensors share, such as `y` and `y.detach()`): a launch taking the array first copies
    the tensor in when Torch changed it since (its version counter moved), and afterwards
    copies the array back into the tensor (weft/_kernel/launch.py), so each side sees the
    other's writes at the points where it would with shared memory."""

    def __init__(self, tensor):
        self.tensor = tensor
        self.version = tensor._version

    def _memory(self) -> np.ndarray:
        """The tensor's own memory as NumPy (bfloat16: its uint16 bits, what weft's bfloat16
        arrays take and give)."""
        view = external.host_view(self.tensor, "wp.from_torch")
        return view.view(np.uint16) if self.tensor.dtype is _torch().bfloat16 else view

    def before_launch(self, a) -> None:
        if self.tensor._version != self.version:
            a.assign(self._memory())
            self.version = self.tensor._version

    def after_launch(self, a) -> None:
        # Written through the tensor's memory, as a kernel writing into shared memory would:
        # Torch's version counter does not move (autograd's saved inputs stay valid).
        target = self._memory()
        values = np.asarray(a.numpy())
        if values.dtype != target.dtype:   # bfloat16 (ml_dtypes' type or its bits)
            values = values.view(target.dtype)
        np.copyto(target, values.reshape(target.shape))


def _storage_exclusive(t, other_refs=0) -> bool:
    """Whether no other tensor shares `t`'s storage (views of it included): only then may `t`
    be re-pointed at a slab, since the others would go on reading and writing the old memory
    (gradcheck writes each grad_output through a view of it). Unknown: False (a copy)."""
    torch = _torch()
    use_count = getattr(torch._C, "_storage_Use_Count", None)
    if use_count is None:
        return False
    try:
        # one reference is the tensor's, one the storage object this call makes
        return use_count(t.untyped_storage()._cdata) <= 2 + other_refs
    except (RuntimeError, AttributeError, TypeError):
        return False


def _tensor_over(a, torch_dtype, shape):
    """A zero-copy CPU tensor over weft array `a` (None where its memory is not mapped here)."""
    torch = _torch()
    rt = a._alloc.runtime
    if not (rt.local and a._info.shm_name) or a.size == 0:
        return None
    view = a.numpy()
    memory.mark_shared(a._alloc)
    if view.dtype.name == "bfloat16":   # ml_dtypes' bfloat16: Torch takes its bits
        view = view.view(np.uint16)
    t = torch.from_numpy(view)
    if t.dtype != torch_dtype:
        t = t.view(torch_dtype)         # same-size alias (int8 <-> uint8, bool <-> uint8)
    return t.reshape(shape) if tuple(t.shape) != tuple(shape) else t


# On a CUDA tensor imported in place without a gradient: ((pointer, shape, strides, dtype,
# dtype asked for), the imported array), the next conversion's first look-up (a loop converting
# the same tensors: no checks, layout work or runtime look-ups before it).
_LAST_IMPORT = "_weft_last_import"


# On a CPU tensor whose storage is weft slab memory: ((pointer, shape, strides, dtype, dtype
# asked for), the array over it), the next conversion's look-up while the tensor points there.
_CPU_ARRAY = "_weft_cpu_array"


def _remembered(t, last, dtype, requires_grad, cuda):
    """The array of `last` (a (key, array) entry remembered on `t` under _LAST_IMPORT or
    _CPU_ARRAY) while it still holds for this conversion: no gradient asked for, the tensor
    unchanged, its session open (and, for a CUDA import, the current one); else None."""
    if last is None or (requires_grad if requires_grad is not None else t.requires_grad):
        return None
    key, known = last
    if key != (t.data_ptr(), t.shape, t.stride(), t.dtype, dtype):
        return None
    rt = known._alloc.runtime
    if rt.closed or (cuda and rt is not _get_runtime()):
        return None
    return known


def _last_cpu_array(t, dtype, requires_grad):
    d = getattr(t, "__dict__", None)
    return _remembered(t, d.get(_CPU_ARRAY) if d is not None else None, dtype, requires_grad, False)


def _last_import(t, dtype, requires_grad):
    d = getattr(t, "__dict__", None)
    return _remembered(t, d.get(_LAST_IMPORT) if d is not None else None, dtype, requires_grad, True)


def from_torch(t, dtype=None, requires_grad=None, grad=None, return_ctype=False, retain_grad=False):
    """A weft array sharing memory with Torch tensor `t` (Warp's wp.from_torch; the memory
    rules are in this module's docstring). `dtype` may be a vector/matrix type whose shape
    matches `t`'s trailing dimensions; `requires_grad` (default: t.requires_grad) maps the
    tensor's .grad to the array's .grad (zeros when the tensor has none); `grad` gives that
    gradient tensor explicitly; `retain_grad` sets the array's retain_grad (its gradient is kept
    through the adjoints of stores to it). `return_ctype=True` returns the array's ctypes
    descriptor (`a.__ctype__()`, Warp's array_t: data and grad addresses in this process, shape,
    byte strides), which keeps the array alive and which launches take as the array."""
    if return_ctype and grad is None and not retain_grad:
        native = _NATIVE_DESCRIPTOR if _NATIVE_DESCRIPTOR is not False else _native_descriptor()
        if native is not None:
            desc = native(t, dtype, requires_grad, _get_runtime)
        else:
            d = getattr(t, "__dict__", None)
            entry = d.get(_LAST_CTYPE) if d is not None else None
            desc = _last_descriptor(t, d, entry, dtype, requires_grad) if entry is not None else None
        if desc is not None:
            return desc
    a = _from_torch(t, dtype, requires_grad, grad)
    if retain_grad:
        a.retain_grad = True
    if not return_ctype:
        return a
    desc = a.__ctype__()
    if grad is None and not retain_grad and _plain(a) and a.__dict__.get("_view_of") is not None:
        d = getattr(t, "__dict__", {})
        for name in (_LAST_IMPORT, _CPU_ARRAY):
            last = d.get(name)
            if last is not None and last[1] is a.__dict__["_view_of"]:
                d[_LAST_CTYPE] = (last, desc, name)
                break
    return desc


# On a tensor whose last conversion is remembered (_LAST_IMPORT or _CPU_ARRAY): (that entry, the
# descriptor made from it, the entry's name). A loop converting the same tensors with
# return_ctype=True gets a copy of the descriptor (its bytes and the array it refers to) without
# making one field by field.
_LAST_CTYPE = "_weft_last_ctype"


_NATIVE_DESCRIPTOR = False     # weft._torch_descriptor.remembered once looked up (None: absent)


def _native_descriptor():
    """weft._torch_descriptor.remembered (clients/python/native/torch_descriptor.c: the look-up
    of _last_descriptor in C), or None when it was not built or WEFT_NATIVE_DESCRIPTOR=0 turns it
    off (the look-up is then done in Python)."""
    global _NATIVE_DESCRIPTOR
    from .. import _native  # noqa: PLC0415

    module = _native.optional("_torch_descriptor", "WEFT_NATIVE_DESCRIPTOR")
    _NATIVE_DESCRIPTOR = module.remembered if module is not None else None
    return _NATIVE_DESCRIPTOR


def _plain(a) -> bool:
    """Whether array `a` has neither a gradient nor retain_grad: all its descriptor says beyond
    the tensor's own facts (pointer, shape, strides) is then fixed, so it may be remembered."""
    return a._grad is None and not a._info.grad_handle and not a._retain_grad


def _last_descriptor(t, d, entry, dtype, requires_grad):
    """A copy of the descriptor of `entry` (remembered in `t`'s __dict__ `d` under _LAST_CTYPE)
    while the conversion it was made from is still the tensor's and still holds (_remembered),
    and its array has neither a gradient nor a flag (_plain); else None."""
    last, desc, name = entry
    if d.get(name) is not last:
        return None                     # the tensor's remembered conversion changed since
    known = _remembered(t, last, dtype, requires_grad, name == _LAST_IMPORT)
    if known is None or not _plain(known):
        return None                     # the tensor changed, another session, or the
        # descriptor would carry a gradient or a flag now
    out = type(desc).from_buffer_copy(desc)
    out._weft_value = desc._weft_value
    return out


def _from_torch(t, dtype, requires_grad, grad):
    if grad is None:
        known = _last_import(t, dtype, requires_grad)
        if known is not None:
            from .cuda_import import _fresh  # noqa: PLC0415

            return _fresh(known)
    what = "wp.from_torch"
    _check_tensor(t, what)
    if dtype is None and t.dtype is _torch().bfloat16:
        from .. import types  # noqa: PLC0415

        dtype = types.bfloat16     # its bits are read as uint16: the dtype is not inferred
    if t.device.type == "cuda":
        from . import cuda_import  # noqa: PLC0415

        rg = requires_grad if requires_grad is not None else t.requires_grad
        if grad is not None:
            _check_tensor(grad, what + " (grad)")
        # imported by CUDA IPC in place, the gradient too (docs/interop.md)
        a = cuda_import.import_torch(t, dtype, what, bool(rg), grad)
        if a is not None:
            if not rg and grad is None:
                try:
                    t.__dict__[_LAST_IMPORT] = ((t.data_ptr(), t.shape, t.stride(), t.dtype, dtype), a)
                except (AttributeError, TypeError):
                    pass
            return a
        # weft memory in place, or moved into weft memory (t re-pointed); a copy (a snapshot
        # later Torch writes do not reach) only for views and where IPC is unavailable
        a, _ = cuda_import.adopt_torch(t, dtype, f"cuda:{t.device.index or 0}", what)
        if requires_grad if requires_grad is not None else t.requires_grad:
            ga = memory.grad_view(a)
            if ga is not None:
                a._requires_grad = True
        return a
    if t.device.type != "cpu":
        raise external.InteropError(f"{what}: the tensor lives on {t.device}, which has no "
                                    f"weft counterpart (weft has cpu and cuda:N)")
    if requires_grad is None:
        requires_grad = bool(t.requires_grad) or grad is not None   # an explicit grad is mapped (Warp)
    if not requires_grad and grad is None:
        # The same conversion again (a loop): the array over the tensor's slab memory,
        # remembered on the tensor while it points there.
        known = _last_cpu_array(t, dtype, False)
        if known is not None:
            from .cuda_import import _fresh  # noqa: PLC0415

            return _fresh(known)
    a = _adopt_tensor(t, dtype, what, requires_grad)
    if not requires_grad and grad is None:
        if a.ptr is not None and a.ptr == t.data_ptr():
            try:
                t.__dict__[_CPU_ARRAY] = ((t.data_ptr(), t.shape, t.stride(), t.dtype, dtype), a)
            except TypeError:
                pass
        return a
    torch = _torch()
    if grad is not None:
        # an explicit gradient (a tensor or a weft array): the array's gradient is that memory
        from ..array import array as weft_array  # noqa: PLC0415

        if isinstance(grad, weft_array):
            if tuple(grad.shape) != tuple(a.shape) or grad.dtype != a.dtype:
                raise ValueError(f"{what}: the gradient array has shape {tuple(grad.shape)} and dtype "
                                 f"{grad.dtype.__name__}, the array {tuple(a.shape)} and {a.dtype.__name__}")
            a._grad = grad
            a._requires_grad = bool(requires_grad)
            return a
        _check_tensor(grad, what + " (grad)")
        a._grad = _adopt_tensor(grad, a.dtype, what + " (grad)")
        a._requires_grad = bool(requires_grad)
        return a
    g = t.grad
    ga = memory.grad_view(a)            # the daemon-side gradient, when the allocation has one
    if ga is None:
        from ..array import zeros  # noqa: PLC0415

        if g is not None:
            ga = _adopt_tensor(g, a.dtype, what + " (grad)")
        else:
            ga = zeros(a.shape, dtype=a.dtype, device="cpu")
        a._grad = ga
    elif g is None:
        memory.set_now(ga)             # a tensor without .grad: the gradient starts at zero
    elif not (g.device.type == "cpu" and ga.ptr is not None and g.data_ptr() == ga.ptr):
        memory.set_now(ga, external.host_view(g, what + " (grad)"))
    if g is None or g.data_ptr() != ga.ptr:
        gt = _tensor_over(ga, t.dtype, tuple(t.shape))
        if gt is not None:
            with torch.no_grad():
                t.grad = gt
    else:
        memory.mark_shared(ga._alloc)
    a._requires_grad = True
    return a


def _cuda_tensor_over(torch, a):
    """torch.utils.dlpack.from_dlpack(a) for a GPU array with an IPC mapping, with the
    exchange done here: the capsule made for Torch's current stream of the array's device
    (what Torch would ask `a.__dlpack__` for: 1 for the legacy default stream), then consumed."""
    raw = getattr(torch._C, "_cuda_getCurrentRawStream", None)
    if raw is None or not torch.cuda.is_initialized():
        return torch.utils.dlpack.from_dlpack(a)
    from . import dlpack  # noqa: PLC0415

    stream = int(raw(a.device.ordinal))
    return torch.utils.dlpack.from_dlpack(dlpack.export(a, stream=1 if stream == 0 else stream))


def to_torch(a, requires_grad=None):
    """A Torch tensor over weft array `a` (Warp's wp.to_torch): zero-copy for CPU arrays of
    local sessions (pending weft commands are finished first); remote sessions get a copy.
    With requires_grad (default: a.requires_grad) the tensor requires grad and its .grad is
    the array's .grad, zero-copy."""
    from ..array import array  # noqa: PLC0415

    if not isinstance(a, array):
        raise TypeError(f"wp.to_torch expects a weft array, got {type(a).__name__}")
    torch = _torch()
    if a.device is not None and a.device.is_cuda:
        if a._info is not None and a.ptr is None:
            # no CUDA IPC mapping in this client (docs/cuda-client.md): a copy
            t = torch.from_numpy(np.array(a.numpy(), copy=True)).to(device_to_torch(a.device))
        else:
            t = _cuda_tensor_over(torch, a)
    else:
        t = _tensor_over(a, dtype_to_torch(a.dtype), tuple(a.numpy().shape)) \
            if a._info is not None else None
        if t is None:
            host = np.array(a.numpy(), copy=True)
            t = torch.from_numpy(host.view(np.uint16) if host.dtype.name == "bfloat16" else host)
    if t.dtype == torch.uint16 and dtype_to_torch(a.dtype) is torch.bfloat16:
        t = t.view(torch.bfloat16)      # bfloat16 travels as its bits
    if requires_grad is None:
        requires_grad = a.requires_grad
    if requires_grad:
        ga = memory.grad_view(a)
        if ga is None:
            a.requires_grad = True      # a gradient array of its own (client side)
            ga = a.grad
        t.requires_grad_(True)
        gt = to_torch(ga, requires_grad=False)
        t.grad = gt
    return t


def stream_from_torch(stream_or_device=None):
    """A weft stream bound to a Torch CUDA stream (Warp's wp.stream_from_torch; default:
    Torch's current stream of the device). Weft work runs on the daemon's session stream, in
    another process; while the returned stream is current (wp.ScopedStream, wp.set_stream),
    launches touching memory Torch holds are ordered with the Torch stream by interprocess
    events: the session's stream waits for the Torch stream's work before the launch, and the
    Torch stream waits for the launch (docs/interop.md, "Ordering")."""
    torch = _torch()
    if isinstance(stream_or_device, getattr(torch.cuda, "Stream", ())):
        device = device_from_torch(stream_or_device.device)
        torch_stream = stream_or_device
    else:
        device = device_from_torch(stream_or_device if stream_or_device is not None
                                   else "cuda")
        torch_stream = None
    if not device.is_cuda:
        raise RuntimeError("streams are CUDA objects; CPU work is ordered by synchronization "
                           "(docs/interop.md)")
    if torch_stream is None:
        torch_stream = torch.cuda.current_stream(device_to_torch(device))
    from .. import streams  # noqa: PLC0415

    stream = streams.Stream(device, cuda_stream=int(torch_stream.cuda_stream))
    stream._torch_stream = torch_stream
    return stream


def stream_to_torch(stream_or_device=None):
    """The Torch stream of a weft stream or device (Warp's wp.stream_to_torch). A weft stream
    bound to a Torch stream gives that stream; the session's stream (or a device) gives a
    Torch ExternalStream over a stream of this process that waits (on the GPU) for weft's
    work queued so far, or, where events are not available, Torch's current stream after
    weft's work finished."""
    torch = _torch()
    from .. import streams  # noqa: PLC0415
    from ..device import get_device  # noqa: PLC0415

    if isinstance(stream_or_device, streams.Stream):
        if stream_or_device._torch_stream is not None:
            return stream_or_device._torch_stream
        device = stream_or_device.device
        stream = stream_or_device
    else:
        device = get_device(stream_or_device)
        stream = None
    if not device.is_cuda:
        raise RuntimeError("streams are CUDA objects; CPU work is ordered by synchronization "
                           "(docs/interop.md)")
    if stream is None:
        stream = streams.Stream(device)
    handle = stream.cuda_stream
    if handle is None:
        from .. import _runtime  # noqa: PLC0415

        _runtime.get_runtime().synchronize()
        return torch.cuda.current_stream(device_to_torch(device))
    return torch.cuda.ExternalStream(handle, device=device_to_torch(device))
