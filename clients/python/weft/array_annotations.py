"""Subscript array annotations (Warp 1.19): `wp.array[float]`, `wp.array2d[wp.vec3]`,
`wp.array[wp.float64, Literal[2]]`, `wp.indexedarray[float, 2]`, `wp.fabricarray[float]`.

Each is a light object holding a dtype and a number of dimensions (no device, no memory): equal
and hashed by (array family, dtype, ndim), printed in the subscript form it was written in,
combinable with `|` into a typing.Union for Python-scope signatures (kernels refuse unions).
The kernel compiler reads `.dtype` and `.ndim` (weft._kernel.typestr.array_type_string).

Also here: the array-family helpers Warp's own code uses on arrays and annotations alike
(`array_type_id`, `concrete_array_type`, `matches_array_class`) and `get_type_code`, Warp's
short code of a type (the form its overload signatures use)."""
from __future__ import annotations

import sys
import typing
from typing import Any

ARRAY_MAX_DIMS = 4

# Warp's array family ids.
ARRAY_TYPE_REGULAR = 0
ARRAY_TYPE_INDEXED = 1
ARRAY_TYPE_FABRIC = 2
ARRAY_TYPE_FABRIC_INDEXED = 3


def _module(name: str):
    # weft.array is both a module and (after `import weft`) the name of the class: go by
    # sys.modules. The modules import this one, so they are looked up when first needed.
    __import__(name)
    return sys.modules[name]


_FAMILY_MODULE = {"array": "weft.array", "indexedarray": "weft.indexedarray",
                  "fabricarray": "weft.fabricarray", "indexedfabricarray": "weft.fabricarray"}


def _family_class(name: str):
    return getattr(_module(_FAMILY_MODULE[name]), name)


def single_literal(value, what: str):
    """N of `Literal[N]`; a bare value is returned as it is. Literal of several values: TypeError."""
    if typing.get_origin(value) is typing.Literal:
        values = typing.get_args(value)
        if len(values) != 1:
            raise TypeError(f"Expected a single Literal value for {what}, got {value!r}")
        return values[0]
    return value


def positive_extent(value, what: str) -> int:
    """A length or dimension written as N or Literal[N]: a positive integer, else TypeError."""
    value = single_literal(value, what)
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise TypeError(f"{what} must be a positive integer, got {value!r}")
    return value


def parse_ndim(value, cls_name: str):
    """The number of dimensions written in an annotation's second parameter: 1 to 4, or
    typing.Any (any number; Python-scope annotations only, kernels need a number)."""
    if value is Any:
        return Any
    value = single_literal(value, f"the number of dimensions of wp.{cls_name}")
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"wp.{cls_name}[dtype, ndim]: ndim must be an integer or Literal[N], "
                        f"got {value!r}")
    if not 1 <= value <= ARRAY_MAX_DIMS:
        raise ValueError(f"wp.{cls_name}: ndim must be between 1 and {ARRAY_MAX_DIMS}, got {value}")
    return value


def _canonical_dtype(dtype):
    """float -> float32 and the like; a type weft does not know passes unchanged (as in Warp:
    refused when a kernel using the annotation is built, not when it is written)."""
    if dtype is Any:
        return Any
    try:
        return _module("weft.array")._canonical_dtype(dtype)
    except TypeError:
        return dtype


class _ArrayAnnotationBase:
    """An array type in an annotation: dtype and ndim, no data."""

    __slots__ = ("dtype", "ndim", "_vars_cache")
    _family = "array"          # the array class it stands for
    _indexed_ = False
    _fabric_ = False

    def __init__(self, dtype, ndim: int = 1):
        self.dtype = _canonical_dtype(dtype)
        self.ndim = ndim
        self._vars_cache = None

    @property
    def _concrete_cls(self):
        return _family_class(self._family)

    @property
    def vars(self) -> dict:
        """What kernel code reads of such an array besides its elements: `shape` (ndim int32
        values) and `ndim`. Built once per annotation."""
        if self._vars_cache is None:
            types = _module("weft.types")
            shape = typing.Tuple[types.int32, ...] if self.ndim is Any else \
                typing.Tuple[(types.int32,) * self.ndim]
            self._vars_cache = {"shape": shape, "ndim": types.int32}
        return self._vars_cache

    def __ctype__(self):
        """A null array descriptor (array_t) of this ndim, as Warp gives for an annotation."""
        return _module("weft.array").array_t(data=0, ndim=0 if self.ndim is Any else self.ndim)

    def _dtype_repr(self) -> str:
        dtype = self.dtype
        if dtype is Any:
            return "Any"
        weft = _module("weft")
        name = getattr(dtype, "__name__", None)
        if name and getattr(weft, name, None) is dtype:
            return f"wp.{name}"
        text = _module("weft.types").type_repr(dtype)
        if getattr(weft, text, None) is dtype:
            return f"wp.{text}"
        key = getattr(dtype, "key", None)
        if isinstance(key, str):
            return key
        return text if getattr(dtype, "_wp_scalar_type_", None) is not None else (name or text)

    def __repr__(self) -> str:
        dtype = self._dtype_repr()
        if self.ndim is Any:
            return f"wp.{self._family}[{dtype}, Any]"
        if self._family == "array":
            return f"wp.array{self.ndim}d[{dtype}]" if self.ndim >= 2 else f"wp.array[{dtype}]"
        if self.ndim == 1:
            return f"wp.{self._family}[{dtype}]"
        return f"wp.{self._family}[{dtype}, Literal[{self.ndim}]]"

    def __eq__(self, other):
        if isinstance(other, _ArrayAnnotationBase):
            return (self._family == other._family and self.dtype == other.dtype
                    and self.ndim == other.ndim)
        return NotImplemented

    def __hash__(self):
        return hash((self._family, self.dtype, self.ndim))

    def __or__(self, other):
        return typing.Union[self, other]

    def __ror__(self, other):
        return typing.Union[other, self]


class _ArrayAnnotation(_ArrayAnnotationBase):
    """wp.array[...], wp.array1d[...] .. wp.array4d[...]."""

    __slots__ = ()


class _IndexedArrayAnnotation(_ArrayAnnotationBase):
    """wp.indexedarray[...]."""

    __slots__ = ()
    _family = "indexedarray"
    _indexed_ = True


class _FabricArrayAnnotation(_ArrayAnnotationBase):
    """wp.fabricarray[...] (Omniverse Fabric data; weft describes the type, kernels refuse it)."""

    __slots__ = ()
    _family = "fabricarray"
    _fabric_ = True


class _IndexedFabricArrayAnnotation(_ArrayAnnotationBase):
    """wp.indexedfabricarray[...] (as wp.fabricarray)."""

    __slots__ = ()
    _family = "indexedfabricarray"
    _fabric_ = True


_ANNOTATION_OF = {"array": _ArrayAnnotation, "indexedarray": _IndexedArrayAnnotation,
                  "fabricarray": _FabricArrayAnnotation,
                  "indexedfabricarray": _IndexedFabricArrayAnnotation}


def subscript(family: str, params) -> _ArrayAnnotationBase:
    """`wp.<family>[dtype]` or `wp.<family>[dtype, ndim]` (ndim an int or Literal[N])."""
    if not isinstance(params, tuple):
        params = (params,)
    if len(params) == 0:
        raise TypeError(f"wp.{family}[...] requires a dtype")
    if len(params) > 2:
        raise TypeError(f"wp.{family} expects 1 or 2 type parameters, got {len(params)}")
    ndim = parse_ndim(params[1], family) if len(params) == 2 else 1
    return _ANNOTATION_OF[family](params[0], ndim)


def subscript_fixed_ndim(family: str, name: str, ndim: int, params) -> _ArrayAnnotationBase:
    """`wp.array2d[dtype]` and the like: one dtype, the ndim is the name's."""
    if isinstance(params, tuple):
        raise TypeError(f"wp.{name} takes a single type parameter (the dtype), got {len(params)}")
    return _ANNOTATION_OF[family](params, ndim)


# ---------------------------------------------------------------------------------------------
# Array families

def concrete_array_type(t) -> type:
    """The array class of an array or annotation (weft.array, weft.indexedarray, ...); type(t)
    for anything else."""
    if isinstance(t, _ArrayAnnotationBase):
        return t._concrete_cls
    for family in ("indexedarray", "array"):      # fabric arrays have no instances in weft
        cls = _family_class(family)
        if isinstance(t, cls):
            return cls
    return type(t)


def matches_array_class(t, cls) -> bool:
    """True when `t` is an instance of array class `cls` or an annotation standing for it."""
    if isinstance(t, _ArrayAnnotationBase):
        return t._concrete_cls is cls
    return isinstance(t, cls)


def array_type_id(a) -> int:
    """ARRAY_TYPE_REGULAR / _INDEXED / _FABRIC / _FABRIC_INDEXED of an array or annotation."""
    family = concrete_array_type(a)
    for name, code in (("array", ARRAY_TYPE_REGULAR), ("indexedarray", ARRAY_TYPE_INDEXED),
                       ("fabricarray", ARRAY_TYPE_FABRIC),
                       ("indexedfabricarray", ARRAY_TYPE_FABRIC_INDEXED)):
        if family is _family_class(name):
            return code
    raise ValueError(f"Invalid array type {type(a).__name__}")


_FAMILY_PREFIX = {"array": "a", "indexedarray": "ia", "fabricarray": "fa",
                  "indexedfabricarray": "ifa"}


def get_type_code(arg_type) -> str:
    """Warp's short code of a type: i4 int32, f8 float64, v3f4 vec3f, m33f8 mat33d, qf4 quatf,
    tf4 transformf, a2f4 a 2-d float32 array, ia1? an indexed array of any dtype, tpl2i4f4 a
    tuple, ? a generic. Raises TypeError for what is not a type."""
    types = _module("weft.types")
    if arg_type is Any:
        return "?"
    if arg_type is Ellipsis:
        return "?"
    origin = typing.get_origin(arg_type)
    if origin is typing.Union or type(arg_type).__name__ == "UnionType":
        raise TypeError("Union type annotations are only supported at Python scope and are "
                        "invalid in Warp kernels/functions")
    if origin is tuple:
        args = typing.get_args(arg_type)
        return f"tpl{len(args)}" + "".join(get_type_code(x) for x in args)
    if types.is_array(arg_type) or isinstance(arg_type, _ArrayAnnotationBase):
        ndim = "?" if arg_type.ndim is Any else str(arg_type.ndim)
        dtype = "?" if arg_type.dtype is Any else get_type_code(arg_type.dtype)
        family = next(name for name, _ in _FAMILY_PREFIX.items()
                      if concrete_array_type(arg_type) is _family_class(name))
        return f"{_FAMILY_PREFIX[family]}{ndim}{dtype}"
    if arg_type is types.Scalar:
        return "s?"
    if arg_type is types.Float:
        return "f?"
    if arg_type is types.Int:
        return "i?"
    if arg_type is str:
        return "str"
    if arg_type in (bool, types.bool):
        return "b"
    if arg_type is int:
        return "i4"
    if arg_type is float:
        return "f4"
    if isinstance(arg_type, type) and issubclass(arg_type, types._Scalar):
        text = arg_type._type_str
        if text == "bfloat16":
            return "bf2"
        if text.startswith(("int", "uint", "float")):
            kind = {"int": "i", "uint": "u", "float": "f"}[text.rstrip("0123456789")]
            return f"{kind}{int(text.lstrip('uintfloa')) // 8}"
    if isinstance(arg_type, type) and getattr(arg_type, "_wp_scalar_type_", None) is not None:
        scalar = get_type_code(arg_type._wp_scalar_type_)
        generic = getattr(arg_type, "_wp_generic_type_str_", "")
        if generic.startswith("quat"):
            return f"q{scalar}"
        if generic.startswith("transform"):
            return f"t{scalar}"
        shape = tuple(arg_type._shape_)

        def dim(n):
            return "?" if n is Any or n == 0 else str(n)

        if len(shape) == 1:
            return f"v{dim(shape[0])}{scalar}"
        if len(shape) == 2:
            return f"m{dim(shape[0])}{dim(shape[1])}{scalar}"
        raise TypeError("Invalid vector/matrix dimensionality")
    if _module("weft.tile").is_tile(arg_type):
        shape = "?" if arg_type.shape is Any else "".join(str(n) for n in arg_type.shape)
        dtype = "?" if arg_type.dtype is Any else get_type_code(arg_type.dtype)
        return f"t{'s' if arg_type.storage == 'shared' else 'r'}{shape}{dtype}"
    key = getattr(arg_type, "key", None)
    if isinstance(key, str) and getattr(arg_type, "cls", None) is not None:
        return key      # a @wp.struct type
    raise TypeError(f"Unrecognized type '{arg_type}'")
