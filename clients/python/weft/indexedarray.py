"""Indexed arrays (Warp's wp.indexedarray): a weft array seen through one optional int32 index
array per dimension. Owns the class, its annotation forms (wp.indexedarray[float],
wp.indexedarray[float, Literal[2]], wp.indexedarray2d[float], wp.indexedarray(dtype=, ndim=)),
and its host-side operations (numpy, fill_, zero_, assign, copies), which gather and scatter
through the indices on the host.

In kernels an indexed array is a parameter of type indexedarray(T,N): the daemon receives the
data array and the index arrays as arrays (each validated as one of the session's arrays), and
the generated code checks every index value against the data array at each access.
"""
from __future__ import annotations

import typing

import numpy as np

import sys

from . import array_annotations as _array_annotations
from . import types
from .array import array as _array_cls  # noqa: F401 - the module is weft.array

_array_mod = sys.modules[__package__ + ".array"]

ARRAY_MAX_DIMS = 4


def _literal_ndim(arg) -> typing.Optional[int]:
    """N of a typing.Literal[N] annotation argument (or a plain int), else None."""
    if isinstance(arg, int) and not isinstance(arg, bool):
        return arg
    if typing.get_origin(arg) is typing.Literal:
        values = typing.get_args(arg)
        if len(values) == 1 and isinstance(values[0], int):
            return values[0]
    return None


def annotation_ndim(origin, args) -> int:
    """The number of dimensions of an indexed-array annotation alias."""
    ndim = getattr(origin, "_default_ndim_", 1)
    if len(args) > 1:
        lit = _literal_ndim(args[1])
        if lit is None:
            raise TypeError(f"invalid number of dimensions {args[1]!r} in an indexedarray "
                            f"annotation: use typing.Literal[N]")
        ndim = lit
    return ndim


def _is_index_array(value) -> bool:
    return isinstance(value, _array_mod.array)


class indexedarray:
    """An array viewed through per-dimension int32 index arrays (Warp's wp.indexedarray)."""

    _default_ndim_ = 1
    _indexed_ = True

    def __class_getitem__(cls, params):
        # wp.indexedarray[float] / wp.indexedarray[float, Literal[2]]: annotation objects.
        return _array_annotations.subscript("indexedarray", params)

    def __init__(self, data=None, indices=None, dtype=typing.Any, ndim=None):
        self.indices = []
        if data is None:
            # An annotation object: wp.indexedarray(dtype=float, ndim=2).
            self.data = None
            self.dtype = dtype
            self.ndim = int(ndim) if ndim is not None else self._default_ndim_
            self.shape = (0,) * self.ndim
            self.size = 0
            self.device = None
            self.indices = [None] * self.ndim
            return
        if not isinstance(data, _array_mod.array):
            raise TypeError(f"indexedarray data must be a weft array, got {type(data).__name__}")
        if ndim is not None and int(ndim) != data.ndim:
            raise ValueError(f"Array dimensions ({data.ndim}) do not match the indexedarray "
                             f"dimensions ({ndim})")
        if indices is None:
            indices = []
        elif _is_index_array(indices):
            indices = [indices]
        indices = list(indices)
        if len(indices) > data.ndim:
            raise ValueError(f"Number of indices ({len(indices)}) exceeds the number of "
                             f"array dimensions ({data.ndim})")
        indices += [None] * (data.ndim - len(indices))
        shape = []
        for d, idx in enumerate(indices):
            if idx is None:
                shape.append(int(data.shape[d]))
                continue
            if not _is_index_array(idx):
                raise TypeError(f"Index array for dimension {d} must be a weft array of int32, "
                                f"got {type(idx).__name__}")
            if types.type_str(idx.dtype) != "int32":
                raise TypeError(f"Index array for dimension {d} must have dtype int32, got "
                                f"{types.type_str(idx.dtype)}")
            if idx.ndim != 1:
                raise ValueError(f"Index array for dimension {d} must be 1-d, got {idx.ndim} "
                                 f"dimensions")
            if idx.device != data.device:
                raise ValueError(f"Index array for dimension {d} is on {idx.device}, the data on "
                                 f"{data.device}")
            shape.append(int(idx.shape[0]))
        self.data = data
        self.dtype = data.dtype
        self.ndim = data.ndim
        self.device = data.device
        self.indices = indices
        self.shape = tuple(shape)
        self.size = int(np.prod(self.shape)) if self.shape else 0

    # -- kernel typing
    def _type_str(self) -> str:
        return f"indexedarray({types.type_str(self.dtype)},{self.ndim})" \
            if self.dtype is not typing.Any else f"indexedarray(any,{self.ndim})"

    @property
    def is_contiguous(self) -> bool:
        """Always False: an indexed view gathers elements, it is never one contiguous block
        (Warp's rule; wp.copy from or into it takes no offsets)."""
        return False

    @property
    def requires_grad(self) -> bool:
        return bool(self.data is not None and self.data.requires_grad)

    @property
    def grad(self):
        """The indexed view of the data's gradient (None without one)."""
        g = self.data.grad if self.data is not None else None
        return indexedarray(g, self.indices) if g is not None else None

    def __len__(self) -> int:
        return self.shape[0]

    def __repr__(self) -> str:
        return f"indexedarray(shape={self.shape}, dtype={types.type_str(self.dtype)})"

    # -- host access
    def _selection(self, data_np=None) -> tuple:
        """Per-dimension index vectors into the data array (bounds-checked on the host)."""
        sel = []
        for d in range(self.ndim):
            n = int(self.data.shape[d])
            idx = self.indices[d]
            if idx is None:
                sel.append(np.arange(n, dtype=np.int64))
                continue
            values = np.asarray(idx.numpy(), dtype=np.int64).reshape(-1)
            bad = (values < 0) | (values >= n)
            if bad.any():
                k = int(np.argmax(bad))
                raise IndexError(f"indexedarray: index {int(values[k])} at position {k} of the "
                                 f"index array of dimension {d} is out of bounds for size {n}")
            sel.append(values)
        return np.ix_(*sel) if sel else ()

    def numpy(self) -> np.ndarray:
        """A NumPy copy of the selected elements (shape + the dtype's inner shape)."""
        values = self.data.numpy()
        if self.size == 0:
            return np.empty(tuple(self.shape) + values.shape[self.ndim:], dtype=values.dtype)
        return np.ascontiguousarray(values[self._selection()])

    def __array__(self, dtype=None, copy=None):
        values = self.numpy()
        return values if dtype is None else values.astype(dtype)

    def list(self):
        if self.size == 0:
            return []
        return _array_mod.array(self.numpy(), dtype=self.dtype, device="cpu").list()

    def _scatter(self, values: np.ndarray) -> None:
        """Writes `values` (broadcast to the selection) into the selected data elements."""
        if self.size == 0:
            return
        full = np.array(self.data.numpy(), copy=True)
        full[self._selection()] = values
        self.data.assign(full)

    def _element(self, value) -> np.ndarray:
        """One element of this dtype as NumPy (value converted as fill_ does for arrays)."""
        np_dtype, inner = _array_mod._elem_layout(self.dtype)
        raw = types.value_to_bytes(self.dtype, value) if types.is_dtype(self.dtype) else \
            _array_mod._struct_bytes(self.dtype, value)
        return np.frombuffer(raw, dtype=np_dtype).reshape(inner)

    def fill_(self, value):
        """Sets every selected element to `value`."""
        if self.size:
            self._scatter(self._element(value))
        return self

    def zero_(self):
        """Sets every selected element to zero."""
        if self.size:
            np_dtype, inner = _array_mod._elem_layout(self.dtype)
            self._scatter(np.zeros(inner, dtype=np_dtype))
        return self

    def assign(self, src):
        """Copies `src` (an array, indexed array, NumPy array or list of this shape) into the
        selected elements."""
        if isinstance(src, (indexedarray, _array_mod.array)):
            if tuple(src.shape) != tuple(self.shape):
                raise RuntimeError(f"Cannot assign an array of shape {tuple(src.shape)} to an "
                                   f"indexedarray of shape {self.shape}")
            src = src.numpy()
        if self.size:
            np_dtype, inner = _array_mod._elem_layout(self.dtype)
            self._scatter(np.asarray(src, dtype=np_dtype).reshape(tuple(self.shape) + inner))
        return self

    def contiguous(self):
        """A new contiguous weft array with a copy of the selected elements."""
        return _array_mod.array(self.numpy(), dtype=self.dtype, shape=self.shape,
                                device=self.device)

    def to(self, device):
        return self.contiguous().to(device)


class _IndexedOfDim:
    """wp.indexedarray1d..4d: construct with that ndim, or subscript for annotations."""

    _indexed_ = True

    def __init__(self, ndim: int):
        self._default_ndim_ = ndim
        self.ndim = ndim
        self.__name__ = self.__qualname__ = f"indexedarray{ndim}d"

    def __call__(self, data=None, indices=None, dtype=typing.Any, ndim=None):
        return indexedarray(data, indices, dtype, self._default_ndim_)

    def __getitem__(self, params):
        return _array_annotations.subscript_fixed_ndim("indexedarray", self.__name__, self.ndim, params)

    def __repr__(self):
        return f"<weft {self.__name__}>"


indexedarray1d = _IndexedOfDim(1)
indexedarray2d = _IndexedOfDim(2)
indexedarray3d = _IndexedOfDim(3)
indexedarray4d = _IndexedOfDim(4)


def is_indexed(obj) -> bool:
    return isinstance(obj, indexedarray)
