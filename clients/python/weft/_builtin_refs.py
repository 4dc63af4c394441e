"""Kernel builtins as Python objects (wp.sin, wp.max, ...): what a Warp program passes for a
`g: wp.Function` parameter or binds to a global (`TARGET = wp.sin`, a parameter default). In
kernel code such a name means the builtin itself (the client sends it as a function symbol
with target "__weft_builtin__.<name>"; the daemon checks that the builtin exists). Called from Python, the scalar
math ones compute with NumPy in float64, and so do the vector ones (length, length_sq, dot,
normalize, cross) on weft vector values, returning a value of the argument's vector type as
Warp does, and expect_eq prints an error to stdout when its arguments differ; others raise: call them inside a kernel."""
from __future__ import annotations

import builtins
import math

import numpy as np

_UNARY = {
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "asin": np.arcsin, "acos": np.arccos,
    "atan": np.arctan, "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh, "sqrt": np.sqrt,
    "cbrt": np.cbrt, "exp": np.exp, "log": np.log, "log2": np.log2, "log10": np.log10,
    "floor": np.floor, "ceil": np.ceil, "trunc": np.trunc, "abs": np.abs, "sign": np.sign,
    "neg": np.negative, "degrees": np.degrees, "radians": np.radians,
}
_BINARY = {
    "add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.divide,
    "min": np.minimum, "max": np.maximum, "pow": np.power, "atan2": np.arctan2, "mod": np.fmod,
}
# Builtins without a Python implementation here (referenced, passed, called in kernels).
_KERNEL_ONLY = ("clamp", "outer", "transpose",
                "determinant", "inverse", "lerp", "smoothstep", "step", "nonzero", "round", "rint",
                "frac", "isnan", "isinf", "isfinite", "erf", "erfc", "erfinv", "erfcinv")


def _vector_type(value):
    from . import types as _types   # noqa: PLC0415 - types imports this module's names lazily
    t = type(value)
    return t if _types.is_vector(t) else None


def _vector_builtin(name: str, args):
    """length/length_sq/dot/normalize/cross on weft vectors, in float64; NotImplemented when the
    arguments are not vectors of one type (and of length 3 for cross)."""
    vt = _vector_type(args[0]) if args else None
    if vt is None or any(type(a) is not vt for a in args):
        return NotImplemented
    x = [np.asarray(a, dtype=np.float64) for a in args]
    if name == "length" and len(x) == 1:
        return float(np.sqrt(np.dot(x[0], x[0])))
    if name == "length_sq" and len(x) == 1:
        return float(np.dot(x[0], x[0]))
    if name == "dot" and len(x) == 2:
        return float(np.dot(x[0], x[1]))
    if name == "normalize" and len(x) == 1:
        n = np.sqrt(np.dot(x[0], x[0]))
        return vt(*((x[0] / n) if n > 0.0 else np.zeros_like(x[0])))   # Warp: zero stays zero
    if name == "cross" and len(x) == 2 and len(x[0]) == 3:
        return vt(*np.cross(x[0], x[1]))
    return NotImplemented


_VECTOR = ("length", "length_sq", "dot", "normalize", "cross")


def _expect_eq(a, b):
    """wp.expect_eq from Python (as Warp's): prints an error to stdout when a != b."""
    if not np.array_equal(np.asarray(a), np.asarray(b)):
        print(f"Error: expect_eq() failed: {a} != {b}")


_CHECKS = {"expect_eq": _expect_eq}


class BuiltinFunction:
    """A kernel builtin by name."""

    _weft_builtin_ = True

    def __init__(self, name: str):
        self.key = name
        self.__name__ = self.__qualname__ = name

    def __call__(self, *args):
        name = self.key
        if name in _CHECKS:
            return _CHECKS[name](*args)
        if name in _VECTOR:
            out = _vector_builtin(name, args)
            if out is NotImplemented:
                raise RuntimeError(f"wp.{name}() from Python takes weft vector values of one type "
                                   f"(vec3 for cross); other forms only inside a kernel or @wp.func")
            return out
        fn = _UNARY.get(name) if len(args) == 1 else _BINARY.get(name) if len(args) == 2 else None
        if fn is None and name in ("min", "max", "round", "abs", "pow"):
            return getattr(builtins, name)(*args)    # min([..]), round(x, n): Python's
        if fn is None:
            raise RuntimeError(f"wp.{name}() with {len(args)} argument(s) can only be called "
                               f"inside a kernel or @wp.func in weft")
        out = fn(*[np.asarray(a, dtype=np.float64) for a in args])
        if np.ndim(out) == 0:
            value = float(out)
            return value if not all(isinstance(a, int) for a in args) or not value.is_integer() \
                or name in ("div", "sqrt", "pow") or not math.isfinite(value) else int(value)
        return out

    def __repr__(self) -> str:
        return f"<weft builtin {self.key}>"


def is_builtin_ref(value) -> bool:
    return isinstance(value, BuiltinFunction)


_NAMES = tuple(_UNARY) + tuple(_BINARY) + _VECTOR + tuple(_CHECKS) + _KERNEL_ONLY
for _name in _NAMES:
    globals()[_name] = BuiltinFunction(_name)
__all__ = list(_NAMES)
