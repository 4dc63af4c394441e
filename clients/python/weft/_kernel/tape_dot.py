"""wp.Tape.visualize: the recorded launches as GraphViz DOT text (Warp's API). Kernels are
boxes, arrays ellipses with an edge into each launch that takes them; record_scope_begin/end
scopes are clusters; with simplify_graph, consecutive launches of one kernel on the same
arguments are one box labelled "(repeated Nx)"."""
from __future__ import annotations


def _quote(text: str) -> str:
    return '"' + str(text).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _type_name(dtype) -> str:
    from ..types import type_repr  # noqa: PLC0415
    try:
        return type_repr(dtype)
    except Exception:  # noqa: BLE001 - a label only
        return getattr(dtype, "__name__", str(dtype))


def _kernel_name(kernel) -> str:
    return getattr(kernel, "key", None) or getattr(kernel, "name", None) or "kernel"


def tape_dot(tape, simplify_graph=True, array_labels=None, graph_direction="LR") -> str:
    """The DOT text of `tape`'s records (launches, record_func callbacks, scopes)."""
    from .launch import is_weft_array  # noqa: PLC0415

    labels = {id(a): name for a, name in (array_labels or {}).items()}
    # Runs of identical consecutive launches (same kernel, same argument objects).
    nodes = []   # (first index, entry, count)
    for index, entry in enumerate(tape.launches):
        args = getattr(entry, "args", None)
        if simplify_graph and nodes and args is not None:
            _, last, count = nodes[-1]
            if getattr(last, "kernel", None) is entry.kernel and \
                    [id(a) for a in last.args] == [id(a) for a in args]:
                nodes[-1] = (nodes[-1][0], last, count + 1)
                continue
        nodes.append((index, entry, 1))
    scopes = sorted(getattr(tape, "_scopes", []), key=lambda s: (s[0], -s[1]))
    lines = ["digraph tape {", f"  graph [rankdir={graph_direction}];"]
    arrays = {}
    body: dict = {}   # node index -> DOT lines

    for n, (index, entry, count) in enumerate(nodes):
        if getattr(entry, "args", None) is None:
            label = f"record_func {getattr(entry.backward, '__name__', 'callback')}"
            values = entry.arrays
        else:
            label = _kernel_name(entry.kernel)
            values = entry.args
        if count > 1:
            label += f" (repeated {count}x)"
        node_lines = [f"  k{n} [shape=box, label={_quote(label)}];"]
        for value in values:
            if not is_weft_array(value):
                continue
            name = arrays.get(id(value))
            if name is None:
                name = arrays[id(value)] = f"a{len(arrays)}"
                text = labels.get(id(value)) or f"array {tuple(value.shape)}"
                tip = (f"array: dtype={_type_name(value.dtype)}, shape={tuple(value.shape)}, "
                       f"requires_grad={bool(value.requires_grad)}")
                lines.append(f"  {name} [shape=ellipse, label={_quote(text)}, "
                             f"tooltip={_quote(tip)}];")
            node_lines.append(f"  {name} -> k{n};")
        body[index] = node_lines

    def emit(first, last, depth):
        """Launch nodes with first <= index < last, and the scopes inside that range."""
        out = []
        index = first
        inner = [s for s in scopes if s[0] >= first and s[1] <= last and s[2] == depth]
        for begin, end, _, name in inner:
            while index < begin:
                out += body.get(index, [])
                index += 1
            out.append(f"  subgraph cluster_{begin}_{end}_{depth} {{")
            out.append(f"    label={_quote(name)};")
            out += ["  " + line for line in emit(begin, end, depth + 1)]
            out.append("  }")
            index = max(index, end)
        while index < last:
            out += body.get(index, [])
            index += 1
        return out

    lines += emit(0, len(tape.launches), 0)
    lines.append("}")
    return "\n".join(lines) + "\n"
