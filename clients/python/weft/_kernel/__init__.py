"""Kernel-side Python API of weft: @wp.kernel, @wp.func, @wp.struct, wp.launch, wp.Tape."""
from .annotations import ArrayType, array1d_type, array2d_type, array3d_type, array4d_type, array_type
from .api import *  # noqa: F401,F403
from .api import __all__ as _api_all

__all__ = list(_api_all) + ["ArrayType", "array_type", "array1d_type", "array2d_type",
                            "array3d_type", "array4d_type"]
