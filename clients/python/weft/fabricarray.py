"""wp.fabricarray and wp.indexedfabricarray: Warp's views of Omniverse Fabric (USD runtime)
attribute data. weft's daemon has no Fabric runtime and cannot reach memory a Fabric stage owns
in the client's process, so these exist as types only: annotations (`wp.fabricarray[float]`,
`wp.fabricarray(dtype=float, ndim=2)`) describe themselves like Warp's, constructing one over
data is refused with a clear error, and the kernel compiler refuses them as parameter types."""
from __future__ import annotations

import typing

from . import array_annotations as _annotations

_NO_FABRIC = ("weft cannot serve Omniverse Fabric data: the daemon has no Fabric runtime and "
              "cannot reach a Fabric stage's memory in the client process. Copy the attribute "
              "into a wp.array instead.")


class fabricarray:
    """A Fabric attribute array (type only in weft, see the module docstring)."""

    _family = "fabricarray"

    def __class_getitem__(cls, params):
        return _annotations.subscript(cls._family, params)

    def __new__(cls, data=None, attrib=None, dtype=typing.Any, ndim=None):
        if data is not None or attrib is not None:
            raise RuntimeError(_NO_FABRIC)
        # Called without data: the annotation form, as wp.array(dtype=..., ndim=...).
        return _annotations.subscript(cls._family, (dtype, ndim if ndim is not None else 1))


class indexedfabricarray(fabricarray):
    """An indexed view of a Fabric attribute array (type only in weft)."""

    _family = "indexedfabricarray"

    def __new__(cls, fa=None, indices=None, dtype=typing.Any, ndim=None):
        if fa is not None or indices is not None:
            raise RuntimeError(_NO_FABRIC)
        return _annotations.subscript(cls._family, (dtype, ndim if ndim is not None else 1))


def fabricarrayarray(**kwargs):
    """A Fabric array of arrays: `fabricarray(..., ndim=2)` (type only in weft)."""
    kwargs["ndim"] = 2
    return fabricarray(**kwargs)


def indexedfabricarrayarray(**kwargs):
    """An indexed Fabric array of arrays: `indexedfabricarray(..., ndim=2)` (type only in weft)."""
    kwargs["ndim"] = 2
    return indexedfabricarray(**kwargs)
