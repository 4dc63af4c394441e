"""wp.launch: checks the arguments against the kernel's parameter types, packs them into
ArgValues (raw bytes, ArrayRef, StructValue), compiles the module lazily for the device and
appends a LaunchCommand to the session's batch. NumPy arrays and lists passed for array
parameters are copied into temporary daemon arrays and copied back after the launch."""
from __future__ import annotations

import ctypes
import os
import struct
import sys
import typing

import numpy as np

from .. import config as _config
from . import module as module_mod
from . import typestr
from .errors import WeftLaunchError
from .functions import Kernel
from .structs import StructInstance, StructType
from .._runtime import varint as _varint
from ..interop import memory as _interop_memory

_PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def is_weft_array(value) -> bool:
    return hasattr(value, "_ref") and hasattr(value, "_handle")


def device_name(device) -> str:
    """"cpu", "cuda:0", ... of a device given as a string, a weft Device or None (current)."""
    if device is None:
        try:
            import weft  # noqa: PLC0415

            device = weft.get_device()
        except Exception:  # noqa: BLE001 - no device API: the CPU
            return "cpu"
    if isinstance(device, str):
        return device
    for attr in ("alias", "name"):
        value = getattr(device, attr, None)
        if isinstance(value, str) and value:
            return value
    return str(device)


# Serialized protobuf fields (wire format: tag, length, bytes), so that a launch's command is
# assembled from bytes cached per kernel, argument and call site instead of built as a message
# and serialized per launch: Command.launch (3), Command.origin (15), LaunchCommand.dim (3,
# packed) and LaunchCommand.args (4).
_COMMAND_LAUNCH = 0x1A
_COMMAND_ORIGIN = 0x7A
_LAUNCH_DIM = 0x1A
_LAUNCH_ARGS = 0x22


def _field(tag: int, payload: bytes) -> bytes:
    """A length-delimited field: its tag byte (field number < 16), length and payload."""
    return bytes((tag,)) + _varint(len(payload)) + payload


def launch_frame_bytes(template_bytes: bytes, dims, fields, origin_field: bytes) -> bytes:
    """A launch as a SubmitRequest.commands element (field 1): the Command whose launch holds
    the plan's fields (`template_bytes`), the dimensions (packed) and the arguments' serialized
    LaunchCommand.args fields, then the origin field. weft._launch_frame builds the same bytes
    in C."""
    body = template_bytes + _field(_LAUNCH_DIM, b"".join(map(_varint, dims))) + b"".join(fields)
    inner = _field(_COMMAND_LAUNCH, body) + origin_field
    return b"\x0a" + _varint(len(inner)) + inner


def caller_origin(depth: int = 1):
    """SourceLocation of the first frame outside the weft package (see caller_origin_entry)."""
    return caller_origin_entry(depth + 1)[1]


def caller_origin_entry(depth: int = 1):
    """(code, SourceLocation, its Command.origin field serialized) of the first frame outside
    the weft package (the user's launch line), starting `depth` frames above the caller. One
    cached entry per (code object, instruction offset): no inspect, no stack walk beyond the
    weft frames. Keys are chosen to cost nothing to hash: a file name (str: its hash is
    cached) and the code object's id, the entry holding the code object so that the id stays
    its own; a code object's own hash walks its bytecode and constants (tens of microseconds
    for a large function on Python 3.12) and `f_lineno` scans the line table, so neither is
    computed on a hit."""
    frame = sys._getframe(depth + 1)
    while frame is not None:
        code = frame.f_code
        filename = code.co_filename
        inside = _INSIDE_PACKAGE.get(filename)
        if inside is None:
            inside = _INSIDE_PACKAGE[filename] = os.path.abspath(filename).startswith(
                _PACKAGE_DIR + os.sep)
        if not inside:
            key = (id(code), frame.f_lasti)
            entry = _ORIGINS.get(key)
            if entry is None or entry[0] is not code:
                if len(_ORIGINS) > 100_000:
                    _ORIGINS.clear()
                origin = _pb().types_pb2.SourceLocation(file=filename, line=frame.f_lineno or 0)
                entry = _ORIGINS[key] = (code, origin, _field(_COMMAND_ORIGIN, origin.SerializeToString()))
            return entry
        frame = frame.f_back
    origin = _pb().types_pb2.SourceLocation()
    return (None, origin, _field(_COMMAND_ORIGIN, b""))


class _Protos:
    """The generated proto modules, imported once (not per launch: `from weft.v1 import`
    inside a function costs an import-machinery call every time)."""

    def __init__(self):
        from weft.v1 import exec_pb2, types_pb2  # noqa: PLC0415

        self.exec_pb2 = exec_pb2
        self.types_pb2 = types_pb2
        self.ArgValue = exec_pb2.ArgValue
        self.Command = exec_pb2.Command
        self.LaunchCommand = exec_pb2.LaunchCommand


_PROTOS = None


def _pb() -> _Protos:
    global _PROTOS
    if _PROTOS is None:
        _PROTOS = _Protos()
    return _PROTOS


_ORIGINS: dict = {}            # (id(code), f_lasti) -> caller_origin_entry's (code, proto, field)
_INSIDE_PACKAGE: dict = {}     # file name -> whether it belongs to the weft package
_DTYPE_TEXT: dict = {}         # dtype object -> type string (array argument checks)


def _dtype_text(dtype) -> str:
    try:
        return _DTYPE_TEXT[dtype]
    except (KeyError, TypeError):
        pass
    try:
        text = typestr.type_string(dtype)
    except TypeError:
        text = str(dtype)
    try:
        _DTYPE_TEXT[dtype] = text
    except TypeError:
        pass
    return text


def normalize_dim(dim) -> list:
    if isinstance(dim, (int, np.integer)):
        dims = [int(dim)]
    else:
        try:
            dims = [int(d) for d in dim]
        except TypeError as err:
            raise WeftLaunchError(f"launch dim must be an int or a tuple of ints, got {dim!r}") \
                from err
    if not 1 <= len(dims) <= 4:
        raise WeftLaunchError(f"launch dim must have 1 to 4 dimensions, got {len(dims)}")
    if any(d < 0 for d in dims):
        raise WeftLaunchError(f"launch dim must not be negative, got {tuple(dims)}")
    return dims


class _PendingCopyBack:
    """A NumPy array the launch wrote through a temporary daemon array."""

    def __init__(self, target: np.ndarray, temp):
        self.target = target
        self.temp = temp

    def apply(self) -> None:
        data = np.asarray(self.temp.numpy())
        np.copyto(self.target, data.reshape(self.target.shape).astype(self.target.dtype,
                                                                      copy=False))


class _MirrorCopyBack:
    """A weft copy of framework memory the launch took (weft.interop.torch.TensorMirror): its
    values go back into the framework's memory after the launch."""

    def __init__(self, mirror, array):
        self.mirror = mirror
        self.array = array

    def apply(self) -> None:
        self.mirror.after_launch(self.array)


class ArgPacker:
    """Packs launch arguments for one kernel and device; keeps temporaries alive."""

    def __init__(self, kernel: Kernel, device: str):
        self.kernel = kernel
        self.device = device
        self.copy_backs: list = []
        self.temps: list = []          # temporary daemon arrays (kept until the launch is done)
        self.resolved: list = []       # the argument objects as launched (temps substituted)

    def _fail(self, name: str, message: str):
        raise WeftLaunchError(f"Invalid argument '{name}' for kernel '{self.kernel.key}': "
                              f"{message}")

    def pack(self, name: str, type_text: str, annotation, value):
        from weft.v1 import exec_pb2  # noqa: PLC0415

        desc = typestr.parse(type_text)
        if desc.kind == "array":
            ref, resolved = self._array_ref(name, desc, annotation, value)
            return exec_pb2.ArgValue(array=ref), resolved
        if desc.kind == "indexedarray":
            return exec_pb2.ArgValue(struct_value=self._indexed_value(name, desc, value)), value
        if desc.kind == "struct":
            if not isinstance(value, StructInstance) or value._struct_type.key != desc.struct_name:
                self._fail(name, f"expected an instance of struct {desc.struct_name}, got "
                                 f"{type(value).__name__}")
            return exec_pb2.ArgValue(struct_value=self._struct_value(value)), value
        if desc.kind == "any":
            self._fail(name, "kernels cannot take typing.Any parameters; use wp.overload or "
                             "concrete annotations")
        if is_weft_array(value) or isinstance(value, (np.ndarray, list)) and desc.kind == "scalar":
            self._fail(name, f"expected a value of type {type_text}, got {type(value).__name__}")
        try:
            return exec_pb2.ArgValue(raw=typestr.pack_value(desc, value)), value
        except (TypeError, ValueError, OverflowError) as err:
            self._fail(name, str(err))

    def _struct_value(self, instance: StructInstance):
        from weft.v1 import exec_pb2  # noqa: PLC0415

        fields = []
        st: StructType = instance._struct_type
        for field in st.fields:
            value = instance._values[field.name]
            arg, _ = self.pack(f"{st.key}.{field.name}", field.type_str, field.annotation, value)
            fields.append(arg)
        return exec_pb2.StructValue(fields=fields)

    def _indexed_value(self, name: str, desc, value):
        """An indexed array as the daemon packs it: its data array, then one int32 index
        array per dimension (a null array where a dimension is not indexed; 4 in all)."""
        from weft.indexedarray import indexedarray  # noqa: PLC0415
        from weft.v1 import exec_pb2, types_pb2  # noqa: PLC0415

        if value is None:
            null = exec_pb2.ArgValue(array=types_pb2.ArrayRef(handle=0))
            return exec_pb2.StructValue(fields=[null] * 5)
        if not isinstance(value, indexedarray):
            self._fail(name, f"expected an indexedarray of {desc.elem.text} with {desc.ndim} "
                             f"dimension(s), got {type(value).__name__}")
        data_desc = typestr.parse(typestr.array_str(desc.elem.text, desc.ndim))
        ref, _ = self._array_ref(name, data_desc, None, value.data)
        fields = [exec_pb2.ArgValue(array=ref)]
        index_desc = typestr.parse("array(int32,1)")
        for d in range(4):
            idx = value.indices[d] if d < len(value.indices) else None
            iref, _ = self._array_ref(f"{name}.indices[{d}]", index_desc, None, idx)
            fields.append(exec_pb2.ArgValue(array=iref))
        return exec_pb2.StructValue(fields=fields)

    def _array_ref(self, name: str, desc, annotation, value):
        from weft.v1 import types_pb2  # noqa: PLC0415

        if value is None:
            return types_pb2.ArrayRef(handle=0), None
        weft_value = getattr(value, "_weft_value", None)
        if weft_value is not None and is_weft_array(weft_value):   # its ctypes descriptor (array_t)
            value = weft_value
        if not is_weft_array(value):
            if getattr(value, "_indexed_", False):   # an indexed view is no plain array (as in Warp)
                self._fail(name, f"expects an array of type array(ndim={desc.ndim}, dtype={desc.elem.text}), "
                                 f"but passed value has type {type(value).__name__}")
            if isinstance(value, np.ndarray) or any(
                    hasattr(value, attr) for attr in ("__array__", "__array_interface__",
                                                      "__dlpack__", "__cuda_array_interface__")):
                value = self._temporary(name, desc, annotation, value)
            else:
                # Warp's message; a list or tuple is no array either (as in Warp)
                self._fail(name, f"expects an array of type "
                                 f"array(ndim={desc.ndim}, dtype={desc.elem.text}), but passed "
                                 f"value has type {type(value).__name__}")
        got = _dtype_text(value.dtype)
        if desc.elem.kind != "any" and got != desc.elem.text:
            self._fail(name, f"expected an array of dtype {desc.elem.text}, got an array of "
                             f"dtype {got}")
        if int(value.ndim) != desc.ndim:
            self._fail(name, f"expected an array with {desc.ndim} dimension(s), got "
                             f"{value.ndim}")
        array_device = device_name(getattr(value, "device", self.device))
        if array_device != self.device and not (self.device == "cuda" and
                                                array_device.startswith("cuda")):
            self._fail(name, f"array is on device {array_device} but the kernel is launched "
                             f"on {self.device}")
        mirror = getattr(value, "_mirror", None)
        if mirror is not None:   # a copy of framework memory: brought up to date, written back after
            mirror.before_launch(value)
            self.copy_backs.append(_MirrorCopyBack(mirror, value))
        return value._ref(), value

    def _temporary(self, name: str, desc, annotation, value):
        """A weft array for a foreign array argument (weft.interop.external.launch_array):
        its own memory when it lives in a weft slab, else a temporary copy (copied back into
        writable sources after the launch)."""
        from weft.interop import external  # noqa: PLC0415

        dtype = _element_dtype(annotation)
        if dtype is typing.Any:
            dtype = None
        try:
            temp, copy_back = external.launch_array(value, dtype, self.device,
                                                    f"argument '{name}'")
        except external.InteropError as err:
            self._fail(name, str(err).replace(f"argument '{name}': ", ""))
        except Exception as err:  # noqa: BLE001 - report as an argument error
            self._fail(name, f"cannot convert {type(value).__name__} to an array of "
                             f"{desc.elem.text}: {err}")
        self.temps.append(temp)
        if copy_back is not None:
            self.copy_backs.append(copy_back if hasattr(copy_back, "apply")
                                   else _PendingCopyBack(copy_back, temp))
        return temp


def _element_dtype(annotation):
    dtype = getattr(annotation, "dtype", None)
    if dtype is not None:
        return dtype
    args = getattr(annotation, "__args__", None)
    if args:
        return args[0]
    return None


def _value_type_string(value) -> str:
    from weft.indexedarray import indexedarray  # noqa: PLC0415

    if isinstance(value, StructInstance):
        return value._struct_type._type_str
    if isinstance(value, indexedarray):
        return value._type_str()
    if is_weft_array(value):
        return typestr.array_str(typestr.type_string(value.dtype), int(value.ndim))
    if isinstance(value, np.ndarray):
        import weft  # noqa: PLC0415

        return typestr.array_str(typestr.type_string(weft.dtype_from_numpy(value.dtype)),
                                 value.ndim)
    text = typestr.constant_type_of(value)
    if text is None:
        raise TypeError(f"cannot infer a kernel type for {type(value).__name__} {value!r}")
    return text


def infer_param_types(kernel: Kernel, args: list) -> list:
    """Concrete parameter types of a generic kernel's launch, from the argument values."""
    if len(args) != len(kernel.param_names):
        raise WeftLaunchError(f"Invalid number of arguments for kernel '{kernel.key}': expected "
                              f"{len(kernel.param_names)} ({', '.join(kernel.param_names)}), "
                              f"got {len(args)}")
    types = []
    for name, declared, value in zip(kernel.param_names, kernel.param_types, args):
        if not typestr.is_generic(declared):
            types.append(declared)
            continue
        try:
            concrete = _value_type_string(value)
        except TypeError as err:
            raise WeftLaunchError(f"Invalid argument '{name}' for generic kernel "
                                  f"'{kernel.key}': {err}") from None
        if not typestr.accepts(declared, concrete):
            raise WeftLaunchError(f"Invalid argument '{name}' for generic kernel '{kernel.key}': "
                                  f"a value of type {concrete} does not match the annotation "
                                  f"{declared}")
        types.append(concrete)
    return types


def pack_arguments(kernel: Kernel, device: str, args: list):
    """(ArgValues, ArgPacker) for args against kernel's params; raises WeftLaunchError."""
    params = kernel.param_names
    if len(args) != len(params):
        raise WeftLaunchError(f"Invalid number of arguments for kernel '{kernel.key}': expected "
                              f"{len(params)} ({', '.join(params)}), got {len(args)}")
    packer = ArgPacker(kernel, device)
    packed = []
    for name, type_text, value in zip(params, kernel.param_types, args):
        annotation = kernel.definition.annotations[name]
        arg, resolved = packer.pack(name, type_text, annotation, value)
        packed.append(arg)
        packer.resolved.append(resolved)
    return packed, packer


def adjoint_arguments(kernel: Kernel, device: str, args: list, adj_args: list):
    """ArgValues of the adjoint arguments: arrays -> the given array (or the arg's .grad),
    values -> the given adjoint value (zero by default), structs -> adjoint structs."""
    from weft.v1 import exec_pb2, types_pb2  # noqa: PLC0415

    packed = []
    for i, (name, type_text) in enumerate(zip(kernel.param_names, kernel.param_types)):
        desc = typestr.parse(type_text)
        given = adj_args[i] if i < len(adj_args) else None
        value = args[i]
        if desc.kind == "array":
            target = given if is_weft_array(given) else (
                getattr(value, "grad", None) if is_weft_array(value) else None)
            packed.append(exec_pb2.ArgValue(array=target._ref() if target is not None
                                            else types_pb2.ArrayRef(handle=0)))
        elif desc.kind == "indexedarray":
            packed.append(exec_pb2.ArgValue(struct_value=_adjoint_indexed(value, given)))
        elif desc.kind == "struct":
            packed.append(exec_pb2.ArgValue(struct_value=_adjoint_struct(
                value, given if isinstance(given, StructInstance) else None)))
        else:
            if given is None or is_weft_array(given):
                packed.append(exec_pb2.ArgValue(raw=bytes(desc.byte_size)))
            else:
                packed.append(exec_pb2.ArgValue(raw=typestr.pack_value(desc, given)))
    return packed


def _adjoint_indexed(value, given):
    """The adjoint of an indexed array: the data's gradient (or the given indexed array's
    data); the kernel takes the indices from the primal argument."""
    from weft.indexedarray import indexedarray  # noqa: PLC0415
    from weft.v1 import exec_pb2, types_pb2  # noqa: PLC0415

    target = None
    if isinstance(given, indexedarray):
        target = given.data
    elif is_weft_array(given):
        target = given
    elif isinstance(value, indexedarray):
        target = getattr(value.data, "grad", None)
    null = exec_pb2.ArgValue(array=types_pb2.ArrayRef(handle=0))
    data = exec_pb2.ArgValue(array=target._ref()) if target is not None else null
    return exec_pb2.StructValue(fields=[data] + [null] * 4)


def _adjoint_struct(value: typing.Optional[StructInstance], given: typing.Optional[StructInstance]):
    from weft.v1 import exec_pb2, types_pb2  # noqa: PLC0415

    fields = []
    st = value._struct_type if value is not None else given._struct_type
    for field in st.fields:
        desc = field.desc
        v = value._values.get(field.name) if value is not None else None
        g = given._values.get(field.name) if given is not None else None
        if desc.kind == "array":
            target = g if is_weft_array(g) else (getattr(v, "grad", None) if is_weft_array(v)
                                                 else None)
            fields.append(exec_pb2.ArgValue(array=target._ref() if target is not None
                                            else types_pb2.ArrayRef(handle=0)))
        elif desc.kind == "indexedarray":
            fields.append(exec_pb2.ArgValue(struct_value=_adjoint_indexed(v, g)))
        elif desc.kind == "struct":
            fields.append(exec_pb2.ArgValue(struct_value=_adjoint_struct(v, g)))
        else:
            raw = typestr.pack_value(desc, g) if g is not None else bytes(desc.byte_size)
            fields.append(exec_pb2.ArgValue(raw=raw))
    return exec_pb2.StructValue(fields=fields)


# --------------------------------------------------------------------------------------------
# The launch hot path: a plan per (kernel, runtime, device) with one packer per parameter,
# ArgValue protos of arrays cached on the array objects, scalars packed with struct.
# --------------------------------------------------------------------------------------------

_STRUCT_FORMATS = {"float32": "<f", "float64": "<d", "int8": "<b", "int16": "<h", "int32": "<i",
                   "int64": "<q", "uint8": "<B", "uint16": "<H", "uint32": "<I",
                   "uint64": "<Q"}
_INT_RANGES = {"int8": (-2**7, 2**7 - 1), "int16": (-2**15, 2**15 - 1),
               "int32": (-2**31, 2**31 - 1), "int64": (-2**63, 2**63 - 1),
               "uint8": (0, 2**8 - 1), "uint16": (0, 2**16 - 1), "uint32": (0, 2**32 - 1),
               "uint64": (0, 2**64 - 1)}


class _ParamPlan:
    """How one kernel parameter is packed on the fast path."""

    __slots__ = ("name", "type_text", "desc", "annotation", "is_array", "elem_text", "elem_any",
                 "ndim", "pack_float", "pack_int", "int_range", "last_raw", "last_arg", "last_field",
                 "composite_dtype", "composite_cls")

    def __init__(self, name, type_text, annotation):
        desc = typestr.parse(type_text)
        self.name = name
        self.type_text = type_text
        self.desc = desc
        self.annotation = annotation
        self.is_array = desc.kind == "array"
        self.elem_text = desc.elem.text if self.is_array else ""
        self.elem_any = self.is_array and desc.elem.kind == "any"
        self.ndim = desc.ndim
        fmt = _STRUCT_FORMATS.get(desc.scalar) if desc.kind == "scalar" else None
        is_float = desc.scalar.startswith("float")
        self.pack_float = struct.Struct(fmt).pack if fmt and is_float else None
        self.pack_int = struct.Struct(fmt).pack if fmt and not is_float else None
        self.int_range = _INT_RANGES.get(desc.scalar)
        self.last_raw = None
        self.last_arg = None
        self.last_field = None      # last_arg as a serialized LaunchCommand.args field
        # vector/matrix/quat/transform values: a weft value with as many components, stored
        # as this scalar type, passes its components' bytes (its class is remembered once it
        # matched; any other value goes through ArgPacker's conversion)
        self.composite_dtype = None
        if desc.kind in ("vec", "mat", "quat", "transform") and desc.scalar != "bfloat16" and \
                sys.byteorder == "little":
            self.composite_dtype = desc.numpy_scalar
        self.composite_cls = None


class _LaunchPlan:
    """What every launch of one kernel on one device of one session repeats: the compiled
    module and kernel name (valid while the module registry version is unchanged) and the
    parameter packers."""

    __slots__ = ("version", "compiled", "kernel_name", "params", "n_params", "template", "template_bytes",
                 "native")

    def __init__(self, kernel: Kernel, compiled, info, device: str):
        self.version = module_mod.registry_version()
        self.compiled = compiled
        self.kernel_name = info.name or kernel.name
        annotations = kernel.definition.annotations
        self.params = [_ParamPlan(n, t, annotations[n])
                       for n, t in zip(kernel.param_names, kernel.param_types)]
        self.n_params = len(self.params)
        pb = _pb()        # the forward LaunchCommand less dim, args and origin (copied per launch)
        self.template = pb.Command(launch=pb.LaunchCommand(
            module_id=compiled.module_id, kernel=self.kernel_name, device=device))
        self.template_bytes = self.template.launch.SerializeToString()   # the same, serialized
        self.native = _native_spec(self)     # for weft._launch_frame, or None


def _native_param(p: _ParamPlan):
    """Parameter p as weft._launch_frame.spec takes it, or None where only the Python path
    packs it (vectors, structs, float16, ...)."""
    if p.is_array:
        return (1, None if p.elem_any else p.elem_text, p.ndim)
    scalar = p.desc.scalar if p.desc.kind == "scalar" else None
    if p.pack_float is not None and scalar in ("float32", "float64"):
        return (2,) if scalar == "float32" else (3,)
    if p.pack_int is not None:
        return (4, struct.calcsize(_STRUCT_FORMATS[scalar]), p.int_range[0], p.int_range[1])
    return None


def _native_spec(plan: _LaunchPlan):
    """The plan as weft._launch_frame builds its launches from (a capsule), or None when the C
    module is absent or a parameter needs the Python path."""
    native = _native_module()
    if native is None:
        return None
    params = [_native_param(p) for p in plan.params]
    if any(p is None for p in params):
        return None
    return native.spec(plan.template_bytes, params)


_NATIVE = False          # weft._launch_frame once looked up (None: absent or turned off)


def _native_module():
    """weft._launch_frame (clients/python/native/launch_frame.c), configured; None when it was
    not built or WEFT_NATIVE_LAUNCH=0 turns it off: launches are then built in Python (the
    same bytes)."""
    global _NATIVE
    if _NATIVE is False:
        from .. import _native  # noqa: PLC0415

        native = _native.optional("_launch_frame", "WEFT_NATIVE_LAUNCH")
        if native is not None:
            native.configure(_array_type(), _ctype_type(), _REF_ATTR)
        _NATIVE = native
    return _NATIVE


def _launch_plan(kernel: Kernel, device: str, runtime, lanes: int = 1) -> _LaunchPlan:
    plans = kernel.__dict__.get("_launch_plans")
    if plans is None:
        plans = kernel._launch_plans = {}
    key = (id(runtime), device, lanes)
    plan = plans.get(key)
    if plan is not None and plan.version == module_mod.registry_version() and \
            plan.compiled is kernel._compiled.get((key[0], device, False, lanes), (0, None))[1]:
        return plan
    compiled, info = module_mod.compile_kernel(kernel, device, backward=False, lanes=lanes)
    plan = plans[key] = _LaunchPlan(kernel, compiled, info, device)
    return plan


# Per array object: (handle, byte_offset, shape, strides, dtype, device, dtype text, ndim,
# device name, ArgValue, the ArgValue as a serialized LaunchCommand.args field). Views are
# immutable; the identity checks of shape/strides/dtype/device catch any attribute that was
# replaced anyway.
_REF_ATTR = "_weft_launch_ref"


def _array_arg(value):
    cached = value.__dict__.get(_REF_ATTR)
    if cached is not None and cached[0] == value._handle and \
            cached[1] == value._byte_offset and cached[2] is value.shape and \
            cached[3] is value.strides and cached[4] is value.dtype and \
            cached[5] is value.device:
        return cached
    pb = _pb()
    arg = pb.ArgValue(array=value._ref())
    cached = (value._handle, value._byte_offset, value.shape, value.strides, value.dtype,
              value.device, _dtype_text(value.dtype), int(value.ndim),
              device_name(value.device), arg, _field(_LAUNCH_ARGS, arg.SerializeToString()))
    try:
        value.__dict__[_REF_ATTR] = cached
    except (AttributeError, TypeError):
        pass
    return cached


# A Torch tensor passed to wp.launch directly: the weft array it resolved to (imported by CUDA
# IPC or weft's own memory, used in place) is remembered on the tensor, keyed by what the
# tensor is (pointer, shape, strides, dtype) and what the parameter asks for, so the next
# launch with it skips the resolution. The tensor holds its storage, so a key that matches
# names the same memory. Only arrays over the tensor's own memory are remembered (never a
# copy).
_FRAMEWORK_ATTR = "_weft_launch_array"


def _framework_key(value, p, device):
    return (value.data_ptr(), value.shape, value.stride(), value.dtype, p.elem_text, p.ndim,
            device)


def _framework_arg(value, p, device):
    d = getattr(value, "__dict__", None)
    entry = d.get(_FRAMEWORK_ATTR) if d is not None else None
    if entry is None:
        return None
    key, known = entry
    if known._alloc.runtime.closed or key != _framework_key(value, p, device):
        return None
    return known


def _remember_framework_arg(value, p, device, launched):
    if launched is value or not type(value).__module__.startswith("torch") or \
            not _is_array(launched):
        return
    try:
        in_place = launched.ptr is not None and launched.ptr == value.data_ptr()
    except Exception:  # noqa: BLE001 - not a tensor after all: nothing remembered
        return
    if not in_place:                     # a copy: the next launch must copy again
        return
    try:
        value.__dict__[_FRAMEWORK_ATTR] = (_framework_key(value, p, device), launched)
    except (AttributeError, TypeError):
        pass


def _is_array(value) -> bool:
    return isinstance(value, _array_type())


def _device_matches(array_device: str, launch_device: str) -> bool:
    return array_device == launch_device or (launch_device == "cuda" and
                                             array_device.startswith("cuda"))


def _pack_fast(kernel: Kernel, plan: _LaunchPlan, device: str, args: list):
    """(ArgValues, ArgPacker or None, resolved args, the ArgValues as serialized
    LaunchCommand.args fields): weft arrays and Python scalars on the fast path (their fields
    cached), anything else (NumPy arrays, structs, vectors, errors) through ArgPacker,
    parameter by parameter; resolved = the arguments as launched (temporaries substituted)."""
    if len(args) != plan.n_params:
        raise WeftLaunchError(f"Invalid number of arguments for kernel '{kernel.key}': expected "
                              f"{plan.n_params} ({', '.join(kernel.param_names)}), "
                              f"got {len(args)}")
    packed = []
    fields = []
    packer = None
    resolved = args
    array_type = _array_type()
    ctype_type = _ctype_type()
    arg_value = _pb().ArgValue
    for i, (p, value) in enumerate(zip(plan.params, args)):
        if p.is_array:
            if type(value) is ctype_type:        # an array's ctypes descriptor (return_ctype=True)
                owner = value._weft_value if hasattr(value, "_weft_value") else None
                if isinstance(owner, array_type):
                    if resolved is args:
                        resolved = list(args)
                    resolved[i] = value = owner
            if isinstance(value, array_type):
                c = _array_arg(value) if value._mirror is None else None   # a mirror: the packer
                if c is not None and (p.elem_any or c[6] == p.elem_text) and c[7] == p.ndim and \
                        _device_matches(c[8], device):
                    packed.append(c[9])
                    fields.append(c[10])
                    continue
            else:
                known = _framework_arg(value, p, device)
                if known is not None:
                    c = _array_arg(known)
                    packed.append(c[9])
                    fields.append(c[10])
                    if resolved is args:
                        resolved = list(args)
                    resolved[i] = known
                    continue
        elif p.pack_float is not None:
            if type(value) is float or type(value) is int:
                try:
                    raw = p.pack_float(value)
                except OverflowError:        # float32 overflow: NumPy's inf, slow path
                    raw = None
                if raw is not None:
                    if raw != p.last_raw:
                        p.last_raw, p.last_arg = raw, arg_value(raw=raw)
                        p.last_field = _field(_LAUNCH_ARGS, p.last_arg.SerializeToString())
                    packed.append(p.last_arg)
                    fields.append(p.last_field)
                    continue
        elif p.pack_int is not None:
            if type(value) is int and p.int_range[0] <= value <= p.int_range[1]:
                raw = p.pack_int(value)
                if raw != p.last_raw:
                    p.last_raw, p.last_arg = raw, arg_value(raw=raw)
                    p.last_field = _field(_LAUNCH_ARGS, p.last_arg.SerializeToString())
                packed.append(p.last_arg)
                fields.append(p.last_field)
                continue
        elif p.composite_dtype is not None:
            cls = type(value)
            if cls is p.composite_cls or (p.composite_cls is None and
                                          _composite_matches(cls, p)):
                data = value._data
                if data.dtype == p.composite_dtype:
                    raw = data.tobytes()
                    if raw != p.last_raw:
                        p.last_raw, p.last_arg = raw, arg_value(raw=raw)
                        p.last_field = _field(_LAUNCH_ARGS, p.last_arg.SerializeToString())
                    packed.append(p.last_arg)
                    fields.append(p.last_field)
                    continue
        if packer is None:
            packer = ArgPacker(kernel, device)
        copy_backs = len(packer.copy_backs)
        arg, launched = packer.pack(p.name, p.type_text, p.annotation, value)
        packed.append(arg)
        fields.append(_field(_LAUNCH_ARGS, arg.SerializeToString()))
        if p.is_array and len(packer.copy_backs) == copy_backs:
            _remember_framework_arg(value, p, device, launched)
        if launched is not value:
            if resolved is args:
                resolved = list(args)
            resolved[i] = launched
    return packed, packer, resolved, fields


def _composite_matches(cls, p) -> bool:
    """True (and remembered on p) when cls is a weft value class whose values pack as p's
    vector, matrix, quaternion or transform type: as many components, stored as p's scalar
    (the bytes ArgPacker would produce, without the conversion)."""
    from weft.types import _Composite  # noqa: PLC0415

    if not (isinstance(cls, type) and issubclass(cls, _Composite)) or \
            int(np.prod(cls._shape_)) != p.desc.count:
        return False
    if np.dtype(cls._value_dtype_) != p.composite_dtype:
        return False
    p.composite_cls = cls
    return True


_ARRAY_TYPE = None


def _array_type():
    global _ARRAY_TYPE
    if _ARRAY_TYPE is None:
        from weft.array import array  # noqa: PLC0415

        _ARRAY_TYPE = array
    return _ARRAY_TYPE


_CTYPE_TYPE = None


def _ctype_type():
    """weft.array.array_t: what array.__ctype__() (and from_torch(return_ctype=True)) gives."""
    global _CTYPE_TYPE
    if _CTYPE_TYPE is None:
        from weft.array import array_t  # noqa: PLC0415

        _CTYPE_TYPE = array_t
    return _CTYPE_TYPE


_TAPE_MOD = None
_RUNTIME_MOD = None


def _modules():
    global _TAPE_MOD, _RUNTIME_MOD
    if _TAPE_MOD is None:
        from weft import _runtime  # noqa: PLC0415

        from . import tape as tape_mod  # noqa: PLC0415

        _TAPE_MOD, _RUNTIME_MOD = tape_mod, _runtime
    return _TAPE_MOD, _RUNTIME_MOD


_DEVICE_NAMES: dict = {}        # device object -> its name (devices are long-lived singletons)


def _launch_device(device, args) -> str:
    if device is None:
        array_type = _array_type()
        for a in args:
            if isinstance(a, array_type):
                device = a.device
                break
        else:
            return device_name(None)
    if type(device) is str:
        return device
    try:
        return _DEVICE_NAMES[device]
    except (KeyError, TypeError):
        pass
    name = device_name(device)
    try:
        _DEVICE_NAMES[device] = name
    except TypeError:
        pass
    return name


def cpu_lanes(device: str, block_dim) -> int:
    """The threads of one CPU block a launch runs cooperatively (Warp's rule): block_dim from 2
    to 1024 when wp.config.enable_cpu_blocks is set, else 1 (one thread per block; block_dim
    None or below 1 also selects 1). Raises Warp's ValueError above 1024."""
    if device != "cpu" or not block_dim or block_dim < 2:
        return 1
    if block_dim > 1024:
        raise ValueError(f"block_dim must be at most 1024 on CPU, got {block_dim}")
    return int(block_dim) if _config.enable_cpu_blocks else 1


def launch(kernel, dim, inputs=(), outputs=(), adj_inputs=(), adj_outputs=(), device=None,
           stream=None, adjoint=False, record_tape=True, record_cmd=False, max_blocks=0,
           block_dim=None):
    """wp.launch: runs kernel over dim (an int or a tuple of up to 4 ints) on device."""
    if not isinstance(kernel, Kernel):
        raise WeftLaunchError(f"wp.launch expects a @wp.kernel, got {type(kernel).__name__}")
    if _config.print_launches:
        from weft.logger import get_logger  # noqa: PLC0415

        get_logger().info(f"kernel: {kernel.key} dim: {dim} inputs: {list(inputs or [])} outputs: "
                          f"{list(outputs or [])} device: {_launch_device(device, [*inputs, *outputs])}")
    if type(dim) is int and dim >= 0:
        dims = [dim]
    else:
        dims = normalize_dim(dim)
    args = [*inputs, *outputs] if outputs else list(inputs or [])
    device = _launch_device(device, args)
    lanes = cpu_lanes(device, block_dim)
    if max_blocks and max_blocks > 0 and device.startswith("cuda") and not module_mod.grid_stride_of(kernel):
        raise WeftLaunchError(
            f"Kernel '{kernel.key}' was launched with max_blocks={max_blocks}, but it was compiled "
            f"without a grid-stride loop (grid_stride=False); capping the block count requires a "
            f"grid-stride loop: @wp.kernel(grid_stride=True), the \"default_grid_stride\" module "
            f"option or wp.config.default_grid_stride=True")
    if record_cmd:
        return Launch(kernel, device, dims, args,
                      list(adj_inputs or []) + list(adj_outputs or []), adjoint,
                      max_blocks, block_dim)
    tape_mod, _runtime = _modules()
    rt = _runtime.get_runtime()
    if _config.verify_autograd_array_access and not adjoint and record_tape and \
            tape_mod.active_tape() is not None and not kernel.__dict__.get("_weft_internal"):
        from . import array_access  # noqa: PLC0415
        array_access.check_launch(kernel, args)
    frame = None                       # the command as bytes (SubmitRequest.commands element)
    generic = kernel.__dict__.get("_weft_is_generic")
    if generic is None:
        generic = kernel.__dict__["_weft_is_generic"] = bool(kernel.is_generic)
    if not adjoint and not generic:
        if len(args) != len(kernel.param_names):     # before compiling, as the slow path does
            pack_arguments(kernel, device, args)
        plan = _launch_plan(kernel, device, rt, lanes)
        # the command as bytes (no message) unless launch options go in it
        as_bytes = lanes <= 1 and not max_blocks and \
            not (block_dim and block_dim > 0 and block_dim != 256 and device != "cpu")
        if as_bytes:
            _, origin, origin_field = caller_origin_entry()
            if plan.native is not None:
                # the whole command in C (weft._launch_frame), or None: an argument the
                # Python path converts or rejects
                frame = _NATIVE.frame(plan.native, dims, args, device, origin_field)
        if frame is None:
            packed, packer, resolved, fields = _pack_fast(kernel, plan, device, args)
        else:
            packer, resolved = None, args
    else:
        plan = None
        as_bytes = False
        if generic:
            kernel = kernel.specialize(infer_param_types(kernel, args))
        packed, packer = pack_arguments(kernel, device, args)
        resolved = packer.resolved
        adj_packed = []
        if adjoint:
            adj_args = list(adj_inputs or []) + list(adj_outputs or [])
            adj_packed = adjoint_arguments(kernel, device, packer.resolved, adj_args)
        compiled, info = module_mod.compile_kernel(kernel, device, backward=bool(adjoint), lanes=lanes)
        module_id, kernel_name = compiled.module_id, info.name or kernel.name
    for d in dims:
        if d == 0:
            return None
    shared = _interop_memory.any_shared() and _interop_memory.touches_shared(resolved)
    gpu_order = None                   # (GPU ordinals, their framework streams) ordered on the GPU
    if shared and device.startswith("cuda"):
        gpu_order = _order_framework_gpu(rt, resolved, device)  # framework work before: seen first
    tape = tape_mod.active_tape()
    pause = tape is not None and (adjoint or not record_tape)
    if pause:
        tape.pause_recording()
    if as_bytes:
        if frame is None:     # not built in C above: the plan's fields, the dimensions, the
            # arguments' cached fields and the call site's (what the message would serialize to)
            frame = launch_frame_bytes(plan.template_bytes, dims, fields, origin_field)
    elif plan is not None:
        pb = _pb()
        command = pb.Command()
        command.CopyFrom(plan.template)
        launch_cmd = command.launch
        launch_cmd.dim.extend(dims)
        launch_cmd.args.extend(packed)
        command.origin.CopyFrom(caller_origin())
    else:
        pb = _pb()
        command = pb.Command(
            launch=pb.LaunchCommand(module_id=module_id, kernel=kernel_name, dim=dims,
                                    args=packed, adjoint=bool(adjoint), adj_args=adj_packed,
                                    device=device),
            origin=caller_origin())
    if frame is None:
        origin = command.origin
        if lanes > 1:                             # cooperative CPU blocks: the kernel's lanes
            command.launch.block_dim = lanes      # (also what wp.block_dim() gives a kernel without tiles)
        elif block_dim and block_dim > 0 and block_dim != 256 and device != "cpu":
            command.launch.block_dim = int(block_dim)   # GPU launch geometry (Warp's options)
        if max_blocks:
            command.launch.max_blocks = int(max_blocks)
    start = False
    if device.startswith("cuda"):       # a large GPU kernel starts at once (Runtime.submit)
        threads = 1
        for d in dims:
            threads *= d
        start = threads >= _runtime.START_GPU_THREADS
        rt.gpu_work = True              # the next synchronize waits for the GPU
    if frame is not None:
        if not (_runtime.LANE_EAGER and device.startswith("cuda") and rt.submit_eager(frame)):
            rt.submit_framed(frame, start)
    else:
        rt.submit(command, start)
    if pause:
        tape.resume_recording()
    elif tape is not None:
        temps = packer.temps if packer is not None else ()
        tape.record_launch(kernel, dims, list(resolved), device, temps, lanes)
    if packer is not None and packer.copy_backs:
        rt.synchronize()
        for pending in packer.copy_backs:
            pending.apply()
    elif gpu_order:
        # memory a framework holds: its stream waits for the launch on the GPU
        _cuda_order().after(rt, gpu_order[0], sources=gpu_order[1])
    elif shared:
        rt.synchronize()       # memory a framework holds: done before the framework reads it
    if _config.verify_fp:
        verify_finite(kernel, resolved, origin)
    return None


def launch_tiled(kernel, dim, inputs=(), outputs=(), adj_inputs=(), adj_outputs=(), device=None,
                 stream=None, adjoint=False, record_tape=True, record_cmd=False, max_blocks=0,
                 block_dim=None):
    """wp.launch_tiled: a launch of one block per tile, `dim` counting tiles. A block runs as
    one thread (Warp's rule on the CPU; weft's on a GPU: tiles belong to the thread computing
    them, docs/tiles.md), so wp.tid() in the kernel gives the tile's index and `block_dim` is
    the launch's thread-block size on a GPU. On the CPU with wp.config.enable_cpu_blocks, a
    block runs block_dim cooperating lanes and the launch is dim + [block_dim], as Warp's."""
    if type(dim) is int:
        dim = [dim]
    if _config.enable_cpu_blocks and block_dim and block_dim > 1 and \
            cpu_lanes(_launch_device(device, [*inputs, *outputs] if outputs else list(inputs or [])), block_dim) > 1:
        dim = [*normalize_dim(dim), int(block_dim)]
    return launch(kernel, dim, inputs, outputs, adj_inputs, adj_outputs, device=device, stream=stream,
                  adjoint=adjoint, record_tape=record_tape, record_cmd=record_cmd,
                  max_blocks=max_blocks, block_dim=block_dim)


def _order_framework_gpu(rt, values, device: str = "cuda"):
    """Makes a launch in the daemon see this process's GPU work (Torch, CuPy, ... streams) on
    the devices of the shared weft GPU arrays among `values`. With interprocess events
    (weft.interop.cuda_order): the session's stream waits for the framework stream, and
    (the GPU ordinals, {ordinal: framework stream}) is returned: the caller orders those
    streams after the launch. Without: a host wait for this process's work on those devices;
    returns None. `device`: the launch's; on "cuda:N" every GPU array of the launch is on N
    (packing refused any other), so the arrays are not walked for their devices."""
    cuda_order = _cuda_order()
    if device.startswith("cuda:"):
        ordinals = _LAUNCH_ORDINALS.get(device)
        if ordinals is None:
            ordinals = _LAUNCH_ORDINALS[device] = frozenset((int(device[5:]),))
    else:
        ordinals = cuda_order.gpu_ordinals(values)
    if cuda_order.enabled(rt, ordinals):
        return ordinals, cuda_order.before(rt, ordinals)
    from weft import _cuda_ipc  # noqa: PLC0415

    for ordinal in ordinals:
        _cuda_ipc.synchronize(ordinal)
    return None


_CUDA_ORDER = None
_LAUNCH_ORDINALS: dict = {}    # "cuda:N" -> frozenset({N})


def _cuda_order():
    """weft.interop.cuda_order, imported once (an import statement costs ~1 us per launch)."""
    global _CUDA_ORDER
    if _CUDA_ORDER is None:
        from weft.interop import cuda_order  # noqa: PLC0415

        _CUDA_ORDER = cuda_order
    return _CUDA_ORDER


def verify_finite(kernel: Kernel, args, origin) -> None:
    """wp.config.verify_fp: raises FloatingPointError when a float array argument of the
    launch holds a NaN or an inf after it ran (waits for the launch)."""
    import weft  # noqa: PLC0415

    weft.synchronize()
    for name, value in zip(kernel.param_names, args):
        if not is_weft_array(value) or value.size == 0:
            continue
        data = np.asarray(value.numpy())
        if data.dtype.kind not in "fc" and not (data.dtype.fields and any(
                f[0].base.kind == "f" for f in data.dtype.fields.values())):
            continue
        if data.dtype.fields:
            bad = any(not np.isfinite(data[f]).all() for f, v in data.dtype.fields.items()
                      if v[0].base.kind == "f")
        else:
            bad = not np.isfinite(data).all()
        if bad:
            where = f"{origin.file}:{origin.line}: " if origin.file else ""
            raise FloatingPointError(f"{where}kernel '{kernel.key}': array argument '{name}' "
                                     f"holds a non-finite value (NaN or inf) after the launch "
                                     f"(wp.config.verify_fp)")


def _zero_argument(kernel: Kernel, name: str, type_text: str):
    """The value of an unset parameter of a wp.Launch: None for arrays, zero for numbers and for
    every component of vectors, matrices, quaternions and transforms, a default struct."""
    desc = typestr.parse(type_text)
    if desc.kind in ("array", "indexedarray"):
        return None
    annotation = kernel.definition.annotations.get(name)
    if desc.kind == "struct":
        return annotation()
    if desc.kind == "scalar":
        return False if desc.scalar == "bool" else 0
    return annotation(*([0] * desc.count))


class Launch:
    """What wp.launch(..., record_cmd=True) returns instead of launching (Warp's wp.Launch): the
    kernel, device, dim and arguments, checked and compiled once; launch() runs it with the
    arguments as they are then (not recorded on a tape, as in Warp); set_dim and set_param_*
    change them. The arguments are `fwd_args` and `adj_args` (Warp's names); `params` lists them
    in Warp's order: the launch bounds, the forward arguments, then (adjoint launches) the
    adjoint ones."""

    def __init__(self, kernel: Kernel, device, dim=0, params=None, adj_params=(), adjoint=False,
                 max_blocks=0, block_dim=None):
        device = device_name(device) if not isinstance(device, str) else device
        adj_params = list(adj_params)
        if params is None:
            # wp.Launch(kernel, device): every parameter at its type's zero (arrays None), set
            # later with set_param_*; a generic kernel needs its arguments to pick an instance
            if kernel.is_generic:
                raise WeftLaunchError(f"wp.Launch of generic kernel '{kernel.key}' needs its "
                                      f"params (they choose the instance)")
            params = [_zero_argument(kernel, name, text)
                      for name, text in zip(kernel.param_names, kernel.param_types)]
            if adjoint and not adj_params:
                # adjoint values at zero too, as Warp's; structs None (their arrays' .grad)
                adj_params = [None if typestr.parse(text).kind == "struct" else zero
                              for text, zero in zip(kernel.param_types, params)]
        if kernel.is_generic:
            kernel = kernel.specialize(infer_param_types(kernel, list(params)))
        self.kernel = kernel
        self.device = device
        self.adjoint = bool(adjoint)
        self.max_blocks = max_blocks
        self.block_dim = block_dim
        self.dim = normalize_dim(dim)
        self.fwd_args = list(params)
        self.adj_args = adj_params + [None] * (len(self.fwd_args) - len(adj_params))
        pack_arguments(kernel, device, self.fwd_args)       # argument errors raise here
        module_mod.compile_kernel(kernel, device, backward=self.adjoint,
                                  lanes=cpu_lanes(device, block_dim))

    @property
    def params(self) -> list:
        """Warp's parameter list: the bounds (the launch dimensions), the forward arguments,
        then the adjoint arguments of an adjoint launch (a copy: set them with set_param_*)."""
        return [tuple(self.dim), *self.fwd_args, *(self.adj_args if self.adjoint else ())]

    def set_dim(self, dim) -> None:
        self.dim = normalize_dim(dim)

    def _index(self, name: str) -> int:
        try:
            return self.kernel.param_names.index(name)
        except ValueError:
            raise KeyError(f"kernel '{self.kernel.key}' has no parameter '{name}'") from None

    def set_param_at_index(self, index: int, value, adjoint: bool = False) -> None:
        if not 0 <= index < len(self.fwd_args):
            raise IndexError(f"kernel '{self.kernel.key}' has {len(self.fwd_args)} parameters, "
                             f"index {index} is out of range")
        if adjoint:
            self.adj_args[index] = value
            return
        name = self.kernel.param_names[index]
        ArgPacker(self.kernel, self.device).pack(name, self.kernel.param_types[index],
                                                 self.kernel.definition.annotations[name], value)
        self.fwd_args[index] = value

    def set_param_by_name(self, name: str, value, adjoint: bool = False) -> None:
        self.set_param_at_index(self._index(name), value, adjoint)

    def set_param_at_index_from_ctype(self, index: int, value, adjoint: bool = False) -> None:
        """Warp's setter from a ctypes value: a weft array's or struct's __ctype__() (the
        array, or the struct as it was then), a ctypes scalar, or a plain value."""
        if hasattr(value, "_weft_value"):
            value = value._weft_value
        elif isinstance(value, ctypes._SimpleCData):
            value = value.value
        elif isinstance(value, ctypes.Structure):
            raise TypeError(f"wp.Launch.set_param_at_index_from_ctype: a {type(value).__name__} "
                            f"that no weft array or struct made cannot be sent to weftd (it "
                            f"holds raw addresses); pass the array or struct itself")
        self.set_param_at_index(index, value, adjoint)

    def set_param_by_name_from_ctype(self, name: str, value, adjoint: bool = False) -> None:
        self.set_param_at_index_from_ctype(self._index(name), value, adjoint)

    def set_params(self, values) -> None:
        for i, value in enumerate(values):
            self.set_param_at_index(i, value)

    def launch(self, stream=None) -> None:
        launch(self.kernel, self.dim, inputs=self.fwd_args,
               adj_inputs=self.adj_args if self.adjoint else (), adjoint=self.adjoint,
               device=self.device, record_tape=False, max_blocks=self.max_blocks,
               block_dim=self.block_dim)
