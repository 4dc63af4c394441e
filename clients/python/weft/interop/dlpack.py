"""DLPack both ways: weft arrays as DLPack producers (`a.__dlpack__`, `a.__dlpack_device__`,
`wp.to_dlpack`) and `wp.from_dlpack` for any producer or legacy capsule.

Export of a CPU array hands out its shared-memory slab with NumPy's DLPack producer over the
zero-copy NumPy view (which keeps the allocation and its mapping alive until the consumer's
deleter runs), so versioned capsules, `max_version`, `dl_device` and `copy` follow the Python
array API standard as NumPy implements it. Pending weft commands are finished before the
capsule is made, so a consumer reads completed data (the `stream` argument must be None for CPU
arrays, as the standard says). Import of CPU data gives a weft array over the same memory when
the producer's memory is a weft slab (a round trip), else a weft array with a copy (the
producer's memory lives in this process, where the daemon cannot see it).
"""
from __future__ import annotations

import ctypes

import numpy as np

from . import external, memory

_KDL_CPU, _KDL_CUDA, _KDL_CUDA_HOST = 1, 2, 3

_PyCapsule_IsValid = ctypes.pythonapi.PyCapsule_IsValid
_PyCapsule_IsValid.restype = ctypes.c_int
_PyCapsule_IsValid.argtypes = [ctypes.py_object, ctypes.c_char_p]
_PyCapsule_GetPointer = ctypes.pythonapi.PyCapsule_GetPointer
_PyCapsule_GetPointer.restype = ctypes.c_void_p
_PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]


class _DLDevice(ctypes.Structure):
    _fields_ = [("device_type", ctypes.c_int32), ("device_id", ctypes.c_int32)]


def dlpack_device(a) -> tuple:
    """(device type, ordinal) of a weft array: (1, 0) for the CPU, (2, N) for cuda:N."""
    device = a.device
    if device is not None and device.is_cuda:
        return (_KDL_CUDA, int(device.ordinal))
    return (_KDL_CPU, 0)


def export(a, stream=None, max_version=None, dl_device=None, copy=None):
    """`a.__dlpack__(...)`: a DLPack capsule over `a`'s memory."""
    if a._info is None:
        raise BufferError("a null array has no memory to export")
    kind, ordinal = dlpack_device(a)
    if dl_device is not None and tuple(int(v) for v in dl_device) != (kind, ordinal):
        if not (tuple(int(v) for v in dl_device)[0] == _KDL_CPU and copy is True):
            raise BufferError(f"cannot export an array on {a.device} to DLPack device "
                              f"{tuple(dl_device)} without a copy")
        view = np.array(a.numpy(), copy=True)       # copy=True: a host copy, as asked
        return _numpy_capsule(view, max_version, a)
    if kind == _KDL_CUDA:
        return _export_cuda(a, stream, max_version)
    if stream is not None:
        raise BufferError(f"stream must be None when exporting a CPU array (got {stream!r})")
    rt = a._alloc.runtime
    zero_copy = rt.local and bool(a._info.shm_name)
    if not zero_copy and copy is False:
        raise BufferError("this array's memory is not mapped in this process (remote session); "
                          "it can only be exported as a copy")
    view = a.numpy()                    # finishes pending commands; zero-copy when local
    if _is_bfloat16(a) and zero_copy and not copy:
        # NumPy cannot export bfloat16: a kDLBfloat capsule over the slab (weft._dlpack)
        from .. import _dlpack as producer  # noqa: PLC0415

        memory.mark_shared(a._alloc)
        return producer.to_capsule(a)
    if copy:
        view = view.copy()
    elif zero_copy:
        memory.mark_shared(a._alloc)
    return _numpy_capsule(view, max_version, a)


def _is_bfloat16(a) -> bool:
    return getattr(a.dtype, "_wp_scalar_type_", a.dtype).__name__ == "bfloat16"


def _numpy_capsule(view: np.ndarray, max_version, a):
    if view.dtype.fields is not None:
        raise BufferError(f"DLPack cannot describe arrays of struct elements ({a.dtype})")
    try:
        if max_version is None:
            return view.__dlpack__()
        return view.__dlpack__(max_version=tuple(max_version))
    except TypeError:                   # NumPy < 2: no max_version, legacy capsules only
        return view.__dlpack__()


def _export_cuda(a, stream, max_version):
    """GPU arrays: a capsule over the CUDA IPC mapping of the array (the array layer's
    producer, weft._dlpack). `stream` (the consumer's stream of this process, array API
    rules: 1 = the legacy default stream, 2 = per-thread default) waits on the GPU for weft's
    queued work (an interprocess event, weft.interop.cuda_order) where the session can;
    otherwise (and for None or -1) weft's pending work is finished first."""
    try:
        from .. import _dlpack as producer  # noqa: PLC0415
    except ImportError:
        raise BufferError(f"DLPack export of {a.device} arrays needs CUDA IPC in this "
                          f"client") from None
    from . import cuda_order  # noqa: PLC0415

    if stream is None or stream == -1 or not isinstance(stream, int) or \
            not cuda_order.ready(a, [0 if stream == 1 else stream]):
        # -1 (the consumer does not want ordering) and odd values: finished on the host
        a._alloc.runtime.synchronize_if_needed()
    capsule = producer.to_capsule(a)
    ptr = a.ptr
    if ptr is not None:
        memory.note_range(a._alloc, f"cuda:{a.device.ordinal}", ptr - a._byte_offset,
                          int(a._info.byte_size))
        memory.mark_shared(a._alloc)
    return capsule


def to_dlpack(a):
    """A legacy ("dltensor") DLPack capsule of a weft array (Warp's wp.to_dlpack)."""
    from ..array import array  # noqa: PLC0415

    if not isinstance(a, array):
        raise TypeError(f"wp.to_dlpack expects a weft array, got {type(a).__name__}")
    return export(a)


def _capsule_device(capsule) -> tuple:
    """(device type, ordinal) stored in an unconsumed DLPack capsule."""
    if _PyCapsule_IsValid(capsule, b"dltensor"):
        base = _PyCapsule_GetPointer(capsule, b"dltensor")
        offset = ctypes.sizeof(ctypes.c_void_p)                 # DLTensor.data
    elif _PyCapsule_IsValid(capsule, b"dltensor_versioned"):
        base = _PyCapsule_GetPointer(capsule, b"dltensor_versioned")
        # version (2 x uint32), manager_ctx, deleter, flags (uint64), then DLTensor
        offset = 8 + 3 * ctypes.sizeof(ctypes.c_void_p) + ctypes.sizeof(ctypes.c_void_p)
    else:
        raise TypeError("not an unconsumed DLPack capsule (its name must be 'dltensor' or "
                        "'dltensor_versioned'; a capsule can be consumed only once)")
    device = _DLDevice.from_address(base + offset)
    return int(device.device_type), int(device.device_id)


class _CapsuleProducer:
    """A legacy capsule dressed as a DLPack producer (for np.from_dlpack)."""

    def __init__(self, capsule):
        self._device = _capsule_device(capsule)
        self._capsule = capsule

    def __dlpack_device__(self):
        return self._device

    def __dlpack__(self, stream=None, max_version=None, dl_device=None, copy=None):
        capsule, self._capsule = self._capsule, None
        if capsule is None:
            raise BufferError("the DLPack capsule was already consumed")
        return capsule


def _is_capsule(obj) -> bool:
    return type(obj).__name__ == "PyCapsule"


class DLPackDtypeError(external.InteropError, RuntimeError):
    """A DLPack tensor whose scalar type the requested dtype cannot alias (a RuntimeError,
    as Warp raises it; also weft's InteropError)."""


_DL_NAMES = {0: "int", 1: "uint", 2: "float", 3: "void_p", 4: "bfloat", 5: "complex", 6: "bool"}


def _check_dtype(dl_dtype, dtype):
    """Warp's aliasing rule for wp.from_dlpack(dtype=): bool8 as bool/int8/uint8, an integer
    as either signedness of its size, a float or bfloat16 only as itself; raises
    DLPackDtypeError in Warp's words otherwise."""
    from .. import types  # noqa: PLC0415
    from ..array import _canonical_dtype  # noqa: PLC0415

    dtype = _canonical_dtype(dtype)
    scalar = getattr(dtype, "_wp_scalar_type_", None)
    if scalar is None:
        return
    code, bits = int(dl_dtype.code), int(dl_dtype.bits)
    if code == 6:
        ok = bits == 8 and scalar in (types.bool, types.int8, types.uint8)
    elif code in (0, 1):
        ok = scalar in types.int_types and np.dtype(scalar._np_dtype_).itemsize * 8 == bits
    elif code == 2:
        ok = scalar in types.float_types and np.dtype(scalar._np_dtype_).itemsize * 8 == bits
    elif code == 4:
        ok = bits == 16 and scalar is types.bfloat16
    else:
        return      # left to the import, which names what it does not support
    if not ok:
        name = f"{_DL_NAMES[code]}{bits}" + (f"x{dl_dtype.lanes}" if dl_dtype.lanes > 1 else "")
        raise DLPackDtypeError(f"Incompatible data types: DLPack {name} and Warp "
                               f"{types.type_repr(dtype)}")


def from_dlpack(source, dtype=None):
    """A weft array of a DLPack producer (an object with __dlpack__/__dlpack_device__: NumPy,
    Torch, JAX, CuPy, Paddle, weft) or a legacy capsule. CPU data in a weft slab is used in
    place; other CPU data is copied into a new weft array."""
    from ..array import array  # noqa: PLC0415

    if isinstance(source, array):
        return source
    if _is_capsule(source):
        source = _CapsuleProducer(source)
    if not hasattr(source, "__dlpack__") or not hasattr(source, "__dlpack_device__"):
        raise TypeError(f"wp.from_dlpack expects a DLPack producer (with __dlpack__ and "
                        f"__dlpack_device__) or a DLPack capsule, got {type(source).__name__}")
    kind, ordinal = source.__dlpack_device__()
    kind, ordinal = int(kind), int(ordinal or 0)     # Paddle's CPU tensors give None
    if kind in (_KDL_CPU, _KDL_CUDA_HOST):
        # the capsule is taken here: bfloat16 (NumPy has no such dtype) is read directly, any
        # other dtype goes to NumPy
        try:
            capsule = source.__dlpack__()
        except TypeError as err:
            raise external.InteropError(f"wp.from_dlpack: {err}") from None
        if not _is_capsule(capsule):
            raise TypeError(f"Expected a valid DLPack capsule, got {type(capsule).__name__}")
        from .. import _dlpack as producer  # noqa: PLC0415
        from .. import types  # noqa: PLC0415

        tensor, _, _ = producer.capsule_tensor(capsule)
        if dtype is not None:
            _check_dtype(tensor.dtype, dtype)
        if tensor.dtype.code == 4:           # kDLBfloat
            try:
                bits = producer.read_bfloat16(capsule)
            except BufferError as err:
                raise external.InteropError(f"wp.from_dlpack: {err}") from None
            out, _ = external.weft_array(bits, dtype=dtype or types.bfloat16, device="cpu",
                                         what="wp.from_dlpack")
            return out
        try:
            view = np.from_dlpack(_CapsuleProducer(capsule))
        except (TypeError, BufferError) as err:
            raise external.InteropError(f"wp.from_dlpack: {err}") from None
        out, _ = external.weft_array(view, dtype=dtype, device="cpu", what="wp.from_dlpack")
        return out
    if kind == _KDL_CUDA:
        # weft memory (a round trip) is used in place; other GPU memory is imported by CUDA
        # IPC, or copied into a weft array where it cannot be (cuda_import.py)
        from . import cuda_import  # noqa: PLC0415

        if external.is_torch_tensor(source):
            out, _ = cuda_import.adopt_torch(source, dtype, f"cuda:{ordinal}", "wp.from_dlpack")
            return out
        if cuda_import.numeric_interface(source):
            found = external.find_cuda_in_place(source, dtype, f"cuda:{ordinal}",
                                                "wp.from_dlpack")
            if found is not None:
                return found
        out = cuda_import.import_object(source, dtype, f"cuda:{ordinal}", "wp.from_dlpack")
        if out is not None:
            return out
        out, _ = cuda_import.copy_in(source, dtype, f"cuda:{ordinal}", "wp.from_dlpack")
        return out
    raise external.InteropError(f"wp.from_dlpack: unsupported DLPack device type {kind}")
