"""Foreign arrays as weft arrays: NumPy arrays, Torch tensors, JAX arrays and anything with
`__array_interface__`, `__array__` or a CPU `__dlpack__`.

`host_view` gives a NumPy view of a foreign CPU array without copying where the framework
allows it; `resolve_layout` checks its dtype against a weft dtype (vector/matrix dtypes take
the trailing dimensions, which must be contiguous); `weft_array` returns a weft array over the
same memory when that memory already lives in a weft slab (found by address, see memory.py),
else a new weft array with a copy. `launch_array` does the same for wp.launch arguments and
says what must be copied back after the launch. Devices are checked: data that lives on a GPU
is never silently read through a CPU path, and the reverse.
"""
from __future__ import annotations

import sys

import numpy as np

from . import memory

MAX_DIMS = 4
DL_CPU, DL_CUDA, DL_CUDA_HOST, DL_CUDA_MANAGED = 1, 2, 3, 13


class InteropError(TypeError):
    """A foreign array weft cannot take as it is (dtype, device, layout)."""


def _torch_tensor_type():
    torch = sys.modules.get("torch")
    return getattr(torch, "Tensor", None) if torch is not None else None


def is_torch_tensor(obj) -> bool:
    tensor_type = _torch_tensor_type()
    return tensor_type is not None and isinstance(obj, tensor_type)


def framework_device(device, cuda_prefix: str, framework: str) -> str:
    """A framework's device string for a weft device: "cpu", or f"{cuda_prefix}:N" for cuda:N
    (Torch names GPUs "cuda", Paddle "gpu")."""
    from ..device import get_device  # noqa: PLC0415

    device = get_device(device)
    if device.is_cpu:
        return "cpu"
    if device.is_cuda:
        return f"{cuda_prefix}:{device.ordinal}"
    raise RuntimeError(f"weft device {device} is not compatible with {framework}")


def foreign_device(obj) -> str:
    """"cpu" or "cuda:N" for a foreign array (NumPy and anything without a device: "cpu")."""
    if isinstance(obj, np.ndarray):
        return "cpu"
    if is_torch_tensor(obj):
        dev = obj.device
        if dev.type == "cuda":
            return f"cuda:{dev.index if dev.index is not None else 0}"
        return dev.type
    if hasattr(obj, "__cuda_array_interface__"):
        return "cuda"           # the ordinal is the pointer's; the launch device decides
    dlpack_device = getattr(obj, "__dlpack_device__", None)
    if dlpack_device is not None and not hasattr(obj, "__array_interface__"):
        try:
            kind, ordinal = dlpack_device()
        except Exception:  # noqa: BLE001 - not a usable DLPack producer: host data
            return "cpu"
        kind = int(kind)
        if kind in (DL_CPU, DL_CUDA_HOST):
            return "cpu"
        if kind in (DL_CUDA, DL_CUDA_MANAGED):
            return f"cuda:{int(ordinal)}"
        return f"dlpack-device-{kind}"
    return "cpu"


def host_view(obj, what: str = "array") -> np.ndarray:
    """A NumPy array over a foreign CPU array's memory (a copy only where the framework has no
    zero-copy path, e.g. plain lists)."""
    if isinstance(obj, np.ndarray):
        return obj
    device = foreign_device(obj)
    if device != "cpu":
        raise InteropError(f"{what} lives on {device}; it cannot be read as CPU data")
    if is_torch_tensor(obj):
        t = obj.detach()
        if t.is_conj():
            t = t.resolve_conj()
        if t.is_neg():
            t = t.resolve_neg()
        if t.dtype is sys.modules["torch"].bfloat16:
            t = t.view(sys.modules["torch"].int16)   # NumPy has no bfloat16: its bits
        try:
            return t.numpy()
        except (TypeError, RuntimeError) as err:
            raise InteropError(f"{what}: unsupported Torch dtype {obj.dtype} ({err})") from None
    if hasattr(obj, "__array_interface__") or hasattr(obj, "__array_struct__"):
        return np.asarray(obj)
    if hasattr(obj, "__dlpack__"):
        try:
            return np.from_dlpack(obj)
        except (TypeError, BufferError, RuntimeError) as err:
            raise InteropError(f"{what}: cannot import through DLPack: {err}") from None
    if hasattr(obj, "__array__") or isinstance(obj, (list, tuple)):
        out = np.asarray(obj)
        if out.dtype == object:
            raise InteropError(f"{what}: cannot convert {type(obj).__name__} to a numeric array")
        return out
    raise InteropError(f"{what}: {type(obj).__name__} is not an array (no __array_interface__, "
                       f"__array__, __dlpack__ or __cuda_array_interface__)")


def _scalar_compatible(np_dtype: np.dtype, weft_scalar) -> bool:
    """Warp's aliasing rule: the same scalar type, or integers (and bool) of the same size
    seen as signed or unsigned."""
    target = np.dtype(weft_scalar._np_dtype_)
    if np_dtype == target:
        return True
    ints = ("i", "u", "b")
    return (np_dtype.kind in ints and target.kind in ints and
            np_dtype.itemsize == target.itemsize)


def resolve_layout(view: np.ndarray, dtype=None, what: str = "array", cast_ok=False):
    """(weft dtype, shape, byte strides) of `view` seen as an array of `dtype` (None: the
    scalar type of the data). Raises InteropError for unsupported dtypes, mismatched element
    shapes, non-contiguous elements and more than 4 dimensions; a different (supported)
    scalar type is an error too unless `cast_ok` (the caller converts by copying)."""
    return resolve_parts(view.dtype, tuple(view.shape), tuple(view.strides), dtype, what,
                         cast_ok)


_LAYOUTS: dict = {}     # (np dtype, shape, strides, dtype) -> resolved layout (hot path)


def resolve_parts(np_dtype, shape: tuple, strides: tuple, dtype=None, what: str = "array",
                  cast_ok=False):
    """resolve_layout of data described by (NumPy dtype, shape, byte strides)."""
    key = (np_dtype, shape, strides, dtype)
    try:
        return _LAYOUTS[key]
    except (KeyError, TypeError):
        pass
    result = _resolve_parts(np.dtype(np_dtype), shape, strides, dtype, what, cast_ok)
    if _scalar_compatible(np.dtype(np_dtype), result[0]._wp_scalar_type_):
        if len(_LAYOUTS) > 4096:
            _LAYOUTS.clear()
        try:
            _LAYOUTS[key] = result
        except TypeError:
            pass
    return result


def _resolve_parts(np_dtype, shape, strides, dtype, what, cast_ok):
    from .. import types  # noqa: PLC0415
    from ..array import _canonical_dtype  # noqa: PLC0415

    try:
        source = types.dtype_from_numpy(np_dtype)
    except TypeError:
        raise InteropError(f"{what}: unsupported dtype {np_dtype} (weft arrays hold bool, "
                           f"int8..int64, uint8..uint64, float16, float32, float64)") from None
    dtype = source if dtype is None else _canonical_dtype(dtype)
    if not types.is_dtype(dtype):
        raise InteropError(f"{what}: cannot view data as {dtype!r}")
    scalar = dtype._wp_scalar_type_
    if not _scalar_compatible(np_dtype, scalar) and not cast_ok:
        raise InteropError(f"{what}: incompatible dtypes: the data is {np_dtype}, the requested "
                           f"dtype {types.type_str(dtype)} has {scalar.__name__} components")
    inner = tuple(dtype._shape_)
    k = len(inner)
    if k:
        if len(shape) < k or shape[len(shape) - k:] != inner:
            raise InteropError(f"{what}: cannot view data of shape {shape} as "
                               f"{types.type_str(dtype)}: the trailing dimensions must be "
                               f"{inner}")
        step = np_dtype.itemsize
        for n, s in zip(reversed(inner), reversed(strides)):
            if s != step and n > 1:
                raise InteropError(f"{what}: the trailing dimensions {inner} are not contiguous "
                                   f"(strides {strides}); a {types.type_str(dtype)} element "
                                   f"must be contiguous")
            step *= n
        shape, strides = shape[:len(shape) - k], strides[:len(strides) - k]
    if not shape:
        shape, strides = (1,), (dtype._length_ * np_dtype.itemsize,)
    if len(shape) > MAX_DIMS:
        raise InteropError(f"{what}: {len(shape)} dimensions; weft arrays have at most "
                           f"{MAX_DIMS}")
    return dtype, shape, strides


def _address(view: np.ndarray) -> int:
    return int(view.__array_interface__["data"][0])


def _span(shape, strides, elem: int):
    """(lowest byte offset relative to the first element, bytes covered)."""
    if any(n == 0 for n in shape):
        return 0, 0
    low = sum(min(0, (n - 1) * s) for n, s in zip(shape, strides))
    high = sum(max(0, (n - 1) * s) for n, s in zip(shape, strides))
    return low, high - low + elem


def elem_bytes(dtype) -> int:
    """Bytes of one element of weft (scalar/vector/matrix) dtype `dtype`."""
    try:
        return _ELEM_BYTES[dtype]
    except KeyError:
        n = dtype._length_ * np.dtype(dtype._wp_scalar_type_._np_dtype_).itemsize
        _ELEM_BYTES[dtype] = n
        return n


_ELEM_BYTES: dict = {}


def find_in_place(view: np.ndarray, dtype, shape, strides):
    """A weft array over the same memory as `view` when it lies in a live weft allocation."""
    if view.size == 0:
        return None
    return find_at(_address(view), dtype, shape, strides)


def find_at(address: int, dtype, shape, strides, space: str = "cpu"):
    """A weft array over [address, ...) laid out as (dtype, shape, byte strides) when that
    memory lies in a live weft allocation, else None."""
    low, nbytes = _span(shape, strides, elem_bytes(dtype))
    if low < 0 or nbytes == 0:
        return None                     # negative strides: weft views need non-negative ones
    hit = memory.find(address, nbytes, space)
    if hit is None:
        return None
    alloc, offset = hit
    try:
        return memory.array_over(alloc, offset, shape, strides, dtype)
    except ValueError:
        return None


def cuda_interface(obj) -> dict:
    """The CUDA Array Interface of a foreign GPU array (Torch tensors included)."""
    if is_torch_tensor(obj):
        obj = obj.detach()
    try:
        return obj.__cuda_array_interface__
    except (AttributeError, RuntimeError, TypeError) as err:
        raise InteropError(f"cannot read the CUDA Array Interface of {type(obj).__name__}: "
                           f"{err}") from None


def find_cuda_in_place(obj, dtype, device: str, what: str):
    """A weft array over a foreign GPU array whose memory is a weft GPU allocation (exported
    to the framework by to_torch / DLPack), else None."""
    space = f"cuda:{device.split(':')[1] if ':' in device else '0'}"
    if is_torch_tensor(obj) and memory.find(int(obj.data_ptr()), 1, space=space) is None:
        return None     # the framework's own memory (most tensors): no layout work
    iface = cuda_interface(obj)
    np_dtype = np.dtype(iface["typestr"])
    shape = tuple(int(s) for s in iface["shape"])
    strides = iface.get("strides")
    if strides is None:
        strides, step = [], np_dtype.itemsize
        for n in reversed(shape):
            strides.append(step)
            step *= max(n, 1)
        strides = tuple(reversed(strides))
    fake = np.lib.stride_tricks.as_strided(np.zeros(1, dtype=np_dtype), shape=shape,
                                           strides=strides, writeable=False)
    wdtype, wshape, wstrides = resolve_layout(fake, dtype, what)
    from ..array import _elem_size  # noqa: PLC0415

    low, nbytes = _span(wshape, wstrides, _elem_size(wdtype))
    if low < 0:
        return None
    hit = memory.find(int(iface["data"][0]), nbytes, space=space)
    if hit is None:
        return None
    alloc, offset = hit
    try:
        return memory.array_over(alloc, offset, wshape, wstrides, wdtype)
    except ValueError:
        return None


def weft_array(obj, dtype=None, device=None, requires_grad=False, what: str = "array"):
    """(weft array, in_place): `obj`'s memory itself when it lives in a weft slab and `device`
    is the CPU (or None), else a new array with a copy on `device`."""
    array_mod = sys.modules["weft.array"]  # the module (weft.array is the class)
    from ..device import get_device  # noqa: PLC0415

    if isinstance(obj, array_mod.array):
        return obj, True
    view = host_view(obj, what)
    dtype, shape, strides = resolve_layout(view, dtype, what)
    target = get_device(device)
    if target.is_cpu:
        found = find_in_place(view, dtype, shape, strides)
        if found is not None:
            if requires_grad:
                found.requires_grad = True
            return found, True
    data = np.ascontiguousarray(view)
    if data.dtype != np.dtype(dtype._wp_scalar_type_._np_dtype_):
        data = data.view(np.dtype(dtype._wp_scalar_type_._np_dtype_))   # signed/unsigned alias
    out = array_mod.array(data, dtype=dtype, shape=shape, device=target,
                          requires_grad=requires_grad)
    return out, False


def launch_array(value, dtype, device: str, what: str):
    """(weft array, NumPy target to copy the result back into or None) for a foreign array
    passed to wp.launch for an array parameter of element `dtype` (None: from the data)."""
    array_mod = sys.modules["weft.array"]  # the module (weft.array is the class)

    source_device = foreign_device(value)
    if source_device != "cpu":
        if not device.startswith("cuda"):
            raise InteropError(f"{what}: the array lives on {source_device} but the kernel is "
                               f"launched on {device}")
        if device == "cuda":
            from ..device import get_device  # noqa: PLC0415

            device = get_device("cuda").alias
        from . import cuda_import  # noqa: PLC0415

        if is_torch_tensor(value):
            # weft memory in place, else imported by CUDA IPC (remembered on the tensor), else
            # moved into weft memory once or copied (cuda_import.adopt_torch)
            temp, src = cuda_import.adopt_torch(value, dtype, device, what)
            return temp, (None if src is None else cuda_import.CopyBack(src, temp))
        found = find_cuda_in_place(value, dtype, device, what)
        if found is not None:
            return found, None
        # not weft memory: imported by CUDA IPC where possible, else a copy into a weft array
        # written back after the launch (cuda_import.py)
        temp = cuda_import.import_object(value, dtype, device, what)
        if temp is not None:
            return temp, None           # imported by CUDA IPC: used in place
        temp, src = cuda_import.copy_in(value, dtype, device, what, cast_ok=True)
        return temp, cuda_import.CopyBack(src, temp)
    if not device.startswith("cpu"):
        raise InteropError(f"{what}: the array lives on the CPU but the kernel is launched on "
                           f"{device}; copy it with wp.array(..., device={device!r})")
    view = host_view(value, what)
    wdtype, shape, strides = resolve_layout(view, dtype, what, cast_ok=True)
    if _scalar_compatible(view.dtype, wdtype._wp_scalar_type_):
        found = find_in_place(view, wdtype, shape, strides)
        if found is not None:
            return found, None
        if is_torch_tensor(value) and value._base is None:
            # a Torch tensor moves into a slab once, as with wp.from_torch (see torch.py):
            # later launches use it in place
            from . import torch as torch_interop  # noqa: PLC0415

            adopted = torch_interop._adopt_tensor(value, wdtype, what, other_refs=1)
            # a tensor that could not move (others share its storage) got a copy: the
            # kernel's writes are copied back into it after the launch
            return adopted, (None if adopted.ptr == value.data_ptr() else view)
    # a copy (converted to the parameter's scalar type where the data has another one)
    data = view
    if view.dtype != np.dtype(wdtype._wp_scalar_type_._np_dtype_) and \
            _scalar_compatible(view.dtype, wdtype._wp_scalar_type_):
        data = np.ascontiguousarray(view).view(wdtype._wp_scalar_type_._np_dtype_)
    temp = array_mod.array(data, dtype=wdtype, shape=shape, device=device)
    writable = not isinstance(value, (list, tuple)) and view.flags.writeable
    return temp, (view if writable else None)

