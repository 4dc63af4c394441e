"""pytest plugin: writes every module the client compiles as a seed of the compile fuzzer.

Usage (with a built weftd):
    WEFT_FUZZ_SEED_DIR=tests/fuzz/corpus/compile WEFT_DAEMON=build/bin/weftd \
        .venv/bin/python -m pytest -q -p capture_compile_seeds clients/python/tests/kernels
(run with tests/fuzz on PYTHONPATH). Each seed is the module in the line format of
tests/fuzz/module_text.h, named by its SHA-1; the codegen line asks for the adjoint too when
the module's options do.
"""
import hashlib
import os
from pathlib import Path


def _field(s: str) -> str:
    if s == "":
        return "-"
    out = []
    for ch in s:
        c = ord(ch)
        if ch == " ":
            out.append("\\s")
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\r":
            out.append("\\r")
        elif ch == "\t":
            out.append("\\t")
        elif ch == "\\":
            out.append("\\\\")
        elif c < 0x20 or c == 0x7F:
            out.append("\\x%02x" % c)
        else:
            out.append(ch)
    text = "".join(out)
    return "\\-" if text == "-" else text


def module_text(source) -> str:
    """weft.v1.ModuleSource -> the compile fuzzer's text format."""
    lines = [f"module {_field(source.name)}"]
    backward = source.options.get("enable_backward", "") in ("true", "1", "True")
    lines.append("codegen cpu" + (" backward" if backward else ""))
    for k in sorted(source.options):
        lines.append(f"option {_field(k)} {_field(source.options[k])}")
    for st in source.structs:
        lines.append(f"struct {_field(st.name)}")
        for f in st.fields:
            lines.append(f"field {_field(f.name)} {_field(f.type)}")
    for sym in source.symbols:
        kind = sym.WhichOneof("kind")
        if kind == "constant":
            lines.append(f"const {_field(sym.name)} {_field(sym.constant.type)} {_field(sym.constant.value)}")
        elif kind == "function":
            lines.append(f"func {_field(sym.name)} {_field(sym.function)}")
        elif kind == "type":
            lines.append(f"type {_field(sym.name)} {_field(sym.type)}")
        elif kind == "builtin_module":
            lines.append(f"builtin {_field(sym.name)} {_field(sym.builtin_module)}")
    for fn in source.functions:
        rec = "kernel" if fn.is_kernel else "function"
        line = f"{rec} {_field(fn.name)} {_field(fn.key)} {_field(os.path.basename(fn.file))} {fn.first_line}"
        if fn.return_type:
            line += f" {_field(fn.return_type)}"
        lines.append(line)
        for name, typ in zip(fn.param_names, fn.param_types):
            lines.append(f"param {_field(name)} {_field(typ)}")
        lines.append("source")
        body = fn.source if fn.source.endswith("\n") else fn.source + "\n"
        lines.append(body + ".end")
    return "\n".join(lines) + "\n"


def pytest_configure(config):
    out_dir = os.environ.get("WEFT_FUZZ_SEED_DIR")
    if not out_dir:
        return
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    from weft._kernel import module as kernel_module  # noqa: PLC0415

    original = kernel_module._compile_source

    def capturing(source, device):
        text = module_text(source).encode()
        (out / hashlib.sha1(text).hexdigest()).write_bytes(text)
        return original(source, device)

    kernel_module._compile_source = capturing
