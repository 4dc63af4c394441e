"""Language: generic kernels (typing.Any parameters) are instantiated per launch argument
types (float32, float64, vec3 arrays) and by wp.overload; generic @wp.func called with
several types from one kernel."""
from typing import Any

import numpy as np
import pytest

import weft as wp


@wp.kernel
def scale_any(a: wp.array(dtype=Any), s: Any):
    i = wp.tid()
    a[i] = a[i] * s


@wp.func
def add_twice(x: Any, y: Any):
    return x + y + y


@wp.kernel
def use_generic_func(f: wp.array(dtype=float), d: wp.array(dtype=wp.float64),
                     v: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    f[i] = add_twice(f[i], 1.0)
    d[i] = add_twice(d[i], wp.float64(0.25))
    v[i] = add_twice(v[i], wp.vec3(1.0, 2.0, 3.0))


def test_generic_kernel_instances(wp, rng):
    x32 = rng.standard_normal(50).astype(np.float32)
    x64 = rng.standard_normal(50)
    xv = rng.standard_normal((50, 3)).astype(np.float32)
    a32, a64 = wp.array(x32), wp.array(x64, dtype=wp.float64)
    av = wp.array(xv, dtype=wp.vec3)
    wp.launch(scale_any, dim=50, inputs=[a32, 2.0])
    wp.launch(scale_any, dim=50, inputs=[a64, wp.float64(3.0)])
    wp.launch(scale_any, dim=50, inputs=[av, 0.5])
    np.testing.assert_allclose(a32.numpy(), x32 * 2, rtol=1e-7)
    np.testing.assert_allclose(a64.numpy(), x64 * 3, rtol=1e-15)
    np.testing.assert_allclose(av.numpy(), xv * 0.5, rtol=1e-7)


def test_explicit_overload(wp):
    instance = wp.overload(scale_any, [wp.array(dtype=wp.float64), wp.float64])
    assert instance.param_types == ["array(float64,1)", "float64"]
    a = wp.full(4, 2.0, dtype=wp.float64)
    wp.launch(instance, dim=4, inputs=[a, wp.float64(1.5)])
    np.testing.assert_array_equal(a.numpy(), 3.0)


def test_generic_func_with_three_types(wp, rng):
    f = rng.standard_normal(20).astype(np.float32)
    d = rng.standard_normal(20)
    v = rng.standard_normal((20, 3)).astype(np.float32)
    fa, da, va = wp.array(f), wp.array(d, dtype=wp.float64), wp.array(v, dtype=wp.vec3)
    wp.launch(use_generic_func, dim=20, inputs=[fa, da, va])
    np.testing.assert_allclose(fa.numpy(), f + 2.0, rtol=1e-6)
    np.testing.assert_allclose(da.numpy(), d + 0.5, rtol=1e-15)
    np.testing.assert_allclose(va.numpy(), v + np.array([2.0, 4.0, 6.0]), rtol=1e-6)


# --- generic patterns: wp.Int / wp.Float / wp.Scalar, vectors and matrices of any length ---

@wp.func
def sum3_int(v: wp.types.vector(3, wp.Int)) -> wp.Int:
    return v[0] + v[1] + v[2]


@wp.func
def sum3_float(v: wp.types.vector(3, wp.Float)) -> wp.Float:
    return v[0] + v[1] + v[2]


@wp.func
def trace2(m: wp.types.matrix((Any, Any), wp.Scalar)):
    return m[0, 0] + m[1, 1]


@wp.func
def twice_scalar(x: wp.Scalar) -> wp.Scalar:
    return x + x


@wp.kernel
def pattern_calls(vi: wp.array(dtype=wp.vec3s), vd: wp.array(dtype=wp.vec3d),
                  md: wp.array(dtype=wp.mat22d), mi: wp.array(dtype=wp.types.matrix((3, 3), wp.int64)),
                  out_i: wp.array(dtype=wp.int16), out_d: wp.array(dtype=wp.float64),
                  out_m: wp.array(dtype=wp.float64), out_mi: wp.array(dtype=wp.int64),
                  out_t: wp.array(dtype=wp.float32)):
    i = wp.tid()
    out_i[i] = sum3_int(vi[i])
    out_d[i] = sum3_float(vd[i])
    out_m[i] = trace2(md[i])
    out_mi[i] = trace2(mi[i])
    out_t[i] = twice_scalar(wp.float32(out_d[i]))


def test_scalar_categories_and_any_shapes(wp, rng):
    n = 16
    vi = rng.integers(-1000, 1000, size=(n, 3)).astype(np.int16)
    vd = rng.standard_normal((n, 3)) * np.array([1e12, 1.0, 1e-12])
    md = rng.standard_normal((n, 2, 2)) * 1e8
    mi = rng.integers(-2**40, 2**40, size=(n, 3, 3), dtype=np.int64)
    outs = [wp.zeros(n, dtype=t) for t in (wp.int16, wp.float64, wp.float64, wp.int64, wp.float32)]
    wp.launch(pattern_calls, dim=n, inputs=[wp.array(vi, dtype=wp.vec3s), wp.array(vd, dtype=wp.vec3d),
                                            wp.array(md, dtype=wp.mat22d),
                                            wp.array(mi, dtype=wp.types.matrix((3, 3), wp.int64)), *outs])
    np.testing.assert_array_equal(outs[0].numpy(), vi.sum(axis=1).astype(np.int16))
    # float64 sums in the kernel's order (left to right), against a float64 reference
    np.testing.assert_allclose(outs[1].numpy(), (vd[:, 0] + vd[:, 1]) + vd[:, 2], rtol=1e-15)
    np.testing.assert_allclose(outs[2].numpy(), md[:, 0, 0] + md[:, 1, 1], rtol=1e-15)
    np.testing.assert_array_equal(outs[3].numpy(), mi[:, 0, 0] + mi[:, 1, 1])
    np.testing.assert_allclose(outs[4].numpy(), 2 * outs[1].numpy().astype(np.float32), rtol=1e-7)


@wp.kernel
def any_length_kernel(v: wp.types.vector(Any, float), out: wp.array(dtype=int)):
    out[0] = len(v)
    out[1] = int(v[len(v) - 1])


def test_kernel_parameter_of_any_length(wp):
    out = wp.zeros(2, dtype=int)
    wp.launch(any_length_kernel, dim=1, inputs=[wp.vec4(1.0, 2.0, 3.0, 7.0), out])
    np.testing.assert_array_equal(out.numpy(), [4, 7])
    wp.launch(any_length_kernel, dim=1, inputs=[wp.vec2(5.0, 9.0), out])
    np.testing.assert_array_equal(out.numpy(), [2, 9])


def test_pattern_mismatch_is_refused(wp):
    out = wp.zeros(2, dtype=int)
    with pytest.raises(wp.WeftLaunchError, match="does not match the annotation"):
        wp.launch(any_length_kernel, dim=1, inputs=[wp.vec3d(1.0, 2.0, 3.0), out])


def test_func_pattern_mismatch_is_a_compile_error(wp, kernel_module):
    mod = kernel_module('''
@wp.func
def only_ints(x: wp.Int):
    return x * 2

@wp.kernel
def k(a: wp.array(dtype=float)):
    a[0] = only_ints(a[0])
''')
    with pytest.raises(Exception, match="only_ints"):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float)])


def test_generic_types_cannot_be_constructed(wp):
    with pytest.raises(TypeError, match="generic"):
        wp.types.vector(Any, float)(1.0, 2.0)
    assert wp.types.vector(3, wp.Float)._wp_generic_type_str_ == "vec_t"
    assert wp.vec3._wp_generic_type_str_ == "vec_t" and wp.mat22._wp_generic_type_str_ == "mat_t"


@wp.kernel
def type_of_values(a: wp.array(dtype=Any), s: Any, out: wp.array(dtype=Any)):
    i = wp.tid()
    zero = type(a[i])(0)
    scaled = a[i] * type(s)(2)
    out[i] = a.dtype(scaled) + zero
    if i == 0:
        wp.expect_eq(type(s)(1.5), s - s + type(s)(1.5))


def test_type_of_a_value_in_a_kernel(wp, rng):
    x = rng.standard_normal(32)
    for dtype in (wp.float32, wp.float64):
        a = wp.array(x, dtype=dtype)
        out = wp.zeros(32, dtype=dtype)
        wp.launch(type_of_values, dim=32, inputs=[a, dtype(3.0), out])
        np.testing.assert_allclose(out.numpy(), x.astype(dtype._np_dtype_) * 2,
                                   rtol=1e-7 if dtype is wp.float32 else 1e-15)


@wp.kernel
def type_attributes(v: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    n = type(v[i]).length
    e = v.dtype.dtype(0.5)
    out[i] = wp.float64(n) * e + wp.dot(v[i], v.dtype(1.0))


def test_type_attributes_in_a_kernel(wp, rng):
    x = rng.standard_normal((8, 3)) * 1e6
    out = wp.zeros(8, dtype=wp.float64)
    wp.launch(type_attributes, dim=8, inputs=[wp.array(x, dtype=wp.vec3d), out])
    np.testing.assert_allclose(out.numpy(), 1.5 + ((x[:, 0] + x[:, 1]) + x[:, 2]), rtol=1e-15)


@wp.kernel
def type_as_a_local(a: Any, out: wp.array(dtype=Any)):
    v = wp.types.vector(length=2, dtype=type(a))   # a zero vector, as in Warp
    T = type(a)
    m = wp.identity(n=v.length, dtype=v.dtype) * a
    out[0] = wp.trace(m)
    out[1] = T(0.5) * a + v[1]


def test_value_dtype_length_and_a_type_bound_to_a_local(wp):
    for dtype in (wp.float32, wp.float64):
        out = wp.zeros(2, dtype=dtype)
        wp.launch(type_as_a_local, dim=1, inputs=[dtype(-1.25), out])
        np.testing.assert_array_equal(out.numpy(), [-2.5, -0.625])


@wp.kernel
def static_len_of_params(v: wp.types.vector(Any, float), m: wp.mat33, out: wp.array(dtype=int)):
    out[0] = wp.static(len(v))
    out[1] = wp.static(len(m)) * 10
    for k in range(wp.static(len(v))):
        out[2 + k] = int(v[k])


def test_static_len_of_a_kernel_parameter(wp):
    out = wp.zeros(8, dtype=int)
    wp.launch(static_len_of_params, dim=1, inputs=[wp.types.vector(5, float)(1.0, 2.0, 3.0, 4.0, 5.0),
                                                   wp.mat33(), out])
    np.testing.assert_array_equal(out.numpy(), [5, 30, 1, 2, 3, 4, 5, 0])


@wp.kernel
def stub_target(x: Any, out: wp.array(dtype=wp.float64)):
    out[0] = wp.float64(x) * wp.float64(2.0)


@wp.overload
def stub_target(x: wp.float32, out: wp.array(dtype=wp.float64)):  # noqa: F811 - Warp's stub form
    ...


def test_overload_stub_instantiates_the_generic_kernel(wp):
    assert isinstance(stub_target, wp.Kernel) and len(stub_target.overloads) == 1
    assert stub_target.overloads[0].param_types[0] == "float32"
    out = wp.zeros(1, dtype=wp.float64)
    wp.launch(stub_target, dim=1, inputs=[wp.float32(1.25), out])
    assert out.numpy()[0] == 2.5

    def with_return(x: wp.float64, out: wp.array(dtype=wp.float64)) -> float: ...
    with_return.__qualname__ = stub_target.__qualname__
    with pytest.raises(TypeError, match="Return annotations are not allowed"):
        wp.overload(with_return)


def test_named_kernels_of_one_function_and_an_ambiguous_stub(wp):
    def body(x: Any, out: wp.array(dtype=wp.float64)):
        out[0] = wp.float64(x) + wp.float64(1.0)

    body.__qualname__ = "named_kernel_body"
    a = wp.kernel(name="named_kernel_a")(body)
    b = wp.kernel(name="named_kernel_b")(body)
    assert a.key == "named_kernel_a" and b.key == "named_kernel_b" and a is not b
    out = wp.zeros(1, dtype=wp.float64)
    wp.launch(b, dim=1, inputs=[wp.float64(2.0), out])
    assert out.numpy()[0] == 3.0

    def named_kernel_body(x: float, out: wp.array(dtype=wp.float64)): ...
    named_kernel_body.__module__, named_kernel_body.__qualname__ = body.__module__, body.__qualname__
    with pytest.raises(RuntimeError, match="Ambiguous kernel lookup"):
        wp.overload(named_kernel_body)


def test_generic_types_never_reach_generated_code(wp, kernel_module):
    """A generic type sent where a concrete one is needed (a struct field, a value constructed
    in kernel code) is refused with a clear error, not emitted with a placeholder layout."""
    mod = kernel_module("""
AnyVec = wp.types.vector(typing.Any, float)

@wp.kernel
def construct(a: wp.array(dtype=float)):
    v = AnyVec(1.0, 2.0)
    a[0] = v[0]
""")
    with pytest.raises(wp.WeftCompileError, match="generic type vec\\(any,float32\\)"):
        wp.launch(mod.construct, dim=1, inputs=[wp.zeros(1, dtype=float)])
    with pytest.raises(TypeError, match="needs a concrete type, not the generic vec\\(3,any_int\\)"):
        kernel_module("""
@wp.struct
class Holder:
    v: wp.types.vector(3, wp.Int)
""")


@wp.struct
class Company:
    many: wp.float64


@wp.kernel
def company_kernel(c: Company, out: wp.array(dtype=wp.float64)):
    out[0] = c.many * wp.float64(2.0)


def test_a_struct_whose_name_holds_any_is_not_generic(wp):
    assert not company_kernel.is_generic
    c = Company()
    c.many = wp.float64(-0.75)
    out = wp.zeros(1, dtype=wp.float64)
    wp.launch(company_kernel, dim=1, inputs=[c, out])
    assert out.numpy()[0] == -1.5
