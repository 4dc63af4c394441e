"""JAX interop: wp.from_jax / wp.to_jax, device and dtype helpers, and jax_kernel.

Both directions go through DLPack. to_jax of a local CPU weft array gives a JAX array over the
weft slab when JAX accepts the memory as it is (JAX may copy when it requires an alignment
the memory lacks); pending weft commands are finished first. from_jax of a JAX array whose
buffer is a weft slab (made by to_jax) is zero-copy; any other JAX CPU array lives in this
process and is copied into a new weft array (JAX arrays are immutable, so the copy is never
stale).

wp.jax_kernel and wp.jax_callable (kernels inside jax.jit, vmap and grad) are in jax_ffi.py.
"""
from __future__ import annotations

import numpy as np

from . import dlpack


def _jax():
    import jax  # noqa: PLC0415

    return jax


def dtype_from_jax(jax_dtype):
    """The weft scalar dtype of a JAX dtype (TypeError for bfloat16, complex, ...)."""
    from .. import types  # noqa: PLC0415

    try:
        return types.dtype_from_numpy(np.dtype(jax_dtype))
    except TypeError:
        raise TypeError(f"Invalid or unsupported data type: {jax_dtype}") from None


def dtype_to_jax(weft_dtype):
    """The JAX (NumPy) dtype of a weft dtype (of its scalar components for vectors)."""
    from .. import types  # noqa: PLC0415
    from ..array import _canonical_dtype  # noqa: PLC0415

    dtype = _canonical_dtype(weft_dtype)
    if not types.is_dtype(dtype):
        raise TypeError(f"Cannot convert {weft_dtype} to a JAX type")
    return _jax().numpy.dtype(dtype._wp_scalar_type_._np_dtype_)


def device_from_jax(jax_device):
    """The weft Device of a JAX device (platform cpu -> "cpu", gpu/cuda -> "cuda:N")."""
    from ..device import get_device  # noqa: PLC0415

    platform = jax_device.platform
    if platform == "cpu":
        return get_device("cpu")
    if platform in ("gpu", "cuda"):
        return get_device(f"cuda:{jax_device.local_hardware_id if hasattr(jax_device, 'local_hardware_id') and jax_device.local_hardware_id is not None else jax_device.id}")
    raise RuntimeError(f"JAX device {jax_device} has no weft counterpart")


def device_to_jax(device):
    """The JAX device of a weft device, among this process's JAX devices (so a process of a
    jax.distributed program gets its own: its CPU, or the local GPU of the same ordinal)."""
    from ..device import get_device  # noqa: PLC0415

    device = get_device(device)
    jax = _jax()
    try:
        local = jax.local_devices(backend="cuda" if device.is_cuda else "cpu")
    except RuntimeError:
        local = []
    if device.is_cuda:
        for d in local:
            if getattr(d, "local_hardware_id", d.id) == device.ordinal:
                return d
    elif device.is_cpu and local:
        return local[0]
    raise RuntimeError(f"weft device {device} has no JAX device in this process")


def from_jax(jax_array, dtype=None):
    """A weft array of a JAX array (through DLPack; see this module's docstring)."""
    jax = _jax()
    if not isinstance(jax_array, jax.Array):
        raise TypeError(f"wp.from_jax expects a jax.Array, got {type(jax_array).__name__}")
    return dlpack.from_dlpack(jax_array, dtype=dtype)


def to_jax(warp_array):
    """A JAX array over a weft array (through DLPack; see this module's docstring)."""
    from ..array import array  # noqa: PLC0415

    if not isinstance(warp_array, array):
        raise TypeError(f"wp.to_jax expects a weft array, got {type(warp_array).__name__}")
    jax = _jax()
    try:
        return jax.dlpack.from_dlpack(warp_array)
    except TypeError:                   # older JAX: capsules only
        return jax.dlpack.from_dlpack(dlpack.to_dlpack(warp_array))
