"""Symbol resolution and ModuleSource contents (docs/protocol.md), checked without a daemon:
warp module aliases, constants (wp.constant, module ints/floats/bools, math.pi, mymod.N),
@wp.func overloads and generics (recursively), struct and vector types, file and line."""
from __future__ import annotations

import math
import typing

import numpy as np
import pytest

import weft
import weft as wp
from weft import types as wtypes
from weft._kernel import api
from weft._kernel import module as module_mod
from weft._kernel.errors import WeftCompileError

alias_of_weft = weft
N_POINTS = 17
HALF = 0.5
FLAG = True
GRAVITY = api.constant(wtypes.vec3(0.0, -9.8, 0.0))
DOUBLE = api.constant(wtypes.float64(2.25))
vec5 = wtypes.vector(5, wtypes.float32)


@api.struct
class Inner:
    weight: float
    values: wp.array(dtype=float)


@api.struct
class Outer:
    inner: Inner
    count: int


@api.func
def scale(x: float):
    return x * HALF


@api.func
def scale(x: int):  # noqa: F811 - an overload, as in Warp
    return x * N_POINTS


@api.func
def twice(x: typing.Any):
    return scale(x) + scale(x)


@api.kernel
def uses_everything(a: wp.array(dtype=float), b: wp.array2d(dtype=wtypes.vec3), o: Outer,
                    s: float):
    i = wp.tid()
    v = vec5()
    g = GRAVITY
    x = twice(a[i]) + math.pi + float(N_POINTS) + alias_of_weft.sin(s)
    if FLAG:
        b[i, 0] = g * x * float(DOUBLE)
    local_name = 3
    a[i] = x + float(local_name) + o.inner.weight


def _source():
    msg, _group = module_mod.build_module_source(uses_everything)
    return msg


def _symbols(msg):
    out = {}
    for s in msg.symbols:
        out.setdefault(s.name, []).append(s)
    return out


def test_functions_are_sent_with_file_line_and_types():
    msg = _source()
    kern = next(f for f in msg.functions if f.is_kernel)
    assert kern.name == "uses_everything"
    assert kern.file == __file__
    lines = open(__file__).read().splitlines()
    assert lines[kern.first_line - 1].startswith("def uses_everything(")
    assert kern.source.startswith("def uses_everything(")
    assert "@api.kernel" not in kern.source
    assert list(kern.param_types) == ["array(float32,1)", "array(vec(3,float32),2)",
                                      f"struct({Outer.key})", "float32"]
    assert list(kern.param_names) == ["a", "b", "o", "s"]


def test_func_overloads_and_generics_are_pulled_in_recursively():
    msg = _source()
    funcs = {f.key: f for f in msg.functions if not f.is_kernel}
    scale_keys = sorted(k for k, f in funcs.items() if f.name == "scale")
    assert len(scale_keys) == 2
    assert {tuple(funcs[k].param_types) for k in scale_keys} == {("float32",), ("int32",)}
    twice_fn = next(f for f in funcs.values() if f.name == "twice")
    assert list(twice_fn.param_types) == ["any"]
    syms = _symbols(msg)
    assert sorted(s.function for s in syms["scale"]) == scale_keys
    assert [s.function for s in syms["twice"]] == [twice_fn.key]


def test_constants_and_modules():
    syms = _symbols(_source())
    assert syms["wp"][0].builtin_module == "warp"
    assert syms["alias_of_weft"][0].builtin_module == "warp"
    assert syms["N_POINTS"][0].constant.type == "int32"
    assert syms["N_POINTS"][0].constant.value == "17"
    assert syms["HALF"][0].constant.type == "float32"
    assert float(syms["HALF"][0].constant.value) == 0.5
    assert syms["FLAG"][0].constant.value == "True"
    assert syms["math.pi"][0].constant.type == "float32"
    assert np.float32(syms["math.pi"][0].constant.value) == np.float32(math.pi)
    assert syms["GRAVITY"][0].constant.type == "vec(3,float32)"
    assert syms["GRAVITY"][0].constant.value == "(0.0, -9.8, 0.0)"
    assert syms["DOUBLE"][0].constant.type == "float64"
    assert "local_name" not in syms and "i" not in syms and "x" not in syms


def test_types_and_structs():
    msg = _source()
    syms = _symbols(msg)
    assert syms["vec5"][0].type == "vec(5,float32)"
    assert syms["Outer"][0].type == f"struct({Outer.key})"
    names = [s.name for s in msg.structs]
    assert names == [Inner.key, Outer.key]          # dependencies first
    inner = msg.structs[0]
    assert [(f.name, f.type) for f in inner.fields] == [("weight", "float32"),
                                                        ("values", "array(float32,1)")]


def test_content_hash_is_deterministic():
    a = module_mod.content_hash(_source())
    b = module_mod.content_hash(_source())
    assert a == b


def test_missing_annotation_is_a_clear_error():
    with pytest.raises(WeftCompileError, match=r"test_symbols_resolution.py:\d+.*'x'.*annotation"):
        @api.kernel
        def no_annotation(x):
            pass


def test_struct_instances_have_attribute_access_and_validate():
    o = Outer()
    assert o.count == 0 and o.inner.weight == 0.0 and o.inner.values is None
    o.count = 5
    o.inner.weight = 1.5
    assert o.count == 5 and o.inner.weight == 1.5
    with pytest.raises(AttributeError):
        o.missing = 1
    with pytest.raises(TypeError):
        o.inner = 3


def test_closure_constants_resolve():
    local_n = 42

    @api.kernel
    def closure_kernel(a: wp.array(dtype=int)):
        a[0] = local_n

    msg, _ = module_mod.build_module_source(closure_kernel)
    syms = _symbols(msg)
    assert syms["local_n"][0].constant.value == "42"
