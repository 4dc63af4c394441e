"""XLA FFI handlers written in Python: the ctypes view of XLA's FFI C API
(`xla/ffi/api/c_api.h`: call frame, buffers, attributes, API table, metadata extension), the
checked decoding of a call frame, and the registration of a Python function as an FFI target
of JAX (`register_ffi_callback`, also the handler under wp.jax_kernel / wp.jax_callable).

XLA calls a registered target through a C function pointer with one argument, the call frame.
Here that pointer is a ctypes callback, so XLA's thread takes the GIL and runs Python:
- The first call of a target asks for its metadata (the call frame's extension list holds an
  XLA_FFI_Metadata_Extension): the handler answers with the FFI API version its structures
  follow and its traits. No trait is advertised, in particular not
  XLA_FFI_HANDLER_TRAITS_COMMAND_BUFFER_COMPATIBLE: on a GPU the handler orders weftd's work
  with XLA's stream through interprocess events or stream memory operations, host calls that
  a CUDA graph cannot capture (a replay would not send the work to weftd at all), so XLA must
  run the call eagerly, outside its command buffers.
- Every other call is an execution: the buffers (data pointer, dtype, rank, dimensions) of the
  operands and results, the attributes (scalars, arrays, strings and dictionaries as XLA
  encodes them), and the execution context, from which the CUDA stream and the device ordinal
  are read through the API table.
Everything read from the frame is checked (struct sizes against the header's, counts, ranks,
dimensions, byte sizes, dtype codes, attribute kinds, string and array lengths) before it is
used; a frame that does not pass, and any exception the Python function raises, becomes an
XLA_FFI_Error made through the API table (JAX raises it with the message). Nothing raises
through ctypes.
"""
from __future__ import annotations

import contextlib
import ctypes
import sys
import threading

import numpy as np

# ---- the C API (xla/ffi/api/c_api.h) -----------------------------------------------------------

API_MAJOR, API_MINOR = 0, 1          # the API version whose layout these structures need

EXTENSION_METADATA = 1
STAGE_EXECUTE = 3
ARG_BUFFER = 1
RET_BUFFER = 1
ATTR_ARRAY, ATTR_DICTIONARY, ATTR_SCALAR, ATTR_STRING = 1, 2, 3, 4

ERROR_CANCELLED = 1
ERROR_UNKNOWN = 2
ERROR_INVALID_ARGUMENT = 3
ERROR_OUT_OF_RANGE = 11
ERROR_UNIMPLEMENTED = 12
ERROR_INTERNAL = 13

_size_t = ctypes.c_size_t
_ptr = ctypes.c_void_p


class ExtensionBase(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("type", ctypes.c_int), ("next", _ptr)]


class ApiVersion(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr),
                ("major_version", ctypes.c_int), ("minor_version", ctypes.c_int)]


class ByteSpan(ctypes.Structure):
    _fields_ = [("ptr", _ptr), ("len", _size_t)]


class Scalar(ctypes.Structure):
    _fields_ = [("dtype", ctypes.c_int), ("value", _ptr)]


class Array(ctypes.Structure):
    _fields_ = [("dtype", ctypes.c_int), ("size", _size_t), ("data", _ptr)]


class Buffer(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("dtype", ctypes.c_int),
                ("data", _ptr), ("rank", ctypes.c_int64), ("dims", _ptr)]


class Args(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("size", ctypes.c_int64),
                ("types", _ptr), ("args", _ptr)]


class Rets(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("size", ctypes.c_int64),
                ("types", _ptr), ("rets", _ptr)]


class Attrs(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("size", ctypes.c_int64),
                ("types", _ptr), ("names", _ptr), ("attrs", _ptr)]


class CallFrame(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("api", _ptr), ("ctx", _ptr),
                ("stage", ctypes.c_int), ("args", Args), ("rets", Rets), ("attrs", Attrs),
                ("future", _ptr)]


class ErrorCreateArgs(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("message", ctypes.c_char_p),
                ("errc", ctypes.c_int)]


class StreamGetArgs(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("ctx", _ptr), ("stream", _ptr)]


class DeviceOrdinalGetArgs(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("ctx", _ptr),
                ("device_ordinal", ctypes.c_int32)]


class Metadata(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("api_version", ApiVersion), ("traits", ctypes.c_uint32),
                ("state_type_id", ctypes.c_int64)]


class MetadataExtension(ctypes.Structure):
    _fields_ = [("extension_base", ExtensionBase), ("metadata", _ptr)]


class Api(ctypes.Structure):
    _fields_ = [("struct_size", _size_t), ("extension_start", _ptr), ("api_version", ApiVersion),
                ("internal_api", _ptr)] + [(name, _ptr) for name in (
                    "Error_Create", "Error_GetMessage", "Error_Destroy", "Handler_Register",
                    "Stream_Get", "Type_Register", "ExecutionContext_Get", "State_Set", "State_Get",
                    "DeviceMemory_Allocate", "DeviceMemory_Free", "ThreadPool_Schedule",
                    "ThreadPool_NumThreads", "Future_Create", "Future_SetAvailable", "Future_SetError",
                    "RunId_Get", "DeviceOrdinal_Get")]


def struct_size(cls, last_field: str) -> int:
    """XLA_FFI_STRUCT_SIZE: the bytes up to the end of `last_field` (what XLA writes in a
    struct's struct_size; fields after it are not counted)."""
    field = getattr(cls, last_field)
    return field.offset + field.size


CALL_FRAME_SIZE = struct_size(CallFrame, "attrs")
BUFFER_SIZE = struct_size(Buffer, "dims")
ARGS_SIZE = struct_size(Args, "args")
RETS_SIZE = struct_size(Rets, "rets")
ATTRS_SIZE = struct_size(Attrs, "attrs")
METADATA_SIZE = struct_size(Metadata, "traits")
METADATA_EXTENSION_SIZE = struct_size(MetadataExtension, "metadata")
API_VERSION_SIZE = struct_size(ApiVersion, "minor_version")
API_BASE_SIZE = struct_size(Api, "Error_Create")   # the least API table errors can be made with

HANDLER = ctypes.CFUNCTYPE(_ptr, _ptr)             # XLA_FFI_Error* (*)(XLA_FFI_CallFrame*)
_ERROR_CREATE = ctypes.CFUNCTYPE(_ptr, ctypes.POINTER(ErrorCreateArgs))
_STREAM_GET = ctypes.CFUNCTYPE(_ptr, ctypes.POINTER(StreamGetArgs))
_DEVICE_ORDINAL_GET = ctypes.CFUNCTYPE(_ptr, ctypes.POINTER(DeviceOrdinalGetArgs))

# Limits on what a frame may describe (far above what any program passes).
MAX_OPERANDS = 4096                  # arguments, results or attributes of one call
MAX_RANK = 64                        # XLA's own limit is lower
MAX_BUFFER_BYTES = 1 << 48
MAX_ATTR_ARRAY = 1 << 24             # elements of one array attribute
MAX_ATTR_STRING = 1 << 24            # bytes of one string attribute
MAX_ATTR_DEPTH = 16                  # nesting of dictionary attributes


# XLA_FFI_DataType code -> NumPy dtype (bfloat16, code 16, is added from JAX's ml_dtypes when a
# target is registered: JAX is loaded then).
DTYPES = {1: np.dtype(np.bool_), 2: np.dtype(np.int8), 3: np.dtype(np.int16),
          4: np.dtype(np.int32), 5: np.dtype(np.int64), 6: np.dtype(np.uint8),
          7: np.dtype(np.uint16), 8: np.dtype(np.uint32), 9: np.dtype(np.uint64),
          10: np.dtype(np.float16), 11: np.dtype(np.float32), 12: np.dtype(np.float64),
          15: np.dtype(np.complex64), 18: np.dtype(np.complex128)}


def _add_bfloat16() -> None:
    ml_dtypes = sys.modules.get("ml_dtypes")
    if ml_dtypes is not None and 16 not in DTYPES:
        DTYPES[16] = np.dtype(ml_dtypes.bfloat16)


class FfiError(Exception):
    """A call frame the handler refuses (returned to XLA as an error with this message)."""

    def __init__(self, message: str, code: int = ERROR_INVALID_ARGUMENT):
        super().__init__(message)
        self.code = code


# ---- reading the frame ---------------------------------------------------------------------


def _count(value, what: str) -> int:
    value = int(value)
    if value < 0 or value > MAX_OPERANDS:
        raise FfiError(f"XLA FFI call frame: {value} {what} (at most {MAX_OPERANDS})")
    return value


def _read(address, n: int, ctype, what: str) -> list:
    """n values of `ctype` at `address` of the call frame (a counted array XLA passes)."""
    if n == 0:
        return []
    if not address:
        raise FfiError(f"XLA FFI call frame: {what} is a null pointer")
    return list((ctype * n).from_address(address))


def _pointers(address, n: int, what: str) -> list:
    return _read(address, n, ctypes.c_void_p, what)


def _ints(address, n: int, what: str) -> list:
    return _read(address, n, ctypes.c_int, what)


def _check_size(actual, expected: int, what: str) -> None:
    if int(actual) < expected:
        raise FfiError(f"XLA FFI call frame: {what} has struct_size {int(actual)}, expected at "
                       f"least {expected} (a JAX/XLA version this handler does not know)")


class FfiBuffer:
    """One operand or result buffer of an FFI call: `shape`, `dtype` (NumPy), `data` (its
    address) and `__cuda_array_interface__` (memory of XLA's CUDA device) or
    `__array_interface__` (host memory of this process, on the CPU platform). Operands are
    read-only (`writable` False): weft launches read them but do not copy anything back into
    them; results are writable. Valid only during the call that received it."""

    __slots__ = ("dtype", "shape", "data", "platform", "writable", "ordinal", "__weakref__")

    def __init__(self, dtype, shape, data, platform, writable, ordinal=None):
        self.dtype = dtype
        self.shape = tuple(shape)
        self.data = int(data or 0)
        self.platform = platform
        self.writable = writable
        self.ordinal = ordinal

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def nbytes(self) -> int:
        return self.size * self.dtype.itemsize

    @property
    def strides(self) -> tuple:
        strides, step = [], self.dtype.itemsize
        for n in reversed(self.shape):
            strides.append(step)
            step *= max(n, 1)
        return tuple(reversed(strides))

    def _interface(self) -> dict:
        return {"shape": self.shape, "typestr": self.dtype.str, "data": (self.data, not self.writable),
                "strides": None, "version": 3}

    @property
    def __cuda_array_interface__(self) -> dict:
        if self.platform != "cuda":
            raise AttributeError("__cuda_array_interface__: this buffer is host memory")
        return self._interface()

    @property
    def __array_interface__(self) -> dict:
        if self.platform == "cuda":
            raise AttributeError("__array_interface__: this buffer is CUDA device memory")
        return self._interface()

    def element(self, index: tuple) -> "FfiBuffer":
        """The sub-buffer at `index` of the leading dimensions (row-major layout)."""
        offset = 0
        for i, s in zip(index, self.strides):
            offset += int(i) * s
        return FfiBuffer(self.dtype, self.shape[len(index):], self.data + offset, self.platform,
                         self.writable, self.ordinal)

    def numpy(self) -> np.ndarray:
        """A NumPy view of a host buffer (CPU platform only)."""
        if self.platform == "cuda":
            raise TypeError("numpy(): this buffer is CUDA device memory")
        if self.size == 0:
            return np.empty(self.shape, dtype=self.dtype)
        return np.asarray(self)

    def __repr__(self):
        return f"<FfiBuffer {self.platform} {self.dtype} {self.shape} at {self.data:#x}>"


def decode_buffer(address, platform: str, writable: bool, what: str, ordinal=None) -> FfiBuffer:
    """An XLA_FFI_Buffer at `address`, checked: struct size, dtype code, rank, dimensions, byte
    size (overflow-checked) and a data pointer where there are bytes."""
    if not address:
        raise FfiError(f"XLA FFI call frame: {what} is a null pointer")
    buf = Buffer.from_address(address)
    _check_size(buf.struct_size, BUFFER_SIZE, f"{what} (XLA_FFI_Buffer)")
    dtype = DTYPES.get(int(buf.dtype))
    if dtype is None:
        raise FfiError(f"XLA FFI call frame: {what} has XLA dtype code {int(buf.dtype)}, which weft "
                       f"does not support (bool, integers, float16/32/64, bfloat16, complex64/128)")
    rank = int(buf.rank)
    if rank < 0 or rank > MAX_RANK:
        raise FfiError(f"XLA FFI call frame: {what} has rank {rank} (0 to {MAX_RANK})")
    if rank and not buf.dims:
        raise FfiError(f"XLA FFI call frame: {what} has rank {rank} and no dimensions")
    shape = tuple(int(d) for d in (ctypes.c_int64 * rank).from_address(buf.dims)) if rank else ()
    nbytes = dtype.itemsize
    for d in shape:
        if d < 0:
            raise FfiError(f"XLA FFI call frame: {what} has a negative dimension ({shape})")
        nbytes *= d
        if nbytes > MAX_BUFFER_BYTES:
            raise FfiError(f"XLA FFI call frame: {what} of shape {shape} and dtype {dtype} is larger "
                           f"than {MAX_BUFFER_BYTES} bytes", ERROR_OUT_OF_RANGE)
    if nbytes and not buf.data:
        raise FfiError(f"XLA FFI call frame: {what} has {nbytes} bytes and a null data pointer")
    return FfiBuffer(dtype, shape, buf.data, platform, writable, ordinal)


def _decode_scalar(address, what):
    if not address:
        raise FfiError(f"XLA FFI attribute {what}: null scalar")
    scalar = Scalar.from_address(address)
    dtype = DTYPES.get(int(scalar.dtype))
    if dtype is None:
        raise FfiError(f"XLA FFI attribute {what}: unsupported scalar dtype code {int(scalar.dtype)}")
    if not scalar.value:
        raise FfiError(f"XLA FFI attribute {what}: null scalar value")
    raw = ctypes.string_at(scalar.value, dtype.itemsize)
    return np.frombuffer(raw, dtype=dtype)[0].item()


def _decode_array(address, what):
    if not address:
        raise FfiError(f"XLA FFI attribute {what}: null array")
    array = Array.from_address(address)
    dtype = DTYPES.get(int(array.dtype))
    if dtype is None:
        raise FfiError(f"XLA FFI attribute {what}: unsupported array dtype code {int(array.dtype)}")
    n = int(array.size)
    if n > MAX_ATTR_ARRAY:
        raise FfiError(f"XLA FFI attribute {what}: {n} elements (at most {MAX_ATTR_ARRAY})",
                       ERROR_OUT_OF_RANGE)
    if n and not array.data:
        raise FfiError(f"XLA FFI attribute {what}: {n} elements and a null data pointer")
    if n == 0:
        return np.empty(0, dtype=dtype)
    return np.frombuffer(ctypes.string_at(array.data, n * dtype.itemsize), dtype=dtype).copy()


def _decode_span(address, what, limit=MAX_ATTR_STRING) -> bytes:
    if not address:
        raise FfiError(f"XLA FFI {what}: null string")
    span = ByteSpan.from_address(address)
    n = int(span.len)
    if n > limit:
        raise FfiError(f"XLA FFI {what}: {n} bytes (at most {limit})", ERROR_OUT_OF_RANGE)
    if n and not span.ptr:
        raise FfiError(f"XLA FFI {what}: {n} bytes and a null pointer")
    return ctypes.string_at(span.ptr, n) if n else b""


def decode_attrs(attrs: Attrs, depth: int = 0) -> dict:
    """The attributes of a call as a dict: scalars as Python numbers (bool for PRED), arrays as
    1-D NumPy arrays (copies), strings as str (bytes where not UTF-8), dictionaries as dicts."""
    if depth > MAX_ATTR_DEPTH:
        raise FfiError(f"XLA FFI attributes nested deeper than {MAX_ATTR_DEPTH}")
    _check_size(attrs.struct_size, ATTRS_SIZE, "attributes (XLA_FFI_Attrs)")
    n = _count(attrs.size, "attributes")
    types = _ints(attrs.types, n, "attribute types")
    names = _pointers(attrs.names, n, "attribute names")
    values = _pointers(attrs.attrs, n, "attribute values")
    out = {}
    for kind, name_at, value_at in zip(types, names, values):
        raw_name = _decode_span(name_at, "attribute name", limit=1 << 16)
        name = raw_name.decode("utf-8", errors="replace")
        what = f"'{name}'"
        if kind == ATTR_SCALAR:
            out[name] = _decode_scalar(value_at, what)
        elif kind == ATTR_ARRAY:
            out[name] = _decode_array(value_at, what)
        elif kind == ATTR_STRING:
            raw = _decode_span(value_at, f"attribute {what}")
            try:
                out[name] = raw.decode("utf-8")
            except UnicodeDecodeError:
                out[name] = raw
        elif kind == ATTR_DICTIONARY:
            if not value_at:
                raise FfiError(f"XLA FFI attribute {what}: null dictionary")
            out[name] = decode_attrs(Attrs.from_address(value_at), depth + 1)
        else:
            raise FfiError(f"XLA FFI attribute {what}: unknown attribute kind {kind}")
    return out


def _api(frame: CallFrame) -> Api:
    if not frame.api:
        raise FfiError("XLA FFI call frame without an API table")
    api = Api.from_address(frame.api)
    if int(api.struct_size) < API_BASE_SIZE or not api.Error_Create:
        raise FfiError("XLA FFI API table too small (no XLA_FFI_Error_Create)")
    return api


def _api_has(api: Api, field: str) -> bool:
    return int(api.struct_size) >= struct_size(Api, field) and bool(getattr(api, field))


def _raise_xla_error(error, what: str) -> None:
    if error:
        raise FfiError(f"XLA FFI {what} failed", ERROR_INTERNAL)


def get_stream(api: Api, ctx) -> int:
    """The platform stream of the execution context (a CUstream on CUDA), 0 if XLA gives none."""
    if not _api_has(api, "Stream_Get"):
        raise FfiError("XLA FFI API table has no XLA_FFI_Stream_Get", ERROR_UNIMPLEMENTED)
    args = StreamGetArgs(struct_size(StreamGetArgs, "stream"), None, ctx, None)
    _raise_xla_error(_STREAM_GET(api.Stream_Get)(ctypes.byref(args)), "Stream_Get")
    return int(args.stream or 0)


def get_device_ordinal(api: Api, ctx):
    """XLA's device ordinal of the execution context, None where the API has no such call."""
    if not _api_has(api, "DeviceOrdinal_Get"):
        return None
    args = DeviceOrdinalGetArgs(struct_size(DeviceOrdinalGetArgs, "device_ordinal"), None, ctx, -1)
    _raise_xla_error(_DEVICE_ORDINAL_GET(api.DeviceOrdinal_Get)(ctypes.byref(args)),
                     "DeviceOrdinal_Get")
    return int(args.device_ordinal) if args.device_ordinal >= 0 else None


def make_error(api_address, code: int, message: str):
    """An XLA_FFI_Error made by XLA's API table (XLA copies the message), as the handler's
    return value; None when the table cannot make one (then the message goes to stderr)."""
    try:
        if api_address:
            api = Api.from_address(api_address)
            if int(api.struct_size) >= API_BASE_SIZE and api.Error_Create:
                args = ErrorCreateArgs(struct_size(ErrorCreateArgs, "errc"), None,
                                       message.encode("utf-8", errors="replace"), int(code))
                return _ERROR_CREATE(api.Error_Create)(ctypes.byref(args))
    except Exception:  # noqa: BLE001 - nothing may raise through ctypes
        pass
    sys.stderr.write(f"weft XLA FFI handler: cannot report an error to XLA: {message}\n")
    return None


def answer_metadata(frame: CallFrame, traits: int = 0) -> bool:
    """If the frame is XLA's metadata query (an XLA_FFI_Metadata_Extension first in its
    extension list), fills in the API version and traits and returns True."""
    if not frame.extension_start:
        return False
    base = ExtensionBase.from_address(frame.extension_start)
    if int(base.type) != EXTENSION_METADATA:
        return False
    _check_size(base.struct_size, METADATA_EXTENSION_SIZE, "metadata extension")
    extension = MetadataExtension.from_address(frame.extension_start)
    if not extension.metadata:
        raise FfiError("XLA FFI metadata extension without metadata")
    metadata = Metadata.from_address(extension.metadata)
    _check_size(metadata.struct_size, METADATA_SIZE, "XLA_FFI_Metadata")
    metadata.api_version = ApiVersion(API_VERSION_SIZE, None, API_MAJOR, API_MINOR)
    metadata.traits = int(traits)
    return True


class ExecutionContext:
    """What a callback learns about the call besides buffers and attributes: `stream` (XLA's
    CUstream on CUDA, None on the CPU), `device_ordinal`, `platform` ("cuda" or "cpu")."""

    __slots__ = ("stream", "device_ordinal", "platform", "stage")

    def __init__(self, stream, device_ordinal, platform, stage):
        self.stream = stream
        self.device_ordinal = device_ordinal
        self.platform = platform
        self.stage = stage

    def __repr__(self):
        stream = "None" if self.stream is None else f"{self.stream:#x}"
        return f"<ExecutionContext {self.platform} device {self.device_ordinal} stream {stream}>"


def decode_frame(frame: CallFrame, platform: str):
    """(inputs, outputs, attrs, ExecutionContext) of an execution frame, all checked."""
    api = _api(frame)
    if int(frame.stage) != STAGE_EXECUTE:
        raise FfiError(f"XLA FFI call at stage {int(frame.stage)}: only execution (stage "
                       f"{STAGE_EXECUTE}) is handled")
    _check_size(frame.args.struct_size, ARGS_SIZE, "arguments (XLA_FFI_Args)")
    _check_size(frame.rets.struct_size, RETS_SIZE, "results (XLA_FFI_Rets)")
    stream, ordinal = None, None
    if platform == "cuda":
        stream = get_stream(api, frame.ctx)
        ordinal = get_device_ordinal(api, frame.ctx)
    n_args = _count(frame.args.size, "arguments")
    n_rets = _count(frame.rets.size, "results")
    inputs, outputs = [], []
    for k, (kind, at) in enumerate(zip(_ints(frame.args.types, n_args, "argument types"),
                                       _pointers(frame.args.args, n_args, "arguments"))):
        if kind != ARG_BUFFER:
            raise FfiError(f"XLA FFI argument {k} has kind {kind}, not a buffer")
        inputs.append(decode_buffer(at, platform, False, f"argument {k}", ordinal))
    for k, (kind, at) in enumerate(zip(_ints(frame.rets.types, n_rets, "result types"),
                                       _pointers(frame.rets.rets, n_rets, "results"))):
        if kind != RET_BUFFER:
            raise FfiError(f"XLA FFI result {k} has kind {kind}, not a buffer")
        outputs.append(decode_buffer(at, platform, True, f"result {k}", ordinal))
    if platform == "cuda" and ordinal is None:
        ordinal = _pointer_ordinal(inputs + outputs)
        for buf in inputs + outputs:
            buf.ordinal = ordinal
    attrs = decode_attrs(frame.attrs)
    return inputs, outputs, attrs, ExecutionContext(stream, ordinal, platform, int(frame.stage))


def _pointer_ordinal(buffers) -> int:
    """The CUDA device of the first buffer with bytes (the driver's answer), else 0."""
    from .. import _cuda_ipc  # noqa: PLC0415

    for buf in buffers:
        if buf.nbytes:
            found = _cuda_ipc.pointer_device(buf.data)
            if found is not None:
                return int(found)
    return 0


# ---- handlers and targets ------------------------------------------------------------------


def _describe(err: BaseException) -> str:
    text = str(err)
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def make_handler(run, platform: str, name: str):
    """A ctypes XLA FFI handler for `platform` ("cuda" or "cpu") that answers the metadata query
    and calls run(inputs, outputs, attrs, ctx) for each execution. Any exception becomes an
    XLA error whose message names the target and the exception. Keep the returned object alive
    as long as XLA may call it."""

    def handler(frame_address):
        api_address = None
        try:
            if not frame_address:
                sys.stderr.write(f"weft XLA FFI handler {name}: null call frame\n")
                return None
            frame = CallFrame.from_address(frame_address)
            api_address = frame.api
            if int(frame.struct_size) < CALL_FRAME_SIZE:
                return make_error(api_address, ERROR_INVALID_ARGUMENT,
                                  f"{name}: XLA_FFI_CallFrame has struct_size {int(frame.struct_size)}, "
                                  f"expected at least {CALL_FRAME_SIZE}")
            if answer_metadata(frame):
                return None
            inputs, outputs, attrs, ctx = decode_frame(frame, platform)
            run(inputs, outputs, attrs, ctx)
            return None
        except FfiError as err:
            return make_error(api_address, err.code, f"{name}: {err}")
        except BaseException as err:  # noqa: BLE001 - nothing may raise through ctypes
            return make_error(api_address, ERROR_UNKNOWN, f"{name}: {_describe(err)}")

    return HANDLER(handler)


_TARGETS_LOCK = threading.Lock()
_TARGETS: dict = {}          # (name, platform) -> handler (kept alive; XLA holds its address)
_CALLBACKS: dict = {}        # name -> the Python function its handlers call now
PLATFORMS = (("CUDA", "cuda"), ("cpu", "cpu"))   # XLA platform name, buffer platform


def register_target(name: str, run) -> None:
    """Makes `name` an XLA FFI target of JAX's CUDA and CPU platforms that calls
    run(inputs, outputs, attrs, ctx). Registering the name again replaces the function (XLA
    keeps the first handler; it looks the function up on each call)."""
    jax = sys.modules.get("jax")
    if jax is None:
        import jax  # noqa: PLC0415
    _add_bfloat16()
    with _TARGETS_LOCK:
        _CALLBACKS[name] = run
        for xla_platform, platform in PLATFORMS:
            if (name, platform) in _TARGETS:
                continue

            def dispatch(inputs, outputs, attrs, ctx, _name=name):
                _CALLBACKS[_name](inputs, outputs, attrs, ctx)

            handler = make_handler(dispatch, platform, name)
            jax.ffi.register_ffi_target(name, jax.ffi.pycapsule(handler), platform=xla_platform)
            _TARGETS[(name, platform)] = handler


@contextlib.contextmanager
def cuda_scope(ctx):
    """Binds XLA's stream as the framework stream of weft's launches on that device while a
    callback runs (a wp.ScopedStream inside the callback overrides it)."""
    from . import cuda_order  # noqa: PLC0415

    previous = cuda_order.set_scoped_stream(ctx.device_ordinal or 0, ctx.stream)
    try:
        yield
    finally:
        cuda_order.set_scoped_stream(ctx.device_ordinal or 0, previous)


def register_ffi_callback(name, func, graph_compatible=True):
    """Registers `func(inputs, outputs, attrs, ctx)` as the XLA FFI target `name` (Warp's
    function), for JAX's CUDA platform and its CPU platform; call it with
    `jax.ffi.ffi_call(name, result_shapes)(*args, **attrs)`.

    `inputs` and `outputs` are FfiBuffer objects (`.shape`, `.dtype`, `.data`, and
    `__cuda_array_interface__` on CUDA or `__array_interface__` on the CPU) that weft
    launches take as arrays; `attrs` the call's attributes; `ctx.stream` XLA's CUDA stream.
    On CUDA, XLA's stream is the framework stream of weft's launches on that device while
    `func` runs (as `wp.ScopedStream(wp.Stream(device, cuda_stream=ctx.stream))`, which
    Warp's examples open, does): a launch on XLA's buffers is imported by CUDA IPC and
    ordered after XLA's work queued on that stream, and XLA's later work after it, without a
    host wait (docs/interop.md, "JAX"). On the CPU the buffers are host memory of this
    process; launches copy them into weftd and the results back, as for any NumPy array.

    `graph_compatible` is accepted for Warp's signature but never advertised to XLA: the
    ordering with weftd consists of host calls a CUDA graph cannot capture, so XLA runs the
    call outside its command buffers."""
    if not isinstance(name, str) or not name:
        raise TypeError("register_ffi_callback: name must be a non-empty string")
    if not callable(func):
        raise TypeError("register_ffi_callback: func must be callable")

    def run(inputs, outputs, attrs, ctx):
        if ctx.platform == "cuda" and ctx.stream is not None:
            with cuda_scope(ctx):
                func(inputs, outputs, attrs, ctx)
        else:
            func(inputs, outputs, attrs, ctx)

    register_target(name, run)
