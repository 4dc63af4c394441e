"""Hardening of the compiler's input (issue 7, findings 1 and 2, native snippets and compile
limits), attacked through the public API: through the Python client where it sends the
hostile request itself, and with hand-made gRPC requests where it would not.

Each case asserts a clear error that names the field or the user's line, that the injected
code did not run (its marker file does not exist), and that the daemon keeps serving."""
import importlib.util
import os
import tempfile
import textwrap
import uuid
from pathlib import Path

import grpc
import numpy as np
import pytest

from weft._kernel.errors import WeftCompileError


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------

def _marker(tmp_path) -> Path:
    return tmp_path / f"pwned-{uuid.uuid4().hex[:8]}"


def _payload(marker: Path) -> str:
    """Text that, pasted raw into generated C++ after a `//` comment or a declaration, ends it
    and runs system() when the module is loaded (what issue 7 found)."""
    return (f'x;\n}};\nextern "C" int system(const char*);\n'
            f'static int weft_pwned = system("touch {marker}");\nstruct weft_more {{\nint y')


def _load(tmp_path, source: str):
    """Imports `source` (with `import weft as wp` in front) from a file: kernels need a file."""
    name = f"weft_sec_{uuid.uuid4().hex[:10]}"
    path = tmp_path / f"{name}.py"
    path.write_text("import weft as wp\n\n" + textwrap.dedent(source))
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _still_serves(wp):
    """A fresh kernel compiles and runs: the daemon survived and serves this session."""
    mod = _load(Path(tempfile.mkdtemp(prefix="weft-sec-")), """
        @wp.kernel
        def add_one(a: wp.array(dtype=float)):
            i = wp.tid()
            a[i] = a[i] + 1.0
    """)
    a = wp.array(np.arange(4, dtype=np.float32), dtype=float)
    wp.launch(mod.add_one, dim=4, inputs=[a])
    np.testing.assert_allclose(a.numpy(), [1, 2, 3, 4])


def _module_pb(name="sec_mod", kernel_name="k", file="sec_test.py", field="mass", struct="sec_mod.S",
               param="a", key=None, body="    a[0] = s.mass\n"):
    """A valid ModuleSource (one kernel taking an array and a struct) with any name replaced."""
    from weft.v1 import module_pb2

    src = f"def {kernel_name if kernel_name.isidentifier() else 'k'}(a: wp.array(dtype=float), s: S):\n" + body
    m = module_pb2.ModuleSource(name=name)
    m.functions.append(module_pb2.FunctionSource(
        name=kernel_name, source=src, file=file, first_line=1, is_kernel=True,
        param_types=["array(float32,1)", f"struct({struct if struct.replace('.', '').isalnum() else 'sec_mod.S'})"],
        param_names=[param, "s"], key=key if key is not None else f"{name}.{kernel_name}"))
    m.symbols.append(module_pb2.Symbol(name="wp", builtin_module="warp"))
    m.symbols.append(module_pb2.Symbol(name="S", type="struct(sec_mod.S)"))
    m.structs.append(module_pb2.StructDef(name="sec_mod.S", fields=[
        module_pb2.StructField(name="pos", type="vec(3,float32)"),
        module_pb2.StructField(name=field, type="float32")]))
    if struct != "sec_mod.S":
        m.structs.append(module_pb2.StructDef(name=struct, fields=[
            module_pb2.StructField(name="z", type="int32")]))
    return m


def _compile_raw(raw, module, device="cpu"):
    from weft.v1 import module_pb2

    return raw.modules.Compile(module_pb2.CompileRequest(module=module, device=device),
                               metadata=raw.metadata, timeout=60)


@pytest.fixture
def raw(weftd):
    with weftd.raw_session("pytest codegen security") as session:
        yield session


# --------------------------------------------------------------------------------------------
# Finding 1: client names reach generated code only mangled or escaped
# --------------------------------------------------------------------------------------------

def test_struct_field_name_injection_through_the_python_client(wp, tmp_path):
    marker = _marker(tmp_path)
    field = _payload(marker)
    mod = _load(tmp_path, f"""
        Evil = wp.struct(type("Evil", (), {{"__annotations__": {{"pos": wp.vec3, {field!r}: float}},
                                          "__module__": __name__, "__qualname__": "Evil"}}))

        @wp.kernel
        def use_evil(s: Evil, out: wp.array(dtype=float)):
            out[0] = s.pos[0]
    """)
    with pytest.raises(WeftCompileError) as info:
        wp.compile(mod.use_evil, device="cpu")
    message = str(info.value)
    assert ".fields[1].name" in message and "is not a Python identifier" in message, message
    assert "x;\\n}" in message, message     # the name is quoted with its newline escaped
    assert not marker.exists()
    _still_serves(wp)


def test_kernel_name_injection_through_the_python_client(wp, tmp_path):
    marker = _marker(tmp_path)
    mod = _load(tmp_path, f"""
        def k(out: wp.array(dtype=float)):
            out[0] = 1.0

        k.__name__ = {_payload(marker)!r}
        evil = wp.kernel(k)
    """)
    with pytest.raises(WeftCompileError) as info:
        wp.compile(mod.evil, device="cpu")
    message = str(info.value)
    assert "functions[0].name" in message and "is not a Python identifier" in message, message
    assert not marker.exists()
    _still_serves(wp)


@pytest.mark.parametrize("field", ["name", "kernel_name", "key", "param", "struct", "field", "option"])
def test_every_name_field_is_refused_raw(weftd, raw, wp, tmp_path, field):
    """Raw gRPC: each name field carrying the payload is refused with INVALID_ARGUMENT naming
    that field; nothing ran; the daemon serves this session and others."""
    marker = _marker(tmp_path)
    payload = _payload(marker)
    if field == "option":
        module = _module_pb()
        module.options[payload] = "1"
        expected = "options key"
    else:
        arg = {"name": "name", "kernel_name": "kernel_name", "key": "key", "param": "param",
               "struct": "struct", "field": "field"}[field]
        module = _module_pb(**{arg: payload})
        expected = {"name": "refused: name '", "kernel_name": "functions[0].name", "key": "functions[0].key",
                    "param": "functions[0].param_names[0]", "struct": "structs[1].name",
                    "field": "structs[0].fields[1].name"}[field]
    with pytest.raises(grpc.RpcError) as info:
        _compile_raw(raw, module)
    assert info.value.code() == grpc.StatusCode.INVALID_ARGUMENT, info.value
    details = info.value.details()
    assert expected in details and "x;\\n}" in details, details
    assert not marker.exists()
    assert _compile_raw(raw, _module_pb()).module_id        # the same session still compiles
    _still_serves(wp)                                        # and so does another


def test_hostile_file_name_is_escaped_not_refused(raw, wp, tmp_path):
    """File names are not identifiers: any text compiles, escaped in the generated comments."""
    marker = _marker(tmp_path)
    for file in [_payload(marker) + "\\", "dir/caf\u00e9 \u202e.py", "a*/b??/c\\"]:
        response = _compile_raw(raw, _module_pb(file=file))
        assert response.module_id and [k.name for k in response.kernels] == ["k"]
    assert not marker.exists()
    _still_serves(wp)


def test_injected_text_inside_kernel_source_is_only_python(raw, tmp_path):
    """The function body is parsed as the kernel language: C++ in it is a syntax error at its
    line, never compiled."""
    marker = _marker(tmp_path)
    module = _module_pb(body=f'    system("touch {marker}");\n')
    with pytest.raises(grpc.RpcError) as info:
        _compile_raw(raw, module)
    assert info.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "sec_test.py:2" in info.value.details(), info.value.details()
    assert not marker.exists()


@pytest.mark.parametrize("value", ["0", "1025", "-1", "abc", "", "16 ", "99999999999999999999",
                                   "16\n#include </etc/passwd>"])
def test_cpu_block_dim_option_is_checked(raw, wp, value):
    """The module option for cooperative CPU blocks is an integer from 1 to 1024 or the module
    is refused (text that is not printable already by the request's check of option values);
    16 compiles."""
    module = _module_pb()
    module.options["cpu_block_dim"] = value
    with pytest.raises(grpc.RpcError) as info:
        _compile_raw(raw, module)
    assert info.value.code() == grpc.StatusCode.INVALID_ARGUMENT, info.value
    details = info.value.details()
    if "\n" in value:     # the compile request's own check of option values comes first
        assert "is not a short printable ASCII value" in details, details
    else:
        assert "module option cpu_block_dim must be an integer from 1 to 1024" in details, details
    module.options["cpu_block_dim"] = "16"
    assert _compile_raw(raw, module).module_id
    _still_serves(wp)


def test_valid_unusual_names_are_mangled_not_refused(raw, wp):
    """Names the identifier grammar accepts but C++ would not (non-ASCII letters in a module
    name, C++ keywords, 'Z' and '_' that a lossy mangling would merge) compile: they are
    mangled, not refused; two structs whose names differ only by '.' and '_' stay distinct."""
    from weft.v1 import module_pb2

    module = _module_pb(name="m\u00f3dulo.Zeta_\u00df", field="delete", body="    a[0] = s.delete\n")
    module.structs.append(module_pb2.StructDef(name="sec_mod_S", fields=[
        module_pb2.StructField(name="template", type="int32")]))
    response = _compile_raw(raw, module)
    assert response.module_id and [k.name for k in response.kernels] == ["k"]
    params = {p.name: p for p in response.kernels[0].params}
    assert params["s"].size == 16, params      # vec3 pos + float delete


# --------------------------------------------------------------------------------------------
# Finding 2: wp.printf formats are checked against the arguments when compiling
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("call, reason", [
    ('wp.printf("%p %p\\n", i, i)', "conversion %p is not supported"),
    ('wp.printf("%s\\n", i)', "conversion %s is not supported"),
    ('wp.printf("%n\\n", i)', "conversion %n is not supported"),
    ('wp.printf("%*d\\n", i, i)', "'*'"),
    ('wp.printf("%d\\n", x)', "expects an integer but argument 1 is float32"),
    ('wp.printf("%f\\n", i)', "expects a float but argument 1 is int32"),
    ('wp.printf("%d %d\\n", i)', "more conversions than arguments"),
    ('wp.printf("%d\\n", i, i)', "1 conversion(s) but 2 argument(s)"),
])
def test_printf_format_is_checked_at_compile_time(wp, tmp_path, call, reason):
    mod = _load(tmp_path, f"""
        @wp.kernel
        def fmt(a: wp.array(dtype=float)):
            i = wp.tid()
            x = a[i]
            {call}
    """)
    with pytest.raises(WeftCompileError) as info:
        wp.compile(mod.fmt, device="cpu")
    message = str(info.value)
    assert reason in message, message
    assert f"{mod.__file__}:8" in message, message     # the printf's line in the user's file
    _still_serves(wp)


def test_allowed_printf_formats_and_literal_percent_signs(wp, tmp_path, capfd):
    mod = _load(tmp_path, """
        @wp.kernel
        def fmt(a: wp.array(dtype=float), n: wp.array(dtype=wp.int64)):
            i = wp.tid()
            wp.printf("sec-fmt %+04d|%x|%.2f|%e|%d|100%%\\n", i, 255, a[i], a[i], n[i])
            print("sec-lit 100% %s %n %p")
    """)
    a = wp.array(np.array([1.5], dtype=np.float32), dtype=float)
    n = wp.array(np.array([-(2 ** 40)], dtype=np.int64), dtype=wp.int64)
    wp.launch(mod.fmt, dim=1, inputs=[a, n])
    wp.synchronize()
    out = capfd.readouterr().out
    assert "sec-fmt +000|ff|1.50|1.500000e+00|-1099511627776|100%" in out, out
    assert "sec-lit 100% %s %n %p" in out, out


# --------------------------------------------------------------------------------------------
# Native snippets: weft compiles only the kernel language
# --------------------------------------------------------------------------------------------

def test_native_snippets_are_refused(wp, tmp_path):
    """A native snippet's C++ never reaches the daemon: the kernel that calls it (through a
    @wp.func) fails to build with the reason and both places; the module's other kernel still
    builds and runs; calling the snippet from Python raises the same refusal."""
    mod = _load(tmp_path, """
        @wp.func_native('return system("id");')
        def snippet(x: int) -> int:
            ...

        @wp.func
        def via_func(x: int):
            return snippet(x) + 1

        @wp.kernel
        def calls_snippet(a: wp.array(dtype=int)):
            i = wp.tid()
            a[i] = via_func(a[i])

        @wp.kernel
        def plain(a: wp.array(dtype=int)):
            i = wp.tid()
            a[i] = a[i] * 3 + 1
    """)
    a = wp.array(np.arange(5, dtype=np.int32), dtype=int)
    with pytest.raises(WeftCompileError) as info:
        wp.launch(mod.calls_snippet, dim=5, inputs=[a])
        wp.synchronize()
    message = str(info.value)
    assert "native snippet" in message and "'via_func' calls 'snippet'" in message, message
    assert "system" not in message, "the snippet's text is not echoed"
    wp.launch(mod.plain, dim=5, inputs=[a])
    np.testing.assert_array_equal(a.numpy(), np.arange(5) * 3 + 1)   # calls_snippet never ran
    with pytest.raises(WeftCompileError):
        mod.snippet(3)


# --------------------------------------------------------------------------------------------
# Compile limits
# --------------------------------------------------------------------------------------------

def test_default_limits_refuse_huge_modules_quickly(raw, wp):
    from weft.v1 import module_pb2

    big = _module_pb(body="    a[0] = s.mass\n" + "    a[0] = a[0] + 1.0\n" * 150_000)  # ~3.5 MB
    with pytest.raises(grpc.RpcError) as info:
        _compile_raw(raw, big)
    assert info.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert "max_module_bytes" in info.value.details(), info.value.details()

    many = _module_pb()
    for n in range(2001):
        many.functions.append(module_pb2.FunctionSource(
            name=f"f{n}", source=f"def f{n}():\n    pass\n", file="many.py", first_line=1,
            key=f"sec_mod.f{n}"))
    with pytest.raises(grpc.RpcError) as info:
        _compile_raw(raw, many)
    assert info.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert "max_functions" in info.value.details() and "2000" in info.value.details()
    _still_serves(wp)


def test_deep_nesting_is_a_clear_error(raw):
    depth = 120
    body = "".join("    " * (d + 1) + "if a[0] > 0.0:\n" for d in range(depth))
    body += "    " * (depth + 1) + "a[0] = 1.0\n"
    with pytest.raises(grpc.RpcError) as info:
        _compile_raw(raw, _module_pb(body=body))
    assert info.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert "too many statically nested blocks" in info.value.details()
    parens = "    a[0] = " + "-" * 1100 + "1.0\n"     # one unit per unary minus
    with pytest.raises(grpc.RpcError) as info:
        _compile_raw(raw, _module_pb(body=parens))
    assert "expression too deeply nested" in info.value.details()
    assert _compile_raw(raw, _module_pb()).module_id


def test_configured_limits(start_weftd, tmp_path):
    """A weftd with small compile limits, set in a TOML file and on the command line."""
    from weft.v1 import module_pb2

    config = tmp_path / "weftd.toml"
    config.write_text("max-module-bytes = 4096\nmax_functions = 3\n")
    limited = start_weftd(["--config", str(config), "--max-block-depth", "4",
                           "--max-expression-depth", "40"])
    with limited.raw_session("pytest limits") as raw:
        assert _compile_raw(raw, _module_pb()).module_id
        with pytest.raises(grpc.RpcError) as info:
            _compile_raw(raw, _module_pb(body="    a[0] = s.mass\n" * 300))
        assert info.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
        assert "4096" in info.value.details() and "max_module_bytes" in info.value.details()

        many = _module_pb()
        for n in range(3):
            many.functions.append(module_pb2.FunctionSource(
                name=f"f{n}", source=f"def f{n}():\n    pass\n", file="m.py", first_line=1,
                key=f"sec_mod.f{n}"))
        with pytest.raises(grpc.RpcError) as info:
            _compile_raw(raw, many)
        assert "at most 3" in info.value.details(), info.value.details()

        nested = "".join("    " * (d + 1) + "if a[0] > 0.0:\n" for d in range(4))
        nested += "    " * 5 + "a[0] = 1.0\n"
        with pytest.raises(grpc.RpcError) as info:
            _compile_raw(raw, _module_pb(body=nested))
        assert "this daemon allows 4" in info.value.details(), info.value.details()
        assert "sec_test.py:" in info.value.details()
        with pytest.raises(grpc.RpcError) as info:
            _compile_raw(raw, _module_pb(body="    a[0] = " + "(" * 30 + "1.0" + ")" * 30 + "\n"))
        assert "expression too deeply nested" in info.value.details()
        assert _compile_raw(raw, _module_pb(body="    a[0] = ((1.0))\n")).module_id
