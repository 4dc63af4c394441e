"""Canonical weft type strings (docs/protocol.md): parsing them into descriptors, naming Python
types and weft dtypes as type strings, and packing Python values into a type's wire bytes."""
from __future__ import annotations

import dataclasses
import math
import typing

import numpy as np

SCALAR_NUMPY = {
    "bool": np.dtype(np.bool_),
    "int8": np.dtype(np.int8),
    "int16": np.dtype(np.int16),
    "int32": np.dtype(np.int32),
    "int64": np.dtype(np.int64),
    "uint8": np.dtype(np.uint8),
    "uint16": np.dtype(np.uint16),
    "uint32": np.dtype(np.uint32),
    "uint64": np.dtype(np.uint64),
    "float16": np.dtype(np.float16),
    "float32": np.dtype(np.float32),
    "float64": np.dtype(np.float64),
    "bfloat16": np.dtype(np.uint16),   # stored as its 16 bits (float32's upper half)
}
FLOAT_SCALARS = ("float16", "float32", "float64", "bfloat16")


def float32_to_bfloat16_bits(values) -> np.ndarray:
    """bfloat16 bit patterns (uint16) of float values: round to nearest even, NaN stays a quiet
    NaN (Warp's conversion)."""
    f = np.asarray(values, dtype=np.float32)
    bits = f.view(np.uint32).astype(np.uint64)
    nan = np.isnan(f)
    rounded = (bits + 0x7FFF + ((bits >> 16) & 1)) >> 16
    out = np.where(nan, (bits >> 16) | 0x40, rounded)
    return out.astype(np.uint16)


def bfloat16_bits_to_float32(bits) -> np.ndarray:
    """float32 values of bfloat16 bit patterns."""
    return (np.asarray(bits, dtype=np.uint16).astype(np.uint32) << 16).view(np.float32)


def to_bfloat16_bits(values) -> np.ndarray:
    """bfloat16 storage of values: uint16 arrays are taken as bit patterns already (Warp),
    ml_dtypes.bfloat16 arrays as their bits, anything else converted from float."""
    if isinstance(values, np.ndarray) and values.dtype == np.uint16:
        return values
    if isinstance(values, np.ndarray) and values.dtype.name == "bfloat16":
        return values.view(np.uint16)
    return float32_to_bfloat16_bits(values)
INT_SCALARS = ("int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64")


@dataclasses.dataclass(frozen=True)
class TypeDesc:
    """A parsed type string. kind: scalar vec mat quat transform array struct any."""

    kind: str
    text: str
    scalar: str = ""                 # element scalar of scalar/vec/mat/quat/transform
    shape: tuple = ()                # value shape: () scalar, (N,) vec, (R, C) mat, (4,) quat, (7,) transform
    elem: typing.Optional["TypeDesc"] = None   # arrays: element type
    ndim: int = 0                    # arrays
    struct_name: str = ""            # structs

    @property
    def is_value(self) -> bool:
        """True for types passed as raw bytes (scalars, vectors, matrices, quats, transforms)."""
        return self.kind in ("scalar", "vec", "mat", "quat", "transform")

    @property
    def numpy_scalar(self) -> np.dtype:
        return SCALAR_NUMPY[self.scalar]

    @property
    def count(self) -> int:
        return int(np.prod(self.shape)) if self.shape else 1

    @property
    def byte_size(self) -> int:
        return self.numpy_scalar.itemsize * self.count


def _split_args(inner: str) -> list:
    """Splits "a,b(c,d),e" at top-level commas."""
    parts, depth, start = [], 0, 0
    for i, ch in enumerate(inner):
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(inner[start:i])
            start = i + 1
    parts.append(inner[start:])
    return parts


_PARSE_CACHE: dict = {}


def parse(text: str) -> TypeDesc:
    """Parses a canonical type string; raises ValueError on anything else."""
    cached = _PARSE_CACHE.get(text)
    if cached is not None:
        return cached
    desc = _parse(text)
    _PARSE_CACHE[text] = desc
    return desc


# Scalar patterns of generic annotations: typing.Any, wp.Int, wp.Float, wp.Scalar.
SCALAR_PATTERNS = ("any", "any_int", "any_float", "any_scalar")


def _extent(text: str) -> int:
    """A vector length or matrix extent; "any" (a generic annotation) is 0."""
    return 0 if text == "any" else int(text)


def _parse(text: str) -> TypeDesc:
    if text in SCALAR_NUMPY:
        return TypeDesc("scalar", text, scalar=text)
    if text in SCALAR_PATTERNS:
        return TypeDesc("any", text, scalar=text)
    if "(" not in text or not text.endswith(")"):
        raise ValueError(f"not a weft type string: {text!r}")
    head, inner = text.split("(", 1)
    args = _split_args(inner[:-1])
    if head == "vec" and len(args) == 2:
        return TypeDesc("vec", text, scalar=args[1], shape=(_extent(args[0]),))
    if head == "mat" and len(args) == 3:
        return TypeDesc("mat", text, scalar=args[2], shape=(_extent(args[0]), _extent(args[1])))
    if head == "quat" and len(args) == 1:
        return TypeDesc("quat", text, scalar=args[0], shape=(4,))
    if head == "transform" and len(args) == 1:
        return TypeDesc("transform", text, scalar=args[0], shape=(7,))
    if head == "array" and len(args) == 2:
        return TypeDesc("array", text, elem=parse(args[0]), ndim=int(args[1]))
    if head == "fixedarray" and 2 <= len(args) <= 5:
        return TypeDesc("fixedarray", text, elem=parse(args[0]), ndim=len(args) - 1,
                        shape=tuple(int(a) for a in args[1:]))
    if head == "indexedarray" and len(args) == 2:
        return TypeDesc("indexedarray", text, elem=parse(args[0]), ndim=int(args[1]))
    if head == "struct" and len(args) == 1:
        return TypeDesc("struct", text, struct_name=args[0])
    raise ValueError(f"not a weft type string: {text!r}")


def _scalar_accepts(pattern: str, scalar: str) -> bool:
    if pattern == "any":
        return True
    if pattern == "any_int":
        return scalar in INT_SCALARS
    if pattern == "any_float":
        return scalar in FLOAT_SCALARS
    if pattern == "any_scalar":
        return scalar in INT_SCALARS or scalar in FLOAT_SCALARS
    return pattern == scalar


def is_generic(text: str) -> bool:
    """Whether a type string is a generic pattern or holds one (`any`, `any_int`,
    `vec(any,float32)`, `array(any,1)`, `tuple(any_float,int32)`); a struct's name never makes
    it one. Strings this parser does not know (function, ref(...)) are not patterns."""
    if text in SCALAR_PATTERNS:
        return True
    if "any" not in text:
        return False                         # the common case, without parsing
    head = text.split("(", 1)[0]
    if head == "tuple" or head == "ref":
        return any(is_generic(a) for a in _split_args(text[len(head) + 1:-1]))
    try:
        d = parse(text)
    except ValueError:
        return False
    if d.kind in ("array", "indexedarray", "fixedarray"):
        return is_generic(d.elem.text)
    return d.kind in ("vec", "mat", "quat", "transform") and (
        d.scalar in SCALAR_PATTERNS or 0 in d.shape)


def accepts(pattern: str, concrete: str) -> bool:
    """Whether a parameter type of a generic annotation (typing.Any, wp.Int/Float/Scalar, a
    vector of any length, an array of any element, ...) takes a value of type `concrete`
    (the daemon applies the same rule to @wp.func calls)."""
    if pattern == concrete or pattern == "any":
        return True
    try:
        p, c = parse(pattern), parse(concrete)
    except ValueError:
        return False
    if p.kind == "any":
        return p.scalar == "any" or (c.kind == "scalar" and _scalar_accepts(p.scalar, c.scalar))
    if p.kind != c.kind:
        return False
    if p.kind in ("array", "indexedarray"):
        return p.ndim == c.ndim and accepts(p.elem.text, c.elem.text)
    if p.kind in ("vec", "mat", "quat", "transform"):
        return _scalar_accepts(p.scalar, c.scalar) and all(
            a == 0 or a == b for a, b in zip(p.shape, c.shape))
    return False


def vec_str(length: int, scalar: str) -> str:
    return f"vec({int(length)},{scalar})"


def mat_str(rows: int, cols: int, scalar: str) -> str:
    return f"mat({int(rows)},{int(cols)},{scalar})"


def array_str(elem: str, ndim: int) -> str:
    return f"array({elem},{int(ndim)})"


# --------------------------------------------------------------------------------------------
# Naming Python objects as type strings
# --------------------------------------------------------------------------------------------

_NUMPY_TO_SCALAR = {v: k for k, v in SCALAR_NUMPY.items() if k != "bfloat16"}


def _scalar_name_of(obj) -> typing.Optional[str]:
    """The scalar type string of a scalar type object (Python, NumPy or weft), else None."""
    if obj is float:
        return "float32"
    if obj is int:
        return "int32"
    if obj is bool:
        return "bool"
    try:
        dt = np.dtype(obj) if isinstance(obj, type) and issubclass(obj, np.generic) else None
    except TypeError:
        dt = None
    if dt is not None and dt in _NUMPY_TO_SCALAR:
        return _NUMPY_TO_SCALAR[dt]
    return None


class FabricArrayRefused(TypeError):
    """type_string of a Fabric array type: such a kernel parameter or struct field can be
    declared (Warp's test files declare them beside other kernels), and the refusal is raised
    when a module using it is built."""


def type_string(obj) -> str:
    """The canonical type string of a type object used in an annotation, a struct field, a
    constructor or an array dtype. Raises TypeError when obj is not a type weft knows."""
    if obj is typing.Any:
        return "any"
    if getattr(obj, "_weft_function_type_", False) and isinstance(obj, type):
        return "function"      # wp.Function: a parameter taking a @wp.func or builtin
    if getattr(obj, "_fabric_", False) is True:
        raise FabricArrayRefused(f"{obj!r}: weft does not support Fabric arrays in kernels")
    if typing.get_origin(obj) is typing.Union or type(obj).__name__ == "UnionType":
        raise TypeError("Union type annotations are only supported at Python scope and are "
                        "invalid in Warp kernels/functions")
    if getattr(typing.get_origin(obj), "__name__", "") == "ref" and \
            getattr(typing.get_origin(obj), "__module__", "").startswith("weft."):
        return f"ref({type_string(typing.get_args(obj)[0])})"
    if typing.get_origin(obj) is tuple:
        # tuple[int, float] parameters and returns; tuple[int, ...] takes any tuple
        args = typing.get_args(obj)
        if not args or Ellipsis in args:
            return "any"
        return "tuple(" + ",".join(type_string(a) for a in args) + ")"
    scalar = _scalar_name_of(obj)
    if scalar is not None:
        return scalar
    # @wp.struct types, weft dtypes (B1) and our own annotation objects all carry _type_str.
    own = getattr(obj, "_type_str", None)
    if isinstance(own, str) and own:
        return own
    if callable(own):
        try:
            text = own()
            if isinstance(text, str):
                return text
        except TypeError:
            pass
    # weft.types.type_str knows every dtype of the array layer.
    try:
        from weft import types as weft_types  # noqa: PLC0415 - optional, written by B1

        fn = getattr(weft_types, "type_str", None)
        if fn is not None:
            text = fn(obj)
            if isinstance(text, str) and text:
                return text
    except Exception:  # noqa: BLE001 - fall through to the structural rules below
        pass
    # Warp-style dtype classes: _wp_scalar_type_ with _shape_ / _length_.
    scalar_type = getattr(obj, "_wp_scalar_type_", None)
    if scalar_type is not None:
        s = type_string(scalar_type)
        generic = getattr(obj, "_wp_generic_type_str_", "")
        shape = tuple(getattr(obj, "_shape_", ()) or ())
        if generic.startswith("quat"):
            return f"quat({s})"
        if generic.startswith("transform"):
            return f"transform({s})"
        if len(shape) == 1:
            return vec_str(shape[0], s)
        if len(shape) == 2:
            return mat_str(shape[0], shape[1], s)
    # Array annotations: anything with a dtype and an ndim (B1's array used as a type, ours).
    array_text = array_type_string(obj)
    if array_text is not None:
        return array_text
    raise TypeError(f"weft cannot use {obj!r} as a kernel type")


def array_type_string(obj) -> typing.Optional[str]:
    """array(T,N) for an array annotation object, or None when obj is not one."""
    # typing-style generic aliases: wp.array[float], wp.array2d[wp.vec3]
    origin = getattr(obj, "__origin__", None)
    args = getattr(obj, "__args__", None)
    if origin is not None and args:
        if getattr(origin, "_indexed_", False):
            from weft.indexedarray import annotation_ndim  # noqa: PLC0415

            return f"indexedarray({type_string(args[0])},{annotation_ndim(origin, args)})"
        ndim = getattr(origin, "_default_ndim_", None) or getattr(origin, "ndim", None)
        if not isinstance(ndim, int):
            ndim = _ndim_from_name(getattr(origin, "__name__", ""))
        if ndim:
            return array_str(type_string(args[0]), ndim)
    dtype = getattr(obj, "dtype", None)
    ndim = getattr(obj, "ndim", None)
    if dtype is not None and isinstance(ndim, int) and not isinstance(obj, type) \
            and not isinstance(obj, np.ndarray):
        if getattr(obj, "_indexed_", False):
            return f"indexedarray({type_string(dtype)},{ndim})"
        return array_str(type_string(dtype), ndim)
    return None


def _ndim_from_name(name: str) -> int:
    name = name.lower()
    for n in (1, 2, 3, 4):
        if name.endswith(f"array{n}d"):
            return n
    if name.endswith("array"):
        return 1
    return 0


# --------------------------------------------------------------------------------------------
# Values
# --------------------------------------------------------------------------------------------

def value_components(value) -> typing.Optional[np.ndarray]:
    """The flat components of a vector/matrix/quat/transform value as float64/int NumPy, or None
    for a plain scalar."""
    if isinstance(value, (bool, int, float, np.generic)):
        return None
    if isinstance(value, np.ndarray):
        return value.reshape(-1)
    if hasattr(value, "__array__"):
        return np.asarray(value).reshape(-1)
    try:
        return np.asarray(list(_flatten(value))).reshape(-1)
    except TypeError:
        return None


def _flatten(value):
    try:
        iterator = iter(value)
    except TypeError:
        yield value
        return
    for item in iterator:
        if isinstance(item, (bool, int, float, np.generic)):
            yield item
        else:
            yield from _flatten(item)


def pack_value(desc: TypeDesc, value) -> bytes:
    """Little-endian bytes of value as type desc (a scalar, vector, matrix, quat, transform),
    converting as Warp does (Python float -> float32, ...). Raises TypeError/ValueError."""
    dt = desc.numpy_scalar.newbyteorder("<")
    if desc.kind == "scalar":
        inner = getattr(value, "value", None)
        if not isinstance(value, (bool, int, float, np.generic)) and \
                isinstance(inner, (bool, int, float, np.generic)):
            value = inner            # a weft scalar instance: wp.float64(2.0)
        if not isinstance(value, (bool, int, float, np.generic)):
            comps = value_components(value)
            if comps is not None and comps.size == 1:
                value = comps[0]
            else:
                value = _scalar_of_weft_value(value)
        if desc.scalar in INT_SCALARS and isinstance(value, (float, np.floating)):
            raise TypeError(f"expected an integer of type {desc.scalar}, got float {value!r}")
        if desc.scalar in INT_SCALARS:
            info = np.iinfo(dt)
            iv = int(value)
            # wrap like a C cast, as Warp's ctypes conversion does
            iv = (iv - info.min) % (int(info.max) - int(info.min) + 1) + info.min
            return np.array(iv, dtype=dt).tobytes()
        if desc.scalar == "bfloat16":
            return float32_to_bfloat16_bits(float(value)).astype(dt).tobytes()
        return np.array(value, dtype=dt).tobytes()
    comps = value_components(value)
    if comps is None:
        raise TypeError(f"expected a value of type {desc.text}, got {type(value).__name__} {value!r}")
    if comps.size != desc.count:
        raise ValueError(f"expected {desc.count} components for {desc.text}, got {comps.size}")
    if desc.scalar == "bfloat16":
        return float32_to_bfloat16_bits(np.asarray(comps, dtype=np.float64)).astype(dt).tobytes()
    return np.asarray(comps, dtype=np.float64 if desc.scalar in FLOAT_SCALARS else None) \
        .astype(dt).tobytes()


def _scalar_of_weft_value(value):
    """A weft scalar instance (e.g. wp.float64(2.0)) as a Python number."""
    for attr in ("value", "_value"):
        inner = getattr(value, attr, None)
        if isinstance(inner, (bool, int, float, np.generic)):
            return inner
    try:
        return float(value)
    except (TypeError, ValueError) as err:
        raise TypeError(f"expected a scalar, got {type(value).__name__} {value!r}") from err


def literal_text(desc: TypeDesc, value) -> str:
    """Python literal text of a constant value of type desc (Constant.value)."""
    if desc.kind == "scalar":
        if not isinstance(value, (bool, int, float, np.generic)):
            value = _scalar_of_weft_value(value)
        if desc.scalar == "bool":
            return "True" if bool(value) else "False"
        if desc.scalar in INT_SCALARS:
            return str(int(value))
        return _float_text(float(value), desc.scalar)
    comps = value_components(value)
    if comps is None:
        raise TypeError(f"constant {value!r} is not a {desc.text}")
    if desc.scalar in INT_SCALARS:
        items = [str(int(c)) for c in comps]
    elif desc.scalar == "bool":
        items = ["True" if c else "False" for c in comps]
    else:
        items = [_float_text(float(c), desc.scalar) for c in comps]
    return "(" + ", ".join(items) + ("," if len(items) == 1 else "") + ")"


def _float_text(f: float, scalar: str = "float64") -> str:
    """Shortest literal that reads back as the same value of `scalar`."""
    if math.isnan(f):
        return "nan"
    if math.isinf(f):
        return "inf" if f > 0 else "-inf"
    if scalar in ("float32", "float16"):
        text = str(SCALAR_NUMPY[scalar].type(f))
        if not math.isinf(float(text)):
            return text
    return repr(f)


def constant_type_of(value) -> typing.Optional[str]:
    """The type string of a Python/NumPy/weft value usable as a kernel constant, or None."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int32" if -2**31 <= value < 2**31 else "int64"
    if isinstance(value, float):
        return "float32"
    if isinstance(value, np.generic):
        return _NUMPY_TO_SCALAR.get(value.dtype)
    cls = type(value)
    try:
        text = type_string(cls)
    except TypeError:
        return None
    try:
        desc = parse(text)
    except ValueError:
        return None
    return text if desc.is_value else None
