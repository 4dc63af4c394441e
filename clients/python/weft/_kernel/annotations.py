"""wp.ref[T]: a @wp.func parameter passed by reference. (Array annotations are
weft.array_annotations.)"""
from __future__ import annotations


class ref:
    """wp.ref[T]: a @wp.func parameter passed by reference (Warp 1.19), sent as the type string
    ref(T). The compiler passes the value in and writes the parameter's final value back to the
    caller's argument (a local, an array element, a component or a struct field) after the call
    (docs/warp-compat.md)."""

    def __class_getitem__(cls, dtype):
        import types as _types  # noqa: PLC0415

        return _types.GenericAlias(cls, (dtype,))
