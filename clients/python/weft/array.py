"""wp.array and the array functions (empty/zeros/ones/full, *_like, from_numpy, clone, copy,
IPC sharing) over daemon allocations.

An array object is a view of one daemon allocation: handle, byte offset, shape, byte strides.
Slices are new views of the same handle (no daemon call). Local (Unix-socket) sessions read
and write CPU arrays through the shared-memory slab, mapped once per process; remote (TCP)
sessions stream bytes with ArrayService.Read/Write. Allocations are freed when the last array
object using them is collected (the Free RPC is deferred to the next safe point).

Internal interface for weft._kernel: `a._handle`, `a._ref()` -> types_pb2.ArrayRef,
`a._info` (ArrayInfo of the allocation, None for a null array).
"""
from __future__ import annotations

import ctypes
import math
import warnings
import weakref
from typing import Any

import numpy as np

from . import _create_ahead, _cuda_ipc, _runtime, types
from . import array_annotations as _array_annotations
from . import config as _config
from . import mempool as _mempool
from . import memory_tracker as _memory_tracker
from .device import Device, get_device
from .errors import WeftError
from .interop import memory as _interop_memory
from .types import (_Composite, _Scalar, dtype_from_numpy, float32, int32, matrix, type_str,
                    vector)

__all__ = [
    "array", "array1d", "array2d", "array3d", "array4d", "empty", "empty_like", "zeros",
    "zeros_like", "ones", "ones_like", "full", "full_like", "from_numpy", "clone", "copy",
    "from_ipc_handle", "ARRAY_MAX_DIMS",
]

ARRAY_MAX_DIMS = 4
INLINE_DATA_MAX_BYTES = 48 << 20     # larger initial data goes through Write / the slab
LOCAL_WRITE_MIN_BYTES = 1 << 20      # local CPU data above this is written through the slab
CHUNK_BYTES = 4 << 20                # Read/Write chunk size

_SCALAR_ENUM = {
    "bool": 1, "int8": 2, "int16": 3, "int32": 4, "int64": 5, "uint8": 6, "uint16": 7,
    "uint32": 8, "uint64": 9, "float16": 10, "float32": 11, "float64": 12,
}
_ENUM_SCALAR = {v: getattr(types, k) for k, v in _SCALAR_ENUM.items()}


# ------------------------------------------------------------------------------------------
# dtype helpers


def _canonical_dtype(dtype):
    """float -> float32, int -> int32, bool -> bool, numpy dtypes -> weft scalars."""
    if dtype is Any:
        return Any
    if dtype is float:
        return float32
    if dtype is int:
        return int32
    if dtype is bool:
        return types.bool
    if types.is_dtype(dtype) or _is_struct(dtype):
        return dtype
    try:
        return dtype_from_numpy(np.dtype(dtype))
    except TypeError:
        raise TypeError(f"Invalid array dtype {dtype!r}") from None


def _is_bf16(dtype) -> bool:
    """bfloat16 or a vector/matrix/... of bfloat16 (stored as its 16 bits)."""
    return getattr(dtype, "_wp_scalar_type_", None) is types.bfloat16


def _ml_bfloat16():
    """ml_dtypes.bfloat16 when that package is installed, else None."""
    try:
        import ml_dtypes  # noqa: PLC0415 - optional
    except ImportError:
        return None
    return ml_dtypes.bfloat16


def _to_bf16_bits(values) -> np.ndarray:
    from ._kernel.typestr import to_bfloat16_bits  # noqa: PLC0415 - weft._kernel imports this module
    return to_bfloat16_bits(values)


def _bf16_source(data):
    """Data for a bfloat16 array: NumPy arrays as they are (uint16 = bits), other values
    (lists, tuples, scalars, weft scalars) as float32."""
    if isinstance(data, np.ndarray):
        return data if data.dtype in (np.uint16,) or data.dtype.name == "bfloat16" \
            else data.astype(np.float32)
    if isinstance(data, types.bfloat16):
        data = data.value
    return np.asarray(data, dtype=np.float32)


def _is_struct(dtype) -> bool:
    """@wp.struct types (weft._kernel.structs.StructType): numpy_dtype() gives their layout."""
    return callable(getattr(dtype, "numpy_dtype", None)) or hasattr(dtype, "_struct_size_")


def _struct_numpy(dtype, values):
    """Struct instance(s) (or a structured NumPy array) as a structured NumPy array."""
    np_dtype = np.dtype(dtype.numpy_dtype())
    if isinstance(values, np.ndarray) and values.dtype.fields is not None:
        return values.astype(np_dtype)
    many = isinstance(values, (list, tuple))
    items = list(values) if many else [values]
    out = np.zeros(len(items), dtype=np_dtype)
    for i, item in enumerate(items):
        _fill_record(out[i:i + 1], item)
    return out if many else out[0]


def _fill_record(record, item):
    for name in record.dtype.names:
        value = getattr(item, name)
        if record.dtype[name].fields is not None:
            _fill_record(record[name], value)
        else:
            record[name] = np.asarray(value)


def _elem_layout(dtype):
    """(numpy scalar dtype, inner element shape) of one array element."""
    if types.is_dtype(dtype):
        return np.dtype(dtype._np_dtype_), tuple(dtype._shape_)
    if callable(getattr(dtype, "numpy_dtype", None)):
        return np.dtype(dtype.numpy_dtype()), ()
    struct_np = getattr(dtype, "_numpy_dtype_", None)
    if struct_np is not None:
        return np.dtype(struct_np), ()
    size = getattr(dtype, "_struct_size_", None)
    if size is not None:
        return np.dtype(np.uint8), (int(size),)
    raise TypeError(f"Invalid array dtype {dtype!r}")


_ELEM_SIZES: dict = {}   # dtype -> bytes per element (dtypes are long-lived type objects)


def _elem_size(dtype) -> int:
    try:
        return _ELEM_SIZES[dtype]
    except (KeyError, TypeError):
        pass
    np_dtype, inner = _elem_layout(dtype)
    size = np_dtype.itemsize * int(np.prod(inner, dtype=np.int64))
    try:
        _ELEM_SIZES[dtype] = size
    except TypeError:   # an unhashable dtype object: computed each time
        pass
    return size


def _inner_strides(np_dtype, inner) -> tuple:
    strides = []
    step = np_dtype.itemsize
    for n in reversed(inner):
        strides.append(step)
        step *= n
    return tuple(reversed(strides))


def _dtype_proto(dtype):
    tp = _runtime.types_pb2
    if _is_bf16(dtype):   # its 16 bits, named bfloat16 (kernels match the name)
        return tp.DType(scalar=_SCALAR_ENUM["uint16"], elem_shape=list(dtype._shape_),
                        type_name=type_str(dtype))
    if types.is_dtype(dtype):
        return tp.DType(scalar=_SCALAR_ENUM[dtype._wp_scalar_type_._type_str],
                        elem_shape=list(dtype._shape_), type_name=type_str(dtype))
    return tp.DType(type_name=type_str(dtype), struct_size=_elem_size(dtype))


def _dtype_from_proto(proto):
    """The weft dtype an ArrayInfo describes (scalar, vector, matrix, quat, transform)."""
    name = proto.type_name
    scalar = _ENUM_SCALAR.get(proto.scalar)
    if name.startswith("quat(") and scalar is not None:
        return types.quaternion(scalar)
    if name.startswith("transform(") and scalar is not None:
        return types.transformation(scalar)
    if scalar is None:
        raise WeftError(f"cannot represent array element type {name or proto!r} in Python; "
                        "pass dtype=")
    shape = list(proto.elem_shape)
    if not shape:
        return scalar
    if len(shape) == 1:
        return vector(shape[0], scalar)
    if len(shape) == 2:
        return matrix(tuple(shape), scalar)
    raise WeftError(f"unsupported element shape {shape}")


def _normalize_shape(shape) -> tuple:
    if isinstance(shape, (int, np.integer)):
        shape = (int(shape),)
    try:
        if isinstance(shape, (str, bytes)):
            raise TypeError
        shape = tuple(int(s) for s in shape)
    except (TypeError, ValueError):
        raise TypeError(f"Invalid array shape {shape!r}: expected an int or a tuple of ints") \
            from None
    if len(shape) > ARRAY_MAX_DIMS:
        raise RuntimeError(f"Arrays may only have up to {ARRAY_MAX_DIMS} dimensions, got "
                           f"shape {shape}")
    if not shape:
        raise RuntimeError("Arrays must have at least one dimension")
    for s in shape:
        if s < 0:
            raise ValueError(f"Array shapes must be non-negative, got {shape}")
    return shape


def _contiguous_strides(shape, elem_size) -> tuple:
    strides = []
    step = elem_size
    for n in reversed(shape):
        strides.append(step)
        step *= max(n, 1)
    return tuple(reversed(strides))


def _infer_dtype(data):
    if isinstance(data, np.ndarray):
        return dtype_from_numpy(data.dtype)
    if isinstance(data, (_Composite, _Scalar)):
        return type(data)
    if isinstance(data, (list, tuple)) and data:
        first = data[0]
        if isinstance(first, (_Composite, _Scalar)):
            return type(first)
        struct_type = getattr(first, "_struct_type", None)
        if struct_type is not None:
            return struct_type
    arr = np.asarray(data)
    if arr.dtype == object:
        raise RuntimeError(f"Failed to infer the dtype of {type(data).__name__} data: pass dtype=")
    return dtype_from_numpy(arr.dtype)


# ------------------------------------------------------------------------------------------
# Allocations and byte transfer


class _Allocation:
    """One daemon allocation held by this process; freed when the last view lets go."""

    __slots__ = ("runtime", "info", "owned", "parent", "_mapping", "_cuda", "_cuda_slab",
                 "keep", "recycle", "pool_bytes", "framework_shared", "__weakref__")

    def __init__(self, runtime, info, owned=True, parent=None):
        self.runtime = runtime
        self.info = info
        self.owned = owned
        self.parent = parent   # a gradient keeps its array's allocation alive
        self._mapping = None
        self.framework_shared = False   # a framework holds it (weft.interop.memory.mark_shared)
        self._cuda = None      # device address in this process (0: no IPC mapping)
        self._cuda_slab = None  # slab id whose mapping this allocation holds
        self.keep = None       # imported framework memory: the object that owns it
        # imported framework memory: called with the ArrayInfo instead of freeing the handle
        # when this allocation dies (weft.interop.cuda_import keeps it for the same block)
        self.recycle = None
        # bytes counted as this process's GPU pool use (weft/mempool.py), uncounted when it dies
        self.pool_bytes = 0

    def cuda_address(self):
        """The allocation's device address in this process (GPU arrays of local sessions,
        through the CUDA IPC mapping of its slab, opened once per slab), else None."""
        if self._cuda is None:
            info = self.info
            address = 0
            if self.runtime.local and getattr(info, "cuda_slab_size", 0) and \
                    info.device.startswith("cuda:"):
                base = _cuda_ipc.slab_address(info, int(info.device.split(":")[1]))
                if base is not None:
                    address = base + int(info.cuda_ipc_offset)
                    self._cuda_slab = int(info.cuda_slab_id)
                    _interop_memory.note_range(self, info.device, address, int(info.byte_size))
            self._cuda = address
        return self._cuda or None

    def forget_cuda(self):
        """Drops the device address (the allocation moved to another slab)."""
        if self._cuda_slab is not None:
            _cuda_ipc.release(self._cuda_slab)
        self._cuda = None
        self._cuda_slab = None

    def mapping(self):
        """The slab mapping of this allocation (local CPU arrays), mapped on first use."""
        if self._mapping is None:
            self._mapping = self.runtime.map_slab(self.info.shm_name, self.info.shm_size)
            _interop_memory.note_mapped(self, self._mapping)   # its address may leave us now
        return self._mapping

    def __del__(self):
        try:
            if self.pool_bytes:
                _mempool.note_freed(self.info.device, self.pool_bytes)
            if self._cuda_slab is not None:
                _cuda_ipc.release(self._cuda_slab)
            if self.owned and self.info.handle:
                if self.recycle is not None and not self.runtime.closed:
                    self.recycle(self.info)
                else:
                    self.runtime.free_later(self.info.handle)
        except Exception:  # noqa: BLE001 - interpreter shutdown: nothing left to free
            pass


_ADDRESSED = weakref.WeakSet()     # allocations whose address this process has handed out


def _has_cuda_interface(data) -> bool:
    """Whether `data` is a foreign GPU array: it has a __cuda_array_interface__ (one that exists
    but refuses this object, as Torch's for a tensor that requires grad, counts too)."""
    try:
        return hasattr(data, "__cuda_array_interface__")
    except Exception:  # noqa: BLE001 - the interface exists; the conversion reports what it lacks
        return True


class _NumpyHolder:
    """Exposes slab memory to NumPy and keeps the allocation (and mapping) alive."""

    __slots__ = ("__array_interface__", "_keep")

    def __init__(self, interface, keep):
        self.__array_interface__ = interface
        self._keep = keep


def _is_local_cpu(rt, info) -> bool:
    return rt.local and bool(info.shm_name)


def _slab_bytes(rt, info, byte_offset, count) -> np.ndarray:
    mapping = rt.map_slab(info.shm_name, info.shm_size)
    start = info.shm_offset + byte_offset
    # the returned array holds the mmap (buffer export) for as long as it lives
    return np.frombuffer(mapping.mm, dtype=np.uint8, count=count, offset=start)


def _gpu_direct(rt, alloc):
    """(ordinal, device address of the allocation) when this process reaches the GPU
    allocation through its CUDA IPC mapping, else None (copies go through the daemon)."""
    if alloc is None or not alloc.info.device.startswith("cuda:"):
        return None
    address = alloc.cuda_address()
    if address is None:
        return None
    return int(alloc.info.device.split(":")[1]), address


def _write_bytes(rt, info, byte_offset: int, payload, alloc=None) -> None:
    """Writes `payload` (bytes-like) at `byte_offset` of the allocation."""
    data = np.frombuffer(memoryview(payload).cast("B"), dtype=np.uint8)
    if byte_offset < 0 or byte_offset + data.size > info.byte_size:
        raise WeftError(f"write of {data.size} bytes at offset {byte_offset} exceeds the "
                        f"allocation ({info.byte_size} bytes)", "OUT_OF_RANGE")
    if _is_local_cpu(rt, info):
        _slab_bytes(rt, info, byte_offset, data.size)[:] = data
        return
    direct = _gpu_direct(rt, alloc)
    if direct is not None and data.size:
        rt.synchronize_if_needed()          # the daemon's queued work on this memory first
        data = np.ascontiguousarray(data)
        _cuda_ipc.copy_from_host(direct[0], direct[1] + byte_offset, data.ctypes.data, data.size)
        return
    ap = _runtime.array_pb2

    def chunks():
        if data.size == 0:
            yield ap.WriteArrayRequest(handle=info.handle,
                                       chunk=ap.ArrayChunk(byte_offset=byte_offset))
            return
        for start in range(0, data.size, CHUNK_BYTES):
            request = ap.WriteArrayRequest(handle=info.handle)
            request.chunk.byte_offset = byte_offset + start
            request.chunk.data = data[start:start + CHUNK_BYTES].tobytes()   # one copy
            yield request

    response = _stream_call(rt, rt.array_stub.Write, chunks())
    if response.bytes_written != data.size:
        raise WeftError(f"daemon wrote {response.bytes_written} of {data.size} bytes", "DATA_LOSS")


def _read_bytes(rt, info, byte_offset: int, count: int, alloc=None) -> np.ndarray:
    """Reads `count` bytes at `byte_offset` of the allocation into a new uint8 array."""
    out = np.empty(count, dtype=np.uint8)
    if count == 0:
        return out
    if _is_local_cpu(rt, info):
        out[:] = _slab_bytes(rt, info, byte_offset, count)
        return out
    direct = _gpu_direct(rt, alloc)
    if direct is not None:
        rt.synchronize_if_needed()
        _cuda_ipc.copy_to_host(direct[0], out.ctypes.data, direct[1] + byte_offset, count)
        return out
    request = _runtime.array_pb2.ReadArrayRequest(handle=info.handle, byte_offset=byte_offset,
                                                  byte_count=count, chunk_size=CHUNK_BYTES)
    received = 0
    import grpc

    rt.order_grpc()
    try:
        for chunk in rt.array_stub.Read(request, metadata=rt.metadata):
            pos = chunk.byte_offset - byte_offset
            n = len(chunk.data)
            if pos < 0 or pos + n > count:
                raise WeftError(f"daemon sent a chunk outside the requested range "
                                f"({chunk.byte_offset}+{n})", "DATA_LOSS")
            out[pos:pos + n] = np.frombuffer(chunk.data, dtype=np.uint8)
            received += n
    except grpc.RpcError as err:
        raise _runtime.error_from_rpc(err) from None
    if received != count:
        raise WeftError(f"short read: {received} of {count} bytes", "DATA_LOSS")
    return out


def _stream_call(rt, method, iterator):
    import grpc

    rt.order_grpc()
    try:
        return method(iterator, metadata=rt.metadata)
    except grpc.RpcError as err:
        raise _runtime.error_from_rpc(err) from None


def _create(dtype, shape, device, requires_grad, init, value=b"", pinned=False):
    rt = _runtime.get_runtime()
    rt.drain_frees()
    if rt.captures and device.is_cuda:
        from .graph import is_capturing  # noqa: PLC0415
        if is_capturing(device):
            refused = _mempool.capture_allocation_error(device, _elem_size(dtype) * math.prod(shape))
            if refused is not None:
                raise refused
    ap = _runtime.array_pb2
    request = ap.CreateArrayRequest(dtype=_dtype_proto(dtype), shape=list(shape),
                                    device=device.alias, requires_grad=bool(requires_grad),
                                    init=init, value=value)
    if pinned and device.is_cpu:
        request.pinned = True        # a slab of its own, page-locked for weftd's GPUs
    ahead_key = response = None
    if not rt.captures and not value and not request.pinned and \
            init in (ap.CreateArrayRequest.EMPTY, ap.CreateArrayRequest.ZEROS) and \
            0 < _elem_size(dtype) * math.prod(shape) <= _create_ahead.MAX_BYTES:
        # a small array made again and again (wp.zeros in a loop): one is created ahead
        ahead_key = request.SerializeToString()
        with rt._lock:
            response = rt.create_ahead.take(ahead_key)
    if response is None:
        try:
            response = rt.array_call("Create", request)
        except WeftError as err:
            with rt._lock:
                gave_back = err.code == "RESOURCE_EXHAUSTED" and rt.create_ahead.give_back_all()
            if not gave_back:
                raise
            rt.flush()                   # the arrays held ahead are freed first
            response = rt.array_call("Create", request)
    if ahead_key is not None:
        with rt._lock:
            rt.create_ahead.created(ahead_key)
    if not device.is_cpu:
        rt._unsynchronized = True   # its zeroing/fill is queued on the session's GPU stream
        rt.work_queued += 1
    grad_info = response.grad_info if response.info.grad_handle and \
        response.grad_info.handle == response.info.grad_handle else None
    return rt, response.info, grad_info


# ------------------------------------------------------------------------------------------
# The array


class array_t(ctypes.Structure):
    """Warp's ctypes descriptor of an array (what `a.__ctype__()` gives): the addresses of the
    data and gradient in this process (0 where there is none), shape, byte strides, ndim. A
    descriptor made by a weft array refers back to it (`_weft_value`), which is how
    wp.Launch.set_param_*_from_ctype takes it."""

    _fields_ = (("data", ctypes.c_uint64), ("grad", ctypes.c_uint64),
                ("shape", ctypes.c_int32 * ARRAY_MAX_DIMS),
                ("strides", ctypes.c_int32 * ARRAY_MAX_DIMS),
                ("ndim", ctypes.c_uint16), ("flags", ctypes.c_uint16))


class array:
    """A multi-dimensional array in weftd memory (Warp's wp.array)."""

    _default_ndim_ = 1
    # A copy of framework memory kept in step with it around launches (interop/torch.py,
    # TensorMirror); None for every other array.
    _mirror = None

    def __class_getitem__(cls, params):
        # wp.array[float], wp.array[float, Literal[2]]: an annotation object (dtype, ndim).
        return _array_annotations.subscript("array", params)

    # -- construction
    def __init__(self, data=None, dtype: Any = Any, shape=None, strides=None, length=None,
                 ptr=None, capacity=None, device=None, pinned=False, copy=True, owner=False,
                 deleter=None, ndim=None, grad=None, requires_grad=False, retain_grad=False):
        if retain_grad and not requires_grad:
            raise ValueError("retain_grad=True requires requires_grad=True")
        self._retain_grad = bool(retain_grad)
        self._alloc = None
        self._info = None
        self._handle = 0
        self._byte_offset = 0
        self._grad = None
        self._requires_grad = bool(requires_grad)
        self.pinned = pinned
        dtype = _canonical_dtype(dtype)
        if ptr is not None:
            self._init_from_ptr(int(ptr), dtype, shape, strides, device)
            return
        if length is not None and shape is None:
            shape = (int(length),)

        if data is None and shape is None:
            # A null array, as used in annotations: wp.array(dtype=wp.vec3, ndim=2).
            self.dtype = dtype
            self.ndim = int(ndim) if ndim is not None else 1
            self.shape = (0,) * self.ndim
            self.strides = (0,) * self.ndim
            self.device = None
            self.size = 0
            return

        self.device = get_device(device)
        self.pinned = bool(pinned) and self.device.is_cpu     # Warp: CPU arrays only
        if data is not None and not isinstance(data, array) and _has_cuda_interface(data):
            self._init_from_cuda_interface(data, dtype, shape, requires_grad)
        elif data is None:
            if dtype is Any:
                dtype = float32
            self._init_new(dtype, _normalize_shape(shape), requires_grad)
        else:
            self._init_from_data(data, dtype, shape, requires_grad)
        if grad is not None:
            self.grad = grad

    def _init_from_cuda_interface(self, data, dtype, shape, requires_grad):
        """wp.array of a foreign GPU array (CuPy, Numba, Torch, ...): that memory, as Warp wraps
        it (weft.interop.cuda_import.array_from_interface); a CPU target is an error, as in
        Warp."""
        if not self.device.is_cuda:
            raise RuntimeError(f"Trying to construct a Warp array from data argument's "
                               f"__cuda_array_interface__ but {self.device} is not CUDA-capable")
        from .interop import cuda_import  # noqa: PLC0415

        out = cuda_import.array_from_interface(data, None if dtype is Any else dtype,
                                               self.device.alias, "wp.array")
        if shape is not None and tuple(_normalize_shape(shape)) != tuple(out.shape):
            out = out.reshape(_normalize_shape(shape))
        if requires_grad:
            out.requires_grad = True
        self.__dict__.update(out.__dict__)    # its allocation holds the framework's memory

    def _init_from_ptr(self, ptr, dtype, shape, strides, device):
        """wp.array(ptr=a.ptr + k, ...): a view of the weft allocation the address lies in (an
        address this process got from some array's .ptr); other memory cannot be wrapped."""
        if dtype is Any:
            dtype = float32
        shape = _normalize_shape(shape if shape is not None else (0,))
        elem = _elem_size(dtype)
        strides = (tuple(int(x) for x in strides) if strides is not None
                   else _contiguous_strides(shape, elem))
        if len(strides) != len(shape):
            raise RuntimeError(f"strides {strides} do not match shape {shape}")
        candidates = []
        for alloc in list(_ADDRESSED):
            base = alloc.mapping().address + alloc.info.shm_offset
            if base <= ptr < base + max(int(alloc.info.byte_size), 1):
                candidates.append((alloc, ptr - base))
        if not candidates:
            # GPU arrays: their addresses in this process's CUDA IPC mappings (see .ptr)
            for space in [s for s in list(_interop_memory._spaces) if s.startswith("cuda:")]:
                hit = _interop_memory.find(ptr, 0, space)
                if hit is not None:
                    candidates.append(hit)
        for alloc, offset in candidates[:1]:
            info = alloc.info
            lo = offset + sum((n - 1) * st for n, st in zip(shape, strides) if n > 0 and st < 0)
            hi = offset + sum((n - 1) * st for n, st in zip(shape, strides) if n > 0 and st > 0)
            if math.prod(shape) and (lo < 0 or hi + elem > info.byte_size):
                raise RuntimeError(f"wp.array(ptr=...): shape {shape} with strides {strides} "
                                   f"at byte {offset} exceeds the allocation it points into "
                                   f"({info.byte_size} bytes)")
            if device is not None and get_device(device).alias != info.device:
                raise RuntimeError(f"wp.array(ptr=...): the memory lives on {info.device}, not "
                                   f"on {get_device(device).alias}")
            self._alloc = alloc
            self._info = info
            self._handle = info.handle
            self._byte_offset = offset
            self.dtype = dtype
            self.shape = shape
            self.strides = strides
            self.ndim = len(shape)
            self.size = math.prod(shape)
            self.device = get_device(info.device)
            return
        raise RuntimeError("wp.array(ptr=...) can only wrap memory of weft arrays of this "
                           "process (an address from some array's .ptr): other memory does not "
                           "live in weftd; pass data= instead")

    def _init_new(self, dtype, shape, requires_grad, init=None, value=b""):
        ap = _runtime.array_pb2
        rt, info, grad_info = _create(dtype, shape, self.device, requires_grad,
                                      ap.CreateArrayRequest.EMPTY if init is None else init,
                                      value, pinned=self.pinned)
        self._adopt(rt, info, dtype, pooled=True, grad_info=grad_info)

    def _adopt(self, rt, info, dtype, owned=True, pooled=False, grad_info=None):
        """`pooled`: a new allocation of the daemon's for this process (counted as GPU pool use
        on a CUDA device, weft/mempool.py). `grad_info`: its gradient's description, which
        Create answered with (a.grad then needs no Describe)."""
        self._alloc = _Allocation(rt, info, owned)
        if grad_info is not None:
            _interop_memory._grad_infos[self._alloc] = grad_info
        if pooled and owned and self.device.is_cuda and info.byte_size:
            self._alloc.pool_bytes = int(info.byte_size)
            _mempool.note_allocated(info.device, self._alloc.pool_bytes)
        if pooled and owned and _memory_tracker.active():
            _memory_tracker.note_allocated(self._alloc, info, getattr(dtype, "__name__", str(dtype)),
                                           info.shape, pinned=bool(getattr(self, "pinned", False)))
        self._info = info
        self._handle = info.handle
        self._byte_offset = 0
        self.dtype = dtype
        self.shape = tuple(int(s) for s in info.shape)
        self.ndim = len(self.shape)
        self.strides = (tuple(int(s) for s in info.strides) if len(info.strides) == self.ndim
                        else _contiguous_strides(self.shape, _elem_size(dtype)))
        self.size = math.prod(self.shape)
        self._requires_grad = bool(info.grad_handle)

    def _init_from_data(self, data, dtype, shape, requires_grad):
        if isinstance(data, array):
            data = data.numpy()
        if dtype is Any:
            dtype = _infer_dtype(data)
        np_dtype, inner = _elem_layout(dtype)
        if np_dtype.fields is not None:
            data = _struct_numpy(dtype, data)
        try:
            arr = _to_bf16_bits(_bf16_source(data)) if _is_bf16(dtype) else \
                np.asarray(data, dtype=np_dtype)
        except (TypeError, ValueError) as err:
            raise RuntimeError(f"Failed to convert input data to an array of dtype "
                               f"{type_str(dtype)}: {err}") from None
        k = len(inner)
        length = int(np.prod(inner, dtype=np.int64))
        if k and not (arr.ndim >= k and tuple(arr.shape[arr.ndim - k:]) == inner):
            # Warp's rules for data whose inner dimensions are not the dtype's shape: trailing
            # dimensions of length 1 go, then an innermost dimension of the dtype's length, or a
            # multiple of it, holds the elements' components
            while arr.ndim > 1 and arr.shape[-1] == 1 and \
                    not (arr.ndim >= k and tuple(arr.shape[arr.ndim - k:]) == inner):
                arr = arr.reshape(arr.shape[:-1])
        if k and arr.ndim >= k and tuple(arr.shape[arr.ndim - k:]) == inner:
            arr_shape = tuple(arr.shape[:arr.ndim - k])
        elif k and arr.ndim >= 1 and arr.shape[-1] == length:
            arr_shape = tuple(arr.shape[:-1]) or (1,)
        elif k and arr.ndim >= 1 and arr.shape[-1] % length == 0 and arr.shape[-1] > 0:
            arr_shape = tuple(arr.shape[:-1]) + (arr.shape[-1] // length,)
        elif k and arr.ndim == 0 and length == 1:
            arr_shape = (1,)
        elif k and arr.size == 0 and arr.ndim == 1:
            arr_shape = (0,)                 # wp.array([], dtype=vec3): no elements
        elif k:
            raise RuntimeError(f"Failed to convert input data of shape {arr.shape} to an array "
                               f"of dtype {type_str(dtype)}: the innermost dimensions must be "
                               f"{inner}, or the innermost one a multiple of {length}")
        else:
            arr_shape = tuple(arr.shape)
        if not arr_shape:
            arr_shape = (1,)
        if shape is not None:
            shape = _normalize_shape(shape)
            if math.prod(shape) != math.prod(arr_shape):
                raise RuntimeError(f"Cannot reshape data of shape {arr_shape} into an array of "
                                   f"shape {shape}")
            arr_shape = shape
        arr_shape = _normalize_shape(arr_shape)
        arr = np.ascontiguousarray(arr)
        if arr.dtype.byteorder == ">":
            arr = arr.astype(arr.dtype.newbyteorder("<"))
        nbytes = arr.nbytes
        ap = _runtime.array_pb2
        rt = _runtime.get_runtime()
        local_direct = rt.local and (self.device.is_cpu or _cuda_ipc.available())
        if nbytes <= INLINE_DATA_MAX_BYTES and not (local_direct and
                                                    nbytes >= LOCAL_WRITE_MIN_BYTES):
            rt, info, grad_info = _create(dtype, arr_shape, self.device, requires_grad,
                                          ap.CreateArrayRequest.DATA, arr.tobytes(),
                                          pinned=self.pinned)
            self._adopt(rt, info, dtype, pooled=True, grad_info=grad_info)
        else:
            rt, info, grad_info = _create(dtype, arr_shape, self.device, requires_grad,
                                          ap.CreateArrayRequest.EMPTY, pinned=self.pinned)
            self._adopt(rt, info, dtype, pooled=True, grad_info=grad_info)
            _write_bytes(rt, info, 0, arr.reshape(-1).view(np.uint8), self._alloc)

    @classmethod
    def _from_info(cls, info, dtype=None, owned=True):
        out = cls.__new__(cls)
        out._grad = None
        out.pinned = False
        out.device = get_device(info.device)
        out._adopt(_runtime.get_runtime(), info, dtype if dtype is not None
                   else _dtype_from_proto(info.dtype), owned)
        return out

    # -- read flags (wp.config.verify_autograd_array_access, Warp's names)
    _is_read = False
    _view_of = None

    def mark_init(self):
        """Resets this array's read flag."""
        self._is_read = False

    def mark_read(self):
        """Marks this array, and the arrays it is a view of, as read by a recorded launch."""
        self._is_read = True
        parent = self._view_of
        while parent is not None:
            parent._is_read = True
            parent = parent._view_of

    def mark_write(self, **kwargs):
        """Warns (stderr) when this array is written after a recorded launch read it; kwargs
        name the writer: arg_name/kernel_name/filename/lineno, or operation/filename/lineno."""
        if not self._is_read:
            return
        from ._kernel.array_access import warn  # noqa: PLC0415
        tail = ("has already been read from in a previous launch. This may corrupt gradient "
                "computation in the backward pass.")
        if all(k in kwargs for k in ("arg_name", "kernel_name", "filename", "lineno")):
            warn(f"Array {self} passed to argument {kwargs['arg_name']} in kernel "
                 f"{kwargs['kernel_name']} at {kwargs['filename']}:{kwargs['lineno']} is being "
                 f"written to but {tail}")
        elif all(k in kwargs for k in ("operation", "filename", "lineno")):
            warn(f"Array {self} is being written to by {kwargs['operation']} at "
                 f"{kwargs['filename']}:{kwargs['lineno']} but {tail}")
        else:
            warn(f"Array {self} is being written to but {tail}")

    def _make_view(self, byte_offset, shape, strides, dtype=None):
        out = array.__new__(array)
        out._alloc = self._alloc
        out._info = self._info
        out._handle = self._handle
        out._byte_offset = int(byte_offset)
        out.dtype = self.dtype if dtype is None else dtype
        out.shape = tuple(int(s) for s in shape)
        out.strides = tuple(int(s) for s in strides)
        out.ndim = len(out.shape)
        out.size = int(np.prod(out.shape, dtype=np.int64))
        out.device = self.device
        out.pinned = self.pinned
        out._requires_grad = self._requires_grad
        out._retain_grad = self._retain_grad
        out._grad = None
        out._view_of = self
        out._base_dtype = self.dtype if self._base_dtype is None else self._base_dtype
        out._reinterpreted = type_str(out.dtype) != type_str(out._base_dtype)
        return out

    # Views: the dtype of the array they were taken from, and whether they read its bytes as
    # another type (array.view(dtype)).
    _base_dtype = None
    _reinterpreted = False

    # -- wire reference (used by commands and by weft._kernel)
    def _ref(self):
        ref = _runtime.types_pb2.ArrayRef(handle=self._handle, byte_offset=self._byte_offset,
                                          shape=list(self.shape), strides=list(self.strides))
        if self._retain_grad:
            ref.retain_grad = True
        if self._reinterpreted:
            # the allocation's bytes read as another dtype (array.view): weftd checks the view
            # with this element type
            ref.view_dtype.CopyFrom(_dtype_proto(self.dtype))
        return ref

    # -- properties
    _capacity = None   # bytes reachable through explicit allocation strides (wp.empty(strides=))

    @property
    def capacity(self) -> int:
        if self._capacity is not None:
            return self._capacity
        return int(self._info.byte_size) if self._info is not None else 0

    @property
    def is_contiguous(self) -> bool:
        expected = _contiguous_strides(self.shape, _elem_size(self.dtype))
        return all(s == e or n <= 1 for s, e, n in zip(self.strides, expected, self.shape))

    @property
    def ptr(self):
        """The address of the first element in this process: in the shared-memory slab for
        CPU arrays, in the CUDA IPC mapping of the slab for GPU arrays (local sessions where
        the client has a CUDA driver, see weft._cuda_ipc); None otherwise, and for an array
        without elements (as Warp)."""
        if self._info is None or self.size == 0:
            return None
        if self.device is not None and self.device.is_cuda:
            address = self._alloc.cuda_address()
            return None if address is None else address + self._byte_offset
        if not self._info.shm_name:
            return None
        if not self._alloc.runtime.local:
            return None
        mapping = self._alloc.mapping()
        _ADDRESSED.add(self._alloc)          # wp.array(ptr=...) can find it again
        return mapping.address + self._info.shm_offset + self._byte_offset

    def __ctype__(self) -> array_t:
        """Warp's ctypes descriptor of this array (array_t), referring back to it."""
        out = array_t(data=self.ptr or 0, ndim=self.ndim)
        grad = self.grad
        out.grad = (grad.ptr or 0) if grad is not None else 0
        for i, (n, s) in enumerate(zip(self.shape, self.strides)):
            out.shape[i], out.strides[i] = n, s
        out.flags = 1 if self._retain_grad else 0
        out._weft_value = self
        return out

    @property
    def requires_grad(self) -> bool:
        return self._requires_grad

    _retain_grad = False

    @property
    def retain_grad(self) -> bool:
        """Whether the gradient is kept through the adjoints of stores to this array instead of
        consumed (Warp's retain_grad; docs/autodiff.md, "Overwritten array elements")."""
        return self._retain_grad

    @retain_grad.setter
    def retain_grad(self, value: bool):
        value = bool(value)
        if value and not self._requires_grad:
            raise ValueError("retain_grad=True requires requires_grad=True")
        self._retain_grad = value

    @requires_grad.setter
    def requires_grad(self, value: bool):
        """True gives the array a zeroed gradient when it has none; False removes it. Both
        reach the daemon (its tape and adjoint launches use the array's gradient)."""
        value = bool(value)
        if value and self.grad is None and self._handle:
            self.grad = zeros(self.shape, dtype=self.dtype, device=self.device)
        elif not value and self._handle and self.grad is not None:
            self.grad = None
        self._requires_grad = value
        if not value:
            self._retain_grad = False

    @property
    def grad(self):
        if self._grad is not None:
            return self._grad
        if self._reinterpreted:
            return None   # a view as another dtype has no gradient (Warp's array.view)
        grad_handle = self._info.grad_handle if self._info is not None else 0
        if not grad_handle:
            return None
        rt = self._alloc.runtime
        ginfo = _interop_memory._grad_infos.get(self._alloc)
        if ginfo is None or ginfo.handle != grad_handle:
            ginfo = rt.array_call("Describe",
                                  _runtime.array_pb2.DescribeArrayRequest(handle=grad_handle)).info
            _interop_memory._grad_infos[self._alloc] = ginfo
        galloc = _Allocation(rt, ginfo, owned=False, parent=self._alloc)
        g = array.__new__(array)
        g._alloc = galloc
        g._info = ginfo
        g._handle = ginfo.handle
        g._byte_offset = self._byte_offset
        g.dtype = self.dtype
        g.shape = self.shape
        g.strides = self.strides
        g.ndim = self.ndim
        g.size = self.size
        g.device = self.device
        g.pinned = self.pinned
        g._requires_grad = False
        g._grad = None
        self._grad = g
        return g

    @grad.setter
    def grad(self, value):
        """`a.grad = g` (or None) as in Warp: g must match a's dtype, shape, device and strides.
        The daemon is told (a SetGradCommand queued in order with the launches), so tapes and
        adjoint launches write g from then on."""
        if value is not None:
            if not isinstance(value, array):
                raise TypeError("grad must be a weft array or None")
            if value.dtype is not self.dtype and type_str(value.dtype) != type_str(self.dtype):
                raise ValueError(f"The given gradient array is incompatible: expected dtype "
                                 f"{type_str(self.dtype)}, got {type_str(value.dtype)}")
            if value.shape != self.shape:
                raise ValueError(f"The given gradient array is incompatible: expected shape "
                                 f"{self.shape}, got {value.shape}")
            if value.device != self.device:
                raise ValueError(f"The given gradient array is incompatible: expected device "
                                 f"{self.device}, got {value.device}")
            if value.strides != self.strides:
                raise ValueError(f"The given gradient array is incompatible: expected strides "
                                 f"{self.strides}, got {value.strides}")
        if self._handle:
            self._set_daemon_grad(value)
        self._grad = value
        self._requires_grad = value is not None

    def _is_whole(self) -> bool:
        if self._info is None or self._byte_offset != 0:
            return False
        info_shape = self.__dict__.get("_info_shape")
        if info_shape is None or info_shape[0] is not self._info:
            info_shape = self._info_shape = (self._info, tuple(int(s) for s in self._info.shape))
        return self.shape == info_shape[1] and self.is_contiguous

    def _set_daemon_grad(self, value) -> None:
        """Tells the daemon when both are whole arrays (it keeps gradients per allocation); a
        view's gradient stays with this view object (explicit adjoint launches use it, the
        daemon's tape uses the allocation's)."""
        if value is not None and value._handle == self._handle:
            raise ValueError("an array cannot be its own gradient")
        if not self._is_whole() or (value is not None and not value._is_whole()):
            return
        rt = self._alloc.runtime
        ep = _runtime.exec_pb2
        grad_ref = value._ref() if value is not None else _runtime.types_pb2.ArrayRef(handle=0)
        rt.submit(ep.Command(set_grad=ep.SetGradCommand(array=self._ref(), grad=grad_ref)))
        self._info.grad_handle = value._handle if value is not None else 0
        self._alloc.recycle = None     # no longer what its import asked for: freed when it dies

    @property
    def vars(self):
        return {}

    def __len__(self):
        return self.shape[0]

    # -- indexing: views, never element access
    def __getitem__(self, key):
        if self._handle == 0 and self.size == 0 and self._info is None:
            raise RuntimeError("Cannot index a null array")
        if not isinstance(key, tuple):
            key = (key,)
        if any(k is Ellipsis for k in key):
            i = key.index(Ellipsis)
            fill = self.ndim - (len(key) - 1)
            key = key[:i] + (slice(None),) * fill + key[i + 1:]
        if len(key) > self.ndim:
            raise IndexError(f"Too many indices ({len(key)}) for an array with {self.ndim} "
                             f"dimension(s)")
        if any(isinstance(k, array) for k in key):
            # a[I], a[:, I], a[I, 1:3, I]: an indexed array over the slices of the others.
            from .indexedarray import indexedarray  # noqa: PLC0415

            if any(isinstance(k, (int, np.integer)) for k in key):
                raise TypeError("Index arrays cannot be combined with integer indices")
            indices = [k if isinstance(k, array) else None for k in key]
            view = self[tuple(slice(None) if isinstance(k, array) else k for k in key)]
            return indexedarray(view, indices + [None] * (self.ndim - len(indices)))
        offset = self._byte_offset
        shape, strides = [], []
        for dim, k in enumerate(key):
            n, s = self.shape[dim], self.strides[dim]
            if isinstance(k, slice):
                start, stop, step = k.indices(n)
                if step <= 0:
                    raise IndexError("Array slices must have a positive step")
                count = max(0, (stop - start + step - 1) // step)
                if count:
                    offset += start * s
                shape.append(count)
                strides.append(s * step)
            elif isinstance(k, (int, np.integer)):
                i = int(k)
                if i < -n or i >= n:
                    raise IndexError(f"Index {i} is out of bounds for dimension {dim} with "
                                     f"size {n}")
                offset += (i + n if i < 0 else i) * s
            else:
                raise TypeError(f"Invalid array index {k!r}: expected an int or a slice")
        shape += self.shape[len(key):]
        strides += self.strides[len(key):]
        if not shape:
            raise RuntimeError("Item indexing is not supported on wp.array objects in Python "
                               "scope; use a.numpy()[i] or a slice such as a[i:i+1]")
        view = self._make_view(offset, shape, strides)
        if self._grad is not None or (self._info is not None and self._info.grad_handle):
            parent_grad = self.grad
            if parent_grad is not None and parent_grad._handle:
                delta = offset - self._byte_offset
                view._grad = parent_grad._make_view(parent_grad._byte_offset + delta, shape,
                                                    strides)
        return view

    def __setitem__(self, key, value):
        raise TypeError("Item assignment is not supported on wp.array objects in Python scope; "
                        "use a.assign(values), a.fill_(value), a[i:j].fill_(value) or, for CPU "
                        "arrays, write through a.numpy()")

    # -- data access
    def _span(self):
        """(first byte offset, byte count) covering every element of this view."""
        elem = _elem_size(self.dtype)
        if self.size == 0:
            return self._byte_offset, 0
        low = self._byte_offset + sum(min(0, (n - 1) * s) for n, s in zip(self.shape, self.strides))
        high = self._byte_offset + sum(max(0, (n - 1) * s) for n, s in zip(self.shape, self.strides))
        return low, high - low + elem

    def numpy(self) -> np.ndarray:
        """The array as NumPy: a zero-copy view of shared memory for CPU arrays of local
        sessions (writes through it are seen by the daemon), else a copy. bfloat16 arrays
        come as ml_dtypes.bfloat16 when that package is installed, else as their uint16 bits
        (as Warp's)."""
        values = self._numpy_storage()
        if _is_bf16(self.dtype):
            bf16 = _ml_bfloat16()
            return values.view(bf16) if bf16 is not None else values
        return values

    def _numpy_storage(self) -> np.ndarray:
        np_dtype, inner = _elem_layout(self.dtype)
        full_shape = tuple(self.shape) + inner
        if self._info is None:
            return np.empty(full_shape, dtype=np_dtype)
        rt = self._alloc.runtime
        rt.synchronize_if_needed()
        full_strides = tuple(self.strides) + _inner_strides(np_dtype, inner)
        if _is_local_cpu(rt, self._info):
            if self.size == 0:
                return np.empty(full_shape, dtype=np_dtype)
            mapping = self._alloc.mapping()
            address = mapping.address + self._info.shm_offset + self._byte_offset
            interface = {"data": (address, False), "shape": full_shape,
                         "strides": full_strides, "typestr": np_dtype.str, "version": 3}
            if np_dtype.fields is not None:
                interface["descr"] = np_dtype.descr
            return np.asarray(_NumpyHolder(interface, (self._alloc, mapping)))
        low, count = self._span()
        raw = _read_bytes(rt, self._info, low, count, self._alloc)
        if self.size == 0:
            return np.empty(full_shape, dtype=np_dtype)
        typed = np.ndarray(full_shape, dtype=np_dtype, buffer=raw,
                           offset=self._byte_offset - low, strides=full_strides)
        return typed if typed.flags.c_contiguous else np.ascontiguousarray(typed)

    def list(self):
        """The elements as a flat Python list (scalars, or dtype instances for vectors etc.)."""
        values = self.numpy()
        if _is_struct(self.dtype):
            return [self.dtype.from_record(r) for r in values.reshape(-1)]
        if types.is_dtype(self.dtype) and self.dtype._shape_:
            flat = values.reshape((-1,) + tuple(self.dtype._shape_))
            return [self.dtype(v) for v in flat]
        return values.reshape(-1).tolist()

    def __array__(self, dtype=None, copy=None):
        values = self.numpy()
        return values if dtype is None else values.astype(dtype)

    @property
    def __array_interface__(self):
        if (self._info is None or not self._info.shm_name or not self._alloc.runtime.local):
            raise AttributeError("__array_interface__ is only available for CPU arrays of "
                                 "local (Unix-socket) sessions; use .numpy()")
        return self.numpy().__array_interface__

    @property
    def __cuda_array_interface__(self):
        """CUDA Array Interface v3 of a GPU array, over this process's IPC mapping of the
        daemon's memory (zero-copy). Where the session orders work with interprocess events
        (weft.interop.cuda_order), "stream" is a stream of this process that stands for
        weft's session stream: it (and the framework's current stream) waits on the GPU for
        weft's queued work, and a consumer orders its stream after it (the protocol's rule).
        Elsewhere weft's queued work is finished first and "stream" is None. Absent
        (AttributeError) where IPC is not available: consumers then fall back to __array__,
        a copy."""
        if self._info is None or self.device is None or not self.device.is_cuda:
            raise AttributeError("__cuda_array_interface__ is only available for GPU arrays")
        ptr = self.ptr
        if ptr is None:
            raise AttributeError(f"__cuda_array_interface__: no CUDA IPC mapping in this client "
                                 f"({_cuda_ipc.reason() or 'not a local session'}); use "
                                 f".numpy() for a copy")
        from .interop import cuda_order  # noqa: PLC0415

        proxy = None
        if cuda_order.enabled(self._alloc.runtime, {int(self.device.ordinal)}):
            proxy = _cuda_ipc.proxy_stream(int(self.device.ordinal))
            # the proxy stream and the framework stream wait for weft's queued work on the GPU
            cuda_order.ready(self, [proxy, cuda_order.framework_stream(int(self.device.ordinal))])
        else:
            self._alloc.runtime.synchronize_if_needed()
        _interop_memory.mark_shared(self._alloc)
        np_dtype, inner = _elem_layout(self.dtype)
        if np_dtype.fields is not None:
            raise AttributeError("__cuda_array_interface__ cannot describe struct elements")
        shape = tuple(self.shape) + tuple(inner)
        strides = tuple(self.strides) + _inner_strides(np_dtype, inner)
        contiguous = strides == _contiguous_strides(shape, np_dtype.itemsize)
        return {"shape": shape, "typestr": np_dtype.str, "descr": [("", np_dtype.str)],
                "data": (ptr if self.size else 0, False),
                "strides": None if contiguous else strides, "version": 3, "stream": proxy}

    @property
    def __dlpack__(self):
        """A DLPack capsule over this array's memory (weft.interop.dlpack.export). Absent
        (AttributeError) for GPU arrays this process has no CUDA IPC mapping of, so consumers
        (torch.as_tensor, cupy.asarray) fall back to __array__, a copy."""
        if (self.device is not None and self.device.is_cuda and self._info is not None
                and self.ptr is None):
            raise AttributeError(f"__dlpack__: no CUDA IPC mapping of this {self.device} array "
                                 f"in this client ({_cuda_ipc.reason() or 'not a local session'})"
                                 f"; use .numpy() for a copy")
        return self._dlpack

    def _dlpack(self, stream=None, max_version=None, dl_device=None, copy=None):
        from .interop import dlpack  # noqa: PLC0415

        return dlpack.export(self, stream=stream, max_version=max_version,
                             dl_device=dl_device, copy=copy)

    def __dlpack_device__(self):
        """(DLPack device type, ordinal): (1, 0) for the CPU, (2, N) for cuda:N."""
        from .interop import dlpack  # noqa: PLC0415

        return dlpack.dlpack_device(self)

    def __str__(self):
        if self._info is None:
            return f"array(null, dtype={getattr(self.dtype, '__name__', self.dtype)})"
        return str(self.numpy())

    def __repr__(self):
        if self._info is None:
            return f"array(null, dtype={getattr(self.dtype, '__name__', self.dtype)})"
        return (f"array({self.numpy()!r}, dtype={getattr(self.dtype, '__name__', self.dtype)}, "
                f"device={self.device})")

    # -- writes
    def fill_(self, value):
        """Sets every element to `value` (a scalar broadcasts over vector/matrix elements)."""
        if self.size == 0 or self._info is None:
            return self
        cmd = _runtime.exec_pb2.Command(fill=_runtime.exec_pb2.FillCommand(
            dst=self._ref(), value=types.value_to_bytes(self.dtype, value)
            if types.is_dtype(self.dtype) else _struct_bytes(self.dtype, value)))
        self._alloc.runtime.submit(cmd)
        return self

    def zero_(self):
        """Sets every element to zero."""
        if self.size == 0 or self._info is None:
            return self
        cmd = _runtime.exec_pb2.Command(fill=_runtime.exec_pb2.FillCommand(
            dst=self._ref(), value=bytes(_elem_size(self.dtype))))
        self._alloc.runtime.submit(cmd)
        return self

    def assign(self, src):
        """Copies `src` (a weft array, NumPy array, list, scalar) into this array."""
        if isinstance(src, array):
            copy(self, src)
            return self
        np_dtype, inner = _elem_layout(self.dtype)
        values = _to_bf16_bits(_bf16_source(src)) if _is_bf16(self.dtype) else \
            np.asarray(src, dtype=np_dtype)
        target_shape = tuple(self.shape) + inner
        if values.shape != target_shape:
            if values.size == math.prod(target_shape):
                values = values.reshape(target_shape)
            else:
                try:
                    values = np.broadcast_to(values, target_shape)
                except ValueError:
                    raise RuntimeError(f"Cannot assign data of shape {values.shape} to an array "
                                       f"of shape {self.shape} and dtype "
                                       f"{type_str(self.dtype)}") from None
        if self.size == 0:
            return self
        rt = self._alloc.runtime
        if self.is_contiguous:
            rt.synchronize_if_needed()
            payload = np.ascontiguousarray(values, dtype=np_dtype).reshape(-1).view(np.uint8)
            _write_bytes(rt, self._info, self._byte_offset, payload, self._alloc)
        else:
            tmp = array(values, dtype=self.dtype, shape=self.shape, device=self.device)
            copy(self, tmp)
        return self

    # -- shape changes (views)
    def reshape(self, shape):
        if isinstance(shape, (int, np.integer)):
            shape = (int(shape),)
        shape = list(int(s) for s in shape)
        if shape.count(-1) > 1:
            raise RuntimeError("Only one dimension of a reshape may be -1")
        if -1 in shape:
            known = math.prod(s for s in shape if s != -1)
            if known == 0 or self.size % known:
                raise RuntimeError(f"Cannot reshape array of shape {self.shape} into "
                                   f"{tuple(shape)}")
            shape[shape.index(-1)] = self.size // known
        shape = _normalize_shape(shape)
        if math.prod(shape) != self.size:
            raise RuntimeError(f"cannot reshape array of shape {self.shape} (size {self.size}) into "
                               f"shape {shape} (size {math.prod(shape)})")
        if not self.is_contiguous:
            raise RuntimeError("Reshaping non-contiguous arrays is unsupported")
        view = self._make_view(self._byte_offset, shape,
                               _contiguous_strides(shape, _elem_size(self.dtype)))
        if self._grad is not None:
            view._grad = self._grad.reshape(shape)
        return view

    def flatten(self):
        return self.reshape(-1)

    def view(self, dtype):
        """The same memory seen as `dtype` (Warp's rules): of the same element size, the same
        shape and strides; a vector/matrix array seen as its scalar gains the element's
        dimensions; a scalar array whose trailing dimensions are a contiguous vector/matrix
        seen as that type loses them (a single element gives shape (1,))."""
        dtype = _canonical_dtype(dtype)
        size, own = _elem_size(dtype), _elem_size(self.dtype)
        src_scalar = getattr(self.dtype, "_wp_scalar_type_", None)
        dst_scalar = getattr(dtype, "_wp_scalar_type_", None)
        src_composite = isinstance(self.dtype, type) and issubclass(self.dtype, _Composite)
        dst_composite = isinstance(dtype, type) and issubclass(dtype, _Composite)
        what = (f"cannot create an array view with dtype {types.type_repr(dtype)} from source "
                f"dtype {types.type_repr(self.dtype)}")
        if size == own:
            shape, strides = self.shape, self.strides
        elif src_composite and isinstance(dtype, type) and issubclass(dtype, _Scalar):
            scalar_size = _elem_size(src_scalar)
            if size != scalar_size:
                raise TypeError(f"{what}: source scalar dtype {types.type_repr(src_scalar)} has "
                                f"size {scalar_size} bytes, but target dtype has size {size} "
                                f"bytes")
            inner = tuple(self.dtype._shape_)
            shape = (*self.shape, *inner)
            strides = (*self.strides, *_contiguous_strides(inner, scalar_size))
        elif dst_composite and isinstance(self.dtype, type) and issubclass(self.dtype, _Scalar):
            scalar_size = _elem_size(dst_scalar)
            if own != scalar_size:
                raise TypeError(f"{what}: source dtype has size {own} bytes, but target scalar "
                                f"dtype {types.type_repr(dst_scalar)} has size {scalar_size} "
                                f"bytes")
            inner = tuple(dtype._shape_)
            k = len(inner)
            if self.ndim < k or tuple(self.shape[-k:]) != inner:
                raise RuntimeError(f"The shape of the source array {tuple(self.shape)} is not "
                                   f"compatible with the requested data type "
                                   f"{types.type_repr(dtype)}")
            if tuple(self.strides[-k:]) != _contiguous_strides(inner, scalar_size):
                raise RuntimeError(f"The inner strides of the source array "
                                   f"{tuple(self.strides)} are not compatible with the "
                                   f"requested data type {types.type_repr(dtype)}")
            shape = tuple(self.shape[:-k]) or (1,)
            strides = tuple(self.strides[:-k]) or (size,)
        else:
            raise TypeError(f"{what}: source dtype has size {own} bytes, but target dtype has "
                            f"size {size} bytes")
        out = self._make_view(self._byte_offset, shape, strides, dtype)
        if out._reinterpreted:
            out._requires_grad = False   # as Warp's: the view has no gradient
        return out

    def transpose(self, axes=None):
        if axes is None:
            axes = tuple(reversed(range(self.ndim)))
        if sorted(axes) != list(range(self.ndim)):
            raise RuntimeError(f"Invalid transpose axes {axes} for {self.ndim} dimensions")
        return self._make_view(self._byte_offset, [self.shape[a] for a in axes],
                               [self.strides[a] for a in axes])

    def contiguous(self):
        return self if self.is_contiguous else clone(self)

    def to(self, device, requires_grad=None):
        device = get_device(device)
        if device == self.device:
            return self
        return clone(self, device=device, requires_grad=requires_grad)

    # -- sharing between client processes
    def ipc_handle(self) -> bytes:
        """An opaque token another local client of the same daemon passes to
        wp.from_ipc_handle to open this allocation."""
        if self._info is None:
            raise RuntimeError("A null array has no IPC handle")
        rt = self._alloc.runtime
        rt.flush()
        token = rt.call(rt.array_stub.Export,
                        _runtime.array_pb2.ExportArrayRequest(handle=self._handle)).token
        # The first export moves an array that shared a slab into a slab of its own (an
        # importer maps the exported bytes and nothing else): views made from now on use the
        # new place. The info object is shared by every view of this allocation.
        ap = _runtime.array_pb2
        _follow_moved_bytes(self, rt, ap)
        grad = self._grad
        if grad is not None and getattr(grad, "_alloc", None) is not None and grad._handle:
            _follow_moved_bytes(grad, rt, ap)
        return token.encode()


def _struct_bytes(dtype, value) -> bytes:
    if callable(getattr(dtype, "numpy_dtype", None)) and not isinstance(value, (bytes, bytearray)):
        return np.asarray(_struct_numpy(dtype, value)).tobytes()
    if isinstance(value, (bytes, bytearray)) and len(value) == _elem_size(dtype):
        return bytes(value)
    raise TypeError(f"Cannot fill an array of {type_str(dtype)} with {value!r}")


class _ArrayOfDim:
    """wp.array1d..array4d: call like wp.array with that ndim, or subscript for annotations
    (wp.array2d[float] is the annotation wp.array[float, Literal[2]], weft.array_annotations)."""

    def __init__(self, ndim: int):
        self._default_ndim_ = ndim
        self.ndim = ndim
        self.__name__ = self.__qualname__ = f"array{ndim}d"
        self.__doc__ = f"An array with {ndim} dimension(s): wp.array(..., ndim={ndim})."

    def __call__(self, *args, **kwargs):
        kwargs["ndim"] = self._default_ndim_
        return array(*args, **kwargs)

    def __getitem__(self, params):
        return _array_annotations.subscript_fixed_ndim("array", self.__name__, self.ndim, params)

    def __repr__(self):
        return f"<weft {self.__name__}>"


array1d = _ArrayOfDim(1)
array2d = _ArrayOfDim(2)
array3d = _ArrayOfDim(3)
array4d = _ArrayOfDim(4)


# ------------------------------------------------------------------------------------------
# Creation functions


def _new_array(shape, dtype, device, requires_grad, init, value=b"", pinned=False):
    out = array.__new__(array)
    out._grad = None
    out.device = get_device(device)
    out.pinned = bool(pinned) and out.device.is_cpu
    dtype = _canonical_dtype(dtype)
    if dtype is Any:
        dtype = float32
    out._init_new(dtype, _normalize_shape(shape), requires_grad, init, value)
    rt = _runtime.get_runtime()
    if rt.captures and init != _runtime.array_pb2.CreateArrayRequest.EMPTY:
        _refill_in_capture(rt, out, init, value)
    return out


def _refill_in_capture(rt, out, init, value) -> None:
    """A zeros/full array made while this thread captures a graph on its device: the graph
    also sets its value (and zeroes its gradient), as Warp's captured memset does."""
    from .graph import is_capturing  # noqa: PLC0415

    if out.size == 0 or not is_capturing(out.device):
        return
    if init == _runtime.array_pb2.CreateArrayRequest.ZEROS:
        out.zero_()
    else:
        rt.submit(_runtime.exec_pb2.Command(fill=_runtime.exec_pb2.FillCommand(
            dst=out._ref(), value=value)))
    if out.grad is not None:
        out.grad.zero_()


def _legacy_length(shape, n):
    """Warp's legacy `n=length` keyword of the array factories: shape (n,)."""
    return shape if n is None else (n,)


def _with_retain(out, retain_grad):
    if retain_grad:
        out.retain_grad = True          # ValueError without requires_grad, as Warp
    return out


def empty(shape=0, dtype=float, device=None, requires_grad=False, pinned=False, *, n=None,
          retain_grad=False, strides=None):
    """An uninitialised array (Warp's wp.empty); `strides` (bytes, >= 0) lays it out in a
    buffer of exactly the bytes those strides reach."""
    shape = _legacy_length(shape, n)
    if strides is not None:
        return _with_retain(_strided_new(shape, dtype, device, requires_grad, strides,
                                         _runtime.array_pb2.CreateArrayRequest.EMPTY, pinned),
                            retain_grad)
    return _with_retain(_new_array(shape, dtype, device, requires_grad,
                                   _runtime.array_pb2.CreateArrayRequest.EMPTY, pinned=pinned),
                        retain_grad)


def zeros(shape=0, dtype=float, device=None, requires_grad=False, pinned=False, *, n=None,
          retain_grad=False, strides=None):
    """An array of zeros (Warp's wp.zeros); `strides` as wp.empty's."""
    shape = _legacy_length(shape, n)
    if strides is not None:
        return _with_retain(_strided_new(shape, dtype, device, requires_grad, strides,
                                         _runtime.array_pb2.CreateArrayRequest.ZEROS, pinned),
                            retain_grad)
    return _with_retain(_new_array(shape, dtype, device, requires_grad,
                                   _runtime.array_pb2.CreateArrayRequest.ZEROS, pinned=pinned),
                        retain_grad)


def _strided_new(shape, dtype, device, requires_grad, strides, init, pinned=False):
    """An array of `shape` with byte `strides` over a new 1-d buffer of the reached bytes
    (rounded up to whole elements): Warp's allocation with explicit strides."""
    shape = _normalize_shape(shape)
    strides = tuple(int(s) for s in strides)
    if len(strides) != len(shape):
        raise ValueError(f"Invalid number of strides, expected {len(shape)} strides, got {len(strides)}")
    if any(s < 0 for s in strides):
        raise NotImplementedError("Negative strides are not supported")
    dtype = _canonical_dtype(dtype)
    item = _elem_size(dtype)
    align = _elem_layout(dtype)[0].itemsize   # the scalar (struct elements: byte) alignment
    if any(s % align for s in strides):
        raise ValueError(f"strides {strides} are not multiples of the {type_str(dtype)} alignment ({align} bytes)")
    reached = 0 if any(d == 0 for d in shape) else item + sum((d - 1) * s for d, s in zip(shape, strides))
    base = _new_array((-(-reached // item),), dtype, device, requires_grad, init, pinned=pinned)
    out = base._make_view(0, shape, strides)
    out._capacity = reached
    return out


def _infer_value_dtype(value):
    """wp.full's dtype for a value, as Warp infers it: int -> int32, float -> float32, bool,
    weft scalars/vectors/matrices/structs -> their type, a sequence -> a vector (1-d) or matrix
    (2-d) of the scalar type NumPy gives it (Python floats: float64, ints: int64)."""
    if isinstance(value, (_Composite, _Scalar)):
        return type(value)
    if isinstance(value, bool):
        return types.bool
    if isinstance(value, int):
        return int32
    if isinstance(value, float):
        return float32
    struct_type = getattr(value, "_struct_type", None)
    if struct_type is not None:
        return struct_type
    if isinstance(value, np.generic):
        return dtype_from_numpy(value.dtype)
    if not hasattr(value, "__len__"):
        raise ValueError(f"Invalid value type for Warp array: {type(value)}")
    try:
        values = np.asarray(value)
    except Exception as err:  # noqa: BLE001 - NumPy's own conversion errors
        raise ValueError(f"Failed to interpret the value as a vector or matrix: {err}") from err
    try:
        scalar = dtype_from_numpy(values.dtype)
    except TypeError:
        raise ValueError(f"Failed to convert {values.dtype} to a Warp data type") from None
    if values.ndim == 1:
        return vector(values.shape[0], scalar)
    if values.ndim == 2:
        return matrix(values.shape, scalar)
    raise ValueError("Values with more than two dimensions are not supported")


def full(shape=0, value=0, dtype=None, device=None, requires_grad=False, pinned=False, *, n=None,
         retain_grad=False):
    """An array with every element set to `value` (Warp's wp.full); dtype None infers it."""
    shape = _legacy_length(shape, n)
    dtype = _canonical_dtype(Any if dtype is None else dtype)
    if dtype is Any:
        dtype = _infer_value_dtype(value)
    payload = (types.value_to_bytes(dtype, value) if types.is_dtype(dtype)
               else _struct_bytes(dtype, value))
    return _with_retain(_new_array(shape, dtype, device, requires_grad,
                                   _runtime.array_pb2.CreateArrayRequest.FILL, payload,
                                   pinned=pinned),
                        retain_grad)


def ones(shape=0, dtype=float, device=None, requires_grad=False, pinned=False, *, n=None,
         retain_grad=False):
    """An array of ones (Warp's wp.ones)."""
    return full(_legacy_length(shape, n), 1, dtype, device, requires_grad, pinned,
                retain_grad=retain_grad)


def _like_grad(src, requires_grad):
    return src.requires_grad if requires_grad is None else requires_grad


def _like_pinned(src, pinned):
    """Warp's rule for *_like and clone: pinned None takes the source's."""
    return bool(getattr(src, "pinned", False)) if pinned is None else bool(pinned)


def empty_like(src, device=None, requires_grad=None, pinned=None, retain_grad=False):
    return empty(src.shape, src.dtype, device if device is not None else src.device,
                 _like_grad(src, requires_grad), _like_pinned(src, pinned), retain_grad=retain_grad)


def zeros_like(src, device=None, requires_grad=None, pinned=None, retain_grad=False):
    return zeros(src.shape, src.dtype, device if device is not None else src.device,
                 _like_grad(src, requires_grad), _like_pinned(src, pinned), retain_grad=retain_grad)


def ones_like(src, device=None, requires_grad=None, pinned=None, retain_grad=False):
    return ones(src.shape, src.dtype, device if device is not None else src.device,
                _like_grad(src, requires_grad), _like_pinned(src, pinned), retain_grad=retain_grad)


def full_like(src, value, device=None, requires_grad=None, pinned=None, retain_grad=False):
    return full(src.shape, value, src.dtype, device if device is not None else src.device,
                _like_grad(src, requires_grad), _like_pinned(src, pinned), retain_grad=retain_grad)


def from_numpy(arr, dtype=None, shape=None, device=None, requires_grad=False):
    """An array with a copy of NumPy data; without dtype, trailing dimensions of 2-4 become
    vectors (and square 2x2..4x4 of a 3+-d array matrices), as Warp does."""
    arr = np.asarray(arr)
    if dtype is None:
        base = dtype_from_numpy(arr.dtype)
        if arr.ndim >= 3 and arr.shape[-2:] in ((2, 2), (3, 3), (4, 4)):
            dtype = matrix(arr.shape[-2:], base)
        elif arr.ndim >= 2 and arr.shape[-1] in (2, 3, 4):
            dtype = vector(arr.shape[-1], base)
        else:
            dtype = base
    return array(arr, dtype=dtype, shape=shape, device=device, requires_grad=requires_grad)


def clone(src, device=None, requires_grad=None, pinned=None):
    """A new array with a copy of `src` (on `device`, default src's)."""
    from .indexedarray import indexedarray  # noqa: PLC0415

    if isinstance(src, indexedarray):
        return array(src.numpy(), dtype=src.dtype, shape=src.shape,
                     device=device if device is not None else src.device,
                     requires_grad=bool(requires_grad))
    dest = empty(src.shape, src.dtype, device if device is not None else src.device,
                 _like_grad(src, requires_grad), _like_pinned(src, pinned))
    copy(dest, src)
    return dest


def _flat_view(a, offset, count):
    """Elements [offset, offset+count) of a contiguous array, or of a strided 1-d array."""
    if a.ndim == 1:
        step = a.strides[0]
        return a._make_view(a._byte_offset + offset * step, (count,), (step,))
    elem = _elem_size(a.dtype)
    return a._make_view(a._byte_offset + offset * elem, (count,), (elem,))


def _on_tape(dest, src) -> bool:
    """Whether a copy must be recorded on the active wp.Tape (a differentiable float copy)."""
    if not (dest.requires_grad or src.requires_grad):
        return False
    from ._kernel.tape import active_tape  # noqa: PLC0415 - weft._kernel imports this module

    if active_tape() is None:
        return False
    scalar = getattr(dest.dtype, "_wp_scalar_type_", dest.dtype)
    return scalar in types.float_types


def _check_copy_types(dest, src, by_value=False) -> None:
    """Warp's rule: a copy moves bytes, between any two dtypes of one element size; a copy by
    value (indexed arrays) needs one dtype."""
    if by_value:
        differ = type_str(src.dtype) != type_str(dest.dtype)
    else:
        differ = _elem_size(src.dtype) != _elem_size(dest.dtype)
    if differ:
        raise RuntimeError(f"Incompatible array data types: destination dtype={types.type_repr(dest.dtype)}, "
                           f"source dtype={types.type_repr(src.dtype)}")


def copy(dest, src, dest_offset=0, src_offset=0, count=0, stream=None):
    """Copies `src` into `dest` (Warp's wp.copy). Offsets and count are in elements of the
    flattened arrays, which must then be contiguous; count 0 copies all of src. `stream`, a
    wp.Stream of one of the arrays' devices, orders the copy as any stream of that device does
    for a weft client: on the session's stream, after the work issued before it."""
    from .indexedarray import indexedarray  # noqa: PLC0415

    if stream is not None:
        from .streams import Stream  # noqa: PLC0415
        if not isinstance(stream, Stream):
            raise TypeError(f"wp.copy(): stream must be a wp.Stream, got {type(stream).__name__}")
        devices = {getattr(a, "device", None) for a in (dest, src)}
        if stream.device not in devices:
            raise RuntimeError(f"wp.copy(): the stream is on {stream.device}, the arrays on "
                               f"{', '.join(sorted(str(d) for d in devices))}")

    if isinstance(dest, indexedarray) or isinstance(src, indexedarray):
        if dest_offset or src_offset or count:
            raise RuntimeError("dest_offset, src_offset, and count are not supported when copying to/from "
                               "non-contiguous indexed or Fabric arrays")
        _check_copy_types(dest, src, by_value=True)
        if tuple(src.shape) != tuple(dest.shape):
            raise RuntimeError(f"Incompatible array shapes: destination shape={tuple(dest.shape)}, "
                               f"source shape={tuple(src.shape)}")
        if src.size:
            dest.assign(src.numpy() if isinstance(src, indexedarray) else src)
        return
    if not isinstance(dest, array) or not isinstance(src, array):
        raise RuntimeError("Copy source and destination must be arrays")
    _check_copy_types(dest, src)
    for value, name in ((src_offset, "Source offset"), (dest_offset, "Destination offset"),
                        (count, "Copy count")):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise RuntimeError(f"wp.copy(): offsets and count must be integers, got {name.lower()} "
                               f"{value!r}")
        if value < 0:
            raise RuntimeError(f"wp.copy(): {name} must be non-negative, got {value}")
    whole = count == 0 and dest_offset == 0 and src_offset == 0
    if whole and src.shape == dest.shape:
        d, s = dest, src
    else:
        strided = [a for a in (src, dest) if a.ndim > 1 and not a.is_contiguous]
        if strided and whole:
            raise RuntimeError(f"Incompatible array shapes: destination shape={tuple(dest.shape)}, "
                               f"source shape={tuple(src.shape)}")
        if strided:
            raise RuntimeError("dest_offset, src_offset, and count are only supported for 1-D "
                               "non-contiguous arrays")
        if count == 0:
            count = src.size - src_offset
        if src_offset + count > src.size:
            raise RuntimeError(f"Trying to copy a range of {count} element(s) from source offset "
                               f"({src_offset}) exceeds the source size ({src.size})")
        if dest_offset + count > dest.size:
            raise RuntimeError(f"Trying to copy a range of {count} element(s) to destination offset "
                               f"({dest_offset}) exceeds the destination size ({dest.size})")
        d = _flat_view(dest, dest_offset, count)
        s = _flat_view(src, src_offset, count)
    if d.size == 0 or d._info is None or s._info is None:
        return
    tape = _overwrite_adjoint_tape(d, s)
    if tape is not None:
        _submit_copy(d, s)
        reason = _overwrite_reason(d, s)
        tape.record_func(backward=lambda: _adj_copy_overwrite(d, s, reason), arrays=[dest, src])
        return
    if d.device == s.device and _on_tape(d, s) and type_str(d.dtype) == type_str(s.dtype):
        from ._kernel.copy_kernels import launch_copy  # noqa: PLC0415

        if _config.verify_autograd_array_access:
            from ._kernel.array_access import caller_location  # noqa: PLC0415
            if dest._is_read:
                filename, lineno = caller_location()
                dest.mark_write(operation="an array copy", filename=filename, lineno=lineno)
            src.mark_read()
        launch_copy(d, s)
        return
    _submit_copy(d, s)


def _submit_copy(d, s) -> None:
    cmd = _runtime.exec_pb2.Command(copy=_runtime.exec_pb2.CopyCommand(dst=d._ref(),
                                                                        src=s._ref()))
    d._alloc.runtime.submit(cmd)


# Copies on a tape whose gradient cannot be accumulated (Warp's "byte-copy adjoint"): gradients
# of types without addition (structs, bool), of different types, or of windows whose bytes may
# overlap. The backward pass overwrites the source window's gradient with the destination
# window's and leaves the destination's, with Warp's warning (once per reason).
_WARNED_COPY_REASONS: set = set()


def _gradient_addable(d, s) -> bool:
    scalar = getattr(d.dtype, "_wp_scalar_type_", None)
    return (scalar is not None and scalar is not types.bool
            and type_str(d.dtype) == type_str(s.dtype))


def _may_overlap(d, s) -> bool:
    """Warp's conservative test: any non-positive stride, or byte extents of one allocation
    that intersect."""
    if not all(st > 0 for a in (d, s) for st in a.strides):
        return True
    if d._handle != s._handle:
        return False

    def extent(a):
        last = sum((n - 1) * st for n, st in zip(a.shape, a.strides))
        return a._byte_offset, a._byte_offset + last + _elem_size(a.dtype)

    (d_lo, d_hi), (s_lo, s_hi) = extent(d), extent(s)
    return d_lo < s_hi and s_lo < d_hi


def _overwrite_adjoint_tape(d, s):
    """The active tape when the copy d <- s needs the overwrite adjoint (both have gradients,
    same device, and the gradients cannot be accumulated); else None."""
    if d.device != s.device or not (d.requires_grad and s.requires_grad):
        return None
    from ._kernel.tape import active_tape  # noqa: PLC0415 - weft._kernel imports this module

    tape = active_tape()
    if tape is None or (_gradient_addable(d, s) and not _may_overlap(d, s)):
        return None
    if d.grad is None or s.grad is None:
        return None
    return tape


def _overwrite_reason(d, s) -> str:
    if not _gradient_addable(d, s):
        return "copy between unsupported gradient dtypes"
    if not (d.is_contiguous and s.is_contiguous):
        return "non-contiguous copy"
    return "overlapping copy"


def _adj_copy_overwrite(d, s, reason: str) -> None:
    if reason not in _WARNED_COPY_REASONS:
        _WARNED_COPY_REASONS.add(reason)
        warnings.warn(f"A tape-recorded wp.copy() encountered a copy pattern whose gradients "
                      f"cannot yet be fully tracked ({reason}). The backward pass may overwrite "
                      f"existing source gradients or fail to clear gradients from overwritten "
                      f"destination values.", UserWarning, stacklevel=4)
    _submit_copy(s.grad, d.grad)


def from_ipc_handle(handle, dtype=None, shape=None, strides=None, device=None):
    """Opens an array another client shared with `a.ipc_handle()` (same daemon, same
    credentials). dtype/shape/strides (bytes) default to the exporter's."""
    token = handle.decode() if isinstance(handle, (bytes, bytearray)) else str(handle)
    rt = _runtime.get_runtime()
    rt.drain_frees()
    info = rt.call(rt.array_stub.Import, _runtime.array_pb2.ImportArrayRequest(token=token)).info
    if device is not None and get_device(device).alias != info.device:
        raise RuntimeError(f"The shared array lives on {info.device}, not on "
                           f"{get_device(device).alias}")
    out = array._from_info(info, _canonical_dtype(dtype) if dtype is not None else None)
    if shape is None and strides is None and (dtype is None or
                                              _elem_size(out.dtype) == _elem_size(
                                                  _dtype_from_proto(info.dtype))):
        return out
    shape = _normalize_shape(shape if shape is not None else
                             (info.byte_size // _elem_size(out.dtype),))
    elem = _elem_size(out.dtype)
    strides = tuple(int(s) for s in strides) if strides is not None else \
        _contiguous_strides(shape, elem)
    if len(strides) != len(shape):
        raise RuntimeError(f"strides {strides} do not match shape {shape}")
    span = sum((n - 1) * s for n, s in zip(shape, strides) if n > 0) + elem
    if any(s < 0 for s in strides) or (math.prod(shape) and span > info.byte_size):
        raise RuntimeError(f"shape {shape} with strides {strides} exceeds the shared "
                           f"allocation ({info.byte_size} bytes)")
    view = out._make_view(0, shape, strides)
    return view


def _follow_moved_bytes(arr, rt, ap):
    """An export may move an allocation into a slab of its own: re-describe it and drop the
    client's mapping of the old place (CPU slab or CUDA IPC mapping) when it moved."""
    info = rt.array_call("Describe", ap.DescribeArrayRequest(handle=arr._handle)).info
    old = arr._alloc.info
    if (info.shm_name, info.shm_offset, info.cuda_slab_id, info.cuda_ipc_offset) == \
            (old.shm_name, old.shm_offset, old.cuda_slab_id, old.cuda_ipc_offset):
        return
    old.CopyFrom(info)
    if arr._info is not old:
        arr._info.CopyFrom(info)
    arr._alloc._mapping = None
    arr._alloc.forget_cuda()
