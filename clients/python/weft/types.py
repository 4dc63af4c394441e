"""weft's data types, as Warp names them: scalars, vectors, matrices, quaternions, transforms,
spatial types, the vector()/matrix() factories, their canonical type strings
(docs/protocol.md), NumPy conversions, and value -> little-endian bytes for the wire.

Every dtype class carries `_type_str` (canonical string, e.g. "vec(3,float32)"),
`_wp_scalar_type_` (its scalar dtype class), `_shape_` (element shape, () for scalars),
`_length_` (number of scalars) and `_np_dtype_` (NumPy dtype of one scalar).
"""
from __future__ import annotations

import builtins
import ctypes
import typing
from typing import Any

import numpy as np

__all__ = [
    "Any", "bool", "float16", "float32", "float64", "int8", "int16", "int32", "int64",
    "uint8", "uint16", "uint32", "uint64", "bfloat16", "handle",
    "scalar_types", "float_types", "int_types", "vector_types",
    "vector", "matrix", "quaternion", "transformation",
    "vec2", "vec3", "vec4", "mat22", "mat33", "mat44", "quat", "transform",
    "spatial_vector", "spatial_matrix",
    "type_str", "type_size", "type_size_in_bytes", "type_scalar_type", "type_length", "types_equal",
    "dtype_to_numpy", "dtype_from_numpy", "value_to_bytes", "is_array", "is_value",
    "is_vector", "is_matrix", "is_quaternion", "is_transformation", "is_float", "is_int",
    "scalar_short_name", "matrix_from_rows", "matrix_from_cols", "Int", "Float", "Scalar",
]

# Python's own names, kept before this module shadows `bool`, `float` and `int`.
_py_bool = builtins.bool
_py_float = builtins.float
_py_int = builtins.int


# ------------------------------------------------------------------------------------------
# Scalars


class _ScalarMeta(type):
    def __repr__(cls):
        return f"<class 'weft.types.{cls.__name__}'>"


class _Scalar(metaclass=_ScalarMeta):
    """Base of the scalar dtype classes; an instance holds one Python value in `.value`."""

    _length_ = 1
    _shape_ = ()
    _type_str = ""
    _np_dtype_ = None
    _wp_scalar_type_ = None
    _py_type_ = _py_float

    def __init__(self, x=0):
        if isinstance(x, _Scalar):
            x = x.value
        self.value = self._py_type_(np.asarray(x).astype(self._np_dtype_).item())
        # Warp shows a float scalar as the number it was given (float32(-1), float32(0.1)),
        # while `.value` is the number the type holds
        self._shown = x if self._py_type_ is _py_float and type(x) in (_py_int, _py_float) \
            else self.value

    def __float__(self):
        return _py_float(self.value)

    def __int__(self):
        return _py_int(self.value)

    def __index__(self):
        if self._py_type_ is _py_float:
            raise TypeError(f"{type(self).__name__} cannot be used as an index")
        return _py_int(self.value)

    def __bool__(self):
        return _py_bool(self.value)

    def __eq__(self, other):
        if isinstance(other, _Scalar):
            other = other.value
        return self.value == other

    def __hash__(self):
        return hash(self.value)

    def __repr__(self):
        return f"{type(self).__name__}({getattr(self, '_shown', self.value)!r})"

    def __str__(self):
        return str(getattr(self, "_shown", self.value))


class scalar_base(_Scalar):
    """Base of the numeric scalar types (Warp's warp.types.scalar_base); not a dtype itself."""


class int_base(scalar_base):
    """Base of the integer scalar types int8..uint64 (Warp's warp.types.int_base)."""

    _py_type_ = _py_int


class float_base(scalar_base):
    """Base of the floating-point scalar types float16/32/64 (Warp's warp.types.float_base)."""


def _make_scalar(name: str, np_dtype, py_type):
    base = _Scalar if py_type is _py_bool else int_base if py_type is _py_int else float_base
    cls = _ScalarMeta(name, (base,), {
        "_type_str": name,
        "_np_dtype_": np.dtype(np_dtype).newbyteorder("<") if np.dtype(np_dtype).itemsize > 1
        else np.dtype(np_dtype),
        "_py_type_": py_type,
        "__module__": __name__,
        "__qualname__": name,
        "__doc__": f"weft scalar type {name} (Warp's wp.{name}).",
    })
    cls._wp_scalar_type_ = cls
    cls._type_ = _CTYPES[name]
    return cls


# Warp's `_type_`: the ctypes type of one scalar (float16 is stored as its 16 bits).
_CTYPES = {"bool": ctypes.c_bool, "int8": ctypes.c_int8, "int16": ctypes.c_int16,
           "int32": ctypes.c_int32, "int64": ctypes.c_int64, "uint8": ctypes.c_uint8,
           "uint16": ctypes.c_uint16, "uint32": ctypes.c_uint32, "uint64": ctypes.c_uint64,
           "float16": ctypes.c_uint16, "float32": ctypes.c_float, "float64": ctypes.c_double,
           "bfloat16": ctypes.c_uint16}


bool = _make_scalar("bool", np.bool_, _py_bool)  # noqa: A001 - Warp's name
int8 = _make_scalar("int8", np.int8, _py_int)
int16 = _make_scalar("int16", np.int16, _py_int)
int32 = _make_scalar("int32", np.int32, _py_int)
int64 = _make_scalar("int64", np.int64, _py_int)
uint8 = _make_scalar("uint8", np.uint8, _py_int)
uint16 = _make_scalar("uint16", np.uint16, _py_int)
uint32 = _make_scalar("uint32", np.uint32, _py_int)
uint64 = _make_scalar("uint64", np.uint64, _py_int)
float16 = _make_scalar("float16", np.float16, _py_float)
float32 = _make_scalar("float32", np.float32, _py_float)
float64 = _make_scalar("float64", np.float64, _py_float)
half = float16
# Warp's wp.handle: the type of object handles (Mesh, Volume, Bvh ids) in kernel parameters, struct
# fields and arrays; it behaves as uint64 in every respect, so it is uint64.
handle = uint64
# bfloat16 (Warp's wp.bfloat16): float32's upper 16 bits, stored as those bits (its NumPy dtype is
# uint16; arrays' numpy() is ml_dtypes.bfloat16 when that package is installed). A value keeps
# bfloat16 precision (rounded to nearest even). Scalars and arrays of scalars only: there are no
# bfloat16 vectors or matrices (as in Warp 1.19, which names none), and it is not in float_types.
bfloat16 = _make_scalar("bfloat16", np.uint16, _py_float)


def _bfloat16_init(self, x=0.0):
    if isinstance(x, _Scalar):
        x = x.value
    from ._kernel.typestr import bfloat16_bits_to_float32, float32_to_bfloat16_bits
    self.value = _py_float(bfloat16_bits_to_float32(float32_to_bfloat16_bits(_py_float(x))))
    self._shown = x if type(x) in (_py_int, _py_float) else self.value


bfloat16.__init__ = _bfloat16_init
float = float32  # noqa: A001 - Warp's alias for annotations
int = int32  # noqa: A001

int_types = (int8, uint8, int16, uint16, int32, uint32, int64, uint64)
float_types = (float16, float32, float64)
# Warp's name for the scalar types whose atomics it refuses; weft implements atomics on every
# scalar type (8- and 16-bit integers included, docs/types.md), so there are none.
non_atomic_types = ()
scalar_types = int_types + float_types
scalar_and_bool_types = scalar_types + (bool,)

_SHORT_NAMES = {float16: "h", float32: "f", float64: "d", int8: "b", uint8: "ub", int16: "s",
                uint16: "us", int32: "i", uint32: "ui", int64: "l", uint64: "ul"}


def scalar_short_name(t) -> str:
    """Warp's suffix of a scalar type in typed names: float32 -> "f", uint8 -> "ub"."""
    return _SHORT_NAMES[t]


def _composite_scalar(dtype):
    """The scalar of a vector/matrix/quaternion/transform type."""
    return _canonical_scalar(dtype)


def _canonical_scalar(dtype):
    """float -> float32, int -> int32, bool -> bool; weft scalar classes pass through."""
    if dtype is _py_float:
        return float32
    if dtype is _py_int:
        return int32
    if dtype is _py_bool:
        return bool
    if isinstance(dtype, type) and issubclass(dtype, _Scalar) and dtype._type_str:
        return dtype
    if isinstance(dtype, (np.dtype, type)) and dtype is not Any:
        try:
            return dtype_from_numpy(np.dtype(dtype))
        except TypeError:
            pass
    raise TypeError(f"Invalid scalar type {dtype!r}: expected one of weft's scalar types "
                    "(float16/32/64, int8..uint64, bool) or Python float/int/bool")


# ------------------------------------------------------------------------------------------
# Vectors and matrices (fixed-size composite values; row-major storage)


class _CompositeMeta(type):
    def __repr__(cls):
        return f"<class 'weft.types.{cls.__name__}'>"


class _Composite(metaclass=_CompositeMeta):
    """Storage and NumPy behaviour shared by vectors, matrices, quaternions and transforms."""

    _length_ = 0
    _shape_ = ()
    _type_str = ""
    _wp_scalar_type_ = None
    _np_dtype_ = None
    _value_dtype_ = None
    __slots__ = ("_data",)

    # -- construction helpers
    def _set_from_flat(self, values):
        flat = np.asarray(values, dtype=np.float64 if self._is_float() else None)
        if flat.size != self._length_:
            raise ValueError(f"Invalid number of values for {type(self).__name__}: expected "
                             f"{self._length_}, got {flat.size}")
        if self._wp_scalar_type_ is bfloat16:   # keep bfloat16 precision (float32 storage)
            from ._kernel.typestr import bfloat16_bits_to_float32, float32_to_bfloat16_bits
            flat = bfloat16_bits_to_float32(float32_to_bfloat16_bits(flat))
        self._data = flat.reshape(self._shape_).astype(self._value_dtype_)

    @classmethod
    def _is_float(cls):
        return cls._wp_scalar_type_ in float_types or cls._wp_scalar_type_ is bfloat16

    @classmethod
    def _py(cls, x):
        return _py_float(x) if cls._is_float() else (
            _py_bool(x) if cls._wp_scalar_type_ is bool else _py_int(x))

    # -- sequence / numpy protocol
    def __len__(self):
        return self._shape_[0]

    def __iter__(self):
        for i in range(self._shape_[0]):
            yield self[i]

    def __array__(self, dtype=None, copy=None):
        out = self._data.copy()
        return out if dtype is None else out.astype(dtype)

    def __eq__(self, other):
        try:
            other_arr = np.asarray(other)
        except Exception:  # noqa: BLE001 - not comparable
            return NotImplemented
        if other_arr.shape != self._data.shape:
            # composites without elements (slices selecting nothing) are equal, as in kernels
            return _py_bool(self._data.size == 0 and other_arr.size == 0)
        return _py_bool(np.all(self._data == other_arr))

    def __ne__(self, other):
        result = self.__eq__(other)
        return result if result is NotImplemented else not result

    __hash__ = None

    def __repr__(self):
        return f"{type(self).__name__}({', '.join(str(self._py(x)) for x in self._data.flat)})"

    def __str__(self):
        if len(self._shape_) == 1:
            return "[" + ", ".join(str(self._py(x)) for x in self._data) + "]"
        rows = ["[" + ", ".join(str(self._py(x)) for x in row) + "]" for row in self._data]
        return "[" + ",\n ".join(rows) + "]"

    # -- arithmetic (component-wise; `*` with a scalar scales; `@` is the matrix product)
    def _wrap(self, data):
        out = type(self).__new__(type(self))
        out._data = np.asarray(data).astype(self._value_dtype_)
        return out

    def _coerce(self, other):
        if isinstance(other, _Composite):
            if other._shape_ != self._shape_:
                raise TypeError(f"Incompatible shapes {type(self).__name__} and "
                                f"{type(other).__name__}")
            return other._data
        if isinstance(other, _Scalar):
            return other.value
        if isinstance(other, (_py_int, _py_float, _py_bool, np.number)):
            return other
        return NotImplemented

    def __add__(self, other):
        o = self._coerce(other)
        if o is NotImplemented or not isinstance(other, _Composite):
            return NotImplemented
        return self._wrap(self._data + o)

    __radd__ = __add__

    def __sub__(self, other):
        o = self._coerce(other)
        if o is NotImplemented or not isinstance(other, _Composite):
            return NotImplemented
        return self._wrap(self._data - o)

    def __rsub__(self, other):
        o = self._coerce(other)
        if o is NotImplemented or not isinstance(other, _Composite):
            return NotImplemented
        return self._wrap(o - self._data)

    def __mod__(self, other):
        """Componentwise remainder of composites of one shape, truncated as in kernels (C's fmod /
        %: the sign of the dividend)."""
        o = self._coerce(other)
        if o is NotImplemented or not isinstance(other, _Composite):
            return NotImplemented
        if np.issubdtype(self._data.dtype, np.integer):
            return self._wrap(np.sign(self._data) * (np.abs(self._data) % np.abs(o)))
        return self._wrap(np.fmod(self._data, o))

    def __mul__(self, other):
        if isinstance(other, _Composite):
            return self._matmul(other)
        o = self._coerce(other)
        if o is NotImplemented:
            return NotImplemented
        return self._wrap(self._data * o)

    def __rmul__(self, other):
        if isinstance(other, _Composite):
            return other._matmul(self)
        o = self._coerce(other)
        if o is NotImplemented:
            return NotImplemented
        return self._wrap(o * self._data)

    def __truediv__(self, other):
        o = self._coerce(other)
        if o is NotImplemented or isinstance(other, _Composite):
            return NotImplemented
        return self._wrap(self._data / o)

    def __rtruediv__(self, other):
        o = self._coerce(other)
        if o is NotImplemented or isinstance(other, _Composite):
            return NotImplemented
        return self._wrap(o / self._data)

    def __matmul__(self, other):
        if not isinstance(other, _Composite):
            return NotImplemented
        return self._matmul(other)

    def __neg__(self):
        return self._wrap(-self._data)

    def __pos__(self):
        return self._wrap(self._data.copy())

    def _matmul(self, other):
        a, b = self, other
        if len(a._shape_) == 1 and len(b._shape_) == 1:
            raise TypeError("use wp.dot / wp.cw_mul for vector-vector products")
        result = np.matmul(a._data.astype(np.float64) if a._is_float() else a._data,
                           b._data)
        if result.ndim == 1:
            return vector(result.shape[0], a._wp_scalar_type_)(result)
        return matrix(result.shape, a._wp_scalar_type_)(result)


class _Vector(_Composite):
    """A fixed-length vector value (Warp's vec_t in Python scope)."""

    __slots__ = ()

    def __init__(self, *args):
        n = len(args)
        if n == 0:
            self._data = np.zeros(self._shape_, dtype=self._value_dtype_)
        elif n == 1:
            (arg,) = args
            if hasattr(arg, "__len__") or isinstance(arg, np.ndarray):
                self._set_from_flat(np.asarray(arg).reshape(-1))
            else:
                self._data = np.full(self._shape_, self._py(_scalar_value(arg)),
                                     dtype=self._value_dtype_)
        elif n == self._length_:
            self._set_from_flat([_scalar_value(a) for a in args])
        else:
            raise ValueError(f"Invalid number of arguments in vector constructor, expected "
                             f"{self._length_} elements, got {n}")

    def __getitem__(self, key):
        if isinstance(key, slice):   # a vector of the slice's length, as Warp (so v[1:] += w works)
            picked = self._data[key]
            out = vector(len(picked), self._wp_scalar_type_)()
            out._data[:] = picked            # the stored values as they are (wrapped integers too)
            return out
        return self._py(self._data[_index(key, self._length_)])

    def __setitem__(self, key, value):
        if isinstance(key, slice):
            self._data[key] = _wrapped(np.asarray(value), self._data.dtype)
        else:
            self._data[_index(key, self._length_)] = _wrapped(_scalar_value(value), self._data.dtype)

    def __getattr__(self, name):
        if len(name) == 1 and name in "xyzw" and "xyzw".index(name) < self._length_:
            return self[("xyzw".index(name))]
        raise AttributeError(f"'{type(self).__name__}' object has no attribute '{name}'")

    def __setattr__(self, name, value):
        if len(name) == 1 and name in "xyzw":
            self[("xyzw".index(name))] = value
        else:
            object.__setattr__(self, name, value)


class _Matrix(_Composite):
    """A fixed-shape matrix value, row-major (Warp's mat_t in Python scope)."""

    __slots__ = ()

    def __init__(self, *args):
        rows, cols = self._shape_
        n = len(args)
        if n == 0:
            self._data = np.zeros(self._shape_, dtype=self._value_dtype_)
        elif n == 1:
            (arg,) = args
            if hasattr(arg, "__len__") or isinstance(arg, np.ndarray):
                self._set_from_flat(np.asarray(arg).reshape(-1))
            else:
                self._data = np.full(self._shape_, self._py(_scalar_value(arg)),
                                     dtype=self._value_dtype_)
        elif n == self._length_:
            self._set_from_flat([_scalar_value(a) for a in args])
        elif n == rows and all(hasattr(a, "__len__") for a in args):
            # Python scope builds matrices from row vectors (as Warp does in Python).
            for row in args:
                if len(row) != cols:
                    raise TypeError(f"Invalid argument in matrix constructor, expected row of "
                                    f"length {cols}, got {row}")
            self._set_from_flat(np.concatenate([np.asarray(r).reshape(-1) for r in args]))
        else:
            raise ValueError(f"Invalid number of arguments in matrix constructor, expected "
                             f"{self._length_} elements, got {n}")

    def __len__(self):
        return self._shape_[0]

    def get_row(self, r):
        return vector(self._shape_[1], self._wp_scalar_type_)(self._data[_index(r, self._shape_[0])])

    def set_row(self, r, v):
        self._data[_index(r, self._shape_[0])] = np.asarray(v)

    def get_col(self, c):
        return vector(self._shape_[0], self._wp_scalar_type_)(self._data[:, _index(c, self._shape_[1])])

    def set_col(self, c, v):
        self._data[:, _index(c, self._shape_[1])] = np.asarray(v)

    def _key(self, key):
        """(row key, column key) with integer indices checked; slices as given."""
        if not isinstance(key, tuple):
            key = (key, slice(None))
        if len(key) != 2:
            raise KeyError(f"Invalid key, expected one or two indices, got {len(key)}")
        return tuple(k if isinstance(k, slice) else _index(k, n) for k, n in zip(key, self._shape_))

    def __getitem__(self, key):
        """m[i, j]: a scalar; m[i] and m[i, cols] / m[rows, j]: a vector; slices on both
        axes: a matrix of the selected shape (as Warp, also in Python scope)."""
        rk, ck = self._key(key)
        picked = self._data[rk, ck]
        if not isinstance(rk, slice) and not isinstance(ck, slice):
            return self._py(picked)
        if isinstance(rk, slice) and isinstance(ck, slice):
            return matrix(picked.shape, self._wp_scalar_type_)(picked.reshape(-1))
        return vector(picked.shape[0], self._wp_scalar_type_)(picked)

    def __setitem__(self, key, value):
        rk, ck = self._key(key)
        if not isinstance(rk, slice) and not isinstance(ck, slice):
            self._data[rk, ck] = _wrapped(_scalar_value(value), self._data.dtype)
            return
        target = self._data[rk, ck]
        data = value._data if isinstance(value, _Composite) else np.asarray(value)
        self._data[rk, ck] = _wrapped(np.asarray(data).reshape(target.shape) if np.size(data) == target.size
                                      else data, self._data.dtype)


def _matrix_from_vectors(vectors, by_rows: _py_bool):
    if not vectors or not all(isinstance(v, _Vector) for v in vectors):
        raise TypeError("matrix_from_rows/matrix_from_cols take one or more vectors")
    first = type(vectors[0])
    if any(type(v)._shape_ != first._shape_ or type(v)._wp_scalar_type_ is not first._wp_scalar_type_
           for v in vectors):
        raise TypeError("matrix_from_rows/matrix_from_cols: all vectors must have the same "
                        "length and scalar type")
    data = np.stack([v._data for v in vectors])
    if not by_rows:
        data = data.T
    return matrix(data.shape, first._wp_scalar_type_)(data.reshape(-1))


def matrix_from_rows(*rows):
    """Python scope wp.matrix_from_rows(v0, v1, ...): the matrix whose rows are the vectors."""
    return _matrix_from_vectors(rows, True)


def matrix_from_cols(*cols):
    """Python scope wp.matrix_from_cols(v0, v1, ...): the matrix whose columns are the vectors."""
    return _matrix_from_vectors(cols, False)


def _wrapped(value, dtype):
    """Integers stored into an integer component wrap around as in C (uint8 -1 -> 255), as
    Warp's ctypes storage does; anything else is left to NumPy's assignment rules."""
    if dtype.kind in "iu" and isinstance(value, (_py_int, np.integer, np.ndarray)) \
            and not isinstance(value, _py_bool) and np.asarray(value).dtype.kind in "iu":
        return np.asarray(value).astype(dtype)
    return value


def _index(key, length):
    try:
        i = key.__index__()
    except AttributeError:
        raise KeyError(f"Invalid key {key!r}, expected int or slice") from None
    if i < -length or i >= length:
        raise IndexError(f"Invalid index {i} for length {length}")
    return i + length if i < 0 else i


def _scalar_value(x):
    return x.value if isinstance(x, _Scalar) else x


_vector_cache: dict = {}
_matrix_cache: dict = {}
_quat_cache: dict = {}
_transform_cache: dict = {}


class _GenericScalarMeta(type):
    def __repr__(cls):
        return f"<class 'weft.types.{cls.__name__}'>"


class Int(metaclass=_GenericScalarMeta):
    """wp.Int: any integer scalar type, in the annotations of generic functions and kernels."""

    _type_str = "any_int"


class Float(metaclass=_GenericScalarMeta):
    """wp.Float: any floating-point scalar type, in generic annotations."""

    _type_str = "any_float"


class Scalar(metaclass=_GenericScalarMeta):
    """wp.Scalar: any integer or floating-point scalar type (not bool), in generic annotations."""

    _type_str = "any_scalar"


def _scalar_pattern(dtype):
    """The type string of a scalar pattern (typing.Any, wp.Int/Float/Scalar), else None."""
    if dtype is Any:
        return "any"
    if dtype in (Int, Float, Scalar):
        return dtype._type_str
    return None


_COMPOSITE_GENERIC_STR = {"_Vector": "vec_t", "_Matrix": "mat_t", "_Quaternion": "quat_t",
                          "_Transformation": "transform_t"}


def _generic_composite(base, name, shape, dtype, type_string):
    """A vector/matrix/quaternion/transform type of a generic annotation: its length or shape
    holds typing.Any, or its scalar is a pattern. It names a pattern that the daemon matches
    (an instance of any type it accepts); it has no values of its own."""

    def __init__(self, *args, **kwargs):
        raise TypeError(f"{name} is a generic type (for annotations): it cannot be constructed")

    return _CompositeMeta(name, (base,), {
        "_length_": Any if Any in shape else _py_int(np.prod(shape)),
        "_shape_": tuple(shape),
        "_type_str": type_string,
        "_wp_scalar_type_": dtype,
        "_wp_type_params_": list(shape) + [dtype],
        "_wp_generic_type_str_": _COMPOSITE_GENERIC_STR[base.__name__],
        "_weft_generic_": True,
        "__init__": __init__,
        "__module__": __name__,
        "__qualname__": name,
    })


def _composite_class(base, name, shape, dtype, type_string, extra=None):
    namespace = {
        "_length_": _py_int(np.prod(shape)),
        "_shape_": tuple(shape),
        "_type_str": type_string,
        "_wp_scalar_type_": dtype,
        "_np_dtype_": dtype._np_dtype_,
        "_type_": dtype._type_,     # Warp's ctypes type of one component
        # Python values keep their components in _value_dtype_: the storage dtype, except
        # bfloat16 (stored as bits), whose values are float32 rounded to bfloat16.
        "_value_dtype_": np.dtype(np.float32) if dtype is bfloat16 else dtype._np_dtype_,
        "_wp_type_params_": list(shape) + [dtype],
        "_wp_generic_type_str_": _COMPOSITE_GENERIC_STR[base.__name__],
        "__module__": __name__,
        "__qualname__": name,
    }
    namespace.update(extra or {})
    return _CompositeMeta(name, (base,), namespace)


def vector(length, dtype):
    """The vector type of `length` elements of `dtype` (Warp's wp.types.vector). `length`
    typing.Any or `dtype` typing.Any/wp.Int/wp.Float/wp.Scalar: a generic annotation type."""
    pattern = _scalar_pattern(dtype)
    if length is Any or pattern is not None:
        scalar = pattern or _composite_scalar(dtype)._type_str
        extent = "any" if length is Any else _py_int(length)
        if extent != "any" and extent <= 0:
            raise ValueError(f"Vector length must be positive, got {length}")
        return _generic_composite(_Vector, f"vec{'' if extent == 'any' else extent}_generic",
                                  (length if length is Any else extent,), dtype,
                                  f"vec({extent},{scalar})")
    dtype = _composite_scalar(dtype)
    length = _py_int(length)
    if length < 0:   # 0: the type of an empty slice (Warp has it; kernels cannot use it)
        raise ValueError(f"Vector length must be non-negative, got {length}")
    key = (length, dtype)
    cls = _vector_cache.get(key)
    if cls is None:
        name = (f"vec{length}{_SHORT_NAMES[dtype]}" if dtype in _SHORT_NAMES
                else f"vec{length}_{dtype._type_str}")
        cls = _composite_class(_Vector, name, (length,), dtype,
                               f"vec({length},{dtype._type_str})")
        _vector_cache[key] = cls
    return cls


def matrix(shape, dtype):
    """The matrix type of `shape` (rows, cols) of `dtype` (Warp's wp.types.matrix)."""
    if len(shape) != 2:
        raise ValueError(f"Matrix shape must have exactly two dimensions, got {len(shape)} "
                         f"dimension{'' if len(shape) == 1 else 's'} in shape {tuple(shape)}")
    pattern = _scalar_pattern(dtype)
    if Any in tuple(shape) or pattern is not None:
        scalar = pattern or _composite_scalar(dtype)._type_str
        dims = tuple(d if d is Any else _py_int(d) for d in shape)
        if any(d is not Any and d <= 0 for d in dims):
            raise ValueError(f"Matrix dimensions must be positive, got {shape}")
        text = ",".join("any" if d is Any else str(d) for d in dims)
        return _generic_composite(_Matrix, "mat_generic", dims, dtype, f"mat({text},{scalar})")
    rows, cols = _py_int(shape[0]), _py_int(shape[1])
    if rows < 0 or cols < 0:   # 0: the type of an empty slice, as for vectors
        raise ValueError(f"Matrix dimensions must be non-negative, got {shape}")
    dtype = _composite_scalar(dtype)
    key = (rows, cols, dtype)
    cls = _matrix_cache.get(key)
    if cls is None:
        name = (f"mat{rows}{cols}{_SHORT_NAMES[dtype]}" if dtype in _SHORT_NAMES
                else f"mat{rows}{cols}_{dtype._type_str}")
        cls = _composite_class(_Matrix, name, (rows, cols), dtype,
                               f"mat({rows},{cols},{dtype._type_str})")
        _matrix_cache[key] = cls
    return cls


class _Quaternion(_Vector):
    """A quaternion (x, y, z, w); defaults to the identity (0, 0, 0, 1)."""

    __slots__ = ()

    def __init__(self, *args):
        if not args:
            self._data = np.array([0, 0, 0, 1], dtype=self._value_dtype_)
        else:
            super().__init__(*args)


def quaternion(dtype=float32):
    """The quaternion type of `dtype` (Warp's wp.types.quaternion)."""
    pattern = _scalar_pattern(dtype)
    if pattern is not None:
        return _generic_composite(_Quaternion, "quat_generic", (4,), dtype, f"quat({pattern})")
    dtype = _composite_scalar(dtype)
    cls = _quat_cache.get(dtype)
    if cls is None:
        cls = _composite_class(_Quaternion, f"quat{_SHORT_NAMES[dtype]}", (4,), dtype,
                               f"quat({dtype._type_str})")
        _quat_cache[dtype] = cls
    return cls


class _Transformation(_Vector):
    """A rigid transform: translation p (3) then rotation q (4, x y z w)."""

    __slots__ = ()

    def __init__(self, *args, p=None, q=None):
        if p is not None or q is not None:
            args = (p if p is not None else (0, 0, 0), q if q is not None else (0, 0, 0, 1))
        if not args:
            self._data = np.array([0, 0, 0, 0, 0, 0, 1], dtype=self._value_dtype_)
        elif len(args) == 2:
            flat = np.concatenate([np.asarray(args[0], dtype=np.float64).reshape(-1),
                                   np.asarray(args[1], dtype=np.float64).reshape(-1)])
            self._set_from_flat(flat)
        else:
            super().__init__(*args)

    @property
    def p(self):
        return vector(3, self._wp_scalar_type_)(self._data[:3])

    @p.setter
    def p(self, value):
        self._set_part(0, 3, value, "p (translation)")

    @property
    def q(self):
        return quaternion(self._wp_scalar_type_)(self._data[3:])

    @q.setter
    def q(self, value):
        self._set_part(3, 7, value, "q (rotation)")

    def _set_part(self, start: int, stop: int, value, what: str) -> None:
        flat = np.asarray(getattr(value, "_data", value), dtype=np.float64).reshape(-1)
        if flat.size != stop - start:
            raise ValueError(f"transform.{what} takes {stop - start} components, got {flat.size}")
        self._data[start:stop] = flat.astype(self._data.dtype)


def transformation(dtype=float32):
    """The transform type of `dtype` (Warp's wp.types.transformation)."""
    pattern = _scalar_pattern(dtype)
    if pattern is not None:
        return _generic_composite(_Transformation, "transform_generic", (7,), dtype,
                                  f"transform({pattern})")
    dtype = _composite_scalar(dtype)
    cls = _transform_cache.get(dtype)
    if cls is None:
        cls = _composite_class(_Transformation, f"transform{_SHORT_NAMES[dtype]}", (7,), dtype,
                               f"transform({dtype._type_str})")
        _transform_cache[dtype] = cls
    return cls


# Warp's named types: vec2..vec4 with typed variants, mat22..mat44, quat, transform, spatial.
_typed = {}
for _scalar in scalar_types:
    _s = _SHORT_NAMES[_scalar]
    for _n in (2, 3, 4):
        _typed[f"vec{_n}{_s}"] = vector(_n, _scalar)
        _typed[f"mat{_n}{_n}{_s}"] = matrix((_n, _n), _scalar)
for _scalar, _s in ((float16, "h"), (float32, "f"), (float64, "d")):
    _typed[f"quat{_s}"] = quaternion(_scalar)
    _typed[f"transform{_s}"] = transformation(_scalar)
    _typed[f"spatial_vector{_s}"] = vector(6, _scalar)
    _typed[f"spatial_matrix{_s}"] = matrix((6, 6), _scalar)
globals().update(_typed)
__all__ += sorted(_typed)
del _scalar, _s, _n

vec2 = _typed["vec2f"]
vec3 = _typed["vec3f"]
vec4 = _typed["vec4f"]
mat22 = _typed["mat22f"]
mat33 = _typed["mat33f"]
mat44 = _typed["mat44f"]
quat = _typed["quatf"]
transform = _typed["transformf"]
spatial_vector = _typed["spatial_vectorf"]
spatial_matrix = _typed["spatial_matrixf"]
vector_types = tuple(_typed.values())


# ------------------------------------------------------------------------------------------
# Subscript generics (Warp 1.19): Vector[float, Literal[3]] is vector(3, float32),
# Matrix[float, 3, 3] matrix((3, 3), float32), Quaternion[T] quaternion(T),
# Transformation[T] transformation(T): the same cached classes.


def _positive_extent(value, what: str) -> int:
    from .array_annotations import positive_extent

    return positive_extent(value, what)


def _subscript_params(params, count: int, name: str, usage: str) -> tuple:
    params = params if isinstance(params, tuple) else (params,)
    if len(params) != count:
        raise TypeError(f"{name}[...] requires {count} parameters ({usage}), got {len(params)}")
    return params


class Vector:
    """Vector[dtype, length]: the vector type vector(length, dtype)."""

    def __class_getitem__(cls, params):
        dtype, length = _subscript_params(params, 2, "Vector", "dtype, length")
        return vector(_positive_extent(length, "Vector length"), dtype)


class Matrix:
    """Matrix[dtype, rows, cols]: the matrix type matrix((rows, cols), dtype)."""

    def __class_getitem__(cls, params):
        dtype, rows, cols = _subscript_params(params, 3, "Matrix", "dtype, rows, cols")
        return matrix((_positive_extent(rows, "Matrix rows"), _positive_extent(cols, "Matrix cols")),
                      dtype)


class Quaternion:
    """Quaternion[dtype]: the quaternion type quaternion(dtype)."""

    def __class_getitem__(cls, dtype):
        return quaternion(dtype)


class Transformation:
    """Transformation[dtype]: the transform type transformation(dtype)."""

    def __class_getitem__(cls, dtype):
        return transformation(dtype)


# The generic each composite class belongs to (Warp's type_is_vector & co. read it).
_Vector._wp_generic_type_hint_ = Vector
_Matrix._wp_generic_type_hint_ = Matrix
_Quaternion._wp_generic_type_hint_ = Quaternion
_Transformation._wp_generic_type_hint_ = Transformation


# ------------------------------------------------------------------------------------------
# Type queries and type strings


def is_vector(t) -> _py_bool:
    return isinstance(t, type) and issubclass(t, _Vector) and not issubclass(
        t, (_Quaternion, _Transformation))


def is_matrix(t) -> _py_bool:
    return isinstance(t, type) and issubclass(t, _Matrix)


def is_quaternion(t) -> _py_bool:
    return isinstance(t, type) and issubclass(t, _Quaternion)


def is_transformation(t) -> _py_bool:
    return isinstance(t, type) and issubclass(t, _Transformation)


def is_float(t) -> _py_bool:
    if t is bfloat16:
        return True
    return t in float_types or t is _py_float


def is_int(t) -> _py_bool:
    return t in int_types or t is _py_int


def is_value(x) -> _py_bool:
    """True for Python/NumPy numbers and weft scalar/composite instances."""
    return isinstance(x, (_py_int, _py_float, _py_bool, np.number, np.bool_, _Scalar, _Composite))


def is_array(x) -> _py_bool:
    """True for an array of any family (array, indexedarray) and for an array annotation
    (wp.array[float], wp.indexedarray(dtype=float), wp.fabricarray[float]), as Warp's."""
    import importlib

    from . import array_annotations

    return isinstance(x, (array_annotations._ArrayAnnotationBase,
                          importlib.import_module("weft.array").array,
                          importlib.import_module("weft.indexedarray").indexedarray))


def is_array_instance(x) -> _py_bool:
    """True for a weft.array (memory in weftd, or a null array used as an annotation)."""
    import importlib

    return isinstance(x, importlib.import_module("weft.array").array)


def type_is_vector(t) -> _py_bool:
    """True for a vector type (not a quaternion or transform), as Warp's."""
    return isinstance(t, type) and getattr(t, "_wp_generic_type_hint_", None) is Vector


def type_is_matrix(t) -> _py_bool:
    return isinstance(t, type) and getattr(t, "_wp_generic_type_hint_", None) is Matrix


def type_is_quaternion(t) -> _py_bool:
    return isinstance(t, type) and getattr(t, "_wp_generic_type_hint_", None) is Quaternion


def type_is_transformation(t) -> _py_bool:
    return isinstance(t, type) and getattr(t, "_wp_generic_type_hint_", None) is Transformation


def is_tile(t) -> _py_bool:
    """True for a tile annotation (wp.tile[float, 8, 4]; weft.tile)."""
    from .tile import is_tile as _is_tile

    return _is_tile(t)


def is_dtype(t) -> _py_bool:
    """True for weft scalar and composite dtype classes."""
    return isinstance(t, type) and issubclass(t, (_Scalar, _Composite)) and _py_bool(t._type_str)


def type_scalar_type(t):
    """The scalar dtype of a dtype (vec3 -> float32); Python float/int/bool canonicalised."""
    if is_dtype(t):
        return t._wp_scalar_type_
    return _canonical_scalar(t)


def type_length(t) -> _py_int:
    if is_dtype(t):
        return t._length_
    return 1


def type_size(t) -> _py_int:
    """Scalars in one value of dtype `t` (Warp's wp.types.type_size): 1 for a scalar, Python
    int/float and a struct; the length of a vector, matrix, quaternion or transform."""
    if t is _py_int or t is _py_float or str(getattr(t, "_type_str", "")).startswith("struct("):
        return 1
    if is_dtype(t):
        return t._length_
    return _canonical_scalar(t)._length_


def type_size_in_bytes(t) -> _py_int:
    """Bytes of one element of dtype `t`."""
    if is_dtype(t):
        return t._length_ * t._np_dtype_.itemsize
    if hasattr(t, "_struct_size_"):
        return t._struct_size_
    return _canonical_scalar(t)._np_dtype_.itemsize


def types_equal(a, b) -> _py_bool:
    try:
        return type_str(a) == type_str(b)
    except TypeError:
        return a == b


def type_str(t) -> str:
    """The canonical type string of docs/protocol.md: float32, vec(3,float32), array(T,N)..."""
    if t is Any or t is typing.Any:
        return "any"
    if t is _py_float:
        return "float32"
    if t is _py_int:
        return "int32"
    if t is _py_bool:
        return "bool"
    type_string = getattr(t, "_type_str", None)
    if isinstance(type_string, str) and type_string:
        return type_string
    if is_array(t):
        # arrays and annotations of both families (an indexed one is no plain array: its
        # kernels take the index arrays too)
        if getattr(t, "_fabric_", False):
            raise TypeError(f"No weft type string for {t!r}: weft does not support Fabric arrays")
        family = "indexedarray" if getattr(t, "_indexed_", False) else "array"
        return f"{family}({'any' if t.dtype is Any else type_str(t.dtype)},{t.ndim})"
    if isinstance(t, (np.dtype,)) or (isinstance(t, type) and issubclass(t, np.generic)):
        return dtype_from_numpy(t)._type_str
    raise TypeError(f"No weft type string for {t!r}")


def type_repr(t) -> str:
    """A readable name of a type, as Warp prints it in messages: float32, vec3f, mat22d,
    quatf, transformd, vector(length=5, dtype=float32), array(ndim=2, dtype=vec3f) for an
    annotation, array(shape=(4,), dtype=float32) for an array, float/int/bool for Python's."""
    if t is Any or t is typing.Any:
        return "Any"
    if is_array(t):
        cls = getattr(t, "_family", None) or type(t).__name__   # an annotation: its array class
        if getattr(t, "device", None) is None:
            return f"{cls}(ndim={t.ndim}, dtype={type_repr(t.dtype)})"
        return f"{cls}(shape={tuple(t.shape)}, dtype={type_repr(t.dtype)})"
    origin = typing.get_origin(t)
    if origin is tuple:
        args = typing.get_args(t)
        return f"tuple({', '.join(type_repr(a) for a in args)})" if args else "tuple"
    if origin is not None and getattr(origin, "__name__", "") == "array":
        args = typing.get_args(t)
        return f"array(ndim=1, dtype={type_repr(args[0]) if args else 'Any'})"
    struct_cls = getattr(t, "cls", None)
    if struct_cls is not None and hasattr(t, "fields") and isinstance(struct_cls, type):
        return type_repr(struct_cls)
    if is_dtype(t) and issubclass(t, _Composite):
        scalar = t._wp_scalar_type_
        short = _SHORT_NAMES.get(scalar)
        if is_transformation(t):
            return f"transform{short}" if short else f"transform(dtype={type_repr(scalar)})"
        if is_quaternion(t):
            return f"quat{short}" if short else f"quat(dtype={type_repr(scalar)})"
        shape = t._shape_
        if is_matrix(t):
            if short and shape[0] <= 4 and shape[1] <= 4:
                return f"mat{shape[0]}{shape[1]}{short}"
            return f"matrix(shape=({shape[0]}, {shape[1]}), dtype={type_repr(scalar)})"
        if short and shape[0] <= 4:
            return f"vec{shape[0]}{short}"
        return f"vector(length={shape[0]}, dtype={type_repr(scalar)})"
    if t in scalar_and_bool_types:
        return t.__name__
    if t is _py_bool:
        return "bool"
    if t is _py_float:
        return "float"
    if t is _py_int:
        return "int"
    name = getattr(t, "__name__", None)
    if name is None:
        return repr(t)
    return f"{t.__module__}.{getattr(t, '__qualname__', name)}"


# ------------------------------------------------------------------------------------------
# NumPy conversions

_NP_TO_WP = {np.dtype(s._np_dtype_).newbyteorder("="): s for s in scalar_and_bool_types}


def dtype_to_numpy(warp_dtype):
    """The NumPy dtype of a weft scalar dtype (Warp's wp.dtype_to_numpy)."""
    try:
        scalar = _canonical_scalar(warp_dtype)
    except TypeError:
        raise TypeError(f"Cannot convert {warp_dtype} to a NumPy type") from None
    return np.dtype(scalar._np_dtype_).type


def dtype_from_numpy(numpy_dtype):
    """The weft scalar dtype of a NumPy dtype (Warp's wp.dtype_from_numpy;
    ml_dtypes.bfloat16 -> bfloat16)."""
    try:
        key = np.dtype(numpy_dtype).newbyteorder("=")
    except TypeError:
        raise TypeError(f"Cannot convert {numpy_dtype} to a Warp type") from None
    if key.name == "bfloat16":
        return bfloat16
    result = _NP_TO_WP.get(key)
    if result is None:
        raise TypeError(f"Cannot convert {numpy_dtype} to a Warp type")
    return result


def _np_float32_to_bfloat16_bits(arr_f32) -> np.ndarray:
    """bfloat16 bits (uint16) of float values, rounded to nearest even (Warp's helper name)."""
    from ._kernel.typestr import float32_to_bfloat16_bits
    return float32_to_bfloat16_bits(arr_f32)


def _np_bfloat16_bits_to_float32(arr_u16) -> np.ndarray:
    """float32 values of bfloat16 bits (Warp's helper name)."""
    from ._kernel.typestr import bfloat16_bits_to_float32
    return bfloat16_bits_to_float32(arr_u16)


def np_scalar_dtype(t) -> np.dtype:
    """The little-endian NumPy dtype of one scalar component of weft dtype `t`."""
    if is_dtype(t):
        return t._np_dtype_
    return _canonical_scalar(t)._np_dtype_


def value_to_bytes(dtype, value) -> bytes:
    """One value of weft dtype `dtype` as little-endian bytes (float16 as IEEE half, bool as
    one byte). Scalars broadcast over vectors/matrices (wp.vec3 fill with 1.0)."""
    if isinstance(value, _Scalar):
        value = value.value
    if not is_dtype(dtype):
        dtype = _canonical_scalar(dtype)
    arr = np.asarray(value)
    if arr.dtype == object:
        raise TypeError(f"Cannot convert {value!r} to {type_str(dtype)}")
    if dtype is bfloat16:
        from ._kernel.typestr import to_bfloat16_bits
        return to_bfloat16_bits(arr).reshape(()).astype("<u2").tobytes()
    if getattr(dtype, "_wp_scalar_type_", None) is bfloat16 and arr.dtype != np.uint16:
        arr = arr.astype(np.float32)
    shape = dtype._shape_
    if arr.shape != shape:
        if arr.size == dtype._length_:
            arr = arr.reshape(shape)
        elif arr.size == 1:
            arr = np.broadcast_to(arr.reshape(()), shape)
        else:
            raise ValueError(f"Cannot convert a value of shape {arr.shape} to "
                             f"{type_str(dtype)} (element shape {shape})")
    if getattr(dtype, "_wp_scalar_type_", None) is bfloat16:
        from ._kernel.typestr import to_bfloat16_bits
        return np.ascontiguousarray(to_bfloat16_bits(arr), dtype="<u2").tobytes()
    return np.ascontiguousarray(arr, dtype=dtype._np_dtype_).tobytes()


_LAZY_ATTRIBUTES = {
    # wp.types.array & co. live in modules that import this one: looked up when first used.
    **{n: "weft.array" for n in ("array", "array1d", "array2d", "array3d", "array4d")},
    **{n: "weft.fabricarray" for n in ("fabricarray", "indexedfabricarray")},
    **{n: "weft.array_annotations" for n in (
        "ARRAY_TYPE_REGULAR", "ARRAY_TYPE_INDEXED", "ARRAY_TYPE_FABRIC", "ARRAY_TYPE_FABRIC_INDEXED",
        "_ArrayAnnotationBase", "_ArrayAnnotation", "_IndexedArrayAnnotation",
        "_FabricArrayAnnotation", "_IndexedFabricArrayAnnotation", "array_type_id",
        "concrete_array_type", "matches_array_class", "get_type_code")},
}


def __getattr__(name):
    module = _LAZY_ATTRIBUTES.get(name)
    if module is not None:
        import importlib

        return getattr(importlib.import_module(module), name)
    raise AttributeError(f"module 'weft.types' has no attribute '{name}'")


def __dir__():
    return sorted(set(globals()) | set(_LAZY_ATTRIBUTES))
