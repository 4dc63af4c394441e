"""Symbol resolution (docs/protocol.md): finds every global name and attribute chain a kernel
or @wp.func uses (body and annotations) and classifies it as the warp module, a constant, a
@wp.func, or a type, evaluating it in the function's closure and globals. A Python enum
member (MyEnum.A, MyEnum.A.value) is the constant of its value."""
from __future__ import annotations

import ast
import builtins
import dataclasses
import enum
import types
import typing

from . import typestr
from .errors import WeftCompileError
from .functions import Function, FunctionDefinition, NativeSnippet
from .structs import StructType

_MISSING = object()


@dataclasses.dataclass
class ResolvedSymbol:
    """One entry of ModuleSource.symbols before it becomes protobuf."""

    name: str
    kind: str                      # "builtin_module" | "constant" | "function" | "type"
    value: str = ""                # module name / function key / type string
    constant_type: str = ""
    constant_value: str = ""

    def signature(self) -> tuple:
        return (self.name, self.kind, self.value, self.constant_type, self.constant_value)


@dataclasses.dataclass
class Resolution:
    """What one function's names resolve to, and the funcs/structs they pull in."""

    symbols: list
    functions: list                # Function objects called
    structs: list                  # StructType objects used


def is_warp_module(value) -> bool:
    """weft's own modules and a package that re-exports weft (a `warp` alias): the namespace of
    kernel builtins. A user's package that merely lives under such a name (warp.tests) is not."""
    if not isinstance(value, types.ModuleType):
        return False
    name = value.__name__
    return (name == "weft" or name.startswith("weft.") or
            getattr(value, "_weft_reexport_of_", None) == "weft")


def _local_names(fdef: ast.FunctionDef) -> set:
    names = {a.arg for a in fdef.args.args + fdef.args.kwonlyargs}
    if fdef.args.vararg:
        names.add(fdef.args.vararg.arg)
    for node in ast.walk(fdef):
        if isinstance(node, ast.Name) and isinstance(node.ctx, (ast.Store, ast.Del)):
            names.add(node.id)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node is not fdef:
            names.add(node.name)
    return names


def _attribute_chain(node) -> typing.Optional[list]:
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
        return parts[::-1]
    return None


class _Collector(ast.NodeVisitor):
    """Collects the free names (and attribute chains rooted at them) in source order."""

    def __init__(self, local_names: set):
        self.local_names = local_names
        self.chains: list = []     # lists of identifiers, root first
        self.operator_names: set = set()

    def visit_Attribute(self, node):
        chain = _attribute_chain(node)
        if chain is not None and chain[0] not in self.local_names:
            self.chains.append(chain)
            return
        self.generic_visit(node)

    def visit_Name(self, node):
        if isinstance(node.ctx, ast.Load) and node.id not in self.local_names:
            self.chains.append([node.id])

    def visit_BinOp(self, node):
        # `a + b` on structs calls the user's @wp.func `add` (Warp's operator overloading): the
        # operator's builtin name is a candidate free name (kept only if it names a @wp.func)
        name = _OPERATOR_FUNCS.get(type(node.op))
        if name is not None and name not in self.local_names:
            self.operator_names.add(name)
        self.generic_visit(node)


# ast operator -> the builtin (and @wp.func) name the compiler calls for it on structs
_OPERATOR_FUNCS = {ast.Add: "add", ast.Sub: "sub", ast.Mult: "mul", ast.MatMult: "mul", ast.Div: "div",
                   ast.FloorDiv: "floordiv", ast.Mod: "mod", ast.Pow: "pow", ast.LShift: "lshift",
                   ast.RShift: "rshift", ast.BitOr: "bit_or", ast.BitXor: "bit_xor", ast.BitAnd: "bit_and"}


def resolve(definition: FunctionDefinition) -> Resolution:
    """Resolves the free names of one function definition (body, annotations, defaults)."""
    if getattr(definition, "build_error", None):
        raise WeftCompileError(definition.build_error)
    fdef = definition.tree
    collector = _Collector(_local_names(fdef))
    for arg in fdef.args.args + fdef.args.kwonlyargs:
        if arg.annotation is not None:
            collector.visit(arg.annotation)
    if fdef.returns is not None:
        collector.visit(fdef.returns)
    for default in fdef.args.defaults:
        collector.visit(default)
    for stmt in fdef.body:
        collector.visit(stmt)

    env = definition.environment()
    scope = definition.func.__globals__
    symbols: dict = {}
    functions: list = []
    structs: list = []

    statics = getattr(definition, "static_values", {})

    def lookup(name):
        if name in statics:
            return statics[name]
        if name in env:
            return env[name]
        return scope.get(name, _MISSING)

    def add(symbol: ResolvedSymbol):
        symbols.setdefault(symbol.signature(), symbol)

    for chain in collector.chains:
        value = lookup(chain[0])
        if value is _MISSING:
            continue            # a Python builtin name (range, len, float, ...) or unknown
        if is_warp_module(value):
            # wp.transform_compose & co are @wp.func in weft's client (as in Warp): a function
            member = getattr(value, chain[1], None) if len(chain) > 1 else None
            if isinstance(member, Function):
                classify(".".join(chain[:2]), member, add, functions, structs)
                continue
            # warp.tests.helpers.CONST: a user's package under the alias name, resolved as Python does
            user_package = (len(chain) > 2 and isinstance(member, types.ModuleType) and
                            not is_warp_module(member))
            if not user_package:
                add(ResolvedSymbol(chain[0], "builtin_module", "warp"))
                continue
        used = 1
        # descend through plain modules: mymod.N, math.pi, pkg.sub.CONST
        while isinstance(value, types.ModuleType) and used < len(chain):
            value = getattr(value, chain[used], _MISSING)
            used += 1
            if value is _MISSING:
                break
            if is_warp_module(value):
                break
        if value is _MISSING:
            continue
        # descend through plain Python objects and classes: foo.compute where foo is an
        # instance holding a @wp.func, Config.N on a class (Warp resolves them the same way)
        while used < len(chain) and _opaque(value):
            value = getattr(value, chain[used], _MISSING)
            used += 1
        if value is _MISSING:
            continue
        # Python enums: MyEnum.A and MyEnum.A.value are the member's value (an int constant)
        if isinstance(value, enum.EnumMeta) and used < len(chain):
            value = value.__members__.get(chain[used], _MISSING)
            used += 1
            if value is _MISSING:
                continue
        if isinstance(value, enum.Enum):
            if used < len(chain) and chain[used] == "value":
                used += 1
            value = value.value
        name = ".".join(chain[:used])
        if is_warp_module(value):
            add(ResolvedSymbol(name, "builtin_module", "warp"))
            continue
        if isinstance(value, NativeSnippet):
            raise WeftCompileError(value.refusal(definition.name, definition.file, definition.first_line))
        classify(name, value, add, functions, structs)

    for name in sorted(collector.operator_names):
        value = lookup(name)
        if isinstance(value, Function):
            classify(name, value, add, functions, structs)

    gradient = getattr(definition, "custom_grad", None)
    if gradient is not None:     # wp.func_grad: travels with the func, keyed after it
        gradient.definition.key = definition.key + "__custom_grad"
        functions.append(gradient)
    replay = getattr(definition, "custom_replay", None)
    if replay is not None:       # wp.func_replay: the same way
        replay.definition.key = definition.key + "__custom_replay"
        functions.append(replay)
    return Resolution(list(symbols.values()), functions, structs)


def _opaque(value) -> bool:
    """True for a Python object or class that means nothing in kernel code itself (an instance
    of a user class, a user class), whose attributes may (a @wp.func, a constant, a type)."""
    if isinstance(value, (Function, StructType, enum.Enum, enum.EnumMeta, types.ModuleType)):
        return False
    if value is None or value is typing.Any or is_warp_module(value):
        return False
    if getattr(value, "__origin__", None) is not None:
        return False
    if isinstance(value, type):
        try:
            typestr.type_string(value)
            return False
        except TypeError:
            return True
    if typestr.constant_type_of(value) is not None or typestr.array_type_string(value) is not None:
        return False
    return hasattr(value, "__dict__") and not callable(value)


def classify(name: str, value, add, functions: list, structs: list) -> None:
    """Adds the symbol(s) that `name` bound to `value` means in kernel code."""
    if isinstance(value, Function):
        if value not in functions:
            functions.append(value)
        for overload in value.overloads:
            add(ResolvedSymbol(name, "function", overload.key))
        return
    if getattr(value, "_weft_builtin_", False) and isinstance(getattr(value, "key", None), str):
        add(ResolvedSymbol(name, "function", "__weft_builtin__." + value.key))   # TARGET = wp.sin
        return
    if isinstance(value, StructType):
        if value not in structs:
            structs.append(value)
        add(ResolvedSymbol(name, "type", value._type_str))
        return
    if isinstance(value, types.ModuleType) or value is None:
        return
    if value is typing.Any:
        add(ResolvedSymbol(name, "type", "any"))
        return
    if isinstance(value, type) or getattr(value, "__origin__", None) is not None:
        if value in (float, int, bool) and getattr(builtins, name, None) is value:
            return
        try:
            add(ResolvedSymbol(name, "type", typestr.type_string(value)))
        except TypeError:
            pass
        return
    constant_type = typestr.constant_type_of(value)
    if constant_type is not None:
        desc = typestr.parse(constant_type)
        add(ResolvedSymbol(name, "constant", "", constant_type, typestr.literal_text(desc, value)))
        return
    array_text = typestr.array_type_string(value)
    if array_text is not None:       # an annotation alias: Points = wp.array(dtype=wp.vec3)
        add(ResolvedSymbol(name, "type", array_text))
        return
    # anything else (a NumPy array, a Python function) is left for the daemon to reject at the
    # user's line as an unknown name
