"""Compile errors: the exception's message names the user's file and the line of the
offending statement (as the daemon's diagnostics give it); wp.compile/load_module report
errors without launching; the daemon keeps serving; a broken kernel does not block the
other kernels of its module."""
import inspect
import re

import numpy as np
import pytest

import weft as wp
from weft._kernel.errors import WeftCompileError


def _line_of(func, needle):
    lines, start = inspect.getsourcelines(func)
    for k, text in enumerate(lines):
        if needle in text:
            return start + k
    raise AssertionError(needle)


def test_unknown_name_names_file_and_line(wp):
    @wp.kernel
    def broken_unknown(a: wp.array(dtype=float)):
        i = wp.tid()
        a[i] = undefined_thing_xyz * 2.0  # noqa: F821 - the error under test

    line = _line_of(broken_unknown.func, "undefined_thing_xyz")
    with pytest.raises(WeftCompileError) as info:
        wp.launch(broken_unknown, dim=1, inputs=[wp.zeros(1, dtype=float)])
    message = str(info.value)
    assert f"{__file__}:{line}" in message, message
    assert "undefined_thing_xyz" in message, message


def test_type_mismatch_names_line(wp):
    @wp.kernel
    def broken_types(a: wp.array(dtype=float)):
        i = wp.tid()
        v = wp.vec3(1.0, 2.0, 3.0)
        a[i] = v + 1.0

    line = _line_of(broken_types.func, "v + 1.0")
    with pytest.raises(WeftCompileError) as info:
        wp.compile(broken_types, device="cpu")
    assert f"{__file__}:{line}" in str(info.value), str(info.value)


def test_unsupported_construct_names_line(wp):
    @wp.kernel
    def broken_construct(a: wp.array(dtype=float)):
        i = wp.tid()
        xs = [x for x in range(3)]
        a[i] = float(xs[0])

    line = _line_of(broken_construct.func, "for x in range(3)]")
    with pytest.raises(WeftCompileError) as info:
        wp.compile(broken_construct, device="cpu")
    assert f"{__file__}:{line}" in str(info.value), str(info.value)


def test_error_in_func_points_into_the_func(wp):
    @wp.func
    def bad_helper(x: float):
        return x + no_such_global_abc  # noqa: F821

    @wp.kernel
    def calls_bad_helper(a: wp.array(dtype=float)):
        i = wp.tid()
        a[i] = bad_helper(a[i])

    line = _line_of(bad_helper.overloads[0].func, "no_such_global_abc")
    with pytest.raises(WeftCompileError) as info:
        wp.compile(calls_bad_helper, device="cpu")
    assert f"{__file__}:{line}" in str(info.value), str(info.value)


@wp.kernel
def fine_sibling(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = 42.0


def test_daemon_keeps_serving_and_siblings_still_compile(wp):
    @wp.kernel
    def broken_again(a: wp.array(dtype=float)):
        a[0] = nope_nope  # noqa: F821

    with pytest.raises(WeftCompileError):
        wp.compile(broken_again, device="cpu")
    a = wp.zeros(4, dtype=float)
    wp.launch(fine_sibling, dim=4, inputs=[a])
    np.testing.assert_array_equal(a.numpy(), 42.0)


def test_load_module_compiles_ahead_of_time(wp, kernel_module):
    good = kernel_module("""
        @wp.kernel
        def k1(a: wp.array(dtype=float)):
            a[wp.tid()] = 1.0

        @wp.kernel
        def k2(a: wp.array(dtype=float)):
            a[wp.tid()] = 2.0
    """)
    compiled = wp.load_module(good, device="cpu")
    assert compiled is not None and compiled.module_id
    bad = kernel_module("""
        @wp.kernel
        def k3(a: wp.array(dtype=float)):
            a[wp.tid()] = missing_name_q
    """)
    with pytest.raises(WeftCompileError) as info:
        wp.load_module(bad, device="cpu")
    line = next(k for k, text in enumerate(open(bad.__file__).read().splitlines(), 1)
                if "missing_name_q" in text)
    assert f"{bad.__file__}:{line}" in str(info.value), str(info.value)


@pytest.mark.parametrize("body", [
    "dst[0.0].x = 1.0",
    "dst[idx[0]].x += 1.0",
    "dst[idx[0]] += wp.vec3(1.0)",
    "dst[idx[0]] = wp.vec3(1.0)",
])
def test_float_index_of_an_element_write_is_a_type_error(wp, kernel_module, body):
    """Warp's TypeError for a non-integer index of an array element being written (a slot
    write); an integer index read inside the target (idx[0]) is fine."""
    m = kernel_module(f"""
        @wp.kernel
        def k(dst: wp.array(dtype=wp.vec3), idx: wp.array(dtype=wp.float32), ok: wp.array(dtype=int)):
            dst[ok[0]].y = 2.0
            {body}
    """)
    with pytest.raises(TypeError, match="Array slot write indices must be integers, got `float32`"):
        wp.load_module(m, device="cpu")


@pytest.mark.parametrize("body,want,got", [
    ("y[i].y = src[i]", "float32", "vec(3,float32)"),
    ("v = y[i]\n            v[1] = src[i]\n            y[i] = v", "float32", "vec(3,float32)"),
    ("m = wp.mat33()\n            m[0] = 1.0\n            y[i] = m[0]", "vec(3,float32)", "float32"),
])
def test_composite_slot_value_of_another_kind_is_a_type_error(wp, kernel_module, body, want, got):
    """Warp's TypeError for a composite slot written with a value of another kind (a vector
    into a component, a scalar into a matrix row)."""
    m = kernel_module(f"""
        @wp.kernel
        def k(y: wp.array(dtype=wp.vec3), src: wp.array(dtype=wp.vec3)):
            i = wp.tid()
            {body}
    """)
    with pytest.raises(TypeError, match=f"Composite slot assignment expects value of type `{re.escape(want)}`, "
                                        f"got `{re.escape(got)}`"):
        wp.load_module(m, device="cpu")


def test_an_unknown_name_is_a_key_error_as_in_warp(wp, kernel_module):
    mod = kernel_module("""
@wp.kernel
def k(a: wp.array(dtype=float)):
    a[0] = typez(1.0)
""")
    with pytest.raises(wp.WarpCodegenKeyError, match="Referencing undefined symbol: typez") as info:
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float)])
    assert isinstance(info.value, KeyError) and "unknown name 'typez'" in str(info.value)
