"""weft.jax_experimental: weft kernels inside jax.jit and XLA FFI callbacks (Warp's
warp.jax_experimental names).
See weft/interop/jax_ffi.py for what they do and their limits."""
from ..interop.jax_ffi import (JaxCallableGraphMode, JaxModulePreloadMode,  # noqa: F401
                               clear_jax_callable_graph_cache, jax_callable, jax_kernel)
from ..interop.xla_ffi import register_ffi_callback  # noqa: F401

__all__ = ["jax_kernel", "jax_callable", "clear_jax_callable_graph_cache", "JaxCallableGraphMode",
           "JaxModulePreloadMode", "register_ffi_callback"]
