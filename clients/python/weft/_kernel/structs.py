"""@wp.struct: struct types declared by annotated Python classes, their Python-side instances
(attribute access, usable as launch arguments) and their wire form (StructDef, StructValue)."""
from __future__ import annotations

import copy
import ctypes
import inspect
import re
import typing

import numpy as np

from . import typestr


def canonical_name(module: str, qualname: str) -> str:
    """module.Qualname with characters a compiler cannot use in a name replaced by '_'."""
    qualname = qualname.replace("<locals>", "locals")
    return re.sub(r"[^A-Za-z0-9_.]", "_", f"{module}.{qualname}")


class StructAttributeError(AttributeError, RuntimeError):
    """Unknown struct field: an AttributeError, and a RuntimeError as Warp raises."""


class StructField:
    """One declared field: name, annotation object and its type string."""

    def __init__(self, name: str, annotation):
        self.name = name
        self.annotation = annotation
        self.type_str = typestr.type_string(annotation)
        if typestr.is_generic(self.type_str):   # typing.Any, wp.Int/Float/Scalar, vector(Any, ...)
            raise TypeError(f"struct field '{name}': a struct field needs a concrete type, not "
                            f"the generic {self.type_str}")
        self.desc = typestr.parse(self.type_str)


class StructInstance:
    """A value of a @wp.struct type: fields as attributes, zero/None until assigned."""

    __slots__ = ("_struct_type", "_values")

    def __init__(self, struct_type: "StructType", **kwargs):
        object.__setattr__(self, "_struct_type", struct_type)
        object.__setattr__(self, "_values", {})
        for field in struct_type.fields:
            self._values[field.name] = struct_type._default(field)
        for name, value in kwargs.items():
            setattr(self, name, value)

    def __getattr__(self, name):
        values = object.__getattribute__(self, "_values")
        if name in values:
            return values[name]
        raise StructAttributeError(f"struct {self._struct_type.key} has no field {name!r}")

    def __setattr__(self, name, value):
        field = self._struct_type.field(name)
        if field is None:
            raise StructAttributeError(f"Trying to set struct attribute that does not exist: "
                                       f"{self._struct_type.key} has no field {name!r}")
        self._values[name] = self._struct_type._convert(field, value)

    def __repr__(self):
        inner = ", ".join(f"{k}={v!r}" for k, v in self._values.items())
        return f"{self._struct_type.cls.__name__}({inner})"

    def _to(self, device) -> "StructInstance":
        """A copy of the struct with its array members on `device` (Warp's StructInstance.to):
        an array already there is referenced as it is, another is copied; an indexed array on
        another device becomes an identity indexed array over a copy of the values it selects;
        nested structs likewise, other fields copied."""
        from weft.device import get_device  # noqa: PLC0415
        return _snapshot(self, get_device(device))

    class _FieldFirst:
        """`inst.to`: the struct's own field of that name where it has one, else the method."""

        def __get__(self, inst, owner):
            if inst is None:
                return owner._to
            values = object.__getattribute__(inst, "_values")
            return values["to"] if "to" in values else inst._to

    to = _FieldFirst()

    def __ctype__(self) -> "StructCtype":
        """Warp's ctypes value of the struct: a snapshot of the fields as they are now (later
        assignments to this instance do not change it), which wp.Launch's
        set_param_*_from_ctype takes."""
        out = StructCtype()
        out._weft_value = _snapshot(self)
        return out


class StructCtype(ctypes.Structure):
    """What StructInstance.__ctype__ gives: a ctypes.Structure (as Warp's) that carries a
    snapshot of the instance in `_weft_value`; weft sends structs field by field, not as
    these bytes."""

    _fields_ = ()


def _snapshot(inst: StructInstance, device=None) -> StructInstance:
    """A copy of a struct instance: nested structs, vectors and matrices copied, arrays shared;
    with `device`, array members not on it copied there (an indexed array as an identity
    indexed array over the values it selects)."""
    from weft.array import array  # noqa: PLC0415
    from weft.indexedarray import indexedarray  # noqa: PLC0415
    from weft.types import _Composite  # noqa: PLC0415

    out = StructInstance(inst._struct_type)
    for name, value in inst._values.items():
        if isinstance(value, StructInstance):
            value = _snapshot(value, device)
        elif isinstance(value, (_Composite, np.ndarray)):
            value = copy.deepcopy(value)
        elif device is not None and isinstance(value, (array, indexedarray)) and \
                value.device is not None and value.device != device:
            moved = value.to(device)
            value = indexedarray(moved) if isinstance(value, indexedarray) else moved
        out._values[name] = value
    return out


def _declared_at(cls) -> str:
    """file:line of a class's declaration, or its module's name where the source is unknown."""
    try:
        return f"{inspect.getsourcefile(cls)}:{inspect.getsourcelines(cls)[1]}"
    except (OSError, TypeError):
        return cls.__module__


class StructType:
    """The type object @wp.struct returns: call it to make an instance."""

    def __init__(self, cls):
        self.cls = cls
        self.key = canonical_name(cls.__module__, cls.__qualname__)
        self._type_str = f"struct({self.key})"
        self.__name__ = cls.__name__
        self.__qualname__ = cls.__qualname__
        self.__module__ = cls.__module__
        self.__doc__ = cls.__doc__
        annotations = typing.get_type_hints(cls) if _hints_are_strings(cls) else \
            dict(getattr(cls, "__annotations__", {}))
        # A Fabric array field makes a struct that can be declared but not used in a kernel: the
        # field is left out and the error is raised when a module using the struct is built.
        self.build_error = None
        self.fields = []
        for name, ann in annotations.items():
            try:
                self.fields.append(StructField(name, ann))
            except typestr.FabricArrayRefused as err:
                if self.build_error is None:
                    self.build_error = (f"{_declared_at(cls)}: error: struct field '{name}' of "
                                        f"{self.key}: {err}")
        self._by_name = {f.name: f for f in self.fields}

    def __call__(self, **kwargs) -> StructInstance:
        return StructInstance(self, **kwargs)

    def __repr__(self):
        return f"<weft struct {self.key}>"

    def field(self, name: str) -> typing.Optional[StructField]:
        return self._by_name.get(name)

    # --- values -------------------------------------------------------------------------
    def _default(self, field: StructField):
        desc = field.desc
        if desc.kind in ("array", "indexedarray"):
            return None
        if desc.kind == "struct":
            return field.annotation()
        if desc.kind == "scalar":
            return False if desc.scalar == "bool" else (
                0 if desc.scalar in typestr.INT_SCALARS else 0.0)
        try:
            return field.annotation()
        except Exception:  # noqa: BLE001 - not constructible without args: zeros
            return np.zeros(desc.shape, dtype=desc.numpy_scalar)

    def _convert(self, field: StructField, value):
        desc = field.desc
        if desc.kind == "struct":
            if not isinstance(value, StructInstance) or value._struct_type.key != desc.struct_name:
                raise TypeError(f"field {field.name} of {self.key} expects a {desc.struct_name}, "
                                f"got {type(value).__name__}")
            return value
        if desc.kind == "array":
            return value
        if desc.kind == "indexedarray":
            from weft.indexedarray import indexedarray  # noqa: PLC0415

            if value is not None and not isinstance(value, indexedarray):
                raise TypeError(f"field {field.name} of {self.key} expects an indexedarray, "
                                f"got {type(value).__name__}")
            return value
        # validate eagerly so errors point at the assignment
        typestr.pack_value(desc, value)
        if desc.kind == "scalar" and desc.scalar == "bool" and not isinstance(value, bool):
            return bool(value)      # `s.flag = 1` holds True, as Warp's bool field does
        return value

    def from_record(self, record) -> StructInstance:
        """The instance one element of numpy_dtype() holds (arrays of structs: list(), [i]):
        scalars as Python numbers, vectors/matrices as their dtype, nested structs likewise."""
        inst = StructInstance(self)
        for field in self.fields:
            desc, value = field.desc, record[field.name]
            if desc.kind == "struct":
                value = field.annotation.from_record(value)
            elif desc.shape:
                value = field.annotation(np.asarray(value).reshape(-1).tolist())
            else:
                value = value.item() if hasattr(value, "item") else value
            inst._values[field.name] = value
        return inst

    # --- wire forms ---------------------------------------------------------------------
    def referenced_structs(self) -> list:
        """Struct types of nested fields (and array members' element structs), depth first."""
        found = []
        for field in self.fields:
            for t in _struct_types_in(field.annotation):
                found.append(t)
        return found

    def numpy_dtype(self) -> np.dtype:
        """A C-layout structured dtype of one element (arrays of structs), natural alignment."""
        names, formats, offsets, offset, align = [], [], [], 0, 1
        for field in self.fields:
            desc = field.desc
            if desc.kind == "struct":
                sub = field.annotation.numpy_dtype()
                fmt, a = sub, max(sub.alignment, 1)
            elif desc.kind in ("array", "indexedarray"):
                raise TypeError(f"struct {self.key} has an array member and cannot be an "
                                f"array element")
            else:
                fmt = np.dtype((desc.numpy_scalar, desc.shape)) if desc.shape else desc.numpy_scalar
                a = desc.numpy_scalar.alignment
            offset = (offset + a - 1) // a * a
            names.append(field.name)
            formats.append(fmt)
            offsets.append(offset)
            offset += np.dtype(fmt).itemsize
            align = max(align, a)
        size = (offset + align - 1) // align * align
        return np.dtype({"names": names, "formats": formats, "offsets": offsets,
                         "itemsize": max(size, 1)}, align=True)


def _hints_are_strings(cls) -> bool:
    return any(isinstance(a, str) for a in getattr(cls, "__annotations__", {}).values())


def _struct_types_in(annotation) -> list:
    if isinstance(annotation, StructType):
        return annotation.referenced_structs() + [annotation]
    dtype = getattr(annotation, "dtype", None)
    if isinstance(dtype, StructType):
        return dtype.referenced_structs() + [dtype]
    args = getattr(annotation, "__args__", None) or ()
    out = []
    for a in args:
        if isinstance(a, StructType):
            out += a.referenced_structs() + [a]
    return out


def struct(cls) -> StructType:
    """@wp.struct: declares a struct type from a class with annotated fields."""
    return StructType(cls)
