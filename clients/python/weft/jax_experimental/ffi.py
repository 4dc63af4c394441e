"""weft.jax_experimental.ffi: Warp's module of the same name (jax_kernel, jax_callable,
register_ffi_callback)."""
from ..interop.jax_ffi import (JaxCallableGraphMode, JaxModulePreloadMode,  # noqa: F401
                               clear_jax_callable_graph_cache, jax_callable, jax_kernel)
from .._src.jax.ffi import register_ffi_callback  # noqa: F401
from ..interop.xla_ffi import ExecutionContext, FfiBuffer  # noqa: F401
