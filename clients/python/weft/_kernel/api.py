"""Public names of the kernel API, re-exported by weft/__init__.py: the decorators
(@kernel, @func, @struct, overload), constant, launch, compile/load_module, Tape and the
module options."""
from __future__ import annotations

import inspect
import sys
import types
import typing
import weakref

from . import cuda_compile
from . import module as module_mod
from .module import Module
from . import typestr
from .errors import (
    WarpCodegenAttributeError,
    WarpCodegenError,
    WarpCodegenIndexError,
    WarpCodegenKeyError,
    WarpCodegenTypeError,
    WarpCodegenValueError,
    WeftCompileError,
    WeftLaunchError,
)
from .functions import (Function, FunctionDefinition, Kernel, NativeSnippet, attach_gradient, attach_replay,
                        static)
from .launch import Launch, launch, launch_tiled
from .structs import StructInstance, StructType, struct
from .tape import Tape

__all__ = [
    "func_replay",
    "Module",
    "Function",
    "Kernel",
    "Launch",
    "Tape",
    "WarpCodegenAttributeError",
    "WarpCodegenError",
    "WarpCodegenIndexError",
    "WarpCodegenKeyError",
    "WarpCodegenTypeError",
    "WarpCodegenValueError",
    "WeftCompileError",
    "WeftLaunchError",
    "compile",
    "compile_aot_module",
    "constant",
    "func",
    "func_native",
    "func_grad",
    "get_module",
    "get_module_options",
    "kernel",
    "launch",
    "launch_tiled",
    "load_module",
    "overload",
    "set_module_options",
    "static",
    "struct",
]


# module="unique" kernels by what they were declared from (_unique_declaration): declaring the
# same code again with the same captured values gives the same kernel, as in Warp, while it lives.
_UNIQUE_KERNELS = weakref.WeakValueDictionary()


def _stable_value(v) -> bool:
    """A value that a kernel declaration may be keyed by: immutable data (held in the key, so it
    is compared by value and never outlived), or a module, class or function (by identity)."""
    if v is None or isinstance(v, (bool, int, float, complex, str, bytes, types.ModuleType, type,
                                   types.FunctionType, types.BuiltinFunctionType, Function, Kernel)):
        return True
    return isinstance(v, tuple) and all(_stable_value(x) for x in v)


def _unique_declaration(function, name, opts):
    """The key of a module="unique" declaration: the code object (by identity: code compiled
    from other text can compare equal), the annotations, the key name, the options and the
    values of the closure cells and of the globals the code names; None (no reuse) when one of
    them is mutable or unhashable, whose value could change what the kernel is."""
    code = function.__code__
    if function.__defaults__ or function.__kwdefaults__:
        return None
    captured = [(id(code), code)]
    for arg, annotation in function.__annotations__.items():
        if type(annotation).__name__ == "array" and type(annotation).__module__.startswith("weft"):
            # wp.array(dtype=T, ndim=N) written as a type: a new object per declaration
            annotation = ("array", annotation.dtype, annotation.ndim)
        captured.append((arg, annotation))
    for cell in function.__closure__ or ():
        try:
            value = cell.cell_contents
        except ValueError:          # a cell not assigned yet
            return None
        if not _stable_value(value):
            return None
        captured.append((type(value), value))
    for global_name in code.co_names:
        if global_name in function.__globals__:
            value = function.__globals__[global_name]
            if not _stable_value(value):
                return None
            captured.append((global_name, type(value), value))
    try:
        key = (code, name, tuple(sorted(opts.items())), tuple(captured))
        hash(key)
    except TypeError:
        return None
    return key


def kernel(f=None, *, enable_backward: typing.Optional[bool] = None, module=None, name=None, **options):
    """@wp.kernel or @wp.kernel(enable_backward=..., module="unique"|name, name=key): declares a
    kernel of its Python module (or of the named module), named `name` when given (Warp's
    kernel key; several kernels may then come from one function). A module="unique" kernel
    declared again from the same code with the same captured values is the same kernel."""

    def wrap(function):
        opts = dict(options)
        if enable_backward is not None:
            opts["enable_backward"] = bool(enable_backward)
        target = None
        if module == "unique":
            opts["module"] = "unique"
            declared = _unique_declaration(function, name, opts)
            earlier = _UNIQUE_KERNELS.get(declared) if declared is not None else None
            if earlier is not None and not earlier.broken:
                return earlier
            made = Kernel(func=function, key=name, module=target, options=opts)
            if declared is not None:
                _UNIQUE_KERNELS[declared] = made
            return made
        if module:
            target = module
        return Kernel(func=function, key=name, module=target, options=opts)

    if f is not None:
        return wrap(f)
    return wrap


def func(f=None, **_options):
    """@wp.func: a function callable from kernels; defining the same name again with other
    annotation types adds an overload; typing.Any parameters make it generic."""

    def wrap(function):
        return module_mod.register_function(FunctionDefinition(function, is_kernel=False))

    if f is not None:
        return wrap(f)
    return wrap


def func_native(snippet=None, adj_snippet=None, replay_snippet=None):
    """Warp's @wp.func_native (a function body written in C++/CUDA). weft does not compile
    native snippets: the daemon compiles only the kernel language, so client C++ never reaches
    its compiler (docs/security.md). The decorated function becomes a NativeSnippet: a kernel
    that calls it (directly or through @wp.func) fails to build with WeftCompileError naming
    both places; the module's other kernels build and run."""

    def wrap(function):
        return NativeSnippet(function)

    return wrap


def func_grad(forward):
    """@wp.func_grad(f): the decorated function is the gradient of @wp.func `f` (the overload
    whose parameter types it starts with). It takes f's parameters, then the adjoints of f's
    return values, and adds to `wp.adjoint[param]`; f's backward pass calls it instead of
    differentiating f's body."""

    def wrap(function):
        gradient = attach_gradient(forward, FunctionDefinition(function, is_kernel=False))
        module_mod.bump_version()
        return gradient

    return wrap


def func_replay(forward):
    """@wp.func_replay(f): Warp's custom replay of @wp.func `f`: a caller's backward pass runs
    it, with f's parameters, to recompute f's results instead of replaying f's body (which skips
    f's side effects; a func whose result depends on them, such as an atomic counter, records
    what it needs and the replay function reads it back). It is attached to every overload of
    `f` with its parameter types."""

    def wrap(function):
        attach_replay(forward, FunctionDefinition(function, is_kernel=False))
        module_mod.bump_version()
        return forward

    return wrap


def overload(target, arg_types=None):
    """wp.overload: Warp's explicit instantiation of a generic kernel or func. The daemon
    instantiates generics per argument types, so this records the concrete signature as an
    overload when given a def with annotations, and otherwise returns the target."""
    if isinstance(target, Kernel):
        if arg_types is None:
            return target
        if isinstance(arg_types, dict):
            arg_types = [arg_types.get(n, a) for n, a in
                         zip(target.param_names, target.definition.annotations.values())]
        try:
            type_strings = [typestr.type_string(t) for t in arg_types]
        except typestr.FabricArrayRefused:
            # no instance over Fabric arrays: they cannot be made in weft (weft/fabricarray.py),
            # and a kernel declared with them reports the refusal when it is built
            return target
        return target.specialize(type_strings, list(arg_types))
    if isinstance(target, Function):
        return target
    if callable(target):
        stubbed = _generic_kernel_of_stub(target)
        if stubbed is not None:
            # decorator form on a stub def named as a generic kernel: that kernel's instance for
            # the stub's annotations; the kernel itself is returned (Warp's behaviour)
            try:
                annotations = dict(inspect.get_annotations(target, eval_str=True))
            except Exception:  # noqa: BLE001 - names the stub cannot resolve: as written
                annotations = dict(getattr(target, "__annotations__", {}))
            ret = annotations.pop("return", None)
            if ret is not None and ret is not type(None) and ret not in ("None", "NoneType", "types.NoneType"):
                raise TypeError("Return annotations are not allowed on @wp.overload stubs")
            missing = [n for n in stubbed.param_names if n not in annotations]
            if missing:
                raise TypeError(f"@wp.overload stub of kernel '{stubbed.key}' does not annotate "
                                f"{', '.join(missing)}")
            overload(stubbed, [annotations[n] for n in stubbed.param_names])
            return stubbed
        # decorator form on a def whose name is an existing generic @wp.func: add it
        definition = FunctionDefinition(target, is_kernel=False)
        existing = module_mod.get_module(definition.module).functions.get(definition.qualname)
        if existing is not None:
            existing.add_overload(definition)
            module_mod.bump_version()
            return existing
        return module_mod.register_function(definition)
    raise TypeError(f"wp.overload expects a @wp.func or @wp.kernel, got {target!r}")


def _generic_kernel_of_stub(stub):
    """The generic kernel a @wp.overload stub def names (same module and qualified name), None
    when it names none; RuntimeError when several kernels were made from that def."""
    module = module_mod.get_module(getattr(stub, "__module__", "") or "__main__")
    qualname = getattr(stub, "__qualname__", None)
    found = [k for k in list(module.kernels.values())
             if k.__qualname__ == qualname and k.is_generic and k.generic_parent is None]
    if len(found) > 1:
        raise RuntimeError(f"Ambiguous kernel lookup for the @wp.overload stub '{qualname}': "
                           f"kernels {', '.join(k.key for k in found)} come from one function")
    return found[0] if found else None


def constant(x):
    """wp.constant: marks a value usable in kernels (scalars, vectors, matrices, ...)."""
    if typestr.constant_type_of(x) is None:
        raise TypeError(f"wp.constant: {type(x).__name__} values cannot be kernel constants "
                        f"(use a scalar, vector, matrix, quaternion or transform)")
    return x


def _device_of(device) -> str:
    from .launch import device_name  # noqa: PLC0415

    return device_name(device)


def _caller_module_name(depth: int = 2) -> str:
    frame = sys._getframe(depth)
    return frame.f_globals.get("__name__", "__main__")


def compile(target=None, device=None, backward: bool = False, arch=None):  # noqa: A001 - Warp-style name
    """Compiles a kernel, a Python module (object or name) or, with no target, the caller's
    module, ahead of time on device. Raises WeftCompileError with the daemon's diagnostics.
    Returns the CompiledModule that did the work: the first one the daemon really compiled
    (kernels of one module share one build, so later kernels are cache hits), else the first.

    With arch (75, 80, 90, "sm_90", ... or a list of them) the daemon compiles for that CUDA
    architecture with NVRTC instead, without loading anything (no GPU needed; device must be
    None, "cuda" or "cuda:N"), and this returns a CudaCompileReport (a list of them for a list
    of architectures): the CUBIN size and, per kernel, forward and adjoint, registers per
    thread, code, shared, local and constant bytes."""
    if arch is not None:
        if isinstance(target, Kernel):
            kernels = [target]
        else:
            kernels = module_mod.kernels_of(_target_module_name(target))
        if isinstance(arch, (list, tuple)):
            return [cuda_compile.compile_for_arch(kernels, a, device) for a in arch]
        return cuda_compile.compile_for_arch(kernels, arch, device)
    dev = _device_of(device)
    if isinstance(target, Kernel):
        return module_mod.compile_kernel(target, dev, backward)[0]
    name = _target_module_name(target)
    result = None
    for compiled in module_mod.compile_module(name, dev, backward):
        if result is None or (result.cache_hit and not compiled.cache_hit):
            result = compiled
    return result


def _target_module_name(target) -> str:
    if target is None:
        name = _caller_module_name(3)
    elif isinstance(target, types.ModuleType):
        name = target.__name__
    elif isinstance(target, str):
        name = target
    elif isinstance(target, module_mod.Module):
        name = target.name
    else:
        raise TypeError(f"wp.compile expects a kernel, a module or a module name, got "
                        f"{target!r}")
    return name


compile_aot_module = cuda_compile.compile_aot_module


def load_module(module=None, device=None, recursive: bool = False):
    """Warp's wp.load_module: compiles the kernels of a module for device now."""
    if module is None:
        module = _caller_module_name()
    names = [module if isinstance(module, str) else getattr(module, "__name__", str(module))]
    if recursive:
        prefix = names[0] + "."
        names += [n for n in module_mod.modules() if n.startswith(prefix)]
    result = None
    for name in names:
        result = compile(name, device=device)
    return result


def get_module(name=None) -> module_mod.Module:
    if name is None:
        name = _caller_module_name()
    if isinstance(name, types.ModuleType):
        name = name.__name__
    return module_mod.get_module(name)


def set_module_options(options: dict, module=None) -> None:
    if module is None:
        module = _caller_module_name()
    module_mod.set_module_options(options, module)


def get_module_options(module=None) -> dict:
    if module is None:
        module = _caller_module_name()
    return module_mod.get_module_options(module)


# keep names used only by re-exporters visible to linters
_ = (StructInstance, StructType, inspect)
