"""weft: Warp-compatible Python client of the weftd compute daemon.

`import weft as wp` gives Warp's names: dtypes (float32, vec3, mat33, quat, transform...),
wp.array and the array functions, devices, synchronization, and (from weft._kernel) the
kernel API (@wp.kernel, @wp.func, @wp.struct, wp.launch, wp.Tape). See docs/python-api.md.
"""
from . import config, types, utils  # noqa: F401
from .config import (LOG_DEBUG, LOG_ERROR, LOG_INFO, LOG_WARNING,  # noqa: F401
                     DeterministicMode)
from .array import (ARRAY_MAX_DIMS, array, array1d, array2d, array3d, array4d, clone,  # noqa: F401
                    copy, empty, empty_like, from_ipc_handle, from_numpy, full, full_like, ones,
                    ones_like, zeros, zeros_like)
from .fixedarray import fixedarray  # noqa: F401
from .indexedarray import (indexedarray, indexedarray1d, indexedarray2d,  # noqa: F401
                           indexedarray3d, indexedarray4d)
from .fabricarray import (fabricarray, fabricarrayarray, indexedfabricarray,  # noqa: F401
                          indexedfabricarrayarray)
from .tile import tile, tile_stack  # noqa: F401
from .device import (Device, ScopedDevice, get_cuda_device, get_cuda_device_count,  # noqa: F401
                     get_cuda_devices, get_cuda_driver_version, get_cuda_supported_archs,
                     get_cuda_toolkit_version, get_device, get_devices, get_preferred_device, init, is_cpu_available,
                     is_cuda_available, is_device_available, set_device, synchronize,
                     synchronize_device, print_diagnostics)
from .errors import WeftError  # noqa: F401
from .mempool import (ScopedMempool, ScopedMempoolAccess, ScopedPeerAccess,  # noqa: F401
                      get_mempool_release_threshold, get_mempool_used_mem_current,
                      get_mempool_used_mem_high, is_mempool_access_enabled,
                      is_mempool_access_supported, is_mempool_enabled, is_mempool_supported,
                      is_peer_access_enabled, is_peer_access_supported,
                      set_mempool_access_enabled, set_mempool_enabled,
                      set_mempool_release_threshold, set_peer_access_enabled)
from .graph import (CaptureMode, Graph, ScopedCapture, capture_begin, capture_debug_dot_print,  # noqa: F401
                    capture_end, capture_if, capture_launch, capture_pause, capture_resume,
                    capture_while, is_conditional_graph_supported)
from .streams import (Event, ScopedStream, Stream, event_from_ipc_handle,  # noqa: F401
                      get_event_elapsed_time, get_stream, record_event, set_stream, synchronize_event,
                      synchronize_stream, wait_event, wait_stream)
from .constants import *  # noqa: F401,F403
from .types import *  # noqa: F401,F403
from .types import (Any, dtype_from_numpy, dtype_to_numpy, matrix, quaternion,  # noqa: F401
                    transformation, type_size_in_bytes, type_str, vector)
from .utils import ScopedTimer, transform_expand  # noqa: F401
from .utils import ScopedLogger, ScopedLogLevel  # noqa: F401
from .logger import Logger, get_logger, set_logger  # noqa: F401
from .memory_tracker import ScopedMemoryTracker, print_memory_report  # noqa: F401
from ._kernel.module import clear_kernel_cache, force_load  # noqa: F401
from ._kernel.kernel_properties import get_cuda_kernel_properties, get_suggested_block_size  # noqa: F401
from .timing import (TIMING_ALL, TIMING_GRAPH, TIMING_KERNEL, TIMING_KERNEL_BUILTIN,  # noqa: F401
                     TIMING_MEMCPY, TIMING_MEMSET, TimingResult, timing_begin, timing_end,
                     timing_print)
from .geometry import (Bvh, BvhQuery, BvhQueryTiled, HashGrid, HashGridQuery, Mesh, MeshQuery,  # noqa: F401
                       MeshQueryAABB, MeshQueryAABBTiled,
                       MeshQueryPoint, MeshQueryRay, bvh_query_t, hash_grid_query_t,
                       is_cubql_available, mesh_query_aabb_t, mesh_query_point_t,
                       mesh_query_ray_t)
from .volume import Volume  # noqa: F401

__version__ = "0.1.0"
_weft_reexport_of_ = "weft"   # carried by packages that re-export weft (see _aliases.py)
DeviceLike = object  # typing alias of Warp (a Device or its alias string)


def constant(x):
    """Marks a module-level value as a kernel compile-time constant (Warp's wp.constant)."""
    return x


from ._builtin_refs import *  # noqa: F401,F403,E402
from ._kernel.annotations import ref  # noqa: F401,E402
from ._kernel.api import *  # noqa: F401,F403,E402
from ._kernel.transform_funcs import (transform_compose, transform_decompose,  # noqa: F401,E402
                                      transform_from_matrix, transform_to_matrix)
from ._kernel.math_funcs import (norm_huber, norm_l1, norm_l2, norm_pseudo_huber,  # noqa: F401,E402
                                 quat_between_vectors, quat_from_euler, quat_to_euler, quat_to_rpy, quat_twist,
                                 quat_twist_angle, quat_twist_angle_signed, smooth_normalize,
                                 transform_twist, transform_wrench, velocity_at_point)

utils.quat_between_vectors = quat_between_vectors   # warp.utils has it too

from .interop.dlpack import from_dlpack, to_dlpack  # noqa: F401,E402
from .interop.jax import (device_from_jax, device_to_jax, dtype_from_jax,  # noqa: F401,E402
                          dtype_to_jax, from_jax, to_jax)
from .interop.jax_ffi import (JaxCallableGraphMode, JaxModulePreloadMode,  # noqa: F401,E402
                              clear_jax_callable_graph_cache, jax_callable, jax_kernel)
from .interop.paddle import (device_from_paddle, device_to_paddle,  # noqa: F401,E402
                             dtype_from_paddle, dtype_to_paddle, from_paddle,
                             stream_from_paddle, to_paddle)
from .interop.torch import (device_from_torch, device_to_torch, dtype_from_torch,  # noqa: F401,E402
                            dtype_to_torch, from_torch, stream_from_torch, stream_to_torch,
                            to_torch)

from . import autograd  # noqa: F401,E402
from . import _aliases  # noqa: E402

_aliases.install()


def __getattr__(name):
    if name == "MarchingCubes":  # Warp's deprecated alias, resolved on first use
        from ._log import log_warning  # noqa: PLC0415
        log_warning("wp.MarchingCubes is deprecated and will be removed in a future version of Warp. "
                    "Use wp.geometry.IsoSurfaceMarchingCubes instead.", DeprecationWarning)
        from .iso_surface import IsoSurfaceMarchingCubes  # noqa: PLC0415
        return IsoSurfaceMarchingCubes
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
