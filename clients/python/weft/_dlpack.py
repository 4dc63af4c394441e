"""DLPack capsules over weft GPU arrays (kDLCUDA), and over CPU arrays NumPy cannot export
(bfloat16, kDLBfloat), made with ctypes; reading a bfloat16 capsule (read_bfloat16).

The capsule's data pointer is the array's address in this process's CUDA IPC mapping of the
daemon's slab (weft._cuda_ipc), so the consumer (Torch, CuPy, JAX) reads and writes the
daemon's memory without a copy. The managed tensor keeps the array's allocation (and so the
mapping) alive until the consumer calls its deleter; a capsule dropped unconsumed runs the
deleter itself. Legacy ("dltensor") capsules only: every consumer of the Python array API
accepts them.
"""
from __future__ import annotations

import ctypes
import struct

import numpy as np

KDL_CPU, KDL_CUDA = 1, 2
_KDL_INT, _KDL_UINT, _KDL_FLOAT, _KDL_BFLOAT, _KDL_BOOL = 0, 1, 2, 4, 6


class DLDevice(ctypes.Structure):
    _fields_ = [("device_type", ctypes.c_int32), ("device_id", ctypes.c_int32)]


class DLDataType(ctypes.Structure):
    _fields_ = [("code", ctypes.c_uint8), ("bits", ctypes.c_uint8), ("lanes", ctypes.c_uint16)]


class DLTensor(ctypes.Structure):
    _fields_ = [("data", ctypes.c_void_p), ("device", DLDevice), ("ndim", ctypes.c_int32),
                ("dtype", DLDataType), ("shape", ctypes.POINTER(ctypes.c_int64)),
                ("strides", ctypes.POINTER(ctypes.c_int64)), ("byte_offset", ctypes.c_uint64)]


class DLManagedTensor(ctypes.Structure):
    pass


_DELETER = ctypes.CFUNCTYPE(None, ctypes.POINTER(DLManagedTensor))
DLManagedTensor._fields_ = [("dl_tensor", DLTensor), ("manager_ctx", ctypes.c_void_p),
                            ("deleter", _DELETER)]

_CAPSULE_DESTRUCTOR = ctypes.CFUNCTYPE(None, ctypes.c_void_p)
_PyCapsule_New = ctypes.pythonapi["PyCapsule_New"]   # a function object of its own
_PyCapsule_New.restype = ctypes.py_object
_PyCapsule_New.argtypes = [ctypes.c_void_p, ctypes.c_char_p, _CAPSULE_DESTRUCTOR]
_PyCapsule_IsValid = ctypes.pythonapi["PyCapsule_IsValid"]   # a function object of its own
_PyCapsule_IsValid.restype = ctypes.c_int
_PyCapsule_IsValid.argtypes = [ctypes.c_void_p, ctypes.c_char_p]
_PyCapsule_GetPointer = ctypes.pythonapi["PyCapsule_GetPointer"]   # a function object of its own
_PyCapsule_GetPointer.restype = ctypes.c_void_p
_PyCapsule_GetPointer.argtypes = [ctypes.c_void_p, ctypes.c_char_p]

_NAME = b"dltensor"     # a capsule keeps the name pointer: this bytes object lives on
_live: dict = {}        # managed tensor address -> (its buffer, keep-alive)


@_DELETER
def _deleter(managed):
    _live.pop(ctypes.addressof(managed.contents), None)


@_CAPSULE_DESTRUCTOR
def _capsule_destructor(capsule):
    # An unconsumed capsule (still named "dltensor") owns its tensor; a consumer renames it.
    if _PyCapsule_IsValid(capsule, b"dltensor"):
        address = _PyCapsule_GetPointer(capsule, b"dltensor")
        _live.pop(address, None)


def dl_dtype(np_dtype: np.dtype) -> DLDataType:
    kind = np_dtype.kind
    code = {"i": _KDL_INT, "u": _KDL_UINT, "f": _KDL_FLOAT, "b": _KDL_BOOL}.get(kind)
    if code is None:
        raise BufferError(f"DLPack cannot describe elements of dtype {np_dtype}")
    return DLDataType(code, np_dtype.itemsize * 8, 1)


_HEAD = struct.Struct("<QiiiBBHQQQQQ")          # a DLManagedTensor: DLTensor, manager_ctx, deleter
assert _HEAD.size == ctypes.sizeof(DLManagedTensor)
_DELETER_ADDRESS = ctypes.cast(_deleter, ctypes.c_void_p).value
_layouts: dict = {}     # (dtype, shape, strides, device) -> (buffer type, packer, fixed fields)
_LAYOUTS_KEPT = 256


def _layout(a):
    """What a capsule of an array of `a`'s dtype, shape, strides and device holds besides its
    addresses, computed once per layout: (ctypes buffer type, its packer, device type and id,
    ndim, DLPack dtype fields, shape and strides in elements)."""
    key = (a.dtype, a.shape, a.strides, a.device)
    hit = _layouts.get(key)
    if hit is not None:
        return hit
    from .array import _elem_layout  # noqa: PLC0415

    np_dtype, inner = _elem_layout(a.dtype)
    if np_dtype.fields is not None:
        raise BufferError(f"DLPack cannot describe arrays of struct elements ({a.dtype})")
    itemsize = np_dtype.itemsize
    if any(s % itemsize for s in a.strides):
        raise BufferError("strides that are not a multiple of the element size")
    shape = tuple(a.shape) + tuple(inner)
    inner_strides = []
    step = 1
    for n in reversed(inner):
        inner_strides.append(step)
        step *= n
    strides = tuple(s // itemsize for s in a.strides) + tuple(reversed(inner_strides))
    ndim = len(shape)
    cuda = a.device is not None and a.device.is_cuda
    device = (KDL_CUDA, int(a.device.ordinal)) if cuda else (KDL_CPU, 0)
    bf16 = getattr(a.dtype, "_wp_scalar_type_", a.dtype).__name__ == "bfloat16"
    dt = DLDataType(_KDL_BFLOAT, 16, 1) if bf16 else dl_dtype(np_dtype)
    buffer_type = ctypes.c_uint64 * (_HEAD.size // 8 + 2 * ndim)   # 8-byte aligned
    packer = struct.Struct(f"<{2 * ndim}q")
    hit = (buffer_type, packer, device, ndim, (dt.code, dt.bits, dt.lanes), shape + strides)
    if len(_layouts) >= _LAYOUTS_KEPT:
        _layouts.clear()
    _layouts[key] = hit
    return hit


def to_capsule(a):
    """A "dltensor" capsule over array `a`: a GPU array in this process's IPC mapping
    (BufferError when the mapping is not available: no CUDA driver here, or IPC refused), a CPU
    array in this process's mapping of its slab. The managed tensor, its shape and its strides
    are one buffer written in one go (its layout computed once per array layout)."""
    ptr = a.ptr
    if ptr is None:
        from ._cuda_ipc import reason  # noqa: PLC0415

        raise BufferError(f"DLPack export of {a.device} memory needs CUDA IPC in this client "
                          f"({reason() or 'not a local session'}); use a.numpy() for a copy")
    buffer_type, packer, device, ndim, dt, dims = _layout(a)
    buf = buffer_type()
    address = ctypes.addressof(buf)
    shape_at = address + _HEAD.size
    _HEAD.pack_into(buf, 0, int(ptr), device[0], device[1], ndim, dt[0], dt[1], dt[2],
                    shape_at, shape_at + 8 * ndim, 0, 0, _DELETER_ADDRESS)
    packer.pack_into(buf, _HEAD.size, *dims)
    _live[address] = (buf, a._alloc)
    return _PyCapsule_New(address, _NAME, _capsule_destructor)


_PyCapsule_GetName = ctypes.pythonapi["PyCapsule_GetName"]   # a function object of its own
_PyCapsule_GetName.restype = ctypes.c_char_p
_PyCapsule_GetName.argtypes = [ctypes.py_object]
_PyCapsule_SetName = ctypes.pythonapi["PyCapsule_SetName"]   # a function object of its own
_PyCapsule_SetName.restype = ctypes.c_int
_PyCapsule_SetName.argtypes = [ctypes.py_object, ctypes.c_char_p]
_PyCapsule_GetPointerObj = ctypes.pythonapi["PyCapsule_GetPointer"]
_PyCapsule_GetPointerObj.restype = ctypes.c_void_p
_PyCapsule_GetPointerObj.argtypes = [ctypes.py_object, ctypes.c_char_p]
_USED = b"used_dltensor"


def capsule_tensor(capsule):
    """(DLTensor, managed tensor address, versioned) of an unconsumed legacy or versioned
    capsule."""
    name = _PyCapsule_GetName(capsule)
    if name not in (b"dltensor", b"dltensor_versioned"):
        raise BufferError("not an unconsumed DLPack capsule")
    address = _PyCapsule_GetPointerObj(capsule, name)
    versioned = name == b"dltensor_versioned"
    # versioned: version (2 x uint32), manager_ctx, deleter, flags (uint64), then the DLTensor
    offset = 8 + 3 * ctypes.sizeof(ctypes.c_void_p) if versioned else 0
    return DLTensor.from_address(address + offset), address, versioned


def read_bfloat16(capsule) -> np.ndarray:
    """A copy (uint16 bit patterns) of the CPU bfloat16 tensor of an unconsumed capsule, which
    this consumes: its deleter runs once the data is copied."""
    t, address, versioned = capsule_tensor(capsule)
    if t.device.device_type not in (KDL_CPU, 3) or t.dtype.code != _KDL_BFLOAT or t.dtype.bits != 16 \
            or t.dtype.lanes != 1:
        raise BufferError("not a CPU bfloat16 DLPack tensor")
    ndim = int(t.ndim)
    shape = [int(t.shape[i]) for i in range(ndim)]
    if t.strides:
        strides = [int(t.strides[i]) * 2 for i in range(ndim)]
    else:
        strides, step = [], 2
        for n in reversed(shape):
            strides.insert(0, step)
            step *= max(n, 1)
    if any(n == 0 for n in shape):
        out = np.zeros(shape, dtype=np.uint16)
    else:
        lo = sum(min(0, (n - 1) * st) for n, st in zip(shape, strides))
        hi = sum(max(0, (n - 1) * st) for n, st in zip(shape, strides)) + 2
        base = int(t.data or 0) + int(t.byte_offset) + lo
        raw = (ctypes.c_uint8 * (hi - lo)).from_address(base)
        first = np.frombuffer(raw, dtype=np.uint16)[-lo // 2:]   # element 0 of the tensor
        view = np.lib.stride_tricks.as_strided(first, shape, strides)
        out = np.array(view, copy=True)
    # consumed: mark the capsule used (its destructor then leaves the tensor alone) and run the
    # producer's deleter ourselves
    _PyCapsule_SetName(capsule, _USED)
    deleter_offset = 8 + ctypes.sizeof(ctypes.c_void_p) if versioned else \
        ctypes.sizeof(DLTensor) + ctypes.sizeof(ctypes.c_void_p)
    fn = ctypes.c_void_p.from_address(address + deleter_offset).value
    if fn:
        ctypes.CFUNCTYPE(None, ctypes.c_void_p)(fn)(address)
    return out
