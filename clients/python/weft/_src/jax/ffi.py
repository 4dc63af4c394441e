"""`warp._src.jax.ffi`: weft's jax_kernel, jax_callable and register_ffi_callback under Warp's
private path (weft/interop/jax_ffi.py, weft/interop/xla_ffi.py)."""
from __future__ import annotations

from ...interop.jax_ffi import (_FFI_CALLABLE_REGISTRY, _FFI_KERNEL_REGISTRY,  # noqa: F401
                                _FFI_REGISTRY_LOCK, JAX_CALLABLE_DEFAULT_GRAPH_CACHE_MAX, FfiCallable,
                                FfiKernel, JaxCallableGraphMode, JaxModulePreloadMode,
                                clear_jax_callable_graph_cache, jax_callable, jax_kernel)
from ...interop.xla_ffi import ExecutionContext, FfiBuffer, register_ffi_callback  # noqa: F401
