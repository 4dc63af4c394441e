"""Kernel modules: the kernels and funcs of one Python module (as in Warp), turned into a
ModuleSource, compiled by the daemon lazily per device, and cached in the process by
(content hash, device) -> module_id and KernelInfo."""
from __future__ import annotations

import dataclasses
import hashlib
import re
import threading
import typing

from .. import config as _config
from . import symbols as symbols_mod
from .errors import WeftCompileError, compile_error
from .functions import Function, FunctionDefinition, Kernel
from .structs import StructType


def default_module_options() -> dict:
    """A new module's options, as Warp fills them: None means "use wp.config's value"."""
    from weft import config  # noqa: PLC0415

    return {"max_unroll": config.max_unroll, "enable_backward": config.enable_backward,
            "fast_math": False, "fuse_fp": True, "lineinfo": None, "mode": None,
            "block_dim": 256, "optimization_level": None}


class Module:
    """The kernels and funcs registered under one module name (Warp's wp.Module): options,
    load(device) to compile its kernels now, unload() to drop this process's compiled state,
    hash_module() for the content hash of what it would compile now."""

    def __init__(self, name: str, loader=None):
        # wp.Module(name) as Warp programs write it: registered under its name, so kernels and
        # funcs declared with module=<this> build together.
        if getattr(self, "_initialized", False):
            return
        self._initialized = True
        self.name = name
        self.kernels: dict = {}        # registry key -> Kernel, registration order
        self.functions: dict = {}      # qualname -> Function
        self.options: dict = default_module_options()

    def load(self, device=None, block_dim=None, binary_path=None):
        """Compiles every (non-generic) kernel of the module for device now; returns the
        CompiledModule of the last kernel (None when the module has no kernels). A kernel whose
        own code does not compile is left out and raises its error when launched (Warp fails the
        whole module load). block_dim is accepted for Warp's signature: CPU launches run one
        thread per block."""
        from .launch import device_name  # noqa: PLC0415

        if binary_path is not None:
            raise NotImplementedError("Module.load(binary_path=...): weft compiles modules in "
                                      "the daemon and loads no binaries from the client")
        built = compile_module(self.name, device_name(device), leave_out_failing=True)
        return built[-1] if built else None

    def unload(self):
        """Forgets this process's compiled state of the module (the daemon keeps its cache:
        the next launch or load asks it again)."""
        with _lock:
            for k in self.kernels.values():
                for instance in [k, *k._specializations.values()]:
                    instance._compiled.clear()
                    instance.__dict__.pop("_launch_plans", None)
            bump_version()

    def mark_modified(self):
        bump_version()

    def hash_module(self) -> str:
        """SHA-256 over the sources the module's kernels would be compiled from now (their
        functions, resolved globals, structs and options)."""
        digest = hashlib.sha256(self.name.encode())
        for k in kernels_of(self.name):
            if k.is_generic:
                continue
            digest.update(content_hash(build_module_source(k)[0]).encode())
        return digest.hexdigest()

    def get_module_hash(self, block_dim=None) -> str:
        return self.hash_module()

    def __repr__(self):
        return f"<weft module {self.name}: {len(self.kernels)} kernel(s)>"

    def __new__(cls, name: str = "", loader=None):
        if name:
            with _lock:
                existing = _modules.get(name)
                if existing is not None:
                    return existing
                module = super().__new__(cls)
                _modules[name] = module
                return module
        return super().__new__(cls)


_lock = threading.RLock()
_modules: dict = {}
_registry_version = 0                  # bumped on every registration: invalidates fast paths
_global_options: dict = {}
_compiled: dict = {}                   # (runtime, content hash, device) -> CompiledModule


def get_module(name: str) -> Module:
    with _lock:
        module = _modules.get(name)
        if module is None:
            module = _modules[name] = Module(name)
        return module


def force_load(device=None, modules=None) -> None:
    """wp.force_load: compiles (and weftd loads) the kernels of `modules` (Module objects or
    names; None: every module with kernels) for `device` (a device, a name, a list of them;
    None: every device) now, so the first launches do not wait for a compile. A kernel whose
    own code does not compile is left out and raises its error when launched."""
    from weft.device import get_device, get_devices  # noqa: PLC0415

    if device is None:
        devices = get_devices()
    elif isinstance(device, (list, tuple)):
        devices = [get_device(d) for d in device]
    else:
        devices = [get_device(device)]
    with _lock:
        if modules is None:
            chosen = [m for m in _modules.values() if m.kernels]
        else:
            chosen = [get_module(m) if isinstance(m, str) else m for m in modules]
    for d in devices:
        for m in chosen:
            if not callable(getattr(m, "load", None)):
                raise TypeError(f"force_load: modules must be wp.Module objects or names, got {type(m).__name__}")
            m.load(d)


def clear_kernel_cache() -> None:
    """wp.clear_kernel_cache: forgets this process's compiled state of every module, so the next
    launch or load asks weftd again. The compiled kernels themselves are weftd's cache, shared
    by all its clients (docs/backends.md): a client neither deletes nor bypasses what others
    use, so weftd answers from that cache (an operator clears it: docs/operations.md)."""
    with _lock:
        for m in _modules.values():
            m.unload()
        _compiled.clear()


def bump_version() -> None:
    global _registry_version
    with _lock:
        _registry_version += 1


def registry_version() -> int:
    return _registry_version


def set_module_options(options: dict, module=None) -> None:
    """wp.set_module_options: options for one module (a module object or name) or all."""
    if module is None:
        _global_options.update(options)
    else:
        name = module if isinstance(module, str) else getattr(module, "__name__", str(module))
        get_module(name).options.update(options)
    bump_version()


def get_module_options(module=None) -> dict:
    if module is None:
        return dict(_global_options)
    name = module if isinstance(module, str) else getattr(module, "__name__", str(module))
    merged = dict(_global_options)
    merged.update(get_module(name).options)
    return merged


def unchecked_requested() -> bool:
    """Some options (global or a module's) turn a safety net off: "bounds_checks" or
    "cancel_poll" false. A session opened now asks weftd for unchecked kernels."""
    def off(options):
        return any(options.get(name, True) in (False, 0, "false", "False", "0")
                   for name in ("bounds_checks", "cancel_poll"))

    with _lock:
        return off(_global_options) or any(off(m.options) for m in list(_modules.values()))


def register_kernel(kernel: Kernel) -> None:
    with _lock:
        module = get_module(kernel.module_name)
        module.kernels.pop(kernel.registry_key, None)
        module.kernels[kernel.registry_key] = kernel
        bump_version()


def register_function(definition: FunctionDefinition) -> Function:
    """Adds a @wp.func def to its module: a new name, or an overload of an existing one."""
    with _lock:
        module = get_module(definition.module)
        existing = module.functions.get(definition.qualname)
        if existing is None:
            existing = module.functions[definition.qualname] = Function(definition)
        else:
            existing.add_overload(definition)
        bump_version()
        return existing


def grid_stride_of(kernel: Kernel) -> bool:
    """Whether the kernel's CUDA entries stride over the grid (see build_options)."""
    return build_options(kernel).get("grid_stride", True) is not False


def build_options(kernel: Kernel) -> dict:
    """The options a kernel's module is compiled with: wp.config's compile settings, then the
    global and module options, then the kernel's own; unset (None) values are left out."""
    from weft import config  # noqa: PLC0415

    options = config.module_options()
    for key, value in get_module_options(kernel.module_name).items():
        if value is not None:
            options[key] = value
    options.update({k: v for k, v in kernel.options.items() if k != "module" and v is not None})
    # CUDA entries: a grid-stride loop unless the kernel, then the module ("default_grid_stride"),
    # then wp.config.default_grid_stride says otherwise; sent only when off (the daemon's default).
    default_stride = options.pop("default_grid_stride", None)
    stride = options.pop("grid_stride", None)
    if stride is None:
        stride = config.default_grid_stride if default_stride is None else default_stride
    if not stride:
        options["grid_stride"] = False
    if options.get("mode") not in ("release", "debug"):
        raise ValueError(f"module option 'mode' must be 'release' or 'debug', got "
                         f"{options.get('mode')!r}")
    return options


# --------------------------------------------------------------------------------------------
# Building a ModuleSource
# --------------------------------------------------------------------------------------------

@dataclasses.dataclass
class _Closure:
    """Everything one kernel needs: its def, the funcs it reaches, their symbols and structs."""

    definitions: list            # FunctionDefinition, kernel first
    symbols: list                # ResolvedSymbol
    structs: list                # StructType, dependencies first


def _closure_of(kernel: Kernel) -> _Closure:
    definitions, seen_defs = [], set()
    symbols, seen_symbols = [], set()
    structs = []
    pending = [kernel.definition]
    while pending:
        definition = pending.pop(0)
        if id(definition) in seen_defs:
            continue
        seen_defs.add(id(definition))
        definitions.append(definition)
        resolution = symbols_mod.resolve(definition)
        for sym in resolution.symbols:
            if sym.signature() not in seen_symbols:
                seen_symbols.add(sym.signature())
                symbols.append(sym)
        for struct_type in resolution.structs:
            for s in struct_type.referenced_structs() + [struct_type]:
                if s not in structs:
                    structs.append(s)
        for ann in definition.annotations.values():
            for s in _structs_in_annotation(ann):
                if s not in structs:
                    structs.append(s)
        for function in resolution.functions:
            pending.extend(function.overloads)
    for s in structs:
        if s.build_error:
            raise WeftCompileError(s.build_error)
    return _Closure(definitions, symbols, structs)


def _structs_in_annotation(ann) -> list:
    found = []
    candidates = [ann, getattr(ann, "dtype", None)] + list(getattr(ann, "__args__", None) or ())
    for c in candidates:
        if isinstance(c, StructType):
            found += c.referenced_structs() + [c]
    return found


def _conflicts(a: _Closure, b: _Closure) -> bool:
    """True when two closures bind one name differently or one key to different source."""
    bound_a: dict = {}
    for s in a.symbols:
        bound_a.setdefault(s.name, set()).add(s.signature())
    bound_b: dict = {}
    for s in b.symbols:
        bound_b.setdefault(s.name, set()).add(s.signature())
    for name, sigs in bound_b.items():
        if name in bound_a and bound_a[name] != sigs:
            return True
    keys_a = {d.key: d.source for d in a.definitions}
    for d in b.definitions:
        if d.key in keys_a and keys_a[d.key] != d.source:
            return True
    return False


def _merge(into: _Closure, other: _Closure) -> None:
    have = {id(d) for d in into.definitions}
    keys = {d.key for d in into.definitions}
    for d in other.definitions:
        if id(d) not in have and d.key not in keys:
            into.definitions.append(d)
            keys.add(d.key)
    sigs = {s.signature() for s in into.symbols}
    for s in other.symbols:
        if s.signature() not in sigs:
            into.symbols.append(s)
            sigs.add(s.signature())
    for s in other.structs:
        if s not in into.structs:
            into.structs.append(s)


# Options the daemon does not read and that must not split a module into several builds:
# enable_backward (adjoints are generated only when a backward pass first needs them).
_CLIENT_ONLY_OPTIONS = ("enable_backward",)


def _message_options(kernel: Kernel) -> dict:
    options = build_options(kernel)
    for key in _CLIENT_ONLY_OPTIONS:
        options.pop(key, None)
    return options


def _partition_groups(module: Module) -> dict:
    """Splits the module's kernels into build groups, in registration order: each kernel joins
    the first group whose kernels it does not clash with (a name bound differently, a key with
    other source, a kernel of the same name, other compile options), else starts a new one.
    The split depends only on the registered kernels, never on which kernel asks, so every
    kernel of a group sends the same message and the group is built once. Computed on every
    build (globals may have changed since). Returns {id(kernel): the group's _Closure}."""
    groups = []      # [closure, kernel names, options]
    member: dict = {}
    for k in list(module.kernels.values()):
        if k.broken or k.is_generic or k.options.get("module") == "unique":
            continue
        try:
            closure = _closure_of(k)
            options = _message_options(k)
        except Exception:  # noqa: BLE001 - an unresolvable kernel is built alone when launched
            continue
        for group in groups:
            if group[2] == options and k.name not in group[1] and not _conflicts(group[0], closure):
                _merge(group[0], closure)
                group[1].add(k.name)
                member[id(k)] = group[0]
                break
        else:
            groups.append([closure, {k.name}, options])
            member[id(k)] = closure
    return member



def _wire_module_name(name: str) -> str:
    """The module name the daemon takes: a dotted name of Python identifiers. Any other name
    (wp.get_module("pkg.<locals>.f:150")) has each other character replaced by '_' and a
    segment that is empty or starts with a digit prefixed with '_'."""
    parts = [re.sub(r"[^A-Za-z0-9_]", "_", p) for p in str(name).split(".")]
    return ".".join(p if p and not p[0].isdigit() else "_" + p for p in parts)

def build_module_source(kernel: Kernel, backward: bool = False, lanes: int = 1):
    """The ModuleSource that compiles `kernel` together with the other kernels of its module's
    build group (see _partition_groups), as a protobuf message. A kernel outside the groups
    (module="unique", a generic kernel's instance, one whose own build failed) is built alone."""
    from weft.v1 import module_pb2  # noqa: PLC0415

    with _lock:
        module = get_module(kernel.module_name)
        group = _partition_groups(module).get(id(kernel))
        if group is None or not any(d is kernel.definition for d in group.definitions):
            group = _closure_of(kernel)

    options = _message_options(kernel)
    if lanes > 1:       # cooperative CPU blocks of `lanes` threads (wp.config.enable_cpu_blocks)
        options["cpu_block_dim"] = int(lanes)
    msg = module_pb2.ModuleSource(name=_wire_module_name(kernel.module_name))
    for key in sorted(options):
        value = options[key]
        msg.options[str(key)] = ("true" if value else "false") if isinstance(value, bool) else str(value)
    # Canonical order, whatever kernel asked: every kernel of a module sends the same message,
    # so the module gets one cache key and is built once (not once per kernel).
    for d in sorted(group.definitions, key=lambda d: (d.key, d.name)):
        msg.functions.append(module_pb2.FunctionSource(
            name=d.name, source=d.source, file=d.file, first_line=d.first_line,
            is_kernel=d.is_kernel, param_types=d.param_types, param_names=d.param_names,
            return_type=d.return_type, key=d.key))
    for s in group.symbols:
        sym = module_pb2.Symbol(name=s.name)
        if s.kind == "builtin_module":
            sym.builtin_module = s.value
        elif s.kind == "function":
            sym.function = s.value
        elif s.kind == "type":
            sym.type = s.value
        else:
            sym.constant.type = s.constant_type
            sym.constant.value = s.constant_value
        msg.symbols.append(sym)
    for st in sorted(group.structs, key=lambda st: st.key):
        msg.structs.append(module_pb2.StructDef(
            name=st.key, fields=[module_pb2.StructField(name=f.name, type=f.type_str)
                                 for f in st.fields]))
    return msg, group


# --------------------------------------------------------------------------------------------
# Compiling
# --------------------------------------------------------------------------------------------

@dataclasses.dataclass
class CompiledModule:
    module_id: str
    kernels: dict            # kernel name -> KernelInfo
    cache_hit: bool
    compile_ms: float


def content_hash(module_source) -> str:
    return hashlib.sha256(module_source.SerializeToString(deterministic=True)).hexdigest()


def format_diagnostics(diagnostics) -> str:
    """Each diagnostic as its source line, a caret under the column, then
    `file:line:col: error: message`: the last diagnostic's message ends the text (as Warp's
    codegen errors end with their message)."""
    severities = {0: "error", 1: "warning", 2: "note"}
    lines = []
    for d in diagnostics:
        loc = d.location
        if d.source_line:
            lines.append("    " + d.source_line.rstrip())
            if loc.column:
                lines.append("    " + " " * max(loc.column - 1, 0) + "^")
        where = f"{loc.file}:{loc.line}:{loc.column}: " if loc.file else ""
        lines.append(f"{where}{severities.get(d.severity, 'error')}: {d.message}")
    return "\n".join(lines)


def _find_kernel_info(compiled: CompiledModule, kernel: Kernel):
    for name in (kernel.name, kernel.key):
        if name in compiled.kernels:
            return compiled.kernels[name]
    return None


def compile_kernel(kernel: Kernel, device: str, backward: bool = False, lanes: int = 1):
    """(CompiledModule, KernelInfo) of kernel on device, compiling its module when needed;
    `lanes` > 1: for cooperative CPU blocks of that many threads. Raises WeftCompileError with
    the daemon's diagnostics."""
    from weft import _runtime  # noqa: PLC0415

    runtime_id = id(_runtime.get_runtime())
    fast_key = (runtime_id, device, backward, lanes)
    cached = kernel._compiled.get(fast_key)
    if cached is not None and cached[0] == _registry_version:
        return cached[1], cached[2]
    source, group = build_module_source(kernel, backward, lanes)
    digest = content_hash(source)
    compiled = _compiled.get((runtime_id, digest, device))
    if compiled is None:
        try:
            compiled = _compile_source(source, device)
        except WeftCompileError as err:
            # a sibling kernel's error must not block this one: retry it alone
            broken = _kernels_at_fault(err, group)
            if broken and not all(k.broken for k in broken):
                for k in broken:
                    k.broken = True
                bump_version()
                if kernel not in broken:
                    return compile_kernel(kernel, device, backward, lanes)
            raise
        _compiled[(runtime_id, digest, device)] = compiled
        if _config.verbose and not compiled.cache_hit:
            from weft.logger import log_info  # noqa: PLC0415

            log_info(f"Module {kernel.module_name} {digest[:7]} load on device '{device}' took "
                     f"{compiled.compile_ms:.2f} ms  (compiled)")
    info = _find_kernel_info(compiled, kernel)
    if info is None:
        raise WeftCompileError(f"the daemon compiled module {kernel.module_name} but reported "
                               f"no kernel named {kernel.name!r} (has {sorted(compiled.kernels)})")
    if not backward and info.adjoint_refused and build_options(kernel).get("enable_backward", True):
        # Warp refuses such a kernel at its first launch when its module generates adjoints
        raise WeftCompileError(f"kernel '{kernel.key}' of module {kernel.module_name}:\n{info.adjoint_refused}")
    kernel._compiled[fast_key] = (_registry_version, compiled, info)
    return compiled, info


class UniqueModule:
    """kernel.module of a module="unique" kernel: Warp gives such a kernel a module of its own,
    so load() compiles that kernel alone and raises its compile error; everything else is the
    Python module's Module (options, unload, hash_module)."""

    def __init__(self, kernel: Kernel, module: Module):
        self._kernel = kernel
        self._module = module

    def __getattr__(self, name):
        return getattr(self._module, name)

    def __repr__(self):
        return f"<weft module of the unique kernel {self._kernel.key}>"

    def load(self, device=None, block_dim=None, binary_path=None):
        from .launch import device_name  # noqa: PLC0415

        if binary_path is not None:
            raise NotImplementedError("Module.load(binary_path=...): weft compiles modules in "
                                      "the daemon and loads no binaries from the client")
        k = self._kernel
        instances = list(k._specializations.values()) if k.is_generic else [k]
        built = [compile_kernel(instance, device_name(device))[0] for instance in instances]
        return built[-1] if built else None


def compile_module(module_name: str, device: str, backward: bool = False,
                   leave_out_failing: bool = False) -> list:
    """Compiles every kernel of a module (a generic kernel: its instances, from wp.overload or
    launches) and returns the CompiledModule of each, in order. A module="unique" kernel is
    not part of it (as in Warp, it has a module of its own: kernel.module.load() builds it).
    A kernel whose own code fails raises its error, or with leave_out_failing is left out of
    its group's build (the others load) and raises when launched; any other error raises."""
    built = []
    for k in kernels_of(module_name):
        if k.options.get("module") == "unique":
            continue
        for instance in list(k._specializations.values()) if k.is_generic else [k]:
            try:
                built.append(compile_kernel(instance, device, backward)[0])
            except WeftCompileError:
                if not (leave_out_failing and instance.broken):
                    raise
    return built


def _kernels_at_fault(err: WeftCompileError, group: _Closure) -> list:
    located = [(d.location.file, d.location.line) for d in err.diagnostics if d.location.file]
    if not located:     # the daemon's message text: "file.py:LINE:COL: error: ..."
        located = [(f, int(line)) for f, line in re.findall(r"([^\s:]+\.py):(\d+)", str(err))]
    faulty = []

    def at_fault(d) -> bool:
        return any(f == d.file and d.first_line <= line <= d.last_line for f, line in located)

    with _lock:
        for module in _modules.values():
            for k in module.kernels.values():
                if not any(x is k.definition for x in group.definitions):
                    continue
                try:
                    reach = _closure_of(k).definitions    # the kernel and every func it calls
                except Exception:  # noqa: BLE001
                    reach = [k.definition]
                if any(at_fault(d) for d in reach):
                    faulty.append(k)
    return faulty


def _compile_source(source, device: str) -> CompiledModule:
    from weft import _runtime  # noqa: PLC0415
    from weft.v1 import module_pb2  # noqa: PLC0415

    rt = _runtime.get_runtime()
    request = module_pb2.CompileRequest(module=source, device=device)
    try:
        response = rt.call(rt.module_stub.Compile, request)
    except Exception as err:  # noqa: BLE001 - a WeftError from the runtime: add context
        diags = list(getattr(err, "diagnostics", []) or [])
        text = format_diagnostics(diags) if diags else str(err)
        raise compile_error(f"module {source.name} failed to compile on {device}:\n{text}",
                            diags) from None
    errors = [d for d in response.diagnostics if d.severity == 0]
    if errors or not response.module_id:
        text = format_diagnostics(response.diagnostics) or "no diagnostics"
        raise compile_error(f"module {source.name} failed to compile on {device}:\n{text}",
                            list(response.diagnostics))
    return CompiledModule(response.module_id, {k.name: k for k in response.kernels},
                          response.cache_hit, response.compile_ms)


def compiled_modules() -> dict:
    return dict(_compiled)


def modules() -> dict:
    return dict(_modules)


def kernels_of(module_name: str) -> list:
    with _lock:
        return list(get_module(module_name).kernels.values())


def all_kernels(module_name: typing.Optional[str] = None) -> list:
    with _lock:
        if module_name is not None:
            return kernels_of(module_name)
        return [k for m in _modules.values() for k in m.kernels.values()]
