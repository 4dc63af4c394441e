"""Geometry objects of Warp's API: wp.HashGrid, wp.Bvh and wp.Mesh (docs/geometry.md).

Each object lives in the daemon, owned by this process's session, on the device of its arrays
(the CPU or a GPU; on a GPU the daemon builds on the host and uploads the tree). Kernels receive `obj.id`, an opaque uint64 that each launch resolves against this
session's objects only: a forged, stale or foreign id is a launch error (kernel, line), never
an address. The arrays an object reads (points, indices, lowers/uppers, velocities) are this
session's arrays; the daemon holds them while the object lives. Operations run after the
commands queued before them (a build sees what earlier launches wrote).
"""
from __future__ import annotations

from . import _runtime
from .device import get_device

__all__ = ["is_cubql_available", "HashGrid", "Bvh", "Mesh", "HashGridQuery", "BvhQuery", "BvhQueryTiled",
           "MeshQueryAABBTiled", "MeshQueryPoint", "MeshQueryRay",
           "MeshQueryAABB", "MeshQuery", "hash_grid_query_t", "bvh_query_t", "mesh_query_point_t", "mesh_query_ray_t",
           "mesh_query_aabb_t", "IsoSurfaceBase", "IsoSurfaceMarchingCubes"]


def __getattr__(name):
    """The iso-surface classes (weft/iso_surface.py) load on first use: their kernels need the
    whole weft package, which imports this module."""
    if name in ("IsoSurfaceBase", "IsoSurfaceMarchingCubes"):
        from . import iso_surface  # noqa: PLC0415
        return getattr(iso_surface, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

_Op = None


def _op():
    global _Op
    if _Op is None:
        _Op = _pb2().GeometryRequest.Op
    return _Op


_PB2 = None


def _pb2():
    global _PB2
    if _PB2 is None:
        import importlib
        try:
            _PB2 = importlib.import_module("weft.v1.geometry_pb2")
        except ModuleNotFoundError:
            _runtime._generate_stubs()
            _PB2 = importlib.import_module("weft.v1.geometry_pb2")
    return _PB2


_STUBS = {}


def _call(rt, **fields) -> int:
    pb2 = _pb2()
    stub = _STUBS.get(id(rt))
    if stub is None or stub[0] is not rt:
        cls = _runtime._make_stub_class(pb2.DESCRIPTOR.services_by_name["GeometryService"])
        stub = (rt, cls(rt.channel))
        _STUBS[id(rt)] = stub
    request = pb2.GeometryRequest(**fields)
    rt.flush()   # the operation runs after everything queued before it
    return rt.geometry_call(stub[1].Call, request).id


def _build_call(rt, **fields) -> None:
    """A build, refit or rebuild: a command of the session's batch (exec Command.geometry), run
    by weftd in order with the launches around it, without waiting for it (as Warp's builds on
    a stream); a failure in the daemon is reported at the next synchronize, as a launch's.
    Inside a graph capture on this thread it is a command of the graph, run at every replay."""
    from .v1 import exec_pb2  # noqa: PLC0415
    rt.submit(exec_pb2.Command(geometry=_pb2().GeometryRequest(**fields)))


def _handle_of(a, what: str) -> int:
    if a is None:
        return 0
    if not hasattr(a, "_handle"):
        raise TypeError(f"{what}: expected a wp.array, got {type(a).__name__}")
    if not a._is_whole():
        raise ValueError(f"{what}: must be a whole contiguous array (not a view)")
    return int(a._handle)


class _Object:
    def __init__(self):
        self.id = 0
        self._rt = None

    def _free(self):
        # A command of the session's next batch (after the commands that may still use the
        # object), never an RPC from a finalizer.
        if self.id and self._rt is not None and _runtime.current_runtime() is self._rt:
            self._rt.free_geometry_later(self.id)
        self.id = 0

    def __del__(self):
        try:
            self._free()
        except Exception:  # noqa: BLE001
            pass


class HashGrid(_Object):
    """A hash grid of dim_x * dim_y * dim_z cells for neighbour queries (Warp's wp.HashGrid)."""

    def __init__(self, dim_x: int, dim_y: int, dim_z: int, device=None, dtype=None):
        super().__init__()
        from . import types as _types
        self.dtype = dtype if dtype is not None else _types.float32
        vec = {_types.float16: _types.vec3h, _types.float32: _types.vec3, _types.float64: _types.vec3d}
        if self.dtype not in vec:
            raise TypeError(f"HashGrid: dtype must be float16, float32 or float64, got {dtype!r}")
        self._point_dtype = vec[self.dtype]
        self.device = get_device(device)
        self._rt = _runtime.get_runtime()
        self.dim_x, self.dim_y, self.dim_z = int(dim_x), int(dim_y), int(dim_z)
        for d in (self.dim_x, self.dim_y, self.dim_z):
            if d < 1 or d > 2**31 - 1:
                raise ValueError(f"HashGrid: dims must be in [1, 2^31), got ({dim_x}, {dim_y}, {dim_z})")
        self.reserved = False
        self.points = None
        self.groups = None
        self.radius = 0.0
        self.id = _call(self._rt, op=_op().CREATE_HASH_GRID, device=str(self.device),
                        dim=[self.dim_x, self.dim_y, self.dim_z])

    def build(self, points, radius: float, groups=None):
        """Sorts `points` (a vec3 array of the grid's dtype, on its device) into cells of width
        `radius` (positive, finite). `groups` (int32, one per point, on the grid's device):
        each point's group id, any int32 value; `wp.hash_grid_query(id, p, r, group)` then
        visits only that group's points. The ids are read at this build (assign new ones, then
        build again). A strided or multi-dimensional array is taken through a contiguous copy."""
        radius = float(radius)
        if not (0.0 < radius < float("inf")):
            raise ValueError(f"HashGrid.build: radius must be a positive finite number, got {radius}")
        from ._kernel.typestr import type_string
        point_dtype = getattr(points, "dtype", None)
        if point_dtype is not self._point_dtype and type_string(point_dtype) != type_string(self._point_dtype):
            raise TypeError(f"HashGrid.build: a grid of dtype {getattr(self.dtype, '__name__', self.dtype)} "
                            f"needs points of {getattr(self._point_dtype, '__name__', self._point_dtype)}, "
                            f"got {getattr(points, 'dtype', type(points).__name__)}")
        if groups is not None:
            if type_string(getattr(groups, "dtype", None)) != "int32":
                raise RuntimeError("groups should be an array of type wp.int32")
            if str(groups.device) != str(self.device):
                raise RuntimeError("groups must live on the same device as this HashGrid")
            if groups.size != points.size:
                raise RuntimeError("groups must have the same length as points")
        if str(points.device) != str(self.device):
            raise RuntimeError("points must live on the same device as this HashGrid")
        built_points = _whole(points)
        built_groups = _whole(groups) if groups is not None else None
        _build_call(self._rt, op=_op().BUILD_HASH_GRID, id=self.id,
                    points=_handle_of(built_points, "HashGrid.build points"),
                    groups=_handle_of(built_groups, "HashGrid.build groups"), radius=float(radius))
        self.points = points
        self.groups = groups
        self.radius = float(radius)
        self.reserved = True

    def reserve(self, num_points: int, with_groups: bool = False):
        """Warp preallocates here; the daemon sizes its buffers (groups included) at build time."""
        if int(num_points) < 0:
            raise ValueError("reserve: num_points must be >= 0")
        self.reserved = True


def _check_groups(groups, device, count: int, device_of: str, length_of: str):
    """Warp's checks of a Bvh's or Mesh's group ids (the daemon checks them again)."""
    from ._kernel.typestr import type_string  # noqa: PLC0415
    if type_string(getattr(groups, "dtype", None)) != "int32" or getattr(groups, "ndim", 1) != 1:
        raise RuntimeError("groups should be a contiguous array of type wp.int32")
    if str(groups.device) != str(device):
        raise RuntimeError(f"groups must live on the same device as {device_of}")
    if groups.shape[0] != count:
        raise RuntimeError(f"groups must have the same length as {length_of}")


def _whole(a):
    """`a` itself when it is a whole contiguous array, else a contiguous copy of it."""
    from .array import clone  # noqa: PLC0415
    if hasattr(a, "_is_whole") and not a._is_whole():
        return clone(a)
    return a


class Bvh(_Object):
    """A bounding volume hierarchy over boxes [lowers[i], uppers[i]] (Warp's wp.Bvh)."""

    def __init__(self, lowers, uppers, constructor: str | None = None, leaf_size: int | None = None,
                 groups=None):
        """`groups` (int32, one per box, on the boxes' device): each group's boxes form one
        subtree, whose root `wp.bvh_get_group_root(id, group)` gives to the queries' `root`
        argument. The ids are read now (rebuild() reuses them)."""
        super().__init__()
        self._rt = _runtime.get_runtime()
        self.device = lowers.device
        self.lowers = lowers
        self.uppers = uppers
        self.groups = groups
        # What weftd builds, whatever was asked: a linear BVH on a GPU (grouped or not), as
        # Warp's default there; a median split on the CPU (docs/geometry.md, "Devices").
        self.constructor = "lbvh" if str(self.device).startswith("cuda") else "median"
        if groups is not None:
            _check_groups(groups, lowers.device, lowers.shape[0], "lowers/uppers", "lowers/uppers")
        self.id = _call(self._rt, op=_op().CREATE_BVH, lowers=_handle_of(lowers, "Bvh lowers"),
                        uppers=_handle_of(uppers, "Bvh uppers"),
                        groups=_handle_of(_whole(groups) if groups is not None else None, "Bvh groups"))

    def refit(self):
        """Recomputes the node bounds from the current lowers/uppers."""
        _build_call(self._rt, op=_op().REFIT, id=self.id)

    def rebuild(self, constructor: str | None = None):
        """Builds a new tree from the current lowers/uppers."""
        _build_call(self._rt, op=_op().REBUILD, id=self.id)


class Mesh(_Object):
    """A triangle mesh with a BVH (Warp's wp.Mesh). `points` stays the caller's array: after
    writing to it, call refit(). The indices are checked (each < len(points)) and copied."""

    def __init__(self, points, indices, velocities=None, support_winding_number: bool = False,
                 bvh_constructor: str | None = None, bvh_leaf_size: int | None = None, groups=None):
        """`groups` (int32, one per face): each group's faces form one subtree of the BVH
        (`wp.mesh_get_group_root(id, group)`, the `root` of the ray queries)."""
        super().__init__()
        self._rt = _runtime.get_runtime()
        self.device = points.device
        self.points = points
        self.indices = indices
        self.velocities = velocities
        self.groups = groups
        self.support_winding_number = bool(support_winding_number)
        if groups is not None:
            _check_groups(groups, points.device, indices.size // 3, "points", "indices / 3")
        self.id = _call(self._rt, op=_op().CREATE_MESH, points=_handle_of(points, "Mesh points"),
                        indices=_handle_of(indices, "Mesh indices"),
                        velocities=_handle_of(velocities, "Mesh velocities"),
                        groups=_handle_of(_whole(groups) if groups is not None else None, "Mesh groups"))

    def refit(self):
        """Recomputes the BVH bounds from the current points."""
        _build_call(self._rt, op=_op().REFIT, id=self.id)

    def rebuild(self, constructor: str | None = None, leaf_size: int | None = None):
        """Builds a new BVH from the current points."""
        _build_call(self._rt, op=_op().REBUILD, id=self.id)


def is_cubql_available() -> bool:
    """Warp's optional cuBQL BVH builder: not part of weft (builds use a median split on the
    CPU and a linear BVH on a GPU)."""
    return False


class _QueryType:
    """A kernel-side query type (only meaningful inside kernels)."""

    def __init__(self, name: str):
        self.__name__ = name
        self._type_str = f"struct({name})"

    def __getitem__(self, dtype):
        """wp.HashGridQuery[wp.float16] and friends: one query type whatever the point precision."""
        return self

    def __repr__(self):
        return self.__name__


HashGridQuery = hash_grid_query_t = _QueryType("HashGridQuery")
BvhQuery = bvh_query_t = _QueryType("BvhQuery")
MeshQueryPoint = mesh_query_point_t = _QueryType("MeshQueryPoint")
MeshQueryRay = mesh_query_ray_t = _QueryType("MeshQueryRay")
MeshQueryAABB = mesh_query_aabb_t = _QueryType("MeshQueryAABB")
MeshQuery = MeshQueryAABB   # Warp's erased sphere / AABB query type: one iterator type here
# The tiled queries (wp.tile_bvh_query_aabb / _ray, wp.tile_mesh_query_aabb; docs/geometry.md).
BvhQueryTiled = _QueryType("BvhQueryTiled")
MeshQueryAABBTiled = _QueryType("MeshQueryAABBTiled")


