"""Fixed-size arrays (Warp's wp.fixedarray): the type of `wp.zeros(shape=..., dtype=...)` called
inside a kernel or func, a value holding its elements on the thread's stack. In Python this is
only an annotation (`-> wp.fixedarray(shape=(2, 3), dtype=int)`); its type string is
fixedarray(T,d0,...). A fixed-size array passes to a func's array parameter as a view of its
elements; it cannot be a kernel argument or struct field.
"""
from __future__ import annotations

import typing

from . import types


class fixedarray:
    """A fixed-size array type: wp.fixedarray(shape=(2, 3), dtype=float)."""

    _fixed_ = True

    def __init__(self, dtype: typing.Any = typing.Any, shape=None):
        if shape is None:
            raise TypeError("wp.fixedarray needs a shape")
        if isinstance(shape, int):
            shape = (shape,)
        shape = tuple(int(n) for n in shape)
        if not 1 <= len(shape) <= 4 or any(n < 1 for n in shape):
            raise ValueError(f"invalid fixed-size array shape {shape}")
        self.dtype = dtype
        self.shape = shape
        self.ndim = len(shape)
        self.size = 1
        for n in shape:
            self.size *= n

    def _type_str(self) -> str:
        return "fixedarray(" + ",".join([types.type_str(self.dtype)] +
                                        [str(n) for n in self.shape]) + ")"

    def __repr__(self) -> str:
        return f"fixedarray(shape={self.shape}, dtype={types.type_str(self.dtype)})"
