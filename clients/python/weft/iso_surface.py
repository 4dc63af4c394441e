"""Marching cubes iso-surfaces of dense 3-D fields: Warp's `warp.geometry.IsoSurfaceMarchingCubes`
(and the deprecated `wp.MarchingCubes` alias), as weft kernels (docs/geometry.md).

A field of float32 values at the nodes of an (nx, ny, nz) grid becomes a triangle mesh: one vertex
per grid edge whose endpoints lie on different sides of the threshold (a node is inside when its
value is below it), placed by linear interpolation of the two values, and the triangles of each
cell from the case tables of `_mc_tables`. On the field's device: counts per node, their prefix
sums (per chunk of nodes on the device; only the chunks' sums come to the host and their starts
go back), vertices, faces.
Vertices are differentiable with respect to the field: under a `wp.Tape`, gradients flow from
`verts` back to `field` through the interpolation; the indices are discrete.
"""
from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

import weft as wp

from . import _mc_tables as _tables
from . import _runtime
from ._log import log_warning

__all__ = ["IsoSurfaceBase", "IsoSurfaceMarchingCubes"]

_INT32_MAX = 2**31 - 1


@wp.func
def _below(v: float, threshold: float):
    if v < threshold:
        return 1
    return 0


@wp.func
def _cell_case(field: wp.array3d[float], i: int, j: int, k: int, threshold: float):
    """Bit c set when corner c (CUBE_CORNER_OFFSETS[c]) is below the threshold."""
    return (_below(field[i, j, k], threshold) | (_below(field[i + 1, j, k], threshold) << 1) |
            (_below(field[i + 1, j + 1, k], threshold) << 2) | (_below(field[i, j + 1, k], threshold) << 3) |
            (_below(field[i, j, k + 1], threshold) << 4) | (_below(field[i + 1, j, k + 1], threshold) << 5) |
            (_below(field[i + 1, j + 1, k + 1], threshold) << 6) | (_below(field[i, j + 1, k + 1], threshold) << 7))


@wp.kernel
def _mc_count(field: wp.array3d[float], threshold: float, case_tri_range: wp.array[wp.int32],
              edge_counts: wp.array[wp.int32],
              tri_counts: wp.array[wp.int32]):
    """Per node: the crossed grid edges that start there (+x, +y, +z) and the triangles of the
    cell whose lowest corner it is."""
    i, j, k = wp.tid()
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    node = (i * ny + j) * nz + k
    inside = _below(field[i, j, k], threshold)
    n = int(0)
    if i + 1 < nx:
        n += wp.abs(_below(field[i + 1, j, k], threshold) - inside)
    if j + 1 < ny:
        n += wp.abs(_below(field[i, j + 1, k], threshold) - inside)
    if k + 1 < nz:
        n += wp.abs(_below(field[i, j, k + 1], threshold) - inside)
    edge_counts[node] = n
    tris = int(0)
    if i + 1 < nx and j + 1 < ny and k + 1 < nz:
        case = _cell_case(field, i, j, k, threshold)
        tris = (case_tri_range[case + 1] - case_tri_range[case]) // 3
    tri_counts[node] = tris


@wp.func
def _edge_point(f0: float, f1: float, threshold: float, p0: wp.vec3, p1: wp.vec3):
    return wp.lerp(p0, p1, (threshold - f0) / (f1 - f0))


@wp.kernel
def _mc_vertices(field: wp.array3d[float], threshold: float, lower: wp.vec3, delta: wp.vec3,
                 edge_offsets: wp.array[wp.int32], verts: wp.array[wp.vec3],
                 edge_vertex: wp.array[wp.int32]):
    """The vertex of each crossed edge starting at this node, and its index by (node, axis)."""
    i, j, k = wp.tid()
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    node = (i * ny + j) * nz + k
    f0 = field[i, j, k]
    inside = _below(f0, threshold)
    p0 = lower + wp.cw_mul(wp.vec3(float(i), float(j), float(k)), delta)
    slot = edge_offsets[node]
    if i + 1 < nx:
        f1 = field[i + 1, j, k]
        if _below(f1, threshold) != inside:
            p1 = lower + wp.cw_mul(wp.vec3(float(i + 1), float(j), float(k)), delta)
            verts[slot] = _edge_point(f0, f1, threshold, p0, p1)
            edge_vertex[node * 3 + 0] = slot
            slot += 1
    if j + 1 < ny:
        f1 = field[i, j + 1, k]
        if _below(f1, threshold) != inside:
            p1 = lower + wp.cw_mul(wp.vec3(float(i), float(j + 1), float(k)), delta)
            verts[slot] = _edge_point(f0, f1, threshold, p0, p1)
            edge_vertex[node * 3 + 1] = slot
            slot += 1
    if k + 1 < nz:
        f1 = field[i, j, k + 1]
        if _below(f1, threshold) != inside:
            p1 = lower + wp.cw_mul(wp.vec3(float(i), float(j), float(k + 1)), delta)
            verts[slot] = _edge_point(f0, f1, threshold, p0, p1)
            edge_vertex[node * 3 + 2] = slot


@wp.kernel
def _mc_faces(field: wp.array3d[float], threshold: float, case_tri_range: wp.array[wp.int32],
              tri_local: wp.array[wp.int32],
              edge_nodes: wp.array[wp.int32], tri_offsets: wp.array[wp.int32],
              edge_vertex: wp.array[wp.int32], indices: wp.array[wp.int32]):
    """The triangles of the cell whose lowest corner is this node, as vertex indices."""
    i, j, k = wp.tid()
    nx, ny, nz = field.shape[0], field.shape[1], field.shape[2]
    if i + 1 >= nx or j + 1 >= ny or k + 1 >= nz:
        return
    case = _cell_case(field, i, j, k, threshold)
    start = case_tri_range[case]
    base = tri_offsets[(i * ny + j) * nz + k] * 3 - start
    for q in range(start, case_tri_range[case + 1]):
        e = tri_local[q]
        ni = i + edge_nodes[4 * e]
        nj = j + edge_nodes[4 * e + 1]
        nk = k + edge_nodes[4 * e + 2]
        indices[base + q] = edge_vertex[((ni * ny + nj) * nz + nk) * 3 + edge_nodes[4 * e + 3]]


@wp.kernel
def _mc_chunk_sums(edge_counts: wp.array[wp.int32], tri_counts: wp.array[wp.int32], chunk: int,
                   edge_sums: wp.array[wp.int32], tri_sums: wp.array[wp.int32]):
    """The sums of the counts of each chunk of `chunk` consecutive nodes."""
    c = wp.tid()
    start = c * chunk
    end = wp.min(start + chunk, edge_counts.shape[0])
    e = int(0)
    t = int(0)
    for k in range(start, end):
        e += edge_counts[k]
        t += tri_counts[k]
    edge_sums[c] = e
    tri_sums[c] = t


@wp.kernel
def _mc_chunk_offsets(edge_counts: wp.array[wp.int32], tri_counts: wp.array[wp.int32], chunk: int,
                      edge_starts: wp.array[wp.int32], tri_starts: wp.array[wp.int32],
                      edge_offsets: wp.array[wp.int32], tri_offsets: wp.array[wp.int32]):
    """Exclusive prefix sums of the counts, each chunk from its start."""
    c = wp.tid()
    start = c * chunk
    end = wp.min(start + chunk, edge_counts.shape[0])
    e = edge_starts[c]
    t = tri_starts[c]
    for k in range(start, end):
        edge_offsets[k] = e
        tri_offsets[k] = t
        e += edge_counts[k]
        t += tri_counts[k]


_table_cache: dict = {"runtime": None, "by_device": {}}


def _device_tables(device):
    """The lookup tables as int32 arrays on `device`, uploaded once per session and device."""
    rt = _runtime.get_runtime()
    if _table_cache["runtime"] is not rt:
        _table_cache["runtime"], _table_cache["by_device"] = rt, {}
    key = str(device)
    found = _table_cache["by_device"].get(key)
    if found is None:
        def upload(values):
            return wp.array(np.asarray(values, dtype=np.int32).ravel(), dtype=wp.int32, device=device)

        found = (upload(_tables.CASE_TO_TRI_RANGE), upload(_tables.TRI_LOCAL_INDICES), upload(_tables.edge_nodes()))
        _table_cache["by_device"][key] = found
    return found


def validate_field(field) -> None:
    """A 3-D float32 array with at least two nodes on every axis (one cell), or the error Warp
    raises."""
    if len(field.shape) != 3:
        raise ValueError(f"Expected a 3D array for 'field', but got an array with shape {field.shape}.")
    if any(n < 2 for n in field.shape):
        raise ValueError(f"Expected 'field' to have at least 2 nodes on each axis, but got an array "
                         f"with shape {field.shape}.")
    if field.dtype != wp.float32:
        raise TypeError(f"Expected a dtype of wp.float32 for 'field', but got {field.dtype}.")


def resolve_domain_bounds(shape, lower, upper):
    """(lower corner, cell size): by default node (i, j, k) sits at (i, j, k)."""
    cells = [float(n - 1) for n in shape[:3]]
    lower = wp.vec3(0.0, 0.0, 0.0) if lower is None else wp.vec3(*[float(x) for x in lower])
    upper = wp.vec3(*cells) if upper is None else wp.vec3(*[float(x) for x in upper])
    delta = wp.vec3(*[(float(upper[a]) - float(lower[a])) / cells[a] for a in range(3)])
    return lower, delta


def _exclusive_offsets(counts: np.ndarray, what: str) -> tuple[np.ndarray, int]:
    total = int(counts.sum(dtype=np.int64))
    if total * (3 if what == "triangles" else 1) > _INT32_MAX:
        raise ValueError(f"marching cubes: the surface has {total} {what}, more than int32 "
                         f"indices can address")
    offsets = np.cumsum(counts, dtype=np.int64) - counts
    return offsets.astype(np.int32), total


def _scratch_size(nodes: int, chunks: int) -> int:
    """int32 words of one extraction's temporaries: per node the edge and triangle counts and
    offsets and three edge vertices; per chunk the two chunk sums."""
    return 7 * nodes + 2 * chunks


def _marching_cubes(field, threshold: float, lower, upper, scratch_holder=None):
    """(verts, indices). The temporaries are views of one int32 block (`scratch_holder`, a dict
    of the calling IsoSurfaceMarchingCubes, keeps it for the next call of the same size and
    device); the host sees the chunk sums once and sends the chunk starts once: a GPU extraction
    costs the daemon one allocation, one download and one upload besides the outputs."""
    validate_field(field)
    origin, delta = resolve_domain_bounds(field.shape, lower, upper)
    device = field.device
    case_tri_range, tri_local, edge_nodes = _device_tables(device)
    nodes = field.shape[0] * field.shape[1] * field.shape[2]
    if 3 * nodes > _INT32_MAX:   # the kernels name grid edges with int32 (node * 3 + axis)
        raise ValueError(f"marching cubes: a field of shape {tuple(field.shape)} has more grid edges than int32 "
                         f"indices can address")
    threshold = float(threshold)
    # prefix sums: chunk sums on the device, the chunks' starts on the host (at most ~64K each)
    chunk = max(256, -(-nodes // 65536))
    chunks = -(-nodes // chunk)
    need = _scratch_size(nodes, chunks)
    key = (str(device), need, _runtime.get_runtime())
    buf = scratch_holder.get(key) if scratch_holder is not None else None
    if buf is None:
        buf = wp.empty(need, dtype=wp.int32, device=device)
        if scratch_holder is not None:
            scratch_holder.clear()
            scratch_holder[key] = buf
    edge_counts, tri_counts = buf[0:nodes], buf[nodes:2 * nodes]
    edge_offsets, tri_offsets = buf[2 * nodes:3 * nodes], buf[3 * nodes:4 * nodes]
    edge_vertex = buf[4 * nodes:7 * nodes]
    sums = buf[7 * nodes:need]
    wp.launch(_mc_count, dim=field.shape, device=device,
              inputs=[field, threshold, case_tri_range, edge_counts, tri_counts])
    wp.launch(_mc_chunk_sums, dim=chunks, device=device, inputs=[edge_counts, tri_counts, chunk],
              outputs=[sums[0:chunks], sums[chunks:]])
    host_sums = sums.numpy()
    edge_starts, vert_total = _exclusive_offsets(host_sums[:chunks], "vertices")
    tri_starts, tri_total = _exclusive_offsets(host_sums[chunks:], "triangles")

    grad = bool(getattr(field, "requires_grad", False))
    verts = wp.empty(vert_total, dtype=wp.vec3, device=device, requires_grad=grad)
    indices = wp.empty(3 * tri_total, dtype=wp.int32, device=device)
    if vert_total == 0:
        return verts, indices
    starts = wp.array(np.concatenate([edge_starts, tri_starts]), dtype=wp.int32, device=device)
    wp.launch(_mc_chunk_offsets, dim=chunks, device=device,
              inputs=[edge_counts, tri_counts, chunk, starts[0:chunks], starts[chunks:]],
              outputs=[edge_offsets, tri_offsets])
    wp.launch(_mc_vertices, dim=field.shape, device=device,
              inputs=[field, threshold, origin, delta, edge_offsets], outputs=[verts, edge_vertex])
    wp.launch(_mc_faces, dim=field.shape, device=device,
              inputs=[field, threshold, case_tri_range, tri_local, edge_nodes, tri_offsets, edge_vertex],
              outputs=[indices])
    return verts, indices


class _DeprecatedDefault:
    def __repr__(self):
        return "None"


_UNSET = _DeprecatedDefault()


def _deprecated(message: str) -> None:
    """Warns at the user's line (two frames up: the deprecated entry point's caller)."""
    log_warning(message, DeprecationWarning, stacklevel=2)


def _deprecated_argument(value, legacy, name: str, legacy_name: str):
    """`value`, or the deprecated keyword's value when that was given (warning as Warp does)."""
    if legacy is _UNSET:
        return value
    if value is not None and legacy is not None:
        raise TypeError(f"Cannot specify both `{name}` and `{legacy_name}`.")
    log_warning(f"IsoSurfaceMarchingCubes() argument `{legacy_name}` is deprecated and will be removed in a "
                f"future version of Warp. Use `{name}` instead.", DeprecationWarning, stacklevel=2)
    return value if legacy is None else legacy


def _deprecated_alias(name: str, attr: str) -> property:
    """A deprecated attribute that reads and writes `attr`, warning as Warp does."""
    message = (f"IsoSurfaceMarchingCubes.{name} is deprecated and will be removed in a future version of Warp. "
               f"Use `{attr}` instead.")

    def get(self):
        _deprecated(message)
        return getattr(self, attr)

    def set(self, value):
        _deprecated(message)
        setattr(self, attr, value)

    return property(get, set, doc=f"Deprecated alias of `{attr}`.")


class IsoSurfaceBase(ABC):
    """Grid dimensions (nodes per axis), the bounds the grid maps to, and the last mesh extracted
    (`verts`, `indices`); the interface of Warp's iso-surface backends."""

    def __init__(self, nx: int, ny: int, nz: int, *, lower=None, upper=None):
        self.nx, self.ny, self.nz = nx, ny, nz
        self.lower, self.upper = lower, upper
        self.verts = None
        self.indices = None

    def resize(self, nx: int, ny: int, nz: int) -> None:
        """New grid dimensions for the next `surface` call."""
        self.nx, self.ny, self.nz = nx, ny, nz

    def _check_field_shape(self, field) -> None:
        validate_field(field)
        if tuple(field.shape) != (self.nx, self.ny, self.nz):
            raise ValueError(f"Field shape {tuple(field.shape)} does not match context grid dimensions "
                             f"{(self.nx, self.ny, self.nz)}.")

    @abstractmethod
    def surface(self, field, threshold: float) -> None:
        """Extracts the surface of `field` at `threshold` into `verts` and `indices`."""

    @classmethod
    @abstractmethod
    def extract(cls, field, threshold: float = 0.0, *, lower=None, upper=None):
        """(verts, indices) of the surface of `field` at `threshold`."""


class IsoSurfaceMarchingCubes(IsoSurfaceBase):
    """Marching cubes over a dense float32 field (Warp's class of that name): `surface` fills
    `verts` (vec3) and `indices` (flat int32, three per triangle); `extract` returns them."""

    CUBE_CORNER_OFFSETS = _tables.CUBE_CORNER_OFFSETS
    EDGE_TO_CORNERS = _tables.EDGE_TO_CORNERS
    CASE_TO_TRI_RANGE = _tables.CASE_TO_TRI_RANGE
    TRI_LOCAL_INDICES = _tables.TRI_LOCAL_INDICES

    def __init__(self, nx: int, ny: int, nz: int, lower=None, upper=None, *,
                 domain_bounds_lower_corner=_UNSET, domain_bounds_upper_corner=_UNSET):
        lower = _deprecated_argument(lower, domain_bounds_lower_corner, "lower", "domain_bounds_lower_corner")
        upper = _deprecated_argument(upper, domain_bounds_upper_corner, "upper", "domain_bounds_upper_corner")
        super().__init__(nx, ny, nz, lower=lower, upper=upper)
        self._scratch = {}   # the temporaries of the last surface() call, reused by the next

    domain_bounds_lower_corner = _deprecated_alias("domain_bounds_lower_corner", "lower")
    domain_bounds_upper_corner = _deprecated_alias("domain_bounds_upper_corner", "upper")

    def surface(self, field, threshold: float) -> None:
        """Extracts the surface of `field` at `threshold` into `verts` and `indices`; the field's
        shape must be the grid's (nx, ny, nz)."""
        self._check_field_shape(field)
        self.verts, self.indices = _marching_cubes(field, threshold, self.lower, self.upper, self._scratch)

    @classmethod
    def extract(cls, field, threshold: float = 0.0, *, lower=None, upper=None):
        """(verts, indices) of the surface of `field` at `threshold`. Node (0, 0, 0) maps to
        `lower` (default the origin) and node (nx-1, ny-1, nz-1) to `upper` (default
        (nx-1, ny-1, nz-1)). Triangles wind counter-clockwise seen from where the field is above
        the threshold (outside a signed distance field)."""
        return _marching_cubes(field, threshold, lower, upper)

    @staticmethod
    def extract_surface_marching_cubes(field, threshold: float = 0.0, domain_bounds_lower_corner=None,
                                       domain_bounds_upper_corner=None):
        """Deprecated name of `extract`."""
        _deprecated("IsoSurfaceMarchingCubes.extract_surface_marching_cubes() is deprecated and will be "
                    "removed in a future version of Warp. Use IsoSurfaceMarchingCubes.extract() instead.")
        return _marching_cubes(field, threshold, domain_bounds_lower_corner, domain_bounds_upper_corner)
