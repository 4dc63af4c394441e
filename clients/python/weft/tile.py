"""wp.tile[dtype, M, N]: Warp's tile annotation type, for @wp.func parameters. A parameter
annotated wp.tile[float, 8, 4] takes tiles of that element type and shape (the daemon type
"tile(float32,8,4)"); wp.tile[float] (no shape) takes any tile, as a generic parameter. Tiles
themselves live in kernels (docs/tiles.md)."""
from __future__ import annotations

import typing

from . import array_annotations as _annotations


class tile:
    """A tile type: dtype, shape (a tuple of extents, or typing.Any) and storage."""

    __slots__ = ("dtype", "shape", "storage")

    def __init__(self, dtype, shape=typing.Any, storage: str = "register"):
        if storage not in ("register", "shared"):
            raise ValueError(f"wp.tile storage must be 'register' or 'shared', got {storage!r}")
        self.dtype = _annotations._canonical_dtype(dtype)
        self.shape = shape if shape is typing.Any else tuple(_annotations.positive_extent(n, "a wp.tile dimension") for n in shape)
        self.storage = storage

    def __class_getitem__(cls, params):
        params = params if isinstance(params, tuple) else (params,)
        if not params:
            raise TypeError("wp.tile[...] requires at least a dtype")
        dtype, dims = params[0], params[1:]
        if len(dims) == 1 and isinstance(dims[0], tuple):
            dims = dims[0]
        return cls(dtype, tuple(dims) if dims else typing.Any)

    def __eq__(self, other):
        if not isinstance(other, tile):
            return NotImplemented
        return (self.dtype, self.shape, self.storage) == (other.dtype, other.shape, other.storage)

    def __hash__(self):
        return hash((self.dtype, self.shape, self.storage))

    def __repr__(self):
        dims = "" if self.shape is typing.Any else ", " + ", ".join(str(n) for n in self.shape)
        return f"wp.tile[{getattr(self.dtype, '__name__', self.dtype)}{dims}]"


def is_tile(t) -> bool:
    """True for a tile annotation."""
    return isinstance(t, tile)


class tile_stack:
    """wp.tile_stack(capacity=..., dtype=...) as an annotation: a @wp.func parameter taking a tile
    stack of that element type and capacity (daemon type "tile_stack(dtype,capacity)"). In a
    kernel the same call makes an empty stack (docs/tiles.md)."""

    __slots__ = ("capacity", "dtype")

    def __init__(self, capacity: int, dtype=float):
        self.capacity = _annotations.positive_extent(capacity, "a wp.tile_stack capacity")
        self.dtype = _annotations._canonical_dtype(dtype)

    def __eq__(self, other):
        return isinstance(other, tile_stack) and (self.capacity, self.dtype) == (other.capacity, other.dtype)

    def __hash__(self):
        return hash((self.capacity, self.dtype))

    def __repr__(self):
        return f"wp.tile_stack(capacity={self.capacity}, dtype={getattr(self.dtype, '__name__', self.dtype)})"
