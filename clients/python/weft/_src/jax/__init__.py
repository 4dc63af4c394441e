"""`warp._src.jax`: the current JAX device, and weft's JAX helpers under Warp's private path."""
from __future__ import annotations

from ...interop.jax import (device_from_jax, device_to_jax, dtype_from_jax,  # noqa: F401
                            dtype_to_jax, from_jax, to_jax)


def get_jax_device():
    """The JAX device work goes to now: jax.default_device's when one is set, else JAX's first."""
    import jax  # noqa: PLC0415

    device = jax.config.jax_default_device
    if device is None:
        device = jax.local_devices()[0]
    elif isinstance(device, str):   # jax.default_device("cpu"): the platform's first device
        device = jax.local_devices(backend=device)[0]
    return device
