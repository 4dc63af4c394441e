"""weft.jax_experimental: weft kernels inside jax.jit (Warp's warp.jax_experimental name).
See weft.interop.jax.jax_kernel for what it does and its limits."""
from .interop.jax import jax_kernel  # noqa: F401

__all__ = ["jax_kernel"]
