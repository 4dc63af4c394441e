"""Paddle interop: wp.from_paddle / wp.to_paddle, gradients, and the device, dtype and stream
helpers (Warp's names and arguments).

Memory (CPU; docs/interop.md, "Paddle", has the rules and the tests behind them):
- `to_paddle(a)` of a local CPU array is zero-copy: the tensor is made by `paddle.from_dlpack`
  over the array's shared-memory slab, so Paddle and weftd read and write the same bytes. The
  capsule holds the slab view, which keeps the weft allocation alive as long as Paddle holds
  the memory.
- `from_paddle(t)` of a tensor whose memory is a weft slab (made by to_paddle, a view of one,
  or a tensor moved before) is a weft array over that memory. Any other CPU tensor lives in
  this process, where the daemon cannot see it: a whole contiguous tensor has its memory moved
  into a new weft slab once (one copy) and is re-pointed at the slab (the same Tensor object:
  optimizers and autograd still hold it); later conversions are zero-copy. A view into part of
  another tensor's memory, or a strided one, is copied instead (a snapshot later Paddle writes
  do not reach): re-pointing it would cut it from the tensor it views.
- Gradients: a tensor with `stop_gradient=False` (or `requires_grad=True`) gets the array's
  gradient as its `.grad` (`Tensor.grad_`, zero-copy), and `to_paddle` of an array that
  requires grad gives a tensor whose `.grad` is the array's gradient.
"""
from __future__ import annotations

import ctypes

import numpy as np

from . import dlpack, external, memory

_FROM_PADDLE: dict = {}      # paddle dtype -> weft scalar type
_TO_PADDLE: dict = {}        # weft scalar type -> paddle dtype
_NAMES: dict = {}            # paddle dtype -> its name (str() calls paddle.uint16 "bfloat16")


class PaddleInteropError(external.InteropError, RuntimeError):
    """A Paddle tensor weft cannot take as asked (dtype, element layout, device). Both a
    RuntimeError (what Warp raises) and weft's InteropError (a TypeError)."""


def _paddle():
    import paddle  # noqa: PLC0415

    return paddle


def _maps() -> None:
    if _FROM_PADDLE:
        return
    paddle = _paddle()
    from .. import types  # noqa: PLC0415

    names = ["bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
             "float16", "bfloat16", "float32", "float64"]
    for name in names:
        pdtype = getattr(paddle, name, None)
        if pdtype is None:
            continue
        _FROM_PADDLE[pdtype] = getattr(types, name)
        _NAMES[pdtype] = name
    # Paddle has no kernels for unsigned integers wider than 8 bits: weft's uint16/32/64 go to
    # Paddle as the signed type of their size (Warp's mapping), the same bits
    for name in names:
        if name in ("uint16", "uint32", "uint64"):
            _TO_PADDLE[getattr(types, name)] = getattr(paddle, "int" + name[4:])
        elif getattr(paddle, name, None) is not None:
            _TO_PADDLE[getattr(types, name)] = getattr(paddle, name)


def _name(pdtype) -> str:
    _maps()
    return _NAMES.get(pdtype) or str(pdtype).replace("paddle.", "")


def dtype_from_paddle(paddle_dtype):
    """The weft scalar dtype of a Paddle dtype (TypeError for complex, float8, ...)."""
    _maps()
    try:
        weft_type = _FROM_PADDLE.get(paddle_dtype)
    except TypeError:               # unhashable: not a Paddle dtype
        weft_type = None
    if weft_type is None:
        raise TypeError(f"Cannot convert Paddle type {paddle_dtype} to a weft type (weft arrays "
                        f"hold bool, int8..int64, uint8..uint64, float16, bfloat16, float32, "
                        f"float64)")
    return weft_type


def dtype_to_paddle(weft_dtype):
    """The Paddle dtype of a weft dtype (of its scalar components for vectors and matrices;
    uint16/32/64 give the signed Paddle type of their size, as in Warp)."""
    from .. import types  # noqa: PLC0415
    from ..array import _canonical_dtype  # noqa: PLC0415

    _maps()
    try:
        dtype = _canonical_dtype(weft_dtype)
    except Exception:  # noqa: BLE001 - anything that is no weft dtype
        dtype = None
    scalar = dtype._wp_scalar_type_ if dtype is not None and types.is_dtype(dtype) else None
    paddle_dtype = _TO_PADDLE.get(scalar)
    if paddle_dtype is None:
        raise TypeError(f"Cannot convert {weft_dtype} to a Paddle type")
    return paddle_dtype


def _compatible(source, target) -> bool:
    """Warp's aliasing rule for from_paddle(dtype=): a float only as itself, an integer as
    either signedness of its size, bool as bool, int8 or uint8."""
    from .. import types  # noqa: PLC0415

    if source is target:
        return True
    if source is types.bool:
        return target in (types.int8, types.uint8)
    size = np.dtype(source._np_dtype_).itemsize
    return (source in types.int_types and target in types.int_types and
            np.dtype(target._np_dtype_).itemsize == size)


def _place_device(place) -> str:
    """"cpu" or "cuda:N" for a Paddle place (pinned host memory is CPU memory)."""
    if place.is_cpu_place() or place.is_cuda_pinned_place():
        return "cpu"
    if place.is_gpu_place():
        return f"cuda:{place.gpu_device_id()}"
    raise PaddleInteropError(f"Paddle device {place} has no weft counterpart (weft has cpu and "
                             f"cuda:N)")


def device_from_paddle(paddle_device):
    """The weft Device of a Paddle device: a string ("cpu", "gpu", "gpu:N"), a Place
    (`tensor.place`) or a CPUPlace / CUDAPlace / CUDAPinnedPlace. RuntimeError for devices weft
    does not have (xpu, custom devices, a GPU weft does not see)."""
    from ..device import get_device  # noqa: PLC0415

    if isinstance(paddle_device, str):
        text = paddle_device.strip().lower()
        if text == "cpu":
            name = "cpu"
        elif text in ("gpu", "cuda"):
            name = "cuda"
        elif text.startswith(("gpu:", "cuda:")) and text.split(":", 1)[1].isdigit():
            name = f"cuda:{int(text.split(':', 1)[1])}"
        else:
            raise RuntimeError(f"Unsupported Paddle device {paddle_device!r} (weft has cpu and "
                               f"cuda:N; Paddle names them 'cpu' and 'gpu:N')")
    elif hasattr(paddle_device, "is_gpu_place"):      # a Place, CPUPlace, CUDAPlace, ...
        try:
            name = _place_device(paddle_device)
        except PaddleInteropError as err:
            raise RuntimeError(str(err)) from None
    else:
        raise TypeError(f"device_from_paddle expects a Paddle place or a device string ('cpu', "
                        f"'gpu', 'gpu:N'), got {paddle_device!r} ({type(paddle_device).__name__})")
    try:
        return get_device(name)
    except Exception as err:  # noqa: BLE001 - no such device in this daemon
        raise RuntimeError(f"Paddle device {paddle_device} has no weft counterpart here: {err}") \
            from None


def device_to_paddle(device):
    """The Paddle device string ("cpu", "gpu:N") of a weft device."""
    return external.framework_device(device, "gpu", "Paddle")


def _check_tensor(t, what):
    paddle = _paddle()
    if not isinstance(t, paddle.Tensor):
        raise TypeError(f"{what} expects a paddle.Tensor, got {type(t).__name__}")


def _layout(t, dtype, what):
    """(weft dtype, shape, byte strides, NumPy dtype of the memory) of CPU tensor `t` seen as
    an array of `dtype` (None: the tensor's own scalar type)."""
    from .. import types  # noqa: PLC0415
    from ..array import _canonical_dtype  # noqa: PLC0415

    source = dtype_from_paddle(t.dtype)
    if dtype is None:
        target = source
    else:
        target = _canonical_dtype(dtype)
        if not types.is_dtype(target):
            raise PaddleInteropError(f"{what}: cannot view a Paddle tensor as {dtype!r}")
        if not _compatible(source, target._wp_scalar_type_):
            raise PaddleInteropError(f"{what}: cannot convert Paddle type {_name(t.dtype)} to weft "
                                     f"type {types.type_str(target)} (incompatible dtypes)")
    np_dtype = np.dtype(source._np_dtype_)
    shape = tuple(int(n) for n in t.shape)
    strides = tuple(int(s) * np_dtype.itemsize for s in t.strides)
    try:
        wdtype, wshape, wstrides = external.resolve_parts(np_dtype, shape, strides, target, what)
    except external.InteropError as err:
        raise PaddleInteropError(str(err)) from None
    return wdtype, wshape, wstrides, np_dtype


def _host_view(t, np_dtype) -> np.ndarray:
    """A NumPy array over CPU tensor `t`'s memory. NumPy takes every Paddle dtype weft has
    through DLPack except bfloat16, which is read as its bits (uint16) at the tensor's address:
    that view does not keep `t` alive, so it is only used while `t` is."""
    if t.dtype != _paddle().bfloat16:
        try:
            return np.from_dlpack(t.detach())  # DLPack refuses tensors that require grad
        except (TypeError, BufferError, RuntimeError) as err:
            raise PaddleInteropError(f"wp.from_paddle: cannot read the tensor: {err}") from None
    shape = tuple(int(n) for n in t.shape)
    strides = tuple(int(s) * np_dtype.itemsize for s in t.strides)
    if not shape or 0 in shape:
        return np.zeros(shape, dtype=np_dtype)
    span = sum((n - 1) * s for n, s in zip(shape, strides)) + np_dtype.itemsize
    raw = np.frombuffer((ctypes.c_char * span).from_address(t.data_ptr()), dtype=np.uint8)
    return np.lib.stride_tricks.as_strided(raw.view(np_dtype)[:1], shape=shape, strides=strides)


def _is_whole(t, np_dtype) -> bool:
    """Whether contiguous `t` covers its whole memory block from its start (not a view into
    part of another tensor's memory): only such a tensor is re-pointed at a slab."""
    try:
        offset = t._offset() if callable(t._offset) else t._offset
        return (t.is_contiguous() and int(offset) == 0 and
                int(t._holder_size()) == int(t.numel()) * np_dtype.itemsize)
    except (AttributeError, RuntimeError, TypeError, ValueError):
        return False


def _tensor_over(a, paddle_dtype=None):
    """A zero-copy CPU Paddle tensor over weft array `a` (None where its memory is not mapped in
    this process: remote sessions, empty arrays). Its shape is the array's with the element
    dimensions of vector/matrix dtypes; unsigned types wider than 8 bits are seen as the signed
    Paddle type of their size."""
    paddle = _paddle()
    rt = a._alloc.runtime
    if not (rt.local and a._info.shm_name) or a.size == 0:
        return None
    if paddle_dtype is None:
        paddle_dtype = dtype_to_paddle(a.dtype)
    if paddle_dtype == paddle.bfloat16:
        capsule = dlpack.export(a)      # a kDLBfloat capsule over the slab (marks it shared)
    else:
        view = a.numpy()                # finishes pending commands; a view of the slab
        memory.mark_shared(a._alloc)
        target = np.dtype(_name(paddle_dtype))
        if view.dtype != target:        # same-size alias (uint32 -> int32, bool <-> uint8)
            view = view.view(target)
        capsule = view.__dlpack__()     # the capsule keeps the view (and the allocation) alive
    return paddle.from_dlpack(capsule)


def _adopt(t, dtype, what, requires_grad=False):
    """A weft array over CPU tensor `t`'s memory: in place when it is weft memory, else a new
    slab with its values (created with a daemon-side gradient when `requires_grad`) to which a
    whole tensor is re-pointed; views get a copy."""
    wdtype, shape, strides, np_dtype = _layout(t, dtype, what)
    if int(t.numel()):
        found = external.find_at(int(t.data_ptr()), wdtype, shape, strides)
        if found is not None:
            memory.mark_shared(found._alloc)
            if requires_grad and memory.grad_view(found) is None:
                found.requires_grad = True
            return found
    from ..array import array  # noqa: PLC0415

    view = _host_view(t, np_dtype)
    data = np.ascontiguousarray(view)
    scalar = np.dtype(wdtype._wp_scalar_type_._np_dtype_)
    if data.dtype != scalar:
        data = data.view(scalar)        # signed/unsigned alias, bool as int8/uint8
    out = array(data, dtype=wdtype, shape=shape, device="cpu", requires_grad=requires_grad)
    if int(t.numel()) and _is_whole(t, np_dtype):
        moved = _tensor_over(out, t.dtype)
        if moved is not None:
            moved = moved.reshape(list(t.shape)) if list(moved.shape) != list(t.shape) else moved
            moved._share_buffer_to(t)   # t now reads and writes the slab
    return out


class _Producer:
    """A GPU Paddle tensor as a DLPack producer whose device is read from its place."""

    def __init__(self, t, ordinal):
        self._t = t
        self._device = (2, int(ordinal))

    def __dlpack_device__(self):
        return self._device

    def __dlpack__(self, stream=None, max_version=None, dl_device=None, copy=None):
        return _paddle().utils.dlpack.to_dlpack(self._t.detach())


def from_paddle(t, dtype=None, requires_grad=None, grad=None, return_ctype=False):
    """A weft array sharing memory with Paddle tensor `t` (Warp's wp.from_paddle; the memory
    rules are in this module's docstring). `dtype` may be a vector/matrix type whose shape
    matches the tensor's trailing dimensions (which must be contiguous); `requires_grad`
    (default: `not t.stop_gradient`) maps the tensor's .grad to the array's .grad (zeros when
    the tensor has none); `grad` (a Paddle tensor or a weft array) gives that gradient
    explicitly. `return_ctype=True` returns the array's ctypes descriptor (Warp's array_t),
    which launches take as the array."""
    a = _from_paddle(t, dtype, requires_grad, grad)
    return a.__ctype__() if return_ctype else a


def _from_paddle(t, dtype, requires_grad, grad):
    what = "wp.from_paddle"
    _check_tensor(t, what)
    device = _place_device(t.place)
    if requires_grad is None:
        requires_grad = (not t.stop_gradient) or grad is not None
    if device != "cpu":
        return _from_paddle_gpu(t, dtype, bool(requires_grad), grad, device, what)
    a = _adopt(t, dtype, what, requires_grad=bool(requires_grad and grad is None))
    if not requires_grad and grad is None:
        return a
    from ..array import array  # noqa: PLC0415

    if grad is not None:
        if isinstance(grad, array):
            if tuple(grad.shape) != tuple(a.shape) or grad.dtype != a.dtype:
                raise ValueError(f"{what}: the gradient array has shape {tuple(grad.shape)} and "
                                 f"dtype {grad.dtype.__name__}, the array {tuple(a.shape)} and "
                                 f"{a.dtype.__name__}")
            a._grad = grad
        else:
            _check_tensor(grad, what + " (grad)")
            a._grad = _adopt(grad, a.dtype, what + " (grad)")
        a._requires_grad = bool(requires_grad)
        return a
    g = t.grad
    ga = memory.grad_view(a)            # the daemon-side gradient of the allocation
    if ga is None:                      # (an array found in place without one)
        from ..array import zeros  # noqa: PLC0415

        ga = _adopt(g, a.dtype, what + " (grad)") if g is not None else \
            zeros(a.shape, dtype=a.dtype, device="cpu")
        a._grad = ga
    elif g is None:
        memory.set_now(ga)             # a tensor without .grad: the gradient starts at zero
    elif not (ga.ptr is not None and int(g.data_ptr()) == ga.ptr):
        memory.set_now(ga, _host_view(g, np.dtype(ga.dtype._wp_scalar_type_._np_dtype_)))
    if g is None or ga.ptr is None or int(g.data_ptr()) != ga.ptr:
        gt = _tensor_over(ga, t.dtype)
        if gt is not None:
            t.grad_ = gt.reshape(list(t.shape)) if list(gt.shape) != list(t.shape) else gt
    else:
        memory.mark_shared(ga._alloc)
    a._requires_grad = True
    return a


def _from_paddle_gpu(t, dtype, requires_grad, grad, device, what):
    """GPU tensors go through DLPack (weft memory in place, else imported by CUDA IPC or copied:
    weft.interop.cuda_import); gradients the same way."""
    ordinal = int(device.split(":")[1])
    a = dlpack.from_dlpack(_Producer(t, ordinal), dtype=dtype)
    if grad is None and not requires_grad:
        return a
    from ..array import array, zeros  # noqa: PLC0415

    if grad is None:
        grad = t.grad
    if grad is None:
        ga = zeros(a.shape, dtype=a.dtype, device=a.device)
        t.grad_ = to_paddle(ga, requires_grad=False)
    elif isinstance(grad, array):
        ga = grad
    else:
        ga = dlpack.from_dlpack(_Producer(grad, ordinal), dtype=a.dtype)
    a._grad = ga
    a._requires_grad = True
    return a


def to_paddle(a, requires_grad=None):
    """A Paddle tensor over weft array `a` (Warp's wp.to_paddle): zero-copy for CPU arrays of
    local sessions (pending weft commands are finished first); remote sessions get a copy.
    With requires_grad (default: a.requires_grad) the tensor has stop_gradient=False and its
    .grad is the array's gradient, zero-copy."""
    from .. import types  # noqa: PLC0415
    from ..array import _canonical_dtype, array  # noqa: PLC0415

    if not isinstance(a, array):
        raise TypeError(f"wp.to_paddle expects a weft array, got {type(a).__name__}")
    if not types.is_dtype(_canonical_dtype(a.dtype)):
        raise PaddleInteropError(f"wp.to_paddle: cannot convert an array of {a.dtype!r} "
                                 f"(structs and other non-numeric elements) to Paddle")
    if a._info is None:
        raise PaddleInteropError("wp.to_paddle: a null array has no memory to share")
    paddle = _paddle()
    pdtype = dtype_to_paddle(a.dtype)
    if a.device is not None and a.device.is_cuda:
        t = paddle.from_dlpack(dlpack.export(a))
    else:
        t = _tensor_over(a, pdtype)
        if t is None:                   # not mapped here (remote session) or empty: a copy
            host = np.array(a.numpy(), copy=True)
            if pdtype == paddle.bfloat16:  # its bits, widened to the float32 of equal value
                wide = (host.view(np.uint16).astype(np.uint32) << 16).view(np.float32)
                t = paddle.to_tensor(wide).astype(pdtype)
            else:
                t = paddle.from_dlpack(host.view(np.dtype(_name(pdtype))))
    if requires_grad is None:
        requires_grad = a.requires_grad
    t.stop_gradient = not requires_grad
    if requires_grad:
        ga = memory.grad_view(a)
        if ga is None:
            a.requires_grad = True      # a gradient array of its own
            ga = a.grad
        t.grad_ = to_paddle(ga, requires_grad=False)
    return t


def stream_from_paddle(stream_or_device=None):
    """A weft stream bound to a Paddle CUDA stream (Warp's wp.stream_from_paddle; default:
    Paddle's current stream of its current device). CPU devices raise RuntimeError: streams
    are CUDA objects (CPU work is ordered by synchronization, docs/interop.md)."""
    paddle = _paddle()
    stream_type = getattr(paddle.device, "Stream", None)
    if stream_type is not None and isinstance(stream_or_device, stream_type):
        paddle_stream = stream_or_device
        device = device_from_paddle(paddle_stream.device)
    else:
        device = device_from_paddle(stream_or_device if stream_or_device is not None
                                    else paddle.device.get_device())
        paddle_stream = None
    if not device.is_cuda:
        raise RuntimeError("streams are CUDA objects; CPU work is ordered by synchronization "
                           "(docs/interop.md)")
    if paddle_stream is None:
        paddle_stream = paddle.device.current_stream(device_to_paddle(device))
    from .. import streams  # noqa: PLC0415

    base = getattr(paddle_stream, "stream_base", paddle_stream)
    stream = streams.Stream(device, cuda_stream=int(base.cuda_stream))
    stream._paddle_stream = paddle_stream      # keeps Paddle's stream alive
    return stream
