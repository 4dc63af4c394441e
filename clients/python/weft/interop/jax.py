"""JAX interop: wp.from_jax / wp.to_jax, device and dtype helpers, and jax_kernel.

Both directions go through DLPack. to_jax of a local CPU weft array gives a JAX array over the
weft slab when JAX accepts the memory as it is (JAX may copy when it requires an alignment
the memory lacks); pending weft commands are finished first. from_jax of a JAX array whose
buffer is a weft slab (made by to_jax) is zero-copy; any other JAX CPU array lives in this
process and is copied into a new weft array (JAX arrays are immutable, so the copy is never
stale).

jax_kernel (weft.jax_experimental.jax_kernel) makes a weft kernel callable inside jax.jit on
the CPU through jax.pure_callback: JAX hands the inputs to the host callback, which copies them
into weft arrays, launches the kernel in the daemon and returns the outputs as NumPy arrays for
JAX. That is two copies per call that Warp's in-process GPU path does not make, and there is no
automatic differentiation through it; GPU arrays would need an XLA FFI handler in this process
that imports JAX's device buffers by CUDA IPC, which is not built.
"""
from __future__ import annotations

import sys

import numpy as np

from . import dlpack, external


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
    """The JAX device of a weft device."""
    from ..device import get_device  # noqa: PLC0415

    device = get_device(device)
    jax = _jax()
    if device.is_cpu:
        return jax.devices("cpu")[0]
    if device.is_cuda:
        for d in jax.devices("gpu"):
            if getattr(d, "local_hardware_id", d.id) == device.ordinal:
                return d
    raise RuntimeError(f"weft device {device} has no JAX device")


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


def jax_kernel(kernel, num_outputs=1, vmap_method="broadcast_all", launch_dims=None,
               output_dims=None, **kwargs):
    """A JAX-callable (inside jax.jit) wrapper of a weft kernel, with Warp's conventions: the
    first len(params) - num_outputs parameters are inputs (arrays, or scalars that must be
    static in JAX), the rest are output arrays. Launch dimensions come from the first input
    array's shape (less vector/matrix dimensions) unless launch_dims is given; outputs are
    shaped like the launch unless output_dims (a shape, or a dict by output name) says
    otherwise. Returns a tuple of the outputs. CPU only (see this module's docstring)."""
    if kwargs.get("enable_backward"):
        raise NotImplementedError("jax_kernel(enable_backward=True): weft's jax_kernel runs "
                                  "through jax.pure_callback, which has no differentiation rule")
    return _JaxKernel(kernel, num_outputs, vmap_method, launch_dims, output_dims)


class _JaxKernel:
    def __init__(self, kernel, num_outputs, vmap_method, launch_dims, output_dims):
        from .._kernel import typestr  # noqa: PLC0415

        self.kernel = kernel
        self.num_outputs = int(num_outputs)
        names = list(kernel.param_names)
        if self.num_outputs < 1 or self.num_outputs > len(names):
            raise ValueError(f"jax_kernel: {kernel.key} has {len(names)} parameters; "
                             f"num_outputs={num_outputs} is not possible")
        self.descs = [typestr.parse(t) for t in kernel.param_types]
        self.names = names
        self.num_inputs = len(names) - self.num_outputs
        for name, desc in zip(names[self.num_inputs:], self.descs[self.num_inputs:]):
            if desc.kind != "array":
                raise TypeError(f"jax_kernel: output '{name}' of {kernel.key} is not an array")
        self.vmap_method = vmap_method
        self.launch_dims = launch_dims
        self.output_dims = output_dims

    def _elem_dtype(self, i):
        from .._kernel.launch import _element_dtype  # noqa: PLC0415

        return _element_dtype(self.kernel.definition.annotations[self.names[i]])

    def _inner(self, i) -> tuple:
        return tuple(getattr(self._elem_dtype(i), "_shape_", ()))

    def __call__(self, *args, launch_dims=None, output_dims=None, vmap_method=None):
        jax = _jax()
        if len(args) != self.num_inputs:
            raise TypeError(f"jax_kernel {self.kernel.key}: expected {self.num_inputs} "
                            f"inputs, got {len(args)}")
        launch_dims = launch_dims if launch_dims is not None else self.launch_dims
        output_dims = output_dims if output_dims is not None else self.output_dims
        arrays, scalars = [], {}
        for i, value in enumerate(args):
            if self.descs[i].kind == "array":
                want = np.dtype(self._elem_dtype(i)._wp_scalar_type_._np_dtype_)
                if np.dtype(value.dtype) != want:
                    raise TypeError(f"jax_kernel {self.kernel.key}: input '{self.names[i]}' "
                                    f"has dtype {value.dtype}, the kernel expects {want}")
                arrays.append((i, value))
            elif isinstance(value, jax.core.Tracer):
                raise TypeError(f"jax_kernel {self.kernel.key}: scalar input "
                                f"'{self.names[i]}' is a traced value; make it static "
                                f"(jax.jit(..., static_argnames=...))")
            else:
                scalars[i] = value
        if launch_dims is None:
            if not arrays:
                raise ValueError(f"jax_kernel {self.kernel.key}: launch_dims is required for "
                                 f"kernels without array inputs")
            i, first = arrays[0]
            k = len(self._inner(i))
            launch_dims = tuple(first.shape[:len(first.shape) - k])
        launch_dims = (int(launch_dims),) if np.isscalar(launch_dims) else \
            tuple(int(d) for d in launch_dims)
        out_specs = []
        for k in range(self.num_outputs):
            i = self.num_inputs + k
            dims = output_dims.get(self.names[i], launch_dims) if isinstance(output_dims, dict) \
                else (output_dims if output_dims is not None else launch_dims)
            dims = (int(dims),) if np.isscalar(dims) else tuple(int(d) for d in dims)
            inner = self._inner(i)
            if not (inner and dims[len(dims) - len(inner):] == inner and
                    len(dims) > len(inner)):
                dims = dims + inner     # Warp's shape convention; JAX's (..., 3) also accepted
            np_dtype = np.dtype(self._elem_dtype(i)._wp_scalar_type_._np_dtype_)
            out_specs.append(jax.ShapeDtypeStruct(dims, np_dtype))

        def host(*host_arrays):
            return self._run(launch_dims, out_specs, [i for i, _ in arrays], host_arrays,
                             scalars)

        method = vmap_method or self.vmap_method
        try:
            result = jax.pure_callback(host, tuple(out_specs), *[a for _, a in arrays],
                                       vmap_method=method)
        except TypeError:               # JAX without vmap_method
            result = jax.pure_callback(host, tuple(out_specs), *[a for _, a in arrays])
        return tuple(result)

    def _run(self, launch_dims, out_specs, array_positions, host_arrays, scalars):
        array_mod = sys.modules["weft.array"]  # the module (weft.array is the class)
        from .._kernel.launch import launch  # noqa: PLC0415

        inputs = [None] * self.num_inputs
        for i, value in scalars.items():
            inputs[i] = value
        for i, value in zip(array_positions, host_arrays):
            view = np.ascontiguousarray(np.asarray(value))
            inputs[i], _ = external.weft_array(view, dtype=self._elem_dtype(i), device="cpu",
                                               what=f"jax_kernel input '{self.names[i]}'")
        outputs = []
        for k, spec in enumerate(out_specs):
            i = self.num_inputs + k
            inner = len(self._inner(i))
            shape = spec.shape[:len(spec.shape) - inner] if inner else spec.shape
            outputs.append(array_mod.zeros(shape, dtype=self._elem_dtype(i), device="cpu"))
        launch(self.kernel, dim=launch_dims, inputs=inputs, outputs=outputs, device="cpu")
        return tuple(np.array(o.numpy(), copy=True).reshape(spec.shape)
                     for o, spec in zip(outputs, out_specs))
