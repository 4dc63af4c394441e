"""jax_kernel and jax_callable: weft kernels and Python functions that launch them, callable
inside jax.jit, jax.vmap and jax.grad (Warp's wp.jax_kernel / wp.jax_callable).

Each wrapper is an XLA FFI target of this process (weft/interop/xla_ffi.py), registered once
per wrapper for JAX's CUDA and CPU platforms and called through jax.ffi.ffi_call; a call's
static settings (launch dimensions, static scalars, output shapes) are kept by the wrapper and
named by an integer attribute of the call. At run time XLA hands the handler its own buffers:
- On a CUDA device they are XLA's device memory. The handler binds each buffer to a weft
  array on that GPU (imported in place by CUDA IPC where the driver can export XLA's memory,
  else a device-to-device copy, written back after the launch: weft/interop/cuda_import.py),
  orders weftd's session stream after XLA's stream, launches, and orders XLA's stream after
  weftd's work (weft/interop/cuda_order.py). No host copy; no host wait where the memory is
  imported and events or stream memory operations order the streams.
- On the CPU they are host memory of this process: inputs are copied into weftd's memory and
  outputs copied back into XLA's result buffers after the launch (two copies Warp does not
  make: weft's kernels run in another process).
Outputs start zeroed (a kernel that writes only some elements leaves zeros elsewhere);
input-output arrays (`in_out_argnames`) are aliased by XLA to their outputs and updated there.

Conventions are Warp's: a kernel's parameters are its inputs (arrays, and scalars that must be
static in JAX) followed by its outputs; `num_outputs` counts the outputs including the
input-output arrays named by `in_out_argnames` (inputs whose updated values are returned, first
among the outputs). Launch dimensions come from the first array input (less its vector or matrix
dimensions) unless `launch_dims` says otherwise; outputs are shaped like the launch unless
`output_dims` (a shape, or a dict by output name) says otherwise. Under jax.vmap the batch axes
lead every array (ffi_call's `vmap_method`) and the handler runs the kernel once per batch
element. `enable_backward=True` gives the wrapper a JAX VJP: the backward pass (another call
of the same target) records the forward launch on a weft Tape, seeds the outputs' gradients
with JAX's cotangents and writes the inputs' gradients into XLA's result buffers.

Wrappers are cached: the same kernel or function with the same settings gives the same object.
"""
from __future__ import annotations

import collections
import contextlib
import enum
import inspect
import itertools
import operator
import sys
import threading

import numpy as np

from . import external, xla_ffi

JAX_CALLABLE_DEFAULT_GRAPH_CACHE_MAX = 64
_MAX_TID_EXTENT = 2**31 - 1
_VMAP_METHODS = ("broadcast_all", "sequential", "sequential_unrolled", "expand_dims")

_FFI_REGISTRY_LOCK = threading.Lock()
_FFI_KERNEL_REGISTRY: dict = {}
_FFI_CALLABLE_REGISTRY: dict = {}
_TARGET_NUMBERS = itertools.count()
_CALL_ATTR = "weft_call"          # the attribute naming a call's static settings
# Handler executions by platform ("cpu", "cuda"): tests check which path ran.
FFI_CALLS: collections.Counter = collections.Counter()


class JaxCallableGraphMode(enum.IntEnum):
    """Warp's CUDA graph capture modes of jax_callable. On the CPU, NONE and JAX run without a
    graph; the WARP modes need CUDA and are refused at run time on the CPU. On CUDA every mode
    runs the function without a graph: weft records none, and XLA does not capture the call
    (its FFI target advertises no command-buffer trait, weft/interop/xla_ffi.py)."""
    NONE = 0
    JAX = 1
    WARP = 2
    WARP_STAGED = 3
    WARP_STAGED_EX = 4


class JaxModulePreloadMode(enum.IntEnum):
    """Where Warp preloads a wrapper's module. weft compiles in the daemon on first launch and
    caches the result, so every mode behaves as CURRENT_DEVICE."""
    NONE = 0
    CURRENT_DEVICE = 1
    ALL_DEVICES = 2


def _jax():
    import jax  # noqa: PLC0415

    return jax


def _hashable(value):
    if isinstance(value, dict):
        return tuple(sorted((k, _hashable(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(_hashable(v) for v in value)
    return value


def _dims(value) -> tuple:
    return (int(value),) if np.isscalar(value) else tuple(int(d) for d in value)


def _check_block_dim(block_dim):
    if block_dim is None:
        return None
    if isinstance(block_dim, bool):
        raise TypeError("jax_kernel(): block_dim must be an integer or None.")
    try:
        block_dim = operator.index(block_dim)
    except TypeError:
        raise TypeError("jax_kernel(): block_dim must be an integer or None.") from None
    if block_dim <= 0:
        raise ValueError("jax_kernel(): block_dim must be positive.")
    return block_dim


def _check_cpu(what):
    weft = sys.modules["weft"]
    if not weft.is_cpu_available():
        raise RuntimeError(f"{what}: this weft daemon does not include CPU support, which JAX's "
                           f"CPU device needs")


class _Param:
    """One parameter of a wrapped kernel or function: name, weft annotation, array or scalar."""

    def __init__(self, name, annotation):
        from .._kernel import typestr  # noqa: PLC0415
        from .._kernel.launch import _element_dtype  # noqa: PLC0415

        self.name = name
        self.annotation = annotation
        desc = typestr.parse(typestr.type_string(annotation))
        self.is_array = desc.kind == "array"
        if self.is_array:
            self.dtype = _element_dtype(annotation)
            self.inner = tuple(getattr(self.dtype, "_shape_", ()))
            self.np_dtype = np.dtype(self.dtype._wp_scalar_type_._np_dtype_)


class _Wrapper:
    """What jax_kernel and jax_callable share: the parameter split, shapes, vmap and the call."""

    def __init__(self, what, params, num_outputs, vmap_method, output_dims, in_out_argnames):
        self.what = what
        self.params = params
        names = [p.name for p in params]
        self.in_out = list(in_out_argnames or ())
        if len(set(self.in_out)) != len(self.in_out):
            raise ValueError(f"{what}: in_out_argnames must not contain duplicate names")
        num_outputs = int(num_outputs)
        pure_outputs = num_outputs - len(self.in_out)
        if num_outputs < 1 or pure_outputs < 0 or pure_outputs > len(params):
            raise ValueError(f"{what}: {len(params)} parameters cannot have num_outputs={num_outputs} "
                             f"with {len(self.in_out)} input-output argument(s)")
        self.num_inputs = len(params) - pure_outputs
        for name in self.in_out:
            if name not in names:
                raise ValueError(f"{what}: in_out_argnames '{name}' did not match any function argument names")
            if name not in names[:self.num_inputs]:
                raise ValueError(f"{what}: in_out arguments should be placed before output-only arguments "
                                 f"('{name}' comes after them)")
            if not params[names.index(name)].is_array:
                raise TypeError(f"{what}: input-output argument '{name}' is not an array")
        for p in params[self.num_inputs:]:
            if not p.is_array:
                raise TypeError(f"{what}: output '{p.name}' is not an array")
        self.outputs = [p for p in params[:self.num_inputs] if p.name in self.in_out] + params[self.num_inputs:]
        if vmap_method is not None and vmap_method not in _VMAP_METHODS:
            raise ValueError(f"{what}: vmap_method must be one of {', '.join(_VMAP_METHODS)}, got {vmap_method!r}")
        self.vmap_method = vmap_method
        self.output_dims = output_dims
        self.has_side_effect = False
        self._ffi_name = None
        self._calls_lock = threading.Lock()
        self._calls: list = []            # _CallSpec by the index a call names
        self._call_index: dict = {}       # hashable settings -> index

    # ---- tracing ---------------------------------------------------------------------------
    def _split(self, args):
        jax = _jax()
        if len(args) != self.num_inputs:
            raise TypeError(f"{self.what}: expected {self.num_inputs} inputs, got {len(args)}")
        arrays, scalars = [], {}
        for i, value in enumerate(args):
            p = self.params[i]
            if p.is_array:
                if np.dtype(value.dtype) != p.np_dtype:
                    raise TypeError(f"{self.what}: input '{p.name}' has dtype {value.dtype}, "
                                    f"expected {p.np_dtype}")
                arrays.append(i)
            elif isinstance(value, jax.core.Tracer):
                raise TypeError(f"{self.what}: scalar input '{p.name}' is a traced value; make it "
                                f"static (jax.jit(..., static_argnames=...))")
            else:
                scalars[i] = value
        return arrays, scalars

    def _launch_dims(self, args, arrays, launch_dims):
        if launch_dims is None:
            if not arrays:
                raise ValueError(f"{self.what}: launch_dims is required without array inputs")
            i = arrays[0]
            shape = tuple(args[i].shape)
            launch_dims = shape[:len(shape) - len(self.params[i].inner)]
        return _dims(launch_dims)

    def _out_shape(self, p, launch_dims, output_dims, args):
        if p.name in self.in_out:
            return tuple(args[[q.name for q in self.params].index(p.name)].shape)
        dims = output_dims.get(p.name, launch_dims) if isinstance(output_dims, dict) else \
            (output_dims if output_dims is not None else launch_dims)
        dims = _dims(dims)
        if not (p.inner and dims[len(dims) - len(p.inner):] == p.inner and len(dims) > len(p.inner)):
            dims = dims + p.inner   # Warp's shape convention; JAX's (..., 3) also accepted
        return dims

    def _call(self, args, launch_dims, output_dims, vmap_method, run_ffi):
        """The call of the FFI target: run_ffi(spec, inputs by position, outputs, device) per
        batch element."""
        jax = _jax()
        arrays, scalars = self._split(args)
        launch_dims = self._launch_dims(args, arrays, launch_dims)
        specs = [jax.ShapeDtypeStruct(self._out_shape(p, launch_dims, output_dims, args), p.np_dtype)
                 for p in self.outputs]
        method = vmap_method or self.vmap_method or "broadcast_all"
        inputs = [args[i] for i in arrays]
        names = [p.name for p in self.params]
        aliases = {arrays.index(names.index(n)): k for k, n in enumerate(self.in_out)}
        spec = _CallSpec(run_ffi, launch_dims, arrays, [tuple(x.shape) for x in inputs],
                         [np.dtype(x.dtype) for x in inputs], specs, scalars)
        call = jax.ffi.ffi_call(self._target(), tuple(specs), vmap_method=method,
                                input_output_aliases=aliases or None,
                                has_side_effect=self.has_side_effect)
        return _varying_as(inputs, call(*inputs, **{_CALL_ATTR: np.int64(self._remember(spec))}))

    # ---- the FFI target ----------------------------------------------------------------------
    def _target(self) -> str:
        if self._ffi_name is None:
            with _FFI_REGISTRY_LOCK:
                if self._ffi_name is None:
                    kind = "kernel" if isinstance(self, FfiKernel) else "callable"
                    name = f"weft_jax_{kind}_{next(_TARGET_NUMBERS)}"
                    xla_ffi.register_target(name, self._execute)
                    self._ffi_name = name
        return self._ffi_name

    def _remember(self, spec) -> int:
        """The index of a call's static settings (the same settings: the same index)."""
        key = spec.key()
        with self._calls_lock:
            if key is not None and key in self._call_index:
                return self._call_index[key]
            self._calls.append(spec)
            index = len(self._calls) - 1
            if key is not None:
                self._call_index[key] = index
            return index

    def _execute(self, inputs, outputs, attrs, ctx):
        """The handler: checks the buffers against the call's settings, then runs the kernel
        (or function) once per element of the leading batch axes jax.vmap added."""
        FFI_CALLS[ctx.platform] += 1
        index = attrs.get(_CALL_ATTR)
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(self._calls):
            raise xla_ffi.FfiError(f"{self.what}: the call names no settings of this wrapper "
                                   f"({_CALL_ATTR}={index!r})")
        spec = self._calls[index]
        if len(inputs) != len(spec.positions) or len(outputs) != len(spec.specs):
            raise xla_ffi.FfiError(f"{self.what}: {len(inputs)} input and {len(outputs)} output buffers, "
                                   f"expected {len(spec.positions)} and {len(spec.specs)}")
        batch = None
        for k, (buf, s) in enumerate(zip(outputs, spec.specs)):
            lead = _check_buffer(buf, tuple(s.shape), np.dtype(s.dtype), f"{self.what} output {k}")
            if batch is None:
                batch = buf.shape[:lead]
            elif buf.shape[:lead] != batch:
                raise xla_ffi.FfiError(f"{self.what}: outputs with different batch shapes "
                                       f"{batch} and {buf.shape[:lead]}")
        leads = []
        for k, (buf, shape, dtype) in enumerate(zip(inputs, spec.shapes, spec.dtypes)):
            lead = _check_buffer(buf, shape, dtype, f"{self.what} input {k}")
            if lead > len(batch) or any(n not in (1, m) for n, m in
                                        zip(buf.shape[:lead], batch[len(batch) - lead:])):
                raise xla_ffi.FfiError(f"{self.what}: input {k} of shape {buf.shape} does not "
                                       f"broadcast to the batch shape {batch}")
            leads.append(lead)
        if ctx.platform == "cpu":
            _check_cpu(self.what)
            device = "cpu"
        else:
            device = f"cuda:{ctx.device_ordinal or 0}"
        with _ordered_with_xla(ctx):
            for idx in np.ndindex(*batch):
                item = {}
                for pos, buf, lead in zip(spec.positions, inputs, leads):
                    item[pos] = buf.element(tuple(0 if buf.shape[k] == 1 else idx[len(batch) - lead + k]
                                                  for k in range(lead))) if lead else buf
                outs = [o.element(idx) if batch else o for o in outputs]
                spec.run(spec, item, outs, device)

    def _bind(self, bound, spec, buffers, outs):
        """(inputs, outputs) of one call as weft arrays over XLA's buffers (in-out arrays: their
        aliased output buffers; outputs zeroed) and the call's static scalars."""
        values = [None] * self.num_inputs
        for i, v in spec.scalars.items():
            values[i] = v
        by_name = dict(zip([p.name for p in self.outputs], outs))
        for i, buf in buffers.items():
            p = self.params[i]
            values[i] = bound.array(by_name.get(p.name, buf), p.dtype, p.name)
        results = [bound.array(buf, p.dtype, p.name, zero=True)
                   for p, buf in zip(self.params[self.num_inputs:], outs[len(self.in_out):])]
        return values, results

class _CallSpec:
    """The static settings of one traced call: the runner, launch dims, the array inputs'
    positions, shapes and dtypes, the output specs and the static scalars."""

    __slots__ = ("run", "launch_dims", "positions", "shapes", "dtypes", "specs", "scalars")

    def __init__(self, run, launch_dims, positions, shapes, dtypes, specs, scalars):
        self.run = run
        self.launch_dims = tuple(launch_dims)
        self.positions = list(positions)
        self.shapes = list(shapes)
        self.dtypes = list(dtypes)
        self.specs = list(specs)
        self.scalars = dict(scalars)

    def key(self):
        key = (self.run, self.launch_dims, tuple(self.positions), tuple(self.shapes),
               tuple(self.dtypes), tuple((tuple(s.shape), np.dtype(s.dtype)) for s in self.specs),
               tuple(sorted((i, type(v).__name__, _hashable(v)) for i, v in self.scalars.items())))
        try:
            hash(key)
        except TypeError:
            return None
        return key


def _check_buffer(buf, shape: tuple, dtype, what: str) -> int:
    """How many leading batch axes `buf` has over the traced `shape` (its trailing axes must
    be that shape, its dtype the traced one)."""
    if buf.dtype != dtype:
        raise xla_ffi.FfiError(f"{what}: dtype {buf.dtype}, expected {dtype}")
    lead = buf.ndim - len(shape)
    if lead < 0 or buf.shape[lead:] != tuple(shape):
        raise xla_ffi.FfiError(f"{what}: shape {buf.shape}, expected {tuple(shape)} (after any "
                               f"batch axes)")
    return lead


@contextlib.contextmanager
def _ordered_with_xla(ctx):
    """On CUDA: weftd's work queued inside comes after XLA's work queued on its stream before
    the call, and XLA's later work on that stream after it; XLA's stream is the framework
    stream of weft's launches meanwhile. By events or stream memory operations (no host
    wait), else by host waits where the session cannot order streams."""
    if ctx.platform != "cuda" or not ctx.stream:
        yield
        return
    from .. import _cuda_ipc, _runtime  # noqa: PLC0415
    from . import cuda_order  # noqa: PLC0415

    rt = _runtime.get_runtime()
    ordinal = int(ctx.device_ordinal or 0)
    with xla_ffi.cuda_scope(ctx):
        ordered = cuda_order.enabled(rt, {ordinal})
        if ordered:
            cuda_order.before(rt, (ordinal,), ctx.stream)
        else:
            _cuda_ipc.synchronize_stream(ordinal, ctx.stream)
        try:
            yield
        finally:
            if ordered:
                cuda_order.after(rt, (ordinal,), [ctx.stream])
            else:
                rt.synchronize()


class _Bound:
    """XLA buffers bound to weft arrays for one run, and what goes back afterwards."""

    def __init__(self, device, what):
        self.device = device
        self.what = what
        self.pending = []

    def array(self, buf, dtype, name, zero=False):
        """A weft array of `dtype` over `buf` (its memory where weft can use it in place, else a
        copy that finish() writes back into a result buffer)."""
        weft = sys.modules["weft"]
        what = f"{self.what} '{name}'"
        if buf.size == 0:
            wdtype, shape, _ = external.resolve_parts(buf.dtype, buf.shape, buf.strides, dtype, what)
            return weft.zeros(shape, dtype=wdtype, device=self.device)
        if zero and buf.platform == "cpu":
            view = buf.numpy()          # a new zeroed weft array, copied into the result after
            wdtype, shape, _ = external.resolve_layout(view, dtype, what)
            temp = weft.zeros(shape, dtype=wdtype, device=self.device)
            self.pending.append((view, temp))
            return temp
        temp, back = external.launch_array(buf, dtype, self.device, what)
        if zero:
            temp.zero_()
        if back is not None and buf.writable:
            self.pending.append((back, temp))
        return temp

    def finish(self):
        if not self.pending:
            return
        from .. import _runtime  # noqa: PLC0415

        _runtime.get_runtime().synchronize()
        for back, temp in self.pending:
            if hasattr(back, "apply"):
                back.apply()            # a CUDA copy (cuda_import.CopyBack)
            else:
                data = np.asarray(temp.numpy())
                np.copyto(back, data.reshape(back.shape).astype(back.dtype, copy=False))
        self.pending = []


class FfiKernel(_Wrapper):
    """wp.jax_kernel's wrapper of a kernel."""

    def __init__(self, kernel, num_outputs, vmap_method, launch_dims, output_dims, in_out_argnames,
                 enable_backward, block_dim):
        params = [_Param(n, kernel.definition.annotations[n]) for n in kernel.param_names]
        super().__init__(f"jax_kernel {kernel.key}", params, num_outputs, vmap_method, output_dims,
                         in_out_argnames)
        self.kernel = kernel
        self.launch_dims = launch_dims
        self.enable_backward = enable_backward
        self.block_dim = block_dim
        if enable_backward and (output_dims is not None or self.in_out):
            raise NotImplementedError(f"{self.what}: output_dims and in_out_argnames are not supported "
                                      f"with enable_backward=True")

    def _check_extents(self, launch_dims):
        for k, extent in enumerate(launch_dims):
            if extent > _MAX_TID_EXTENT:
                raise ValueError(f"Warp cannot launch a kernel using wp.tid() with extent {extent} in "
                                 f"dimension {k}; the largest extent is {_MAX_TID_EXTENT}")

    def __call__(self, *args, launch_dims=None, output_dims=None, vmap_method=None):
        if self.enable_backward:
            if launch_dims is not None:
                raise TypeError(f"{self.what}: launch_dims cannot be overridden per-call with enable_backward=True")
            if output_dims is not None:
                raise TypeError(f"{self.what}: output_dims is not supported with enable_backward=True")
            if vmap_method is not None:
                raise TypeError(f"{self.what}: vmap_method cannot be overridden per-call with enable_backward=True")
            return self._differentiable(args)
        launch = launch_dims if launch_dims is not None else self.launch_dims
        arrays, _ = self._split(args)
        self._check_extents(self._launch_dims(args, arrays, launch))
        return self._call(args, launch, output_dims if output_dims is not None else self.output_dims,
                          vmap_method, self._run_ffi)

    def _run_ffi(self, spec, buffers, outs, device):
        """One forward launch on XLA's buffers (in-out arrays: their aliased output buffers)."""
        bound = _Bound(device, self.what)
        values, results = self._bind(bound, spec, buffers, outs)
        sys.modules["weft"].launch(self.kernel, dim=spec.launch_dims, inputs=values, outputs=results,
                                   device=device, block_dim=self.block_dim)
        bound.finish()

    def _run_backward_ffi(self, spec, buffers, outs, device):
        """The backward pass on XLA's buffers: the forward inputs and the cotangents in, the
        inputs' gradients out."""
        weft = sys.modules["weft"]
        bound = _Bound(device, self.what)
        values = [None] * self.num_inputs
        for i, v in spec.scalars.items():
            values[i] = v
        forward = sorted(i for i in buffers if i < self.num_inputs)
        for i in forward:
            p = self.params[i]
            values[i] = weft.clone(bound.array(buffers[i], p.dtype, p.name), requires_grad=True)
        grads, results = {}, []
        for k, p in enumerate(self.params[self.num_inputs:]):
            g = bound.array(buffers[self.num_inputs + k], p.dtype, f"{p.name} (cotangent)")
            o = weft.zeros(g.shape, dtype=p.dtype, device=device, requires_grad=True)
            results.append(o)
            grads[o] = g
        tape = weft.Tape()
        with tape:
            weft.launch(self.kernel, dim=spec.launch_dims, inputs=values, outputs=results, device=device,
                        block_dim=self.block_dim)
        tape.backward(grads=grads)
        for i, buf in zip(forward, outs):
            p = self.params[i]
            weft.copy(bound.array(buf, p.dtype, f"{p.name} (gradient)", zero=True), values[i].grad)
        bound.finish()

    def _differentiable(self, args):
        jax = _jax()
        arrays, scalars = self._split(args)
        launch_dims = self._launch_dims(args, arrays, self.launch_dims)
        self._check_extents(launch_dims)
        positions = list(arrays)
        nout = len(self.outputs)

        # outputs are shaped like the first array input (less its vector/matrix dimensions), which
        # is the launch unless launch_dims fixes a smaller one (Warp's differentiable wrapper)
        first = self.params[positions[0]] if positions else None
        out_dims = None if first is None else \
            tuple(args[positions[0]].shape[:len(args[positions[0]].shape) - len(first.inner)])

        def forward(*xs):
            full = list(args)
            for i, x in zip(positions, xs):
                full[i] = x
            return self._call(full, launch_dims, out_dims, None, self._run_ffi)

        @jax.custom_vjp
        def apply(*xs):
            return forward(*xs)

        def apply_fwd(*xs):
            return forward(*xs), xs

        def apply_bwd(xs, cotangents):
            grad_specs = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in xs]
            operands = [*xs, *cotangents]
            where = positions + [self.num_inputs + k for k in range(nout)]
            spec = _CallSpec(self._run_backward_ffi, launch_dims, where,
                             [tuple(x.shape) for x in operands], [np.dtype(x.dtype) for x in operands],
                             grad_specs, scalars)
            call = jax.ffi.ffi_call(self._target(), tuple(grad_specs), vmap_method="broadcast_all")
            return _varying_as(operands, call(*operands, **{_CALL_ATTR: np.int64(self._remember(spec))}))

        apply.defvjp(apply_fwd, apply_bwd)
        return tuple(apply(*[args[i] for i in positions]))


def _varying_as(inputs, outputs) -> tuple:
    """The call's outputs, varying over every manual mesh axis an input varies over (inside
    jax.shard_map with check_vma; ffi_call's outputs are not in the JAX versions tested): without it a lax.scan carry through the call changes type."""
    jax = _jax()
    if not (hasattr(jax, "typeof") and hasattr(jax.lax, "pcast")):     # JAX before varying axes
        return tuple(outputs)

    def varying(x) -> set:
        return set(getattr(getattr(jax.typeof(x), "manual_axis_type", None), "varying", ()) or ())

    axes = set().union(*(varying(x) for x in inputs))
    out = []
    for y in outputs:
        missing = tuple(sorted(axes - varying(y)))
        out.append(jax.lax.pcast(y, missing, to="varying") if missing else y)
    return tuple(out)


class FfiCallable(_Wrapper):
    """wp.jax_callable's wrapper of a Python function that launches weft kernels."""

    def __init__(self, func, num_outputs, graph_mode, vmap_method, output_dims, in_out_argnames,
                 stage_in_argnames=None, stage_out_argnames=None):
        sig = inspect.signature(func)
        annotations = getattr(func, "__annotations__", {})
        params = []
        for name in sig.parameters:
            if name not in annotations:
                raise TypeError(f"jax_callable {func.__name__}: parameter '{name}' needs a type annotation")
            params.append(_Param(name, annotations[name]))
        super().__init__(f"jax_callable {func.__name__}", params, num_outputs, vmap_method, output_dims,
                         in_out_argnames)
        self.func = func
        self.graph_mode = JaxCallableGraphMode(graph_mode)
        self.stage_in_argnames = set(stage_in_argnames or ())
        self.stage_out_argnames = set(stage_out_argnames or ())

    def __call__(self, *args, output_dims=None, vmap_method=None):
        return self._call(args, None, output_dims if output_dims is not None else self.output_dims,
                          vmap_method, self._run_ffi)

    def _run_ffi(self, spec, buffers, outs, device):
        """The function on weft arrays bound to XLA's buffers (in-out arrays: their aliased
        output buffers). Graph modes: weft records no CUDA graph of the function (XLA does not
        capture the call either); on the CPU the WARP modes are refused, as in Warp."""
        if device == "cpu" and self.graph_mode not in (JaxCallableGraphMode.NONE, JaxCallableGraphMode.JAX):
            raise RuntimeError(f"{self.what}: graph mode {self.graph_mode.name} captures a CUDA graph and "
                               f"is not available on the CPU")
        bound = _Bound(device, self.what)
        values, results = self._bind(bound, spec, buffers, outs)
        self.func(*values, *results)
        bound.finish()


def jax_kernel(kernel, num_outputs=1, vmap_method="broadcast_all", launch_dims=None, output_dims=None,
               in_out_argnames=None, module_preload_mode=JaxModulePreloadMode.CURRENT_DEVICE,
               enable_backward=False, has_side_effect=False, block_dim=None):
    """A JAX-callable wrapper of a weft kernel (see this module's docstring)."""
    block_dim = _check_block_dim(block_dim)
    JaxModulePreloadMode(module_preload_mode)
    key = (kernel, int(num_outputs), vmap_method, _hashable(launch_dims), _hashable(output_dims),
           tuple(in_out_argnames or ()), bool(enable_backward), bool(has_side_effect), block_dim)
    with _FFI_REGISTRY_LOCK:
        found = _FFI_KERNEL_REGISTRY.get(key)
        if found is None:
            found = FfiKernel(kernel, num_outputs, vmap_method, launch_dims, output_dims, in_out_argnames,
                              bool(enable_backward), block_dim)
            found.has_side_effect = bool(has_side_effect)
            _FFI_KERNEL_REGISTRY[key] = found
    return found


def jax_callable(func, num_outputs=1, graph_mode=JaxCallableGraphMode.JAX, vmap_method="broadcast_all",
                 output_dims=None, in_out_argnames=None, stage_in_argnames=None, stage_out_argnames=None,
                 graph_cache_max=JAX_CALLABLE_DEFAULT_GRAPH_CACHE_MAX,
                 module_preload_mode=JaxModulePreloadMode.CURRENT_DEVICE, has_side_effect=False):
    """A JAX-callable wrapper of a Python function that launches weft kernels on its array
    arguments (see this module's docstring). Staging and graph caching are CUDA graph
    features; weft records no graph of the function, so they change nothing."""
    JaxModulePreloadMode(module_preload_mode)
    key = (func, int(num_outputs), int(graph_mode), vmap_method, _hashable(output_dims),
           tuple(in_out_argnames or ()), tuple(stage_in_argnames or ()), tuple(stage_out_argnames or ()),
           bool(has_side_effect))
    with _FFI_REGISTRY_LOCK:
        found = _FFI_CALLABLE_REGISTRY.get(key)
        if found is None:
            found = FfiCallable(func, num_outputs, graph_mode, vmap_method, output_dims, in_out_argnames,
                                stage_in_argnames, stage_out_argnames)
            found.has_side_effect = bool(has_side_effect)
            _FFI_CALLABLE_REGISTRY[key] = found
    return found


def clear_jax_callable_graph_cache(callable=None):  # noqa: A002 - Warp's name
    """Warp drops the CUDA graphs a jax_callable captured; weft captures none."""
