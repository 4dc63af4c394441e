"""Array annotation types: what `wp.array(dtype=wp.vec3)`, `wp.array2d(dtype=float)`,
`wp.array(dtype=float, ndim=2)`, `wp.array[float]` and `wp.array2d[float]` mean in a kernel
signature or struct field. weft.array (the array layer) may delegate to these when it is called
without data; the kernel API also accepts any object with `dtype` and `ndim` attributes."""
from __future__ import annotations

import typing

from . import typestr


class ArrayType:
    """The type of an array parameter: element dtype and number of dimensions."""

    def __init__(self, dtype=float, ndim: int = 1):
        if not 1 <= int(ndim) <= 4:
            raise ValueError(f"arrays have 1 to 4 dimensions, got ndim={ndim}")
        self.dtype = dtype
        self.ndim = int(ndim)

    @property
    def _type_str(self) -> str:
        return typestr.array_str(typestr.type_string(self.dtype), self.ndim)

    def __eq__(self, other):
        return isinstance(other, ArrayType) and other._type_str == self._type_str

    def __hash__(self):
        return hash(self._type_str)

    def __repr__(self):
        return f"array(dtype={getattr(self.dtype, '__name__', self.dtype)}, ndim={self.ndim})"


class _ArrayTypeFactory:
    """`array`, `array2d`, ...: called with dtype= for a type, subscripted for the same."""

    def __init__(self, ndim: int, name: str):
        self._ndim = ndim
        self.__name__ = name

    def __call__(self, dtype=float, ndim: typing.Optional[int] = None, **_ignored) -> ArrayType:
        return ArrayType(dtype, ndim if ndim is not None else self._ndim)

    def __getitem__(self, dtype) -> ArrayType:
        return ArrayType(dtype, self._ndim)

    def __repr__(self):
        return f"<weft array type factory {self.__name__}>"


array_type = _ArrayTypeFactory(1, "array")
array1d_type = _ArrayTypeFactory(1, "array1d")
array2d_type = _ArrayTypeFactory(2, "array2d")
array3d_type = _ArrayTypeFactory(3, "array3d")
array4d_type = _ArrayTypeFactory(4, "array4d")


class ref:
    """wp.ref[T]: a @wp.func parameter passed by reference (Warp 1.19), sent as the type string
    ref(T). The compiler passes the value in and writes the parameter's final value back to the
    caller's argument (a local, an array element, a component or a struct field) after the call
    (docs/warp-compat.md)."""

    def __class_getitem__(cls, dtype):
        import types as _types  # noqa: PLC0415

        return _types.GenericAlias(cls, (dtype,))
