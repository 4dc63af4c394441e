"""Kernel builtins as Python objects (wp.sin, wp.max, ...): what a Warp program passes for a
`g: wp.Function` parameter or binds to a global (`TARGET = wp.sin`, a parameter default). In
kernel code such a name means the builtin itself (the client sends it as a function symbol
with target "__weft_builtin__.<name>"; the daemon checks that the builtin exists). Called from Python, the scalar
math ones compute with NumPy in float64, and so do the vector ones (length, length_sq, dot,
normalize, cross) on weft vector values, returning a value of the argument's vector type as
Warp does, the quaternion/transform ones (quat_identity, quat_from_axis_angle, quat_rpy,
quat_rotate, quat_to_matrix, transform_point, ...) likewise, and expect_eq prints an error to
stdout when its arguments differ; others raise: call them inside a kernel."""
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
    """The vector (or quaternion: length, dot and normalize take them too) type of value."""
    from . import types as _types   # noqa: PLC0415 - types imports this module's names lazily
    t = type(value)
    return t if _types.is_vector(t) or _types.type_is_quaternion(t) else None


def _vector_builtin(name: str, args):
    """length/length_sq/dot/normalize/cross on weft vectors (and quaternions), in float64;
    NotImplemented when the arguments are not vectors of one type (and of length 3 for cross)."""
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


# Quaternion and transform builtins from Python: float64 math, results in the scalar type of
# the arguments (float32 for Python numbers), with the kernel builtins' formulas (native/quat.h).
def _scalar_of(*values):
    from . import types as _types   # noqa: PLC0415
    for v in values:
        s = getattr(type(v), "_wp_scalar_type_", None)
        if s is not None:
            return s
        if isinstance(v, _types._Scalar):
            return type(v)
    return _types.float32


def _quat(scalar, x):
    from . import types as _types   # noqa: PLC0415
    return _types.quaternion(scalar)(*x)


def _qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def _rotate(q, v):
    q = np.asarray(q, dtype=np.float64)
    return _qmul(_qmul(q, np.append(np.asarray(v, dtype=np.float64), 0.0)), q * [-1, -1, -1, 1])[:3]


def _quat_identity(dtype=None):
    from . import types as _types   # noqa: PLC0415
    return _quat(dtype or _types.float32, (0.0, 0.0, 0.0, 1.0))


def _transform_identity(dtype=None):
    from . import types as _types   # noqa: PLC0415
    return _types.transformation(dtype or _types.float32)(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _quat_from_axis_angle(axis, angle):
    h = 0.5 * float(angle)
    a = np.asarray(axis, dtype=np.float64) * np.sin(h)
    return _quat(_scalar_of(axis, angle), (a[0], a[1], a[2], np.cos(h)))


def _quat_rpy(roll, pitch, yaw):
    cy, sy = np.cos(0.5 * float(yaw)), np.sin(0.5 * float(yaw))
    cr, sr = np.cos(0.5 * float(roll)), np.sin(0.5 * float(roll))
    cp, sp = np.cos(0.5 * float(pitch)), np.sin(0.5 * float(pitch))
    return _quat(_scalar_of(roll, pitch, yaw), (cy * sr * cp - sy * cr * sp, cy * cr * sp + sy * sr * cp,
                                                sy * cr * cp - cy * sr * sp, cy * cr * cp + sy * sr * sp))


def _quat_inverse(q):
    x = np.asarray(q, dtype=np.float64)
    return _quat(_scalar_of(q), (-x[0], -x[1], -x[2], x[3]))


def _quat_rotate(q, v):
    return type(v)(*_rotate(q, v))


def _quat_rotate_inv(q, v):
    x = np.asarray(q, dtype=np.float64)
    return type(v)(*_rotate(x * [-1, -1, -1, 1], v))


def _quat_to_matrix(q):
    from . import types as _types   # noqa: PLC0415
    cols = [_rotate(q, e) for e in np.eye(3)]
    return _types.matrix((3, 3), _scalar_of(q))(*np.stack(cols, axis=1).reshape(-1))


def _transform_point(t, p):
    x = np.asarray(t, dtype=np.float64)
    return type(p)(*(_rotate(x[3:], p) + x[:3]))


def _transform_vector(t, v):
    return type(v)(*_rotate(np.asarray(t, dtype=np.float64)[3:], v))


_QUATERNION = {
    "quat_identity": _quat_identity, "transform_identity": _transform_identity,
    "quat_from_axis_angle": _quat_from_axis_angle, "quat_rpy": _quat_rpy,
    "quat_inverse": _quat_inverse, "quat_rotate": _quat_rotate, "quat_rotate_inv": _quat_rotate_inv,
    "quat_to_matrix": _quat_to_matrix, "transform_point": _transform_point,
    "transform_vector": _transform_vector,
}


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

    def __call__(self, *args, **kwargs):
        name = self.key
        if name in _QUATERNION:
            return _QUATERNION[name](*args, **kwargs)
        if kwargs:
            raise RuntimeError(f"wp.{name}() from Python takes no keyword arguments")
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


_NAMES = tuple(_UNARY) + tuple(_BINARY) + _VECTOR + tuple(_CHECKS) + tuple(_QUATERNION) + _KERNEL_ONLY
for _name in _NAMES:
    globals()[_name] = BuiltinFunction(_name)
__all__ = list(_NAMES)
