"""wp.get_cuda_kernel_properties and wp.get_suggested_block_size: what the CUDA driver says of a
kernel's forward entry as weftd loaded it on a GPU (ModuleService.KernelProperties): registers
and local memory per thread, and the occupancy API's block size. The kernel's module is compiled
for the device first when needed, as a launch would."""
from __future__ import annotations

from .. import _runtime


def _properties(kernel, device, what: str):
    from weft.device import get_device  # noqa: PLC0415

    from .functions import Kernel  # noqa: PLC0415
    from .module import compile_kernel  # noqa: PLC0415

    if not isinstance(kernel, Kernel):
        raise TypeError(f"{what}: expected a Warp kernel (@wp.kernel), got {type(kernel).__name__}")
    if kernel.is_generic:
        raise RuntimeError(f"{what}: kernel '{kernel.key}' is generic; pass an overload returned by "
                           f"wp.overload")
    device = get_device(device)
    if not device.is_cuda:
        raise RuntimeError(f"{what}: {device.alias} is not a CUDA device")
    compiled, info = compile_kernel(kernel, device.alias)
    rt = _runtime.get_runtime()
    return rt.call(rt.module_stub.KernelProperties, _runtime.module_pb2.KernelPropertiesRequest(
        module_id=compiled.module_id, kernel=info.name, device=device.alias))


def get_cuda_kernel_properties(kernel, device=None, block_dim=None) -> dict:
    """{"register_count": registers per thread, "local_memory_size": bytes per thread} of the
    kernel's forward entry on a CUDA device (the default device when None). weft compiles one
    entry per kernel for every block size, so `block_dim` (a positive int) changes nothing.
    TypeError for a non-kernel, RuntimeError for a generic kernel or a non-CUDA device."""
    if block_dim is not None and (isinstance(block_dim, bool) or not isinstance(block_dim, int) or block_dim <= 0):
        raise ValueError(f"get_cuda_kernel_properties: block_dim must be a positive integer, got {block_dim!r}")
    r = _properties(kernel, device, "get_cuda_kernel_properties")
    return {"register_count": int(r.register_count), "local_memory_size": int(r.local_memory_size)}


def get_suggested_block_size(kernel, device=None) -> tuple:
    """(block_size, min_grid_size): the block size of highest occupancy for the kernel on a CUDA
    device (cuOccupancyMaxPotentialBlockSize in weftd) and the fewest blocks of it that fill the
    GPU; (1, 1) on the CPU, as Warp gives."""
    from weft.device import get_device  # noqa: PLC0415

    if get_device(device).is_cpu:
        return (1, 1)
    r = _properties(kernel, device, "get_suggested_block_size")
    if r.suggested_block_size <= 0:
        raise RuntimeError("get_suggested_block_size: the CUDA driver weftd runs with has no occupancy API")
    return (int(r.suggested_block_size), int(r.min_grid_size))
