"""`warp._src.jax.ffi`: weft's jax_kernel and jax_callable under Warp's private path, and
register_ffi_callback, which weft cannot offer (see the function)."""
from __future__ import annotations

from ...interop.jax_ffi import (_FFI_CALLABLE_REGISTRY, _FFI_KERNEL_REGISTRY,  # noqa: F401
                                _FFI_REGISTRY_LOCK, JAX_CALLABLE_DEFAULT_GRAPH_CACHE_MAX, FfiCallable,
                                FfiKernel, JaxCallableGraphMode, JaxModulePreloadMode,
                                clear_jax_callable_graph_cache, jax_callable, jax_kernel)


def register_ffi_callback(name, func, graph_compatible=True):
    """Warp registers `func` as an XLA FFI target of the CUDA platform, called with JAX's device
    buffers in this process. weft's kernels run in the daemon, and JAX's CUDA buffers would have
    to be shared with it by CUDA IPC from inside XLA's call, which is not built."""
    raise NotImplementedError("register_ffi_callback: XLA FFI callbacks on JAX's CUDA buffers are not "
                              "available in weft (kernels run in the daemon); use jax_kernel or "
                              "jax_callable, which run on the CPU")
