"""@wp.kernel and @wp.func: capturing a Python function's source, file and line and its
resolved parameter types; @wp.func overloads (by annotation types) and generic funcs."""
from __future__ import annotations

import ast
import copy
import inspect
import re
import textwrap
import typing

from ..tile import is_tile, tile_stack
from . import typestr
from .errors import WeftCompileError
from .structs import StructInstance, canonical_name


class FunctionDefinition:
    """One Python def as the daemon sees it: source without decorators, file, def line,
    parameter names and type strings, and the environment its global names resolve in."""

    def __init__(self, func, is_kernel: bool):
        self.func = func
        self.is_kernel = is_kernel
        self.name = func.__name__
        self.module = func.__module__
        self.qualname = func.__qualname__
        try:
            lines, start = inspect.getsourcelines(func)
        except (OSError, TypeError) as err:
            raise WeftCompileError(f"weft cannot read the source of {self.qualname}: {err} "
                                   f"(kernels must be defined in a file)") from err
        self.file = inspect.getsourcefile(func) or inspect.getfile(func)
        text = textwrap.dedent("".join(lines))
        tree = ast.parse(text)
        fdef = next(n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)))
        def_index = fdef.lineno - 1          # decorators come before the def line
        self.first_line = start + def_index
        body_lines = text.splitlines(keepends=True)[def_index:]
        self.source = textwrap.dedent("".join(body_lines))
        self.last_line = self.first_line + len(body_lines) - 1
        self.tree = next(n for n in ast.parse(self.source).body
                         if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)))
        self.static_values: dict = {}     # name in source -> value of a wp.static(...) call
        # The first error this definition defers to the build of a module using it (a wp.static
        # expression that fails, a parameter type kernels cannot take): see _defer_error.
        self.build_error = None
        self._expand_static()
        self.param_names = [a.arg for a in self.tree.args.args]
        hints = self._annotations()
        self.annotations = {}
        self.param_types = []
        for name in self.param_names:
            if name not in hints:
                raise WeftCompileError(
                    f"{self.file}:{self.first_line}: error: parameter '{name}' of "
                    f"'{self.name}' needs a type annotation")
            ann = hints[name]
            self.annotations[name] = ann
            if isinstance(ann, tile_stack):
                try:
                    self.param_types.append(f"tile_stack({typestr.type_string(ann.dtype)},{int(ann.capacity)})")
                except TypeError as err:
                    raise WeftCompileError(
                        f"{self.file}:{self.first_line}: error: parameter '{name}' of "
                        f"'{self.name}': {err}") from err
                continue
            if is_tile(ann):
                # wp.tile[dtype, M, N]: "tile(dtype,M,N)"; a tile of any shape is generic ("any").
                try:
                    if ann.shape is typing.Any:
                        self.param_types.append("any")
                    else:
                        self.param_types.append("tile(" + typestr.type_string(ann.dtype) + "," +
                                                ",".join(str(int(n)) for n in ann.shape) + ")")
                except TypeError as err:
                    raise WeftCompileError(
                        f"{self.file}:{self.first_line}: error: parameter '{name}' of "
                        f"'{self.name}': {err}") from err
                continue
            try:
                self.param_types.append(typestr.type_string(ann))
            except typestr.FabricArrayRefused as err:
                self._defer_error(self.first_line, 1, f"parameter '{name}' of '{self.name}': {err}")
                self.param_types.append("any")
            except TypeError as err:
                raise WeftCompileError(
                    f"{self.file}:{self.first_line}: error: parameter '{name}' of "
                    f"'{self.name}': {err}") from err
        self.return_type = ""
        if "return" in hints and hints["return"] is not None and not is_kernel:
            ret = hints["return"]
            if ret is not type(None):
                try:
                    self.return_type = _return_type_string(ret)
                except TypeError:
                    self.return_type = ""
        self.key = canonical_name(self.module, self.qualname)
        self.custom_grad = None      # GradientFunction set by wp.func_grad
        self.custom_replay = None    # GradientFunction (the replay function) set by wp.func_replay

    def _is_static_call(self, node, scope: dict) -> bool:
        chain = []
        while isinstance(node, ast.Attribute):
            chain.append(node.attr)
            node = node.value
        if not isinstance(node, ast.Name):
            return False
        value = scope.get(node.id)
        for attr in reversed(chain):
            value = getattr(value, attr, None)
        return value is static

    def _expand_static(self) -> None:
        """wp.static(expr): the expression is evaluated here, in the function's globals and
        closure, and its call is replaced in the source by a name bound to the value (a
        constant, a @wp.func, a type; resolved like any global). Warp evaluates it at code
        generation. An expression that cannot be evaluated here (it names a kernel variable)
        is left in place, and the daemon reports it at its line."""
        scope = dict(self.func.__globals__)
        scope.update(self.environment())
        calls = [n for n in ast.walk(self.tree)
                 if isinstance(n, ast.Call) and self._is_static_call(n.func, scope)]
        if not calls:
            return
        inner = {id(m) for c in calls for m in ast.walk(c) if m is not c}
        calls = [c for c in calls if id(c) not in inner]
        # names local to the function (parameters, assignment and loop targets) are kernel
        # variables, even where a global of the same name exists: an expression reading one is
        # left to the daemon (a loop variable of a constant range, a literal-valued local)
        local_names = {a.arg for a in self.tree.args.args}
        local_names |= {n.id for n in ast.walk(self.tree) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
        lines = [ln.encode() for ln in self.source.splitlines(keepends=True)]
        attribute_bases = {id(n.value) for n in ast.walk(self.tree) if isinstance(n, ast.Attribute)}
        edits = []
        for call in calls:
            if len(call.args) != 1 or call.keywords:
                continue
            if any(isinstance(n, ast.Name) and n.id in local_names for n in ast.walk(call.args[0])):
                continue
            try:
                code = compile(ast.Expression(call.args[0]), self.file, "eval")
                value = eval(code, scope)  # noqa: S307 - the user's own wp.static expression
            except ArithmeticError as err:   # the expression itself fails (as in Warp)
                self._static_error(call, f"Error evaluating static expression: {err}")
                continue
            except Exception:  # noqa: BLE001 - kernel names, kernel-only builtins: left to the daemon
                continue
            if _is_runtime_array(value):
                self._static_error(call, "Static expression returns an unsupported value: a Warp array cannot be "
                                         "created inside Warp kernels")
                continue
            if value is None:
                self._static_error(call, "Static expression returns an unsupported value: None is returned")
                continue
            if id(call) not in attribute_bases and _is_plain_object(value):
                # an object that means nothing in kernel code (its attributes might: kept when
                # the expression reads one)
                self._static_error(call, f"Static expression returns an unsupported value: value of type "
                                         f"{type(value)}")
                continue
            if isinstance(value, StructInstance):
                # a struct value: rebuilt in the kernel by its constructor, one bound name per
                # field value (nested structs likewise); a struct holding an array cannot be
                path = _struct_array_path(value, value._struct_type.key.rsplit(".", 1)[-1])
                if path is not None:
                    self._static_error(call, "Static expression returns an unsupported value: the returned Warp "
                                             "struct contains a data type that cannot be constructed inside Warp "
                                             f"kernels: a Warp array cannot be created inside Warp kernels at {path}")
                    continue
                edits.append((call, self._static_struct_text(value)))
                continue
            name = f"_wp_static_{len(self.static_values)}"
            self.static_values[name] = value
            edits.append((call, name))
        # replace from the end so earlier offsets (UTF-8 bytes, as ast gives them) stay valid;
        # a call over several lines keeps its line count: (name\n...\n)
        for call, name in sorted(edits, key=lambda e: (e[0].lineno, e[0].col_offset), reverse=True):
            first, last = call.lineno - 1, call.end_lineno - 1
            text = ("(" + name + "\n" * (last - first) + ")").encode()
            lines[first] = lines[first][:call.col_offset] + text + lines[last][call.end_col_offset:]
            for k in range(first + 1, last + 1):
                lines[k] = b""
        if edits:
            self.source = b"".join(lines).decode()
            self.tree = next(n for n in ast.parse(self.source).body
                             if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)))

    def _static_struct_text(self, value) -> str:
        """`T(field=v, ...)` for a struct value, each type and leaf value bound to a new static
        name (field names are the struct's, validated identifiers)."""
        from weft.types import _Composite  # noqa: PLC0415 - weft.types imports the kernel API

        def bind(v) -> str:
            name = f"_wp_static_{len(self.static_values)}"
            self.static_values[name] = v
            return name

        def field_text(f) -> str:
            v = value._values[f.name]
            if isinstance(v, StructInstance):
                return self._static_struct_text(v)
            ann = f.annotation
            if isinstance(ann, type) and issubclass(ann, _Composite) and not isinstance(v, ann):
                v = ann(v)        # Python scope keeps what was assigned (a quatf in a quatd field)
            return bind(v)

        st = value._struct_type
        fields = ", ".join(f"{f.name}={field_text(f)}" for f in st.fields)
        return f"{bind(st)}({fields})"

    def _static_error(self, call, message: str) -> None:
        """A wp.static expression that fails here, reported at the call's line."""
        self._defer_error(self.first_line + call.lineno - 1, call.col_offset + 1, message)

    def _defer_error(self, line: int, column: int, message: str) -> None:
        """An error raised when a module using this function is built (as Warp's at code
        generation), at the given line: a wp.static expression that fails here, a parameter type
        kernels cannot take. The first one is kept."""
        if self.build_error is None:
            self.build_error = f"{self.file}:{line}:{column}: error: {message}"

    def _annotations(self) -> dict:
        """The evaluated annotations; string annotations (PEP 563) are evaluated in the
        function's globals and closure, so kernels inside functions may use local types."""
        raw = dict(getattr(self.func, "__annotations__", {}))
        if not any(isinstance(v, str) for v in raw.values()):
            return raw
        scope = dict(self.func.__globals__)
        scope.update(self.environment())
        hints = {}
        for name, value in raw.items():
            if isinstance(value, str):
                try:
                    value = eval(value, scope)  # noqa: S307 - the user's own annotation text
                except Exception as err:  # noqa: BLE001
                    raise WeftCompileError(
                        f"{self.file}:{self.first_line}: error: cannot evaluate the annotation "
                        f"{value!r} of '{name}' in '{self.name}': {err}") from err
            hints[name] = value
        return hints

    @property
    def is_generic(self) -> bool:
        return any(typestr.is_generic(t) for t in self.param_types)

    def environment(self) -> dict:
        """Closure variables over globals: where the body's free names resolve."""
        env = {}
        code = getattr(self.func, "__code__", None)
        closure = getattr(self.func, "__closure__", None)
        if code is not None and closure:
            for name, cell in zip(code.co_freevars, closure):
                try:
                    env[name] = cell.cell_contents
                except ValueError:       # cell not filled yet
                    pass
        return env


def _is_runtime_array(value) -> bool:
    """A weft array object (not an annotation): what a wp.static expression cannot return."""
    from weft.array import array as _array  # noqa: PLC0415 - weft.array imports the kernel API
    from weft.indexedarray import indexedarray as _indexedarray  # noqa: PLC0415

    return isinstance(value, (_array, _indexedarray))


def _python_value_fits(value, annotation) -> bool:
    """Whether a Python-scope argument matches a parameter annotation closely enough to pick
    that overload (exact class for weft value types, int / float / bool for scalars)."""
    if annotation is None or annotation is typing.Any:
        return True
    if isinstance(annotation, type):
        if isinstance(value, annotation):
            return True
        name = getattr(annotation, "__name__", "")
        if name.startswith("float"):
            return isinstance(value, float)
        if name.startswith(("int", "uint")):
            return isinstance(value, int) and not isinstance(value, bool)
        if name == "bool":
            return isinstance(value, bool)
        return False
    return True


def static(expr):
    """wp.static(expr) in kernel code: the value of a Python expression, evaluated once when
    the kernel or func is defined (see FunctionDefinition._expand_static). In Python scope it
    returns expr."""
    return expr


def _is_plain_object(value) -> bool:
    """An instance of a user class that is nothing in kernel code (see symbols._opaque)."""
    from .symbols import _opaque  # noqa: PLC0415 - symbols imports this module

    return not isinstance(value, type) and _opaque(value)


def _struct_array_path(value, path: str):
    """The dotted path of the first array inside a struct value (Foo.bar.baz), else None."""
    for f in value._struct_type.fields:
        v = value._values.get(f.name)
        if _is_runtime_array(v):
            return path + "." + f.name
        if isinstance(v, StructInstance):
            inner = _struct_array_path(v, path + "." + f.name)
            if inner is not None:
                return inner
    return None


def _return_type_string(ret) -> str:
    origin = getattr(ret, "__origin__", None)
    if origin is tuple:
        return "tuple(" + ",".join(typestr.type_string(a) for a in ret.__args__) + ")"
    return typestr.type_string(ret)


def _module_name(module, default: str) -> str:
    """The module name of a Kernel's `module` argument: None, a name, a Python module or a
    weft Module."""
    if module is None:
        return default
    if isinstance(module, str):
        return module
    return getattr(module, "name", None) or getattr(module, "__name__", None) or str(module)


def sanitize_key(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.]", "_", text)


class Function:
    """What @wp.func returns: one name with one or more overloads (by annotation types)."""

    # As an annotation (g: wp.Function) a parameter taking a @wp.func or a builtin.
    _weft_function_type_ = True

    def __init__(self, definition: FunctionDefinition):
        self.__name__ = definition.name
        self.__qualname__ = definition.qualname
        self.__module__ = definition.module
        self.__doc__ = definition.func.__doc__
        self.key = definition.key
        self.module = definition.module
        self.overloads: list = []
        self.add_overload(definition)

    def add_overload(self, definition: FunctionDefinition) -> None:
        for i, existing in enumerate(self.overloads):
            if existing.param_types == definition.param_types:
                self.overloads[i] = definition     # redefinition replaces, as in Warp
                break
        else:
            self.overloads.append(definition)
        # overloads of one name differ by key: name plus their parameter types
        if len(self.overloads) == 1:
            self.overloads[0].key = self.key
        else:
            for d in self.overloads:
                d.key = sanitize_key(self.key + "__" + "_".join(d.param_types))

    def __call__(self, *args, **kwargs):
        """Called from Python scope, as in Warp: the Python function itself runs, with the
        client's Python-side values (vectors, matrices, scalars). With several overloads, the
        first whose parameter count and annotated types accept the arguments runs."""
        overload = self._python_overload(args, kwargs)
        return overload.func(*args, **kwargs)

    def _python_overload(self, args, kwargs):
        if len(self.overloads) == 1:
            return self.overloads[0]
        candidates = []
        for d in self.overloads:
            try:
                bound = inspect.signature(d.func).bind(*args, **kwargs)
            except TypeError:
                continue
            candidates.append(d)
            hints = d.annotations
            if all(_python_value_fits(value, hints.get(name)) for name, value in bound.arguments.items()):
                return d
        if candidates:
            return candidates[0]
        raise TypeError(f"no overload of @wp.func {self.key} takes these arguments")

    def __repr__(self):
        return f"<weft func {self.key} ({len(self.overloads)} overload(s))>"


class NativeSnippet:
    """What @wp.func_native returns in weft: a named placeholder for a function whose body is
    client C++/CUDA. The daemon compiles only the kernel language, never client C++
    (docs/security.md), so a kernel that reaches one fails to build (that kernel only, with the
    reason and the places); defining one is not an error, so the other kernels of its module
    still build and run."""

    def __init__(self, func):
        self.func = func
        self.__name__ = func.__name__
        self.__qualname__ = getattr(func, "__qualname__", func.__name__)
        self.__doc__ = func.__doc__
        self.__module__ = getattr(func, "__module__", None)
        try:
            self.file = inspect.getsourcefile(func) or "<unknown>"
            self.line = inspect.getsourcelines(func)[1]
        except (OSError, TypeError):
            self.file, self.line = "<unknown>", 0

    def refusal(self, caller: str, file: str, line: int) -> str:
        return (f"{file}:{line}: error: '{caller}' calls '{self.__name__}', a native snippet "
                f"(@wp.func_native, {self.file}:{self.line}): weft does not compile native "
                "snippets: the daemon compiles only the kernel language, never client C++ "
                "(see docs/security.md); write the function as a @wp.func instead")

    def __call__(self, *args, **kwargs):
        raise WeftCompileError(self.refusal("Python", self.file, self.line))

    def __repr__(self):
        return f"<weft native snippet {self.__qualname__} (not compiled)>"


class GradientFunction:
    """A custom gradient (wp.func_grad) attached to one @wp.func overload. It is sent with the
    overload, under the key `<overload key>__custom_grad`, whenever a kernel reaches the
    overload; the daemon calls it in the func's backward pass instead of differentiating the
    body. Parameters: the func's, then the adjoints of its return values; the body adds to
    `wp.adjoint[param]`."""

    def __init__(self, definition: FunctionDefinition):
        self.definition = definition
        self.overloads = [definition]


def attach_gradient(forward: Function, definition: FunctionDefinition) -> GradientFunction:
    """Attaches `definition` as the custom gradient of the overload of `forward` whose
    parameter types it starts with. Raises TypeError when none does."""
    if not isinstance(forward, Function):
        raise TypeError(f"wp.func_grad expects a @wp.func, got {forward!r}")
    gradient = GradientFunction(definition)
    matched = False
    for overload in forward.overloads:
        n = len(overload.param_types)
        if definition.param_types[:n] == overload.param_types:
            overload.custom_grad = gradient
            matched = True
    if not matched:
        raise TypeError(
            f"{definition.file}:{definition.first_line}: error: gradient '{definition.name}' does not "
            f"match any overload of '{forward.__name__}': its parameters must start with the "
            f"func's parameter types, then take the adjoints of its return values")
    return gradient


def attach_replay(forward: Function, definition: FunctionDefinition) -> GradientFunction:
    """Attaches `definition` as the custom replay (wp.func_replay) of every overload of
    `forward` whose parameter types it has. It is sent with the overload under the key
    `<overload key>__custom_replay`; the func's replay twin calls it. Raises TypeError when no
    overload matches."""
    if not isinstance(forward, Function):
        raise TypeError(f"wp.func_replay expects a @wp.func, got {forward!r}")
    replay = GradientFunction(definition)
    matched = False
    for overload in forward.overloads:
        if definition.param_types == overload.param_types:
            overload.custom_replay = replay
            matched = True
    if not matched:
        raise TypeError(
            f"{definition.file}:{definition.first_line}: error: replay function '{definition.name}' does not "
            f"match any overload of '{forward.__name__}': it must take the func's parameters")
    return replay


class Kernel:
    """What @wp.kernel returns: a launchable kernel of one module. Constructed directly as in
    Warp, wp.Kernel(func, key=None, module=None, options=None) registers func as a kernel of
    `module` (a Module, a module object or name; default: func's Python module) under `key`
    (default: the function's name). `key` is Warp's kernel name; the daemon sees the
    definition's module-qualified key."""

    def __init__(self, func=None, key=None, module=None, options=None, code_transformers=None,
                 *, definition: FunctionDefinition = None, register: bool = True):
        if definition is None:
            if func is None:
                raise TypeError("wp.Kernel needs a Python function (func=...)")
            definition = FunctionDefinition(func, is_kernel=True)
        if code_transformers:
            raise NotImplementedError("wp.Kernel(code_transformers=...): weft compiles the "
                                      "function's source text in the daemon; AST transformers "
                                      "are not supported")
        if key:
            definition.key = canonical_name(definition.module, str(key))
        self.definition = definition
        self.func = definition.func
        self.key = str(key) if key else definition.name
        self.__name__ = definition.name
        self.__qualname__ = definition.qualname
        self.__module__ = definition.module
        self.__doc__ = definition.func.__doc__
        self.module_name = _module_name(module, definition.module)
        self.options = dict(options or {})
        self.broken = False        # set when its own compile failed: left out of other builds
        self._compiled: dict = {}  # (runtime, device, backward) -> (version, CompiledModule, KernelInfo)
        self._specializations: dict = {}   # generic kernels: concrete param types -> Kernel
        self.generic_parent = None
        # registered under its key when one is given (several kernels of one def), else its
        # qualified name (a redefinition replaces the earlier kernel)
        self.registry_key = str(key) if key else definition.qualname
        if register:
            from . import module as module_mod  # noqa: PLC0415 - module.py imports this file

            module_mod.register_kernel(self)

    @property
    def module(self):
        """The Module this kernel belongs to (Warp's kernel.module); a module="unique" kernel's
        is a module of its own (module.UniqueModule), as in Warp."""
        from . import module as module_mod  # noqa: PLC0415

        if self.options.get("module") == "unique":
            return module_mod.UniqueModule(self, module_mod.get_module(self.module_name))
        return module_mod.get_module(self.module_name)

    @property
    def is_generic(self) -> bool:
        return self.definition.is_generic

    @property
    def overloads(self) -> list:
        """The instances of a generic kernel made so far (wp.overload, launches), Warp's
        kernel.overloads."""
        return list(self._specializations.values())

    def add_overload(self, arg_types) -> "Kernel":
        """Warp's kernel.add_overload(arg_types): the instance of this generic kernel for the given
        parameter types (a list in parameter order, or a dict by name), as wp.overload gives."""
        from .api import overload  # noqa: PLC0415

        return overload(self, arg_types)

    def specialize(self, param_types: list, annotations: typing.Optional[list] = None) -> "Kernel":
        """The instance of a generic kernel (typing.Any parameters) for concrete types;
        `annotations`, when given, are the concrete Python types (structs they name are
        compiled with the instance)."""
        key = tuple(param_types)
        existing = self._specializations.get(key)
        if existing is not None:
            return existing
        for declared, concrete in zip(self.definition.param_types, param_types):
            if not typestr.is_generic(declared) and declared != concrete:
                raise TypeError(f"kernel {self.key}: parameter type {declared} cannot be "
                                f"specialized to {concrete}")
        definition = copy.copy(self.definition)
        definition.param_types = list(param_types)
        definition.key = sanitize_key(self.key + "__" + "_".join(param_types))
        if annotations is not None:
            definition.annotations = dict(zip(definition.param_names, annotations))
        instance = Kernel(definition=definition, module=self.module_name, options=self.options,
                          register=False)
        instance.key = self.key
        instance.generic_parent = self
        self._specializations[key] = instance
        return instance

    @property
    def adj(self):
        """Warp's kernel.adj, as far as parameter access goes: fun_name, filename,
        fun_lineno and args[i].label / .is_read / .is_write (weft._kernel.array_access)."""
        adj = self.__dict__.get("_weft_adj")
        if adj is None:
            from .array_access import Adjoint  # noqa: PLC0415
            adj = self.__dict__["_weft_adj"] = Adjoint(self.definition).analyze()
        return adj

    @property
    def name(self) -> str:
        return self.definition.name

    @property
    def param_names(self) -> list:
        return self.definition.param_names

    @property
    def param_types(self) -> list:
        return self.definition.param_types

    def __call__(self, *args, **kwargs):
        raise RuntimeError(f"kernel {self.key} cannot be called directly: use wp.launch")

    def __repr__(self):
        return f"<weft kernel {self.key}>"
