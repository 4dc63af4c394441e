"""Sparse volumes of Warp's API (wp.Volume): NanoVDB files and buffers read and written with
NumPy on the client, the grid itself held by the daemon (docs/geometry.md).

A volume is a set of leaves, 8x8x8 voxel blocks at index-space origins that are multiples of
8, each with a 512-bit active mask and (for value grids) 512 values; an index-to-world affine
map; a background value for voxels outside every leaf. The client sends exactly that to the
daemon (GeometryRequest CREATE_VOLUME: leaves, masks, values, value_type, background,
transform) and keeps a host copy of the topology (leaf origins, masks, map, name, blind data)
for the introspection calls. Kernels read and write the `values` array in place.

This module owns: the NanoVDB layout facts it needs (per-type node sizes and offsets), a
bounds-checked NanoVDB reader (file header, codecs none/zip, grid, tree, root, internal nodes,
leaves, blind data) and a writer of breadth-first NanoVDB grids and files, the tile/voxel
computations of the allocation calls, and the `Volume` class.
"""
from __future__ import annotations

import math
import struct
import zlib
from typing import NamedTuple

import numpy as np

from . import _runtime
from . import types as _types
from .device import get_device
from .geometry import _Object, _call, _handle_of, _op

__all__ = ["Volume"]

# ---------------------------------------------------------------------------------------------
# NanoVDB layout facts (PNanoVDB.h)

_MAGIC_NUMB = 0x304244566F6E614E   # "NanoVDB0"
_MAGIC_GRID = 0x314244566F6E614E   # "NanoVDB1"
_MAGIC_FILE = 0x324244566F6E614E   # "NanoVDB2"
_MAJOR_VERSION = 32
_VERSION = (32 << 21) | (8 << 10) | 0
_ALIGN = 32
_GRID_SIZE = 672
_TREE_SIZE = 64
_FILE_HEADER_SIZE = 16
_FILE_META_SIZE = 176
_BLIND_META_SIZE = 288
_NAME_SIZE = 256
_LEAF_VOXELS = 512
_UPPER_TABLE = 32768
_LOWER_TABLE = 4096
_UPPER_CHILD_MASK = 4128
_LOWER_CHILD_MASK = 544
_NODE_VALUE_MASK = 32
_FLAG_HAS_BBOX = 1 << 1
_CHECKSUM_DISABLED = (1 << 64) - 1
_FLAG_BREADTH_FIRST = 1 << 5
_CLASS_UNKNOWN = 0
_CLASS_INDEX_GRID = 8

_TYPE_NAMES = ["?", "float", "double", "int16", "int32", "int64", "Vec3f", "Vec3d", "Mask", "Half",
               "uint32", "bool", "RGBA8", "Float4", "Float8", "Float16", "FloatN", "Vec4f", "Vec4d",
               "Index", "OnIndex", "IndexMask", "OnIndexMask", "PointIndex", "Vec3u8", "Vec3u16", "uint8"]

INDEX = 19
ON_INDEX = 20


class _Layout(NamedTuple):
    """Where one grid type keeps its data: value component dtype and count, root background
    offset and size, root tile value offset and size, table offsets/strides of the upper and
    lower nodes, leaf table offset and leaf size."""
    scalar: str
    components: int
    root_background: int
    root_size: int
    tile_value: int
    tile_size: int
    table_stride: int
    upper_table: int
    upper_size: int
    lower_table: int
    lower_size: int
    leaf_table: int
    leaf_size: int

    @property
    def value_bytes(self) -> int:
        return np.dtype(self.scalar).itemsize * self.components


def _layout(scalar, components, bg, root, tile_val, tile, stride, up_t, up, lo_t, lo, leaf_t, leaf):
    return _Layout(scalar, components, bg, root, tile_val, tile, stride, up_t, up, lo_t, lo, leaf_t, leaf)


_LAYOUTS = {
    1: _layout("<f4", 1, 28, 64, 20, 32, 8, 8256, 270400, 1088, 33856, 96, 2144),
    2: _layout("<f8", 1, 32, 96, 24, 32, 8, 8256, 270400, 1088, 33856, 128, 4224),
    4: _layout("<i4", 1, 28, 64, 20, 32, 8, 8256, 270400, 1088, 33856, 96, 2144),
    5: _layout("<i8", 1, 32, 96, 24, 32, 8, 8256, 270400, 1088, 33856, 128, 4224),
    6: _layout("<f4", 3, 28, 96, 20, 32, 16, 8256, 532544, 1088, 66624, 128, 6272),
    7: _layout("<f8", 3, 32, 128, 24, 64, 24, 8288, 794720, 1120, 99424, 160, 12448),
    10: _layout("<u4", 1, 28, 64, 20, 32, 8, 8256, 270400, 1088, 33856, 96, 2144),
    17: _layout("<f4", 4, 28, 96, 20, 64, 16, 8288, 532576, 1120, 66656, 128, 8320),
    18: _layout("<f8", 4, 32, 160, 24, 64, 32, 8320, 1056896, 1152, 132224, 160, 16544),
    INDEX: _layout("<u8", 1, 32, 96, 24, 32, 8, 8256, 270400, 1088, 33856, 80, 96),
    ON_INDEX: _layout("<u8", 1, 32, 96, 24, 32, 8, 8256, 270400, 1088, 33856, 80, 96),
}


def _type_name(grid_type: int) -> str:
    return _TYPE_NAMES[grid_type] if 0 <= grid_type < len(_TYPE_NAMES) else "End"


def _is_index_type(grid_type: int) -> bool:
    return grid_type in (INDEX, ON_INDEX)


def _layout_of(grid_type: int) -> _Layout:
    layout = _LAYOUTS.get(grid_type)
    if layout is None:
        raise RuntimeError(f"NanoVDB grid type {_type_name(grid_type)!r} ({grid_type}) is not supported by weft "
                           f"volumes (supported: {', '.join(_type_name(t) for t in _LAYOUTS)})")
    return layout


_MAX_EXPANDED_LEAVES = 1 << 16   # internal-node tiles expanded into at most this many leaves


# ---------------------------------------------------------------------------------------------
# The grid content shared by the reader, the writer and the daemon request


class BlindData(NamedTuple):
    """One blind-data (feature) array of a grid: its metadata and raw bytes."""
    name: str
    value_count: int
    value_size: int
    semantic: int
    data_class: int
    data_type: int
    data: bytes


class GridContent:
    """One sparse grid: leaf origins (n, 3) int32, active masks (n, 8) uint64 (voxel (x, y, z)
    of a leaf is bit x*64 + y*8 + z), values (n*512, components) of the layout's scalar dtype
    (None for index grids), background (components,), index-to-world matrix (3, 3) and
    translation (3,) in float64, voxel size (3,), name, grid class and blind data."""

    def __init__(self, grid_type, origins, masks, values, background, matrix, translation,
                 voxel_size=None, name="", grid_class=_CLASS_UNKNOWN, blind=()):
        self.grid_type = int(grid_type)
        self.layout = _layout_of(self.grid_type)
        self.origins = np.ascontiguousarray(origins, dtype=np.int32).reshape(-1, 3)
        self.masks = np.ascontiguousarray(masks, dtype=np.uint64).reshape(-1, 8)
        self.values = values
        self.background = np.asarray(background, dtype=self.layout.scalar).reshape(self.layout.components)
        self.matrix = np.asarray(matrix, dtype=np.float64).reshape(3, 3)
        self.translation = np.asarray(translation, dtype=np.float64).reshape(3)
        self.voxel_size = (self.matrix @ np.ones(3) if voxel_size is None
                           else np.asarray(voxel_size, dtype=np.float64).reshape(3))
        self.name = name
        self.grid_class = int(grid_class)
        self.blind = list(blind)

    @property
    def leaf_count(self) -> int:
        return self.origins.shape[0]

    @property
    def is_index(self) -> bool:
        return _is_index_type(self.grid_type)

    def without_values(self) -> GridContent:
        out = GridContent(self.grid_type, self.origins, self.masks, None, self.background, self.matrix,
                          self.translation, self.voxel_size, self.name, self.grid_class, self.blind)
        out.grid_index = getattr(self, "grid_index", 0)
        out.grid_count = getattr(self, "grid_count", 1)
        return out

    def active_count(self) -> int:
        if getattr(self, "_active_count", None) is None:
            self._active_count = int(_popcount64(self.masks).sum())
        return self._active_count


_BYTE_POPCOUNT = np.unpackbits(np.arange(256, dtype=np.uint8)[:, None], axis=1).sum(axis=1).astype(np.int64)


def _popcount64(words: np.ndarray) -> np.ndarray:
    raw = np.ascontiguousarray(words, dtype="<u8").view(np.uint8).reshape(words.shape + (8,))
    return _BYTE_POPCOUNT[raw].sum(axis=-1)


def _mask_bits(masks: np.ndarray) -> np.ndarray:
    """(n, 512) bool: bit b of each leaf mask."""
    raw = np.ascontiguousarray(masks, dtype="<u8").view(np.uint8).reshape(-1, 64)
    return np.unpackbits(raw, axis=1, bitorder="little").astype(bool)


_LOCAL = np.stack(np.unravel_index(np.arange(_LEAF_VOXELS), (8, 8, 8)), axis=1).astype(np.int32)


def voxel_coords(origins: np.ndarray, masks: np.ndarray, active_only: bool) -> np.ndarray:
    """Index-space coordinates (m, 3) int32 of the voxels of the leaves, in leaf then bit order:
    every voxel of every leaf, or only the active ones (an OnIndex grid's rank order)."""
    origins = np.asarray(origins, dtype=np.int32).reshape(-1, 3)
    if not active_only:
        return (origins[:, None, :] + _LOCAL[None, :, :]).reshape(-1, 3)
    masks = np.ascontiguousarray(masks, dtype="<u8").reshape(-1, 8)
    leaf, word = np.nonzero(masks)                       # only the words with active voxels
    bits = np.unpackbits(masks[leaf, word].view(np.uint8).reshape(-1, 8), axis=1, bitorder="little")
    row, bit = np.nonzero(bits)
    return origins[leaf[row]] + _LOCAL[word[row] * 64 + bit]


# ---------------------------------------------------------------------------------------------
# Bounds-checked reading


class _Reader:
    """Reads little-endian fields of one buffer; every read outside it is a RuntimeError."""

    def __init__(self, data, what="NanoVDB buffer"):
        self.data = memoryview(data).cast("B") if not isinstance(data, bytes) else data
        self.size = len(self.data)
        self.what = what

    def check(self, offset: int, count: int, field: str):
        if offset < 0 or count < 0 or offset + count > self.size:
            raise RuntimeError(f"{self.what} is truncated or corrupt: {field} (bytes {offset}..{offset + count}) "
                               f"lies outside the buffer of {self.size} bytes")

    def array(self, offset: int, dtype, count: int, field: str) -> np.ndarray:
        dtype = np.dtype(dtype)
        if count == 0:
            return np.zeros(0, dtype)
        self.check(offset, count * dtype.itemsize, field)
        return np.frombuffer(self.data, dtype=dtype, count=count, offset=offset)

    def scalar(self, offset: int, fmt: str, field: str):
        size = struct.calcsize(fmt)
        self.check(offset, size, field)
        return struct.unpack_from(fmt, self.data, offset)[0]

    def name(self, offset: int, field: str) -> str:
        self.check(offset, _NAME_SIZE, field)
        raw = bytes(self.data[offset:offset + _NAME_SIZE])
        end = raw.find(b"\0")
        if end < 0:
            raise RuntimeError(f"{self.what} is corrupt: {field} is not NUL-terminated")
        return raw[:end].decode("utf-8", errors="replace")


def _split_file(data) -> list:
    """The grid buffers of a NanoVDB file (header, metadata, grids; codec none or zip; one or
    more segments) or of a raw grid buffer (grids back to back)."""
    reader = _Reader(data, "NanoVDB file")
    magic = reader.scalar(0, "<Q", "file header")
    if magic == _MAGIC_GRID:
        return [bytes(reader.data)]
    buffers = []
    offset = 0
    while offset < reader.size:
        if buffers and reader.size - offset < _FILE_HEADER_SIZE:
            break
        reader.check(offset, _FILE_HEADER_SIZE, "file header")
        magic, version, grid_count, codec = struct.unpack_from("<QIHH", reader.data, offset)
        if magic not in (_MAGIC_NUMB, _MAGIC_FILE):
            if not buffers:
                raise RuntimeError("NanoVDB signature not found")
            break
        if version >> 21 != _MAJOR_VERSION:
            raise RuntimeError("Unsupported NanoVDB version")
        if grid_count == 0:
            raise RuntimeError("NanoVDB file is corrupt: a segment holds no grid")
        offset, segment = _read_segment(reader, offset + _FILE_HEADER_SIZE, grid_count, codec)
        buffers.extend(segment)
    return buffers


def _read_segment(reader: _Reader, offset: int, grid_count: int, codec: int):
    sizes = []
    for i in range(grid_count):
        grid_size = reader.scalar(offset, "<Q", f"metadata of grid {i}")
        file_size = reader.scalar(offset + 8, "<Q", f"metadata of grid {i}")
        name_size = reader.scalar(offset + 136, "<I", f"metadata of grid {i}")
        sizes.append((grid_size, file_size))
        offset += _FILE_META_SIZE + name_size
        reader.check(offset, 0, f"name of grid {i}")
    buffers = []
    for i, (grid_size, file_size) in enumerate(sizes):
        if codec == 0:
            reader.check(offset, grid_size, f"grid {i}")
            buffers.append(bytes(reader.data[offset:offset + grid_size]))
            offset += grid_size
        elif codec == 1:
            chunk = reader.scalar(offset, "<Q", f"zip chunk size of grid {i}")
            reader.check(offset + 8, chunk, f"zip chunk of grid {i}")
            try:
                raw = zlib.decompress(bytes(reader.data[offset + 8:offset + 8 + chunk]))
            except zlib.error as err:
                raise RuntimeError(f"NanoVDB file is corrupt: grid {i} does not decompress ({err})") from None
            if len(raw) != grid_size:
                raise RuntimeError(f"NanoVDB file is corrupt: grid {i} decompresses to {len(raw)} bytes, "
                                   f"its metadata says {grid_size}")
            buffers.append(raw)
            offset += 8 + chunk
        elif codec == 2:
            raise RuntimeError("NanoVDB buffer is compressed using blosc, which weft does not read; "
                               "save it with codec 'zip' or 'none'")
        else:
            raise RuntimeError(f"Unsupported codec code: {codec}")
    return offset, buffers


def parse_grids(buffer) -> list:
    """GridContent of every grid of a raw buffer of grids laid back to back."""
    grids = []
    offset = 0
    data = bytes(buffer)
    while offset < len(data):
        reader = _Reader(memoryview(data)[offset:], f"NanoVDB grid {len(grids)}")
        grid, size = _parse_grid(reader)
        grids.append(grid)
        offset += size
        if grid_count_of(reader) <= len(grids):
            break
    if not grids:
        raise RuntimeError("NanoVDB buffer holds no grid")
    return grids


def grid_count_of(reader: _Reader) -> int:
    return reader.scalar(28, "<I", "grid count")


def parse_file(data) -> list:
    """GridContent of every grid of a NanoVDB file's bytes."""
    grids = []
    for buffer in _split_file(data):
        grids.extend(parse_grids(buffer))
    return grids


def _parse_grid(reader: _Reader):
    magic = reader.scalar(0, "<Q", "grid header")
    if magic not in (_MAGIC_NUMB, _MAGIC_GRID):
        raise RuntimeError("NanoVDB signature not found on grid!")
    reader.check(0, _GRID_SIZE + _TREE_SIZE, "grid and tree headers")
    grid_size = reader.scalar(32, "<Q", "grid size")
    if grid_size < _GRID_SIZE + _TREE_SIZE or grid_size > reader.size:
        raise RuntimeError(f"{reader.what} is truncated or corrupt: its header says {grid_size} bytes, "
                           f"the buffer holds {reader.size}")
    reader = _Reader(reader.data[:grid_size], reader.what)
    grid_type = reader.scalar(636, "<I", "grid type")
    layout = _layout_of(grid_type)
    name = reader.name(40, "grid name")
    map_d = reader.array(296 + 88, "<f8", 21, "map")
    matrix, translation = map_d[:9].reshape(3, 3).copy(), map_d[18:21].copy()
    voxel_size = reader.array(608, "<f8", 3, "voxel size").copy()
    grid_class = reader.scalar(632, "<I", "grid class")
    blind = _parse_blind(reader)
    tree = _GRID_SIZE
    offsets = reader.array(tree, "<u8", 4, "tree header")
    counts = reader.array(tree + 32, "<u4", 3, "tree header")
    n_leaf = int(counts[0])
    if n_leaf == 0:
        raise RuntimeError(f"{reader.what} holds no leaf: weft volumes need at least one")
    leaf_begin = tree + int(offsets[0])
    raw = reader.array(leaf_begin, np.uint8, n_leaf * layout.leaf_size, "leaf nodes").reshape(n_leaf, layout.leaf_size)
    origins = np.ascontiguousarray(raw[:, 0:12]).view("<i4") & np.int32(~7)
    masks = np.ascontiguousarray(raw[:, 16:80]).view("<u8")
    root = tree + int(offsets[3])
    background = reader.array(root + layout.root_background, layout.scalar, layout.components, "background")
    values = None
    if not _is_index_type(grid_type):
        table = raw[:, layout.leaf_table:layout.leaf_table + _LEAF_VOXELS * layout.value_bytes]
        values = np.ascontiguousarray(table).view(layout.scalar).reshape(n_leaf * _LEAF_VOXELS, layout.components)
        extra = _tile_leaves(reader, layout, offsets, counts, root, background, name)
        if extra is not None:
            origins = np.concatenate([origins, extra[0]])
            masks = np.concatenate([masks, extra[1]])
            values = np.concatenate([values, extra[2]])
    _check_distinct(origins, reader.what)
    grid = GridContent(grid_type, origins, masks, values, background.copy(), matrix, translation, voxel_size,
                       name, grid_class, blind)
    grid.grid_index = reader.scalar(24, "<I", "grid index")
    grid.grid_count = reader.scalar(28, "<I", "grid count")
    return grid, grid_size


def _parse_blind(reader: _Reader) -> list:
    meta_offset = reader.scalar(640, "<q", "blind metadata offset")
    count = reader.scalar(648, "<I", "blind metadata count")
    if count == 0:
        return []
    reader.check(meta_offset, count * _BLIND_META_SIZE, "blind metadata")
    blind = []
    for i in range(count):
        entry = meta_offset + i * _BLIND_META_SIZE
        data_offset, value_count, value_size, semantic, data_class, data_type = struct.unpack_from(
            "<qQIIII", reader.data, entry)
        name = reader.name(entry + 32, f"blind data name {i}")
        nbytes = value_count * value_size
        reader.check(entry + data_offset, nbytes, f"blind data {i}")
        data = bytes(reader.data[entry + data_offset:entry + data_offset + nbytes])
        blind.append(BlindData(name, value_count, value_size, semantic, data_class, data_type, data))
    return blind


def _check_distinct(origins: np.ndarray, what: str):
    if _unique_rows(origins)[0].shape[0] != origins.shape[0]:
        raise RuntimeError(f"{what} is corrupt: two leaves have the same origin")


def _key_coords(keys: np.ndarray) -> np.ndarray:
    """Origins of the upper nodes of root keys (NanoVDB's coord_to_key, inverted)."""
    mask = np.uint64((1 << 21) - 1)
    parts = [(keys >> np.uint64(s)) & mask for s in (42, 21, 0)]
    return np.stack([(p << np.uint64(12)).astype(np.uint32).view(np.int32) for p in parts], axis=1)


def _node_index(addresses: np.ndarray, begin: int, count: int, stride: int, what: str) -> np.ndarray:
    index, rest = np.divmod(addresses - begin, stride)
    if np.any(rest != 0) or np.any(index < 0) or np.any(index >= count):
        raise RuntimeError(f"{what} is corrupt: a child offset does not point at a node")
    return index


def _table_tiles(nodes, layout, n_entries, table_off, mask_off, background):
    """(node, entry, is_active, value, child_offset) views of the tables of internal nodes."""
    n = nodes.shape[0]
    child = np.unpackbits(np.ascontiguousarray(nodes[:, mask_off:mask_off + n_entries // 8]), axis=1,
                          bitorder="little").astype(bool)
    active = np.unpackbits(np.ascontiguousarray(nodes[:, _NODE_VALUE_MASK:_NODE_VALUE_MASK + n_entries // 8]),
                           axis=1, bitorder="little").astype(bool)
    table = nodes[:, table_off:table_off + n_entries * layout.table_stride].reshape(n, n_entries, layout.table_stride)
    offsets = np.ascontiguousarray(table[:, :, :8]).view("<i8").reshape(n, n_entries)
    values = np.ascontiguousarray(table[:, :, :layout.value_bytes]).view(layout.scalar).reshape(
        n, n_entries, layout.components)
    differs = np.any(values != background, axis=2) | active
    return child, active, values, offsets, differs & ~child


def _tile_leaves(reader, layout, offsets, counts, root, background, name):
    """Leaves (origins, masks, values) of internal-node tiles whose value differs from the
    background or that are active; None when there are none."""
    tree = _GRID_SIZE
    n_upper, n_lower = int(counts[2]), int(counts[1])
    tile_count = reader.scalar(root + 24, "<I", "root tile count")
    tiles = reader.array(root + layout.root_size, np.uint8, tile_count * layout.tile_size,
                         "root tiles").reshape(tile_count, layout.tile_size)
    keys = np.ascontiguousarray(tiles[:, 0:8]).view("<u8").ravel()
    children = np.ascontiguousarray(tiles[:, 8:16]).view("<i8").ravel()
    states = np.ascontiguousarray(tiles[:, 16:20]).view("<u4").ravel()
    tile_values = np.ascontiguousarray(tiles[:, layout.tile_value:layout.tile_value + layout.value_bytes]).view(
        layout.scalar).reshape(tile_count, layout.components)
    root_tiles = (children == 0) & ((states != 0) | np.any(tile_values != background, axis=1))
    if np.any(root_tiles):
        raise RuntimeError(_tile_limit_message(name, int(root_tiles.sum()) * (512 ** 3)))
    upper_begin = tree + int(offsets[2])
    lower_begin = tree + int(offsets[1])
    uppers = reader.array(upper_begin, np.uint8, n_upper * layout.upper_size, "upper nodes").reshape(
        n_upper, layout.upper_size)
    lowers = reader.array(lower_begin, np.uint8, n_lower * layout.lower_size, "lower nodes").reshape(
        n_lower, layout.lower_size)
    u_child, u_active, u_values, u_offsets, u_tiles = _table_tiles(
        uppers, layout, _UPPER_TABLE, layout.upper_table, _UPPER_CHILD_MASK, background)
    l_child, l_active, l_values, l_offsets, l_tiles = _table_tiles(
        lowers, layout, _LOWER_TABLE, layout.lower_table, _LOWER_CHILD_MASK, background)
    if not u_tiles.any() and not l_tiles.any():
        return None
    expanded = int(u_tiles.sum()) * 4096 + int(l_tiles.sum())
    if expanded > _MAX_EXPANDED_LEAVES:
        raise RuntimeError(_tile_limit_message(name, expanded))
    has_child = children != 0
    upper_index = _node_index(root + children[has_child], upper_begin, n_upper, layout.upper_size, "root")
    upper_origin = np.zeros((n_upper, 3), np.int32)
    upper_origin[upper_index] = _key_coords(keys[has_child])
    origins, actives, values = [], [], []
    node, entry = np.nonzero(u_tiles)
    for u, e in zip(node, entry):
        base = upper_origin[u] + 128 * np.array([e >> 10, (e >> 5) & 31, e & 31], np.int32)
        block = np.stack(np.unravel_index(np.arange(4096), (16, 16, 16)), axis=1).astype(np.int32) * 8 + base
        origins.append(block)
        actives.append(np.full(4096, u_active[u, e]))
        values.append(np.broadcast_to(u_values[u, e], (4096, layout.components)))
    node, entry = np.nonzero(u_child)
    addresses = upper_begin + node.astype(np.int64) * layout.upper_size + u_offsets[node, entry]
    lower_index = _node_index(addresses, lower_begin, n_lower, layout.lower_size, "upper node")
    lower_origin = np.zeros((n_lower, 3), np.int32)
    lower_origin[lower_index] = upper_origin[node] + 128 * np.stack([entry >> 10, (entry >> 5) & 31, entry & 31],
                                                                    axis=1).astype(np.int32)
    node, entry = np.nonzero(l_tiles)
    origins.append(lower_origin[node] + 8 * np.stack([entry >> 8, (entry >> 4) & 15, entry & 15],
                                                     axis=1).astype(np.int32))
    actives.append(l_active[node, entry])
    values.append(l_values[node, entry])
    active = np.concatenate(actives)
    tile_origins = np.concatenate(origins).astype(np.int32)
    tile_masks = np.where(active[:, None], np.uint64(0xFFFFFFFFFFFFFFFF), np.uint64(0)).astype(np.uint64)
    tile_masks = np.broadcast_to(tile_masks, (active.shape[0], 8)).copy()
    tile_values = np.repeat(np.concatenate(values).astype(layout.scalar), _LEAF_VOXELS, axis=0)
    return tile_origins, tile_masks, tile_values


def _tile_limit_message(name: str, leaves: int) -> str:
    return (f"NanoVDB grid {name!r}: its internal-node tiles with non-background values cover {leaves} "
            f"leaves of 8^3 voxels; weft expands tiles into leaves only up to {_MAX_EXPANDED_LEAVES} leaves")


# ---------------------------------------------------------------------------------------------
# Writing


def _align(n: int) -> int:
    return (n + _ALIGN - 1) // _ALIGN * _ALIGN


def _unique_rows(coords: np.ndarray):
    """Distinct rows of (n, 3) int coords sorted by x, then y, then z, and each row's index."""
    coords = np.asarray(coords, dtype=np.int64).reshape(-1, 3)
    if coords.shape[0] == 0:
        return coords.astype(np.int32), np.zeros(0, np.int64)
    low = coords.min(axis=0)
    span = coords.max(axis=0) - low
    if np.all(span < (1 << 21)):
        shifted = coords - low
        keys = (shifted[:, 0] << 42) | (shifted[:, 1] << 21) | shifted[:, 2]
        unique, inverse = np.unique(keys, return_inverse=True)
        rows = np.stack([unique >> 42, (unique >> 21) & ((1 << 21) - 1), unique & ((1 << 21) - 1)], axis=1) + low
        return rows.astype(np.int32), inverse.ravel()
    rows, inverse = np.unique(coords, axis=0, return_inverse=True)
    return rows.astype(np.int32), inverse.ravel()


def _leaf_bboxes(origins: np.ndarray, masks: np.ndarray):
    """Per leaf: the min and max index coordinates of its active voxels (the origin for both
    when none is active) and whether any is."""
    bits = _mask_bits(masks).reshape(-1, 8, 8, 8)
    lo = np.empty((origins.shape[0], 3), np.int32)
    hi = np.empty((origins.shape[0], 3), np.int32)
    for axis in range(3):
        others = tuple(a for a in (1, 2, 3) if a != axis + 1)
        occupied = bits.any(axis=others)
        first = np.argmax(occupied, axis=1)
        last = 7 - np.argmax(occupied[:, ::-1], axis=1)
        lo[:, axis] = first
        hi[:, axis] = last
    any_active = bits.reshape(bits.shape[0], -1).any(axis=1)
    lo[~any_active] = 0
    hi[~any_active] = 0
    return origins + lo, origins + hi, any_active


def _group_bbox(group: np.ndarray, n_groups: int, lo: np.ndarray, hi: np.ndarray):
    glo = np.full((n_groups, 3), np.iinfo(np.int32).max, np.int32)
    ghi = np.full((n_groups, 3), np.iinfo(np.int32).min, np.int32)
    np.minimum.at(glo, group, lo)
    np.maximum.at(ghi, group, hi)
    return glo, ghi


class _Topology(NamedTuple):
    upper_origins: np.ndarray
    lower_origins: np.ndarray
    lower_parent: np.ndarray
    leaf_parent: np.ndarray


def _topology(origins: np.ndarray) -> _Topology:
    lower_of_leaf = origins & np.int32(~127)
    lower_origins, leaf_parent = _unique_rows(lower_of_leaf)
    upper_origins, lower_parent = _unique_rows(lower_origins & np.int32(~4095))
    return _Topology(upper_origins, lower_origins, lower_parent, leaf_parent)


def grid_byte_size(grid: GridContent) -> int:
    """The byte size of the NanoVDB grid write_grid makes of `grid`."""
    return _grid_plan(grid, _topology(grid.origins))["size"]


def _grid_plan(grid: GridContent, topo: _Topology) -> dict:
    layout = grid.layout
    plan = {"root": _GRID_SIZE + _TREE_SIZE}
    plan["upper"] = _align(plan["root"] + layout.root_size + len(topo.upper_origins) * layout.tile_size)
    plan["lower"] = plan["upper"] + len(topo.upper_origins) * layout.upper_size
    plan["leaf"] = plan["lower"] + len(topo.lower_origins) * layout.lower_size
    plan["blind_meta"] = _align(plan["leaf"] + grid.leaf_count * layout.leaf_size)
    offset = plan["blind_meta"] + len(grid.blind) * _BLIND_META_SIZE
    plan["blind_data"] = []
    for entry in grid.blind:
        offset = _align(offset)
        plan["blind_data"].append(offset)
        offset += len(entry.data)
    plan["size"] = _align(offset)
    return plan


def _child_bits(node_count: int, parent: np.ndarray, entry: np.ndarray, table: int) -> np.ndarray:
    bits = np.zeros((node_count, table), bool)
    bits[parent, entry] = True
    return np.packbits(bits, axis=1, bitorder="little")


def _write_internal(buf, begin, size, table_off, mask_off, layout, origins, lo, hi, children, bg_entry):
    """Fills internal nodes: bbox, child masks, tables of background values with the
    children's relative offsets (children: parent index, table entry, child address)."""
    n = origins.shape[0]
    table_count = (mask_off - _NODE_VALUE_MASK) * 8
    nodes = buf[begin:begin + n * size].reshape(n, size)
    nodes[:, 0:12] = lo.astype("<i4").view(np.uint8).reshape(n, 12)
    nodes[:, 12:24] = hi.astype("<i4").view(np.uint8).reshape(n, 12)
    parent, entry, address = children
    nodes[:, mask_off:mask_off + table_count // 8] = _child_bits(n, parent, entry, table_count)
    table = nodes[:, table_off:table_off + table_count * layout.table_stride].reshape(n, table_count,
                                                                                       layout.table_stride)
    table[:, :, :len(bg_entry)] = np.frombuffer(bg_entry, np.uint8)
    relative = (address - (begin + parent.astype(np.int64) * size)).astype("<i8")
    table[parent, entry, 0:8] = relative.view(np.uint8).reshape(-1, 8)


def _entry_of(child_origins: np.ndarray, shift: int, dim_bits: int) -> np.ndarray:
    local = (child_origins.astype(np.int64) >> shift) & ((1 << dim_bits) - 1)
    return (local[:, 0] << (2 * dim_bits)) | (local[:, 1] << dim_bits) | local[:, 2]


def write_grid(grid: GridContent, grid_index: int = 0, grid_count: int = 1) -> bytes:
    """A breadth-first NanoVDB grid buffer of `grid` (root, upper 32^3, lower 16^3 internal
    nodes, leaves in the grid's leaf order, blind data)."""
    layout = grid.layout
    topo = _topology(grid.origins)
    plan = _grid_plan(grid, topo)
    buf = np.zeros(plan["size"], np.uint8)
    leaf_lo, leaf_hi, leaf_any = _leaf_bboxes(grid.origins, grid.masks)
    if leaf_any.any():
        bbox = (leaf_lo[leaf_any].min(axis=0), leaf_hi[leaf_any].max(axis=0))
    else:
        bbox = (grid.origins.min(axis=0), grid.origins.min(axis=0))
    lower_lo, lower_hi = _group_bbox(topo.leaf_parent, len(topo.lower_origins), leaf_lo, leaf_hi)
    upper_lo, upper_hi = _group_bbox(topo.lower_parent, len(topo.upper_origins), lower_lo, lower_hi)
    bg_bytes = grid.background.astype(layout.scalar).tobytes()
    _write_leaves(buf, plan["leaf"], grid, leaf_lo, leaf_hi, leaf_any)
    leaf_addr = plan["leaf"] + np.arange(grid.leaf_count, dtype=np.int64) * layout.leaf_size
    _write_internal(buf, plan["lower"], layout.lower_size, layout.lower_table, _LOWER_CHILD_MASK, layout,
                    topo.lower_origins, lower_lo, lower_hi,
                    (topo.leaf_parent, _entry_of(grid.origins, 3, 4), leaf_addr), bg_bytes)
    lower_addr = plan["lower"] + np.arange(len(topo.lower_origins), dtype=np.int64) * layout.lower_size
    _write_internal(buf, plan["upper"], layout.upper_size, layout.upper_table, _UPPER_CHILD_MASK, layout,
                    topo.upper_origins, upper_lo, upper_hi,
                    (topo.lower_parent, _entry_of(topo.lower_origins, 7, 5), lower_addr), bg_bytes)
    _write_root(buf, plan, layout, topo, bbox, bg_bytes)
    value_count = _index_value_count(grid)
    _write_blind(buf, plan, grid)
    _write_headers(buf, plan, grid, topo, bbox, grid_index, grid_count, value_count)
    return buf.tobytes()


def _index_value_count(grid: GridContent) -> int:
    if grid.grid_type == INDEX:
        return grid.leaf_count * _LEAF_VOXELS + 1
    if grid.grid_type == ON_INDEX:
        return grid.active_count() + 1
    return 0


def _write_leaves(buf, begin, grid, lo, hi, any_active):
    layout = grid.layout
    n = grid.leaf_count
    leaves = buf[begin:begin + n * layout.leaf_size].reshape(n, layout.leaf_size)
    leaves[:, 0:12] = lo.astype("<i4").view(np.uint8).reshape(n, 12)
    dif = (hi - lo).astype(np.uint8)
    leaves[:, 12:15] = dif
    leaves[:, 15] = np.where(any_active, _FLAG_HAS_BBOX, 0).astype(np.uint8)
    leaves[:, 16:80] = grid.masks.astype("<u8").view(np.uint8).reshape(n, 64)
    if grid.grid_type == INDEX:
        first = 1 + np.arange(n, dtype=np.uint64) * _LEAF_VOXELS
        leaves[:, 80:88] = first.astype("<u8").view(np.uint8).reshape(n, 8)
    elif grid.grid_type == ON_INDEX:
        counts = _popcount64(grid.masks)                      # (n, 8)
        first = 1 + np.concatenate([[0], np.cumsum(counts.sum(axis=1))[:-1]]).astype(np.uint64)
        prefix = np.cumsum(counts[:, :7], axis=1).astype(np.uint64)   # active bits before words 1..7
        packed = np.zeros(n, np.uint64)
        for word in range(7):
            packed |= prefix[:, word] << np.uint64(9 * word)
        leaves[:, 80:88] = first.astype("<u8").view(np.uint8).reshape(n, 8)
        leaves[:, 88:96] = packed.astype("<u8").view(np.uint8).reshape(n, 8)
    else:
        values = np.ascontiguousarray(grid.values, dtype=layout.scalar).reshape(n, _LEAF_VOXELS * layout.components)
        table = leaves[:, layout.leaf_table:layout.leaf_table + _LEAF_VOXELS * layout.value_bytes]
        table[:] = values.view(np.uint8).reshape(n, -1)


def _write_root(buf, plan, layout, topo, bbox, bg_bytes):
    root = plan["root"]
    struct.pack_into("<3i3iI", buf, root, *[int(v) for v in bbox[0]], *[int(v) for v in bbox[1]],
                     len(topo.upper_origins))
    buf[root + layout.root_background:root + layout.root_background + len(bg_bytes)] = np.frombuffer(bg_bytes, np.uint8)
    n = len(topo.upper_origins)
    tiles = buf[root + layout.root_size:root + layout.root_size + n * layout.tile_size].reshape(n, layout.tile_size)
    u = topo.upper_origins.astype(np.int32).view(np.uint32).astype(np.uint64) >> np.uint64(12)
    keys = u[:, 2] | (u[:, 1] << np.uint64(21)) | (u[:, 0] << np.uint64(42))
    tiles[:, 0:8] = keys.astype("<u8").view(np.uint8).reshape(n, 8)
    child = plan["upper"] + np.arange(n, dtype=np.int64) * layout.upper_size - root
    tiles[:, 8:16] = child.astype("<i8").view(np.uint8).reshape(n, 8)
    tiles[:, layout.tile_value:layout.tile_value + len(bg_bytes)] = np.frombuffer(bg_bytes, np.uint8)


def _write_blind(buf, plan, grid):
    for i, (entry, data_at) in enumerate(zip(grid.blind, plan["blind_data"])):
        meta = plan["blind_meta"] + i * _BLIND_META_SIZE
        struct.pack_into("<qQIIII", buf, meta, data_at - meta, entry.value_count, entry.value_size,
                         entry.semantic, entry.data_class, entry.data_type)
        name = entry.name.encode("utf-8")[:_NAME_SIZE - 1]
        buf[meta + 32:meta + 32 + len(name)] = np.frombuffer(name, np.uint8)
        buf[data_at:data_at + len(entry.data)] = np.frombuffer(entry.data, np.uint8)


def _world_bbox(grid: GridContent, bbox) -> np.ndarray:
    lo, hi = np.asarray(bbox[0], np.float64), np.asarray(bbox[1], np.float64) + 1.0
    corners = np.array([[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]]
                        for a in (0, 1) for b in (0, 1) for c in (0, 1)])
    world = corners @ grid.matrix.T + grid.translation
    return np.concatenate([world.min(axis=0), world.max(axis=0)])


def _write_headers(buf, plan, grid, topo, bbox, grid_index, grid_count, value_count):
    name = grid.name.encode("utf-8")
    if len(name) >= _NAME_SIZE:
        raise ValueError(f"grid name of {len(name)} bytes: NanoVDB grid names hold at most {_NAME_SIZE - 1}")
    struct.pack_into("<QQIIIIQ", buf, 0, _MAGIC_NUMB, _CHECKSUM_DISABLED, _VERSION,
                     _FLAG_BREADTH_FIRST | _FLAG_HAS_BBOX, grid_index, grid_count, plan["size"])
    buf[40:40 + len(name)] = np.frombuffer(name, np.uint8)
    inverse = np.linalg.inv(grid.matrix)
    map_f = np.concatenate([grid.matrix.ravel(), inverse.ravel(), grid.translation, [1.0]]).astype("<f4")
    map_d = np.concatenate([grid.matrix.ravel(), inverse.ravel(), grid.translation, [1.0]]).astype("<f8")
    buf[296:296 + 88] = map_f.view(np.uint8)
    buf[296 + 88:296 + 264] = map_d.view(np.uint8)
    buf[560:608] = _world_bbox(grid, bbox).astype("<f8").view(np.uint8)
    buf[608:632] = grid.voxel_size.astype("<f8").view(np.uint8)
    grid_class = _CLASS_INDEX_GRID if grid.is_index else grid.grid_class
    blind_offset = plan["blind_meta"] if grid.blind else plan["size"]
    struct.pack_into("<IIqIIQQ", buf, 632, grid_class, grid.grid_type, blind_offset, len(grid.blind), 0,
                     value_count, _MAGIC_GRID)
    tree = _GRID_SIZE
    struct.pack_into("<QQQQIIIIIIQ", buf, tree, plan["leaf"] - tree, plan["lower"] - tree, plan["upper"] - tree,
                     plan["root"] - tree, grid.leaf_count, len(topo.lower_origins), len(topo.upper_origins),
                     0, 0, 0, grid.active_count())


def write_file(grids: list, codec: str = "none") -> bytes:
    """A NanoVDB file of one segment holding `grids` (codec "none", "zip" or "blosc")."""
    codecs = {"none": 0, "zip": 1, "blosc": 2}
    if codec not in codecs:
        raise RuntimeError(f"Unsupported codec requested: {codec}")
    compress = _compressor(codec)
    metas, bodies = [], []
    for index, grid in enumerate(grids):
        raw = write_grid(grid, index, len(grids))
        body = raw if compress is None else compress(raw)
        metas.append(_file_meta(grid, raw, len(body), codecs[codec]))
        bodies.append(body if compress is None else struct.pack("<Q", len(body)) + body)
    out = [struct.pack("<QIHH", _MAGIC_NUMB, _VERSION, len(grids), codecs[codec])]
    out.extend(metas)
    out.extend(bodies)
    return b"".join(out)


def _compressor(codec: str):
    if codec == "zip":
        return zlib.compress
    if codec == "blosc":
        try:
            import blosc  # noqa: PLC0415
        except ImportError as err:
            raise RuntimeError(f"blosc compression was requested, but Python module could not be imported: "
                               f"{err}") from err
        return blosc.compress
    return None


def _file_meta(grid: GridContent, raw: bytes, file_size: int, codec: int) -> bytes:
    reader = _Reader(raw)
    counts = reader.array(_GRID_SIZE + 32, "<u4", 3, "tree")
    root = _GRID_SIZE + _TREE_SIZE
    index_bbox = reader.array(root, "<i4", 6, "root bbox")
    name = grid.name.encode("utf-8") + b"\0"
    meta = struct.pack("<QQQQII", len(raw), file_size, 0, grid.active_count(), grid.grid_type,
                       reader.scalar(632, "<I", "class"))
    meta += raw[560:608] + index_bbox.tobytes() + raw[608:632]
    meta += struct.pack("<I4I3IHHI", len(name), int(counts[0]), int(counts[1]), int(counts[2]), 1, 0, 0, 0,
                        codec, 0, _VERSION)
    assert len(meta) == _FILE_META_SIZE
    return meta + name


# ---------------------------------------------------------------------------------------------
# Allocation: points to leaves


def world_to_index(points: np.ndarray, matrix: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Index coordinates (n, 3) int64 of the voxels nearest world points (round half up)."""
    local = (np.asarray(points, np.float64).reshape(-1, 3) - translation) @ np.linalg.inv(matrix).T
    return np.floor(local + 0.5).astype(np.int64)


def leaves_of_tiles(ijk: np.ndarray):
    """Distinct leaf origins (sorted by x, then y, then z) of index coordinates."""
    origins, _ = _unique_rows(np.asarray(ijk, np.int64) & ~np.int64(7))
    return origins


def leaves_of_voxels(ijk: np.ndarray):
    """Leaf origins (sorted) and active masks of the leaves holding index coordinates."""
    ijk = np.asarray(ijk, np.int64).reshape(-1, 3)
    origins, leaf = _unique_rows(ijk & ~np.int64(7))
    local = ijk & 7
    bit = (local[:, 0] << 6) | (local[:, 1] << 3) | local[:, 2]
    masks = np.zeros((origins.shape[0], 8), np.uint64)
    np.bitwise_or.at(masks, (leaf, bit >> 6), np.left_shift(np.uint64(1), (bit & 63).astype(np.uint64)))
    return origins, masks


_FULL_MASKS = np.uint64(0xFFFFFFFFFFFFFFFF)


# ---------------------------------------------------------------------------------------------
# Value types


_ALLOCATION_TYPES = ("int32", "uint32", "int64", "float", "double", "Vec3f", "Vec3d", "Vec4f", "Vec4d")
_TYPE_NUMBER = {"float": 1, "double": 2, "int32": 4, "int64": 5, "Vec3f": 6, "Vec3d": 7, "uint32": 10,
                "Vec4f": 17, "Vec4d": 18, "Index": INDEX, "OnIndex": ON_INDEX}


def _nvdb_dtypes() -> dict:
    t = _types
    return {"float": t.float32, "double": t.float64, "int16": t.int16, "int32": t.int32, "int64": t.int64,
            "Vec3f": t.vec3f, "Vec3d": t.vec3d, "Half": t.float16, "uint32": t.uint32, "bool": t.bool,
            "Vec4f": t.vec4f, "Vec4d": t.vec4d, "Vec3u8": t.vec3ub, "Vec3u16": t.vec3us, "uint8": t.uint8}


def grid_type_of_value(bg_value) -> int:
    """The NanoVDB grid type of a background value, as Warp picks it (Python float: float32,
    int: int32, a plain sequence of 3 or 4 numbers: Vec3f / Vec4f, weft scalars and vectors:
    their own type); TypeError for other types."""
    value_type = type(bg_value)
    if value_type is float:
        value_type = _types.float32
    elif value_type is int:
        value_type = _types.int32
    elif value_type is bool:
        value_type = _types.bool
    elif isinstance(bg_value, np.generic):
        value_type = _types.dtype_from_numpy(bg_value.dtype)
    is_vector = _types.is_dtype(value_type) and _types.is_vector(value_type)
    if not (_types.is_value(bg_value) or is_vector) and hasattr(bg_value, "__len__") and len(bg_value) \
            and _types.is_value(bg_value[0]):
        value_type = _types.vector(len(bg_value), _types.float32)
    for name in _ALLOCATION_TYPES:
        if _types.types_equal(value_type, _nvdb_dtypes()[name]):
            return _TYPE_NUMBER[name]
    raise TypeError(f"Unsupported bg_value type for volume allocation {_types.type_repr(value_type)}. "
                    f"Supported volume types are {', '.join(_ALLOCATION_TYPES)}.")


def _normalize_voxel_size(voxel_size) -> tuple:
    if isinstance(voxel_size, (int, float, np.floating, np.integer)) and not isinstance(voxel_size, bool):
        s = float(voxel_size)
        voxel_size = (s, s, s)
    elif isinstance(voxel_size, (list, tuple, np.ndarray)) or _types.is_value(voxel_size):
        voxel_size = tuple(float(v) for v in np.asarray(voxel_size).ravel())
        if len(voxel_size) != 3:
            raise ValueError(f"voxel_size must be a scalar or a 3-element sequence, got length {len(voxel_size)}")
    else:
        raise TypeError(
            f"voxel_size must be a numeric scalar or a sequence of 3 floats, got {type(voxel_size).__name__}")
    if not all(math.isfinite(v) and v > 0.0 for v in voxel_size):
        raise ValueError(f"All voxel_size components must be finite and positive, got {voxel_size}")
    return voxel_size


def _transform_of(voxel_size, transform) -> np.ndarray:
    if transform is None:
        if voxel_size is None:
            raise ValueError("Either 'voxel_size' or 'transform' must be provided")
        return np.diag(_normalize_voxel_size(voxel_size)).astype(np.float64)
    if voxel_size is not None:
        raise ValueError("Only one of 'voxel_size' or 'transform' must be provided")
    matrix = np.asarray(transform, dtype=np.float32).astype(np.float64).reshape(3, 3)
    if not np.all(np.isfinite(matrix)) or abs(np.linalg.det(matrix)) < 1e-30:
        raise ValueError("transform must be a finite invertible 3x3 matrix")
    return matrix


def _points_of(points, what: str, point_mask=None):
    """(n, 3) coordinates of a tile/voxel point array and whether they are world positions."""
    if not _types.is_array(points):
        raise RuntimeError(f"{what} must be contiguous and either a 1D Warp array of vec3f or vec3i or a 2D "
                           f"n-by-3 array of int32 or float32.")
    scalar = _types.type_scalar_type(points.dtype)
    length = _types.type_length(points.dtype)
    shaped = (points.ndim == 1 and length == 3) or (points.ndim == 2 and length == 1 and points.shape[1] == 3)
    if scalar not in (_types.int32, _types.float32) or not shaped or not points.is_contiguous:
        raise RuntimeError(f"{what} must be contiguous and either a 1D Warp array of vec3f or vec3i or a 2D "
                           f"n-by-3 array of int32 or float32.")
    coords = np.asarray(points.numpy()).reshape(-1, 3)
    if point_mask is not None:
        if not _types.is_array(point_mask) or _types.type_str(point_mask.dtype) != "int32" or point_mask.ndim != 1:
            raise RuntimeError("point_mask must be a contiguous 1D Warp array with dtype int32")
        if point_mask.shape[0] < coords.shape[0]:
            raise RuntimeError(f"point_mask must have at least {coords.shape[0]} entries")
        coords = coords[np.asarray(point_mask.numpy())[:coords.shape[0]] != 0]
    return coords, scalar is _types.float32


def _refuse_rebuildable(rebuildable, *capacities):
    if rebuildable or any(c is not None for c in capacities):
        raise NotImplementedError("weft volumes are not rebuildable: allocate a new volume instead "
                                  "(rebuildable=True and the max_* capacities are not supported)")


# ---------------------------------------------------------------------------------------------
# The client object


class Volume(_Object):
    """A sparse volume held by the daemon (Warp's wp.Volume). Kernels take `volume.id`."""

    CLOSEST = 0
    LINEAR = 1

    REBUILD_SUCCESS = 0
    REBUILD_LEAF_CAPACITY_EXCEEDED = 1 << 0
    REBUILD_LOWER_CAPACITY_EXCEEDED = 1 << 1
    REBUILD_UPPER_CAPACITY_EXCEEDED = 1 << 2
    REBUILD_VOXEL_CAPACITY_EXCEEDED = 1 << 3
    REBUILD_INVALID_INPUT = 1 << 4

    class RebuildInfo(NamedTuple):
        kind: str | None
        max_voxel_count: int
        max_leaf_node_count: int
        max_lower_node_count: int
        max_upper_node_count: int

    class ActiveStats(NamedTuple):
        voxel_count: int
        leaf_node_count: int
        lower_node_count: int
        upper_node_count: int

    class GridInfo(NamedTuple):
        name: str
        size_in_bytes: int
        grid_index: int
        grid_count: int
        type_str: str
        translation: object
        transform_matrix: object

    class FeatureArrayInfo(NamedTuple):
        name: str
        ptr: int
        value_size: int
        value_count: int
        type_str: str

    def __init__(self, data=None, copy: bool = True):
        """A volume of the NanoVDB grid buffer in `data` (a uint8 wp.array); later grids of the
        buffer come with load_next_grid()."""
        super().__init__()
        self._grid = None
        self._next_grids = []
        self._previous_grid = None
        self.values = None
        if data is None:
            return
        if not _types.is_array(data):
            raise TypeError(f"Volume: data must be a wp.array of uint8, got {type(data).__name__}")
        raw = np.ascontiguousarray(data.numpy()).view(np.uint8).tobytes()
        grids = parse_grids(raw)
        self._attach(grids[0], data.device)
        self._next_grids = grids[1:]

    # -- construction
    @classmethod
    def _from_grid(cls, grid: GridContent, device, next_grids=()) -> Volume:
        volume = cls(None)
        volume._attach(grid, get_device(device))
        volume._next_grids = list(next_grids)
        return volume

    def _attach(self, grid: GridContent, device):
        from .array import array as _array  # noqa: PLC0415
        self._rt = _runtime.get_runtime()
        self.device = get_device(device)
        self._grid = grid.without_values()   # the daemon's array holds the values from here on
        self._grid_index = getattr(grid, "grid_index", 0)
        self._grid_count = getattr(grid, "grid_count", 1)
        self.leaves = _array(grid.origins, dtype=_types.int32, device=self.device)
        self.masks = _array(grid.masks, dtype=_types.uint64, device=self.device)
        self.values = None
        if not grid.is_index:
            self.values = _array(np.ascontiguousarray(grid.values).reshape(grid.leaf_count * _LEAF_VOXELS, -1)
                                 if grid.layout.components > 1 else grid.values.reshape(-1),
                                 dtype=self._value_dtype(), device=self.device)
        transform = list(grid.matrix.ravel()) + list(grid.translation)
        self.id = _call(self._rt, op=_op().CREATE_VOLUME, leaves=_handle_of(self.leaves, "Volume leaves"),
                        masks=_handle_of(self.masks, "Volume masks"),
                        values=_handle_of(self.values, "Volume values"), value_type=grid.grid_type,
                        background=b"" if grid.is_index else grid.background.tobytes(),
                        transform=[float(v) for v in transform])

    def _value_dtype(self):
        return _nvdb_dtypes().get(_type_name(self._grid.grid_type))

    def _content(self) -> GridContent:
        """The grid with the current values (read back from the daemon)."""
        self._require()
        grid = self._grid
        values = None
        if self.values is not None:
            values = np.asarray(self.values.numpy()).reshape(grid.leaf_count * _LEAF_VOXELS, grid.layout.components)
        out = GridContent(grid.grid_type, grid.origins, grid.masks, values, grid.background, grid.matrix,
                          grid.translation, grid.voxel_size, grid.name, grid.grid_class, grid.blind)
        return out

    def _require(self):
        if not self.id or self._grid is None:
            raise RuntimeError("Invalid Volume")

    # -- loading and saving
    @classmethod
    def load_from_nvdb(cls, file_or_buffer, device=None) -> Volume:
        """A volume of the first grid of a NanoVDB file (a file object or its bytes); the
        file's later grids come with load_next_grid()."""
        try:
            data = file_or_buffer.read()
        except AttributeError:
            data = file_or_buffer
        if isinstance(data, str):
            raise TypeError("load_from_nvdb takes a file object or bytes, not a path string; "
                            "use open(path, 'rb')")
        grids = parse_file(data)
        return cls._from_grid(grids[0], device, grids[1:])

    @classmethod
    def load_from_address(cls, grid_ptr: int, buffer_size: int = 0, device=None) -> Volume:
        raise RuntimeError("Volume.load_from_address: weft volumes live in the daemon and cannot alias a raw "
                           "address; pass the grid bytes to wp.Volume(wp.array(..., dtype=wp.uint8))")

    def load_next_grid(self) -> Volume | None:
        """A volume of the next grid of the file or buffer this one came from (None after the
        last)."""
        if not self._next_grids:
            return None
        volume = Volume._from_grid(self._next_grids[0], self.device, self._next_grids[1:])
        volume._previous_grid = self
        return volume

    def save_to_nvdb(self, path, codec: str = "none"):
        """Writes this grid (and the later grids of the file it came from) to a NanoVDB file."""
        if codec not in ("none", "zip", "blosc"):
            raise RuntimeError(f"Unsupported codec requested: {codec}")
        self._require()
        if self._grid_index > 0:
            raise RuntimeError("Saving of aliased Volumes is not supported. Use `save_to_nvdb` on the original "
                               "volume, before any `load_next_grid` calls.")
        data = write_file([self._content()] + list(self._next_grids), codec)
        with open(path, "wb") as out:
            out.write(data)
        return path

    def array(self):
        """The volume as a NanoVDB grid buffer: a uint8 wp.array (a copy) on its device."""
        from .array import array as _array  # noqa: PLC0415
        raw = np.frombuffer(write_grid(self._content(), 0, 1), dtype=np.uint8)
        out = _array(raw, dtype=_types.uint8, device=self.device)
        out.deleter = None
        return out

    # -- introspection
    def get_tile_count(self) -> int:
        self._require()
        return self._grid.leaf_count

    def get_voxel_count(self) -> int:
        self._require()
        if self._grid.grid_type == ON_INDEX:
            return self._grid.active_count()
        return self._grid.leaf_count * _LEAF_VOXELS

    def get_tiles(self, out=None):
        """Leaf origins (n, 3) int32, in leaf order."""
        self._require()
        return self._coords_out(self._grid.origins, out)

    def get_voxels(self, out=None):
        """Coordinates of the indexable voxels: all voxels of every leaf (value and Index grids)
        or the active ones (OnIndex), in index order."""
        self._require()
        coords = voxel_coords(self._grid.origins, self._grid.masks, self._grid.grid_type == ON_INDEX)
        return self._coords_out(coords, out)

    def _coords_out(self, coords: np.ndarray, out):
        from .array import array as _array  # noqa: PLC0415
        count = coords.shape[0]
        if out is None:
            return _array(coords.astype(np.int32), dtype=_types.int32, device=self.device)
        if str(out.device) != str(self.device) or out.shape[0] < count:
            raise RuntimeError(f"'out' array must an array with at least {count} rows on device {self.device}")
        scalar = _types.type_scalar_type(out.dtype)
        length = _types.type_length(out.dtype)
        shaped = (out.ndim == 1 and length == 3) or (out.ndim == 2 and length == 1 and out.shape[1] == 3)
        if scalar is not _types.int32 or not shaped or not out.is_contiguous:
            raise RuntimeError("'out' must be a contiguous 1D array with type vec3i or a 2D array of type int32 "
                               "with shape (N, 3) ")
        full = np.asarray(out.numpy()).reshape(-1, 3).copy()
        full[:count] = coords
        out.assign(_array(full, dtype=out.dtype, device=self.device))
        return out

    def get_active_stats(self) -> Volume.ActiveStats:
        self._require()
        topo = _topology(self._grid.origins)
        return Volume.ActiveStats(self.get_voxel_count(), self._grid.leaf_count, len(topo.lower_origins),
                                  len(topo.upper_origins))

    def get_voxel_size(self) -> tuple:
        self._require()
        return tuple(float(np.float32(v)) for v in self._grid.voxel_size)

    def get_grid_info(self) -> Volume.GridInfo:
        self._require()
        grid = self._grid
        return Volume.GridInfo(grid.name, grid_byte_size(grid), self._grid_index, self._grid_count,
                               _type_name(grid.grid_type), _types.vec3f(*grid.translation.astype(np.float32)),
                               _types.mat33f(*grid.matrix.astype(np.float32).ravel()))

    @property
    def dtype(self):
        """The weft dtype of the values (None for index grids)."""
        self._require()
        return None if self._grid.is_index else self._value_dtype()

    @property
    def is_index(self) -> bool:
        self._require()
        return self._grid.is_index

    @property
    def is_rebuildable(self) -> bool:
        return False

    def get_rebuild_info(self) -> Volume.RebuildInfo:
        return Volume.RebuildInfo(None, 0, 0, 0, 0)

    def rebuild(self, points, status=None, point_mask=None):
        raise RuntimeError("Volume is not rebuildable")

    # -- feature arrays (NanoVDB blind data)
    def get_feature_array_count(self) -> int:
        self._require()
        return len(self._grid.blind)

    def _blind(self, feature_index: int) -> BlindData:
        self._require()
        if not 0 <= int(feature_index) < len(self._grid.blind):
            raise RuntimeError("Invalid feature array")
        return self._grid.blind[int(feature_index)]

    def get_feature_array_info(self, feature_index: int) -> Volume.FeatureArrayInfo:
        entry = self._blind(feature_index)
        return Volume.FeatureArrayInfo(entry.name, 0, entry.value_size, entry.value_count,
                                       _type_name(entry.data_type))

    def feature_array(self, feature_index: int, dtype=None):
        """Feature array `feature_index` as a wp.array (a copy) of `dtype` (default: from its
        metadata, bytes when unknown) on the volume's device."""
        from .array import array as _array  # noqa: PLC0415
        entry = self._blind(feature_index)
        if dtype is None:
            dtype = _nvdb_dtypes().get(_type_name(entry.data_type), _types.uint8)
        size = _types.type_size_in_bytes(dtype)
        value_count, value_size = entry.value_count, entry.value_size
        if size == 1:
            value_count, value_size = value_count * value_size, 1
        elif value_size == 1 and value_count % size == 0:
            value_count, value_size = value_count // size, size
        if size != value_size:
            raise RuntimeError(f"Cannot cast feature data of size {value_size} to array dtype "
                               f"{_types.type_repr(dtype)}")
        scalar = np.dtype(_types.np_scalar_dtype(dtype)).newbyteorder("<")
        values = np.frombuffer(entry.data, dtype=scalar)
        shape = (value_count,) + ((_types.type_length(dtype),) if _types.type_length(dtype) > 1 else ())
        return _array(values.reshape(shape), dtype=dtype, device=self.device)

    # -- allocation
    @staticmethod
    def _normalize_voxel_size(voxel_size) -> tuple:
        return _normalize_voxel_size(voxel_size)

    @classmethod
    def allocate(cls, min, max, voxel_size, bg_value=0.0, translation=(0.0, 0.0, 0.0),  # noqa: A002
                 points_in_world_space=False, device=None) -> Volume:
        """A volume with every tile of the index box [min, max] (inclusive; world positions
        when points_in_world_space) allocated, all voxels active and set to bg_value."""
        voxel_size = _normalize_voxel_size(voxel_size)
        if points_in_world_space:
            vs = np.asarray(voxel_size, dtype=np.float32)
            min = np.around((np.array(min, dtype=np.float32) - translation) / vs)  # noqa: A001
            max = np.around((np.array(max, dtype=np.float32) - translation) / vs)  # noqa: A001
        lo = np.array(min, dtype=np.int32).reshape(3) // 8
        hi = np.array(max, dtype=np.int32).reshape(3) // 8
        axes = [np.arange(lo[a], hi[a] + 1, dtype=np.int64) * 8 for a in range(3)]
        origins = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        if origins.shape[0] == 0:
            raise ValueError(f"Volume.allocate: empty box min={tuple(min)} max={tuple(max)}")
        return cls._allocate_leaves(origins.astype(np.int32), np.diag(voxel_size), translation, bg_value, device)

    @classmethod
    def allocate_by_tiles(cls, tile_points, voxel_size=None, bg_value=0.0, translation=(0.0, 0.0, 0.0),
                          device=None, transform=None, rebuildable: bool = False, max_tiles=None,
                          max_lower_nodes=None, max_upper_nodes=None, status=None, point_mask=None) -> Volume:
        """A volume with the tiles holding `tile_points` (int32/vec3i: index space; float32/vec3f:
        world space, the tile of the nearest voxel) allocated, all voxels active and set to
        bg_value (None: an OnIndex grid)."""
        _refuse_rebuildable(rebuildable, max_tiles, max_lower_nodes, max_upper_nodes)
        device = get_device(device)
        matrix = _transform_of(voxel_size, transform)
        coords, in_world = _points_of(tile_points, "tile_points", point_mask)
        ijk = world_to_index(coords, matrix, np.asarray(translation, np.float64)) if in_world else coords
        origins = leaves_of_tiles(ijk)
        return cls._allocate_leaves(origins, matrix, translation, bg_value, device)

    @classmethod
    def allocate_by_voxels(cls, voxel_points, voxel_size=None, translation=(0.0, 0.0, 0.0), device=None,
                           transform=None, rebuildable: bool = False, max_active_voxels=None,
                           max_leaf_nodes=None, max_lower_nodes=None, max_upper_nodes=None, status=None,
                           point_mask=None) -> Volume:
        """An OnIndex volume whose active voxels are those holding `voxel_points`."""
        _refuse_rebuildable(rebuildable, max_active_voxels, max_leaf_nodes, max_lower_nodes, max_upper_nodes)
        device = get_device(device)
        matrix = _transform_of(voxel_size, transform)
        coords, in_world = _points_of(voxel_points, "voxel_points", point_mask)
        ijk = world_to_index(coords, matrix, np.asarray(translation, np.float64)) if in_world else coords
        origins, masks = leaves_of_voxels(ijk)
        grid = GridContent(ON_INDEX, origins, masks, None, 0, matrix, translation)
        return cls._from_grid(grid, device)

    @classmethod
    def _allocate_leaves(cls, origins, matrix, translation, bg_value, device) -> Volume:
        n = origins.shape[0]
        masks = np.full((n, 8), _FULL_MASKS, np.uint64)
        if bg_value is None:
            grid = GridContent(ON_INDEX, origins, masks, None, 0, matrix, translation)
        else:
            grid_type = grid_type_of_value(bg_value)
            if isinstance(bg_value, _types._Scalar):
                bg_value = bg_value.value
            layout = _layout_of(grid_type)
            background = np.asarray(bg_value, dtype=np.float64 if layout.scalar[1] == "f" else np.int64)
            background = np.broadcast_to(background.astype(layout.scalar).reshape(-1), (layout.components,))
            values = np.empty((n * _LEAF_VOXELS, layout.components), layout.scalar)
            values[:] = background
            grid = GridContent(grid_type, origins, masks, values, background, matrix, translation)
        return cls._from_grid(grid, device)

    @classmethod
    def load_from_numpy(cls, ndarray: np.ndarray, min_world=(0.0, 0.0, 0.0), voxel_size=1.0, bg_value=0.0,
                        device=None) -> Volume:
        """A volume of a dense array (X, Y, Z) (or (X, Y, Z, 3) with a 3-value bg_value: Vec3f),
        voxel (i, j, k) at min_world + (i, j, k) * voxel_size; padded to whole tiles with
        bg_value; an int bg_value makes an int32 volume, other scalars float32."""
        voxel_size = _normalize_voxel_size(voxel_size)
        ndarray = np.asarray(ndarray)
        vector = hasattr(bg_value, "__len__")
        if vector:
            grid_type, dtype, tail = 6, np.float32, (3,)
        elif isinstance(bg_value, int) and not isinstance(bg_value, bool):
            grid_type, dtype, tail = 4, np.int32, ()
        else:
            grid_type, dtype, tail = 1, np.float32, ()
        shape = tuple(math.ceil(s / 8) * 8 for s in ndarray.shape[:3])
        padded = np.empty(shape + tail, dtype=dtype)
        padded[...] = np.asarray(bg_value, dtype=dtype)
        padded[:ndarray.shape[0], :ndarray.shape[1], :ndarray.shape[2]] = ndarray
        tiles = [s // 8 for s in shape]
        blocks = padded.reshape(tiles[0], 8, tiles[1], 8, tiles[2], 8, -1).transpose(0, 2, 4, 1, 3, 5, 6)
        values = np.ascontiguousarray(blocks).reshape(-1, len(tail) and 3 or 1)
        axes = [np.arange(t, dtype=np.int32) * 8 for t in tiles]
        origins = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        masks = np.full((origins.shape[0], 8), _FULL_MASKS, np.uint64)
        background = np.broadcast_to(np.asarray(bg_value, dtype=dtype).reshape(-1), (len(tail) and 3 or 1,))
        grid = GridContent(grid_type, origins, masks, values, background, np.diag(voxel_size),
                           np.asarray(min_world, np.float64))
        return cls._from_grid(grid, device)
