"""Which array parameters a kernel reads and writes (Warp's `kernel.adj.args[i].is_read` /
`is_write`), found from the kernel's Python syntax tree and those of the @wp.func it calls; and
the checks of `wp.config.verify_autograd_array_access` (Warp's): a launch recorded on a tape
that writes an array an earlier recorded launch read, or a kernel that writes an array after
reading it, prints a warning (the backward pass would see the overwritten values).

Rules (Warp's codegen): `a[i]` as a value reads a; `a[i] = v`, `a[i] op= v`, `a[i].x = v` and
`wp.atomic_*(a, ...)` write it (an in-place operator is a write only); `v = a[i]` on fewer
indices than a's dimensions is a view of a (its reads and writes are a's); passing a to a
@wp.func reads/writes a as the func's parameter does; passing it to another builtin reads it."""
from __future__ import annotations

import ast
import dataclasses
import sys

_ATOMICS = {"atomic_add", "atomic_sub", "atomic_min", "atomic_max", "atomic_cas", "atomic_exch",
            "atomic_and", "atomic_or", "atomic_xor"}


@dataclasses.dataclass
class ArgAccess:
    """One kernel parameter as Warp's adj.args[i] describes it."""

    label: str
    is_read: bool = False
    is_write: bool = False


class Adjoint:
    """The part of Warp's `kernel.adj` that reports parameter access."""

    def __init__(self, definition):
        self.fun_name = definition.name
        self.filename = definition.file
        self.fun_lineno = definition.first_line
        self.args = [ArgAccess(n) for n in definition.param_names]
        self.write_after_read: list = []     # parameters written after being read, in order
        self._definition = definition
        self._analyzed = False

    def analyze(self) -> "Adjoint":
        if not self._analyzed:
            self._analyzed = True
            access = _access_of(self._definition, set())
            for arg in self.args:
                read, write, war = access.get(arg.label, (False, False, False))
                arg.is_read, arg.is_write = read, write
                if war:
                    self.write_after_read.append(arg.label)
        return self


def _array_ndim(type_str: str) -> int:
    if type_str.startswith("array(") and type_str.endswith(")"):
        try:
            return int(type_str.rsplit(",", 1)[1][:-1])
        except ValueError:
            return 0
    return 0


def _resolve(definition, node):
    """The Python object a call's function expression names (a weft Function, or None)."""
    scope = dict(definition.func.__globals__)
    scope.update(definition.environment())
    scope.update(definition.static_values)
    chain = []
    while isinstance(node, ast.Attribute):
        chain.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    value = scope.get(node.id)
    for attr in reversed(chain):
        value = getattr(value, attr, None)
    return value


def _access_of(definition, visiting: set) -> dict:
    """param name -> (read, write, written after read) for the array parameters of one def."""
    key = id(definition)
    if key in visiting:              # recursion: no further information
        return {}
    visiting = visiting | {key}
    ndims = {n: _array_ndim(t) for n, t in zip(definition.param_names, definition.param_types)}
    arrays = {n for n, d in ndims.items() if d or definition.param_types[definition.param_names.index(n)] == "any"}
    alias: dict = {n: n for n in arrays}     # local name -> array parameter it views
    alias_ndim: dict = {n: ndims[n] for n in arrays}   # local name -> dimensions it has
    state: dict = {n: [False, False, False] for n in arrays}

    def base_param(node):
        """The array parameter a (possibly indexed/attributed) expression is rooted at; None
        for the array's metadata (`a.shape[0]` reads no element)."""
        while isinstance(node, (ast.Subscript, ast.Attribute)):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and \
                    node.value.id in alias and node.attr in ("shape", "ndim", "size", "strides"):
                return None
            node = node.value
        return alias.get(node.id) if isinstance(node, ast.Name) else None

    def read(p):
        if p is not None:
            state[p][0] = True

    def write(p):
        if p is not None:
            if state[p][0]:
                state[p][2] = True
            state[p][1] = True

    def visit_expr(node):
        if isinstance(node, ast.Subscript):
            p = base_param(node)
            visit_expr_children(node)
            read(p)
            return
        if isinstance(node, ast.Call):
            target = _resolve(definition, node.func)
            name = node.func.attr if isinstance(node.func, ast.Attribute) else \
                node.func.id if isinstance(node.func, ast.Name) else ""
            for a in node.args:
                if not isinstance(a, ast.Name):
                    visit_expr(a)
            for k in node.keywords:
                visit_expr(k.value)
            args = [base_param(a) if isinstance(a, ast.Name) else None for a in node.args]
            if hasattr(target, "overloads"):           # a @wp.func: its own parameters' access
                for d in getattr(target, "overloads", []):
                    inner = _access_of(d, visiting)
                    for p, pname in zip(args, d.param_names):
                        r, w, war = inner.get(pname, (False, False, False))
                        if r:
                            read(p)
                        if w:
                            write(p)
                        if war and p is not None:
                            state[p][2] = True
            elif name in _ATOMICS:
                if args:
                    write(args[0])
            else:
                for p in args:
                    read(p)
            return
        visit_expr_children(node)

    def visit_expr_children(node):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.expr):
                visit_expr(child)

    def visit_target(node):
        if isinstance(node, (ast.Subscript, ast.Attribute)):
            p = base_param(node)
            if isinstance(node, ast.Subscript):
                visit_expr(node.slice)
            if p is not None:
                write(p)
        elif isinstance(node, (ast.Tuple, ast.List)):
            for e in node.elts:
                visit_target(e)

    def visit_stmt(node):
        if isinstance(node, ast.Assign):
            # `v = a[i]` with fewer indices than a's dimensions: v views a
            value = node.value
            if len(node.targets) == 1 and isinstance(node.targets[0], ast.Name) and \
                    isinstance(value, ast.Subscript) and isinstance(value.value, ast.Name) and \
                    value.value.id in alias:
                p = alias[value.value.id]
                n_idx = len(value.slice.elts) if isinstance(value.slice, ast.Tuple) else 1
                have = alias_ndim.get(value.value.id, 0)
                if have > n_idx:
                    visit_expr(value.slice)
                    alias[node.targets[0].id] = p
                    alias_ndim[node.targets[0].id] = have - n_idx
                    return
            visit_expr(value)
            for t in node.targets:
                visit_target(t)
            return
        if isinstance(node, ast.AugAssign):
            visit_expr(node.value)
            visit_target(node.target)       # in place: a write, not a read (Warp)
            return
        if isinstance(node, ast.AnnAssign):
            if node.value is not None:
                visit_expr(node.value)
            visit_target(node.target)
            return
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.stmt):
                visit_stmt(child)
            elif isinstance(child, ast.expr):
                visit_expr(child)

    for stmt in definition.tree.body:
        visit_stmt(stmt)
    return {p: tuple(v) for p, v in state.items()}


# ------------------------------------------------------------------------------------------
# Read flags of arrays (wp.config.verify_autograd_array_access)


def warn(message: str) -> None:
    """Warp's log_warning: through the active logger (one line on the current stderr by
    default)."""
    from weft.logger import log_warning  # noqa: PLC0415

    log_warning(message, UserWarning)


def check_launch(kernel, args) -> None:
    """A launch being recorded with wp.config.verify_autograd_array_access: the kernel's own
    write-after-read warning (once per kernel, as Warp's codegen gives it), then the arrays'
    read flags and the warning for writing an array an earlier recorded launch read."""
    adj = kernel.adj
    if not kernel.__dict__.get("_weft_access_warned"):
        kernel.__dict__["_weft_access_warned"] = True
        warn_write_after_read(kernel)
    check_kernel_launch(kernel, args)


def check_kernel_launch(kernel, args) -> None:
    """Marks the arrays a recorded launch reads, and warns for those it writes after an earlier
    recorded launch read them (Warp's Tape._check_kernel_array_access)."""
    adj = kernel.adj
    for i, arg in enumerate(args):
        if i >= len(adj.args) or not hasattr(arg, "mark_read"):
            continue
        a = adj.args[i]
        if a.is_write:
            arg.mark_write(arg_name=a.label, kernel_name=adj.fun_name, filename=adj.filename,
                           lineno=adj.fun_lineno)
        if a.is_read:
            arg.mark_read()


def warn_write_after_read(kernel) -> None:
    """Warp's codegen warning for a kernel that writes an array after reading it."""
    adj = kernel.adj
    for label in adj.write_after_read:
        warn(f"Array passed to argument {label} in kernel {adj.fun_name} at "
             f"{adj.filename}:{adj.fun_lineno} is being written to after it has been read from "
             f"within the same kernel. This may corrupt gradient computation in the backward pass.")


def caller_location():
    """(file, line) of the innermost frame outside the weft package."""
    import os  # noqa: PLC0415

    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
    frame = sys._getframe(1)
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(package):
        frame = frame.f_back
    return (frame.f_code.co_filename, frame.f_lineno) if frame is not None else (None, None)
