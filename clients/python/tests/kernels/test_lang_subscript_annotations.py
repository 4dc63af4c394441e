"""Language: Warp 1.19's subscript annotations. `wp.array[float]`, `wp.array2d[wp.vec3]`,
`wp.array[T, Literal[N]]`, `wp.indexedarray[T]`, `Vector[T, N]` / `Matrix[T, R, C]` in kernel
and func signatures, struct fields and overloads (run on every test device against float64
references), the annotation objects themselves (equality, hashing, repr, the array-family
helpers, Warp's type codes), and what is refused: malformed subscripts, unions in kernels,
Fabric arrays and tiles in kernels (with file:line), lists passed for arrays."""
from __future__ import annotations

from typing import Any, Literal

import numpy as np
import pytest

import weft as wp
import weft.types as wt
from weft.types import Matrix, Quaternion, Transformation, Vector


@wp.kernel
def axpy_subscript(x: wp.array[float], y: wp.array[float], a: float, out: wp.array[float]):
    i = wp.tid()
    out[i] = a * x[i] + y[i]


@wp.kernel
def rows_dot(m: wp.array2d[Vector[wp.float64, Literal[3]]], v: wp.array[wp.vec3d],
             out: wp.array[wp.float64, Literal[2]]):
    i, j = wp.tid()
    out[i, j] = wp.dot(m[i, j], v[j])


@wp.kernel
def mat_apply(ms: wp.array[Matrix[float, 3, 3]], vs: wp.array[wp.vec3], out: wp.array[wp.vec3]):
    i = wp.tid()
    out[i] = ms[i] * vs[i]


@wp.kernel
def gather_indexed(a: wp.indexedarray[float], out: wp.array[float]):
    i = wp.tid()
    out[i] = a[i] * 2.0
    a[i] = -a[i]          # through the view: the base array changes at the indexed places


@wp.struct
class Samples:
    values: wp.array[wp.float64]
    scale: wp.float64


@wp.kernel
def scale_struct(s: Samples, out: wp.array[wp.float64]):
    i = wp.tid()
    out[i] = s.values[i] * s.scale


@wp.func
def first_plus(a: wp.array[Any], k: int):
    return a[0] + a[k]


@wp.kernel
def generic_scale(x: wp.array[Any], s: Any):
    i = wp.tid()
    x[i] = s * x[i]


wp.overload(generic_scale, [wp.array[wp.float32], wp.float32])
wp.overload(generic_scale, {"x": wp.array[wp.float64], "s": wp.float64})


@wp.kernel
def call_first_plus(a: wp.array[wp.float64], out: wp.array[wp.float64]):
    i = wp.tid()
    out[i] = first_plus(a, i)


def test_subscript_annotated_kernels_match_float64(device, rng):
    n = 1000
    # huge and tiny magnitudes side by side: the sum must keep both within float32 rounding
    x = (rng.standard_normal(n) * np.logspace(-30, 30, n)).astype(np.float32)
    y = (rng.standard_normal(n) * np.logspace(30, -30, n)).astype(np.float32)
    out = wp.empty(n, dtype=float)
    wp.launch(axpy_subscript, dim=n, inputs=[wp.array(x), wp.array(y), 1.5, out])
    ref = 1.5 * x.astype(np.float64) + y.astype(np.float64)
    # two float32 roundings (the product, the sum): bounded by the terms' size, not the result's
    # (where they nearly cancel)
    bound = 2.0 ** -23 * (np.abs(1.5 * x.astype(np.float64)) * 2 + np.abs(ref))
    assert np.all(np.abs(out.numpy() - ref) <= bound), np.max(np.abs(out.numpy() - ref) / bound)

    m = rng.standard_normal((7, 5, 3))
    v = rng.standard_normal((5, 3)) * 1e6
    got = wp.empty((7, 5), dtype=wp.float64)
    wp.launch(rows_dot, dim=(7, 5), inputs=[wp.array(m, dtype=wp.vec3d), wp.array(v, dtype=wp.vec3d), got])
    np.testing.assert_allclose(got.numpy(), np.einsum("ijk,jk->ij", m, v), rtol=1e-12)


def test_subscript_matrix_and_indexed_and_struct_parameters(device, rng):
    n = 64
    # near-singular matrices: rows almost parallel
    base = rng.standard_normal((n, 1, 3))
    ms = (base + 1e-6 * rng.standard_normal((n, 3, 3))).astype(np.float32)
    vs = rng.standard_normal((n, 3)).astype(np.float32)
    out = wp.empty(n, dtype=wp.vec3)
    wp.launch(mat_apply, dim=n, inputs=[wp.array(ms, dtype=wp.mat33), wp.array(vs, dtype=wp.vec3), out])
    ref = np.einsum("nij,nj->ni", ms.astype(np.float64), vs.astype(np.float64))
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-5, atol=1e-5 * np.abs(ref).max())

    data = rng.standard_normal(50).astype(np.float32)
    idx = rng.choice(50, size=17, replace=False).astype(np.int32)
    base = wp.array(data)
    view = wp.indexedarray1d(base, [wp.array(idx)])
    got = wp.empty(17, dtype=float)
    wp.launch(gather_indexed, dim=17, inputs=[view, got])
    np.testing.assert_allclose(got.numpy(), data[idx].astype(np.float64) * 2.0, rtol=1e-7)
    expected = data.copy()
    expected[idx] = -expected[idx]
    np.testing.assert_array_equal(base.numpy(), expected)
    # an indexed view where a plain array is expected is refused, never copied
    with pytest.raises(RuntimeError, match=r"argument 'x'.*but passed value has type indexedarray"):
        wp.launch(axpy_subscript, dim=17, inputs=[view, got, 1.0, got])

    s = Samples()
    values = rng.standard_normal(33) * 1e-200
    s.values = wp.array(values, dtype=wp.float64)
    s.scale = 3e150
    res = wp.empty(33, dtype=wp.float64)
    wp.launch(scale_struct, dim=33, inputs=[s, res])
    np.testing.assert_allclose(res.numpy(), values * 3e150, rtol=1e-15)


def test_subscript_generic_overloads_and_funcs(device, rng):
    x32 = rng.standard_normal(9).astype(np.float32)
    a32 = wp.array(x32)
    wp.launch(generic_scale, dim=9, inputs=[a32, wp.float32(3.0)])
    np.testing.assert_allclose(a32.numpy(), x32.astype(np.float64) * 3.0, rtol=1e-6)
    x64 = rng.standard_normal(9)
    a64 = wp.array(x64, dtype=wp.float64)
    wp.launch(generic_scale, dim=9, inputs=[a64, wp.float64(-0.25)])
    np.testing.assert_allclose(a64.numpy(), x64 * -0.25, rtol=1e-15)

    out = wp.empty(9, dtype=wp.float64)
    wp.launch(call_first_plus, dim=9, inputs=[a64, out])
    got = a64.numpy()
    np.testing.assert_allclose(out.numpy(), got[0] + got, rtol=1e-15)


def test_annotation_objects_describe_themselves():
    a = wp.array[float]
    assert (a.dtype, a.ndim) == (wp.float32, 1)
    assert a == wp.array[wp.float32] and hash(a) == hash(wp.array[wp.float32])
    assert a != wp.array[float, Literal[2]] and a != wp.indexedarray[float]
    assert wp.array[wp.float64, 3].ndim == 3
    assert wp.array2d[wp.vec3].ndim == 2
    assert not isinstance(a, wp.array) and not hasattr(a, "__dict__")
    assert a.vars is a.vars
    assert repr(wp.array[wp.uint32]) == "wp.array[wp.uint32]"
    assert repr(wp.array4d[wp.vec3f]) == "wp.array4d[wp.vec3f]"
    assert repr(wp.indexedarray[wp.float64, Literal[2]]) == "wp.indexedarray[wp.float64, Literal[2]]"
    assert repr(wp.array[wp.float32, Any]) == "wp.array[wp.float32, Any]"
    # the factory form and the subscript form are the same type
    assert wt.get_type_code(wp.array(dtype=int, ndim=2)) == wt.get_type_code(wp.array2d[int]) == "a2i4"
    assert wt.get_type_code(wp.array[wp.mat22d]) == "a1m22f8"
    assert wt.get_type_code(wp.indexedarray(dtype=Any)) == "ia1?"
    assert wt.get_type_code(wp.quatf) == "qf4" and wt.get_type_code(wp.transformd) == "tf8"
    assert wt.array_type_id(wp.array[float]) == wt.ARRAY_TYPE_REGULAR
    assert wt.array_type_id(wp.indexedarray2d[float]) == wt.ARRAY_TYPE_INDEXED
    assert wt.array_type_id(wp.fabricarray(dtype=float, ndim=2)) == wt.ARRAY_TYPE_FABRIC
    assert wt.array_type_id(wp.indexedfabricarray[float]) == wt.ARRAY_TYPE_FABRIC_INDEXED
    assert wt.concrete_array_type(wp.indexedarray[float]) is wp.indexedarray
    assert wt.matches_array_class(wp.array[float], wp.array)
    assert not wt.matches_array_class(wp.array[float], wp.indexedarray)
    assert wt.is_array(wp.fabricarray[float]) and wt.is_array(wp.indexedarray(dtype=float))
    # union with other types at Python scope
    assert (a | None).__args__ == (a, type(None))


def test_composite_generics_are_the_cached_types():
    assert Vector[float, Literal[3]] is wp.vec3f is Vector[wp.float32, 3]
    assert Matrix[wp.float64, Literal[2], Literal[4]] is wp.types.matrix((2, 4), wp.float64)
    assert Quaternion[wp.float64] is wp.quatd and Transformation[wp.float32] is wp.transformf
    assert wt.type_is_vector(wp.vec3) and not wt.type_is_vector(wp.quat)
    assert wt.type_is_matrix(wp.mat22) and wt.type_is_quaternion(wp.quatd)
    assert wt.type_is_transformation(wp.transform)
    t = wp.tile[float, Literal[8], 4]
    assert wt.is_tile(t) and t.shape == (8, 4) and t.storage == "register"
    assert wp.tile[wp.float64].shape is Any and wp.tile[float, (4, 4)].shape == (4, 4)


@pytest.mark.parametrize("make, error, pattern", [
    (lambda: Vector[float], TypeError, r"requires 2 parameters"),
    (lambda: Vector[float, 0], TypeError, r"positive integer"),
    (lambda: Vector[float, -3], TypeError, r"positive integer"),
    (lambda: Vector[float, Literal[2, 3]], TypeError, r"single Literal value"),
    (lambda: Vector[float, "3"], TypeError, r"positive integer"),
    (lambda: Matrix[float, 3], TypeError, r"requires 3 parameters"),
    (lambda: wp.array[float, Literal[1, 2]], TypeError, r"single Literal value"),
    (lambda: wp.array[float, 5], ValueError, r"ndim must be between 1 and 4"),
    (lambda: wp.array[float, 0], ValueError, r"ndim must be between"),
    (lambda: wp.array[float, True], TypeError, r"ndim must be an integer"),
    (lambda: wp.array[float, 1, 2], TypeError, r"expects 1 or 2 type parameters"),
    (lambda: wp.array2d[float, Literal[2]], TypeError, r"single type parameter"),
    (lambda: wp.tile[()], TypeError, r"requires at least a dtype"),
    (lambda: wp.tile[float, -1, 4], TypeError, r"positive integer"),
    (lambda: wp.types.matrix((2,), wp.float32), ValueError,
     r"exactly two dimensions, got 1 dimension in shape \(2,\)"),
    (lambda: wp.fabricarray(np.zeros(3)), RuntimeError, r"Omniverse Fabric"),
])
def test_malformed_subscripts_are_refused(make, error, pattern):
    with pytest.raises(error, match=pattern):
        make()


def test_unions_fabric_and_tiles_are_refused_in_kernels(kernel_module, device):
    with pytest.raises(RuntimeError, match=r"Union type annotations are only supported at Python scope"):
        kernel_module("""
            @wp.func
            def f(a: wp.array[float] | float) -> float:
                return 0.0
        """)
    # a kernel taking a Fabric array can be declared (Warp's test files declare such kernels
    # beside others); building it is the error, at its line, and its module's other kernels run
    fabric = kernel_module("""
        @wp.kernel
        def k(a: wp.fabricarray[float]):
            pass

        @wp.kernel
        def sibling(out: wp.array[float]):
            out[wp.tid()] = 2.0
    """)
    with pytest.raises(RuntimeError, match=r"\.py:\d+:1: error: parameter 'a' of 'k': .*Fabric arrays"):
        wp.launch(fabric.k, dim=1, inputs=[wp.zeros(1, dtype=float, device=device)], device=device)
    assert wp.overload(fabric.k, [wp.fabricarray[float]]) is fabric.k   # no Fabric instance
    out = wp.zeros(3, dtype=float, device=device)
    wp.launch(fabric.sibling, dim=3, inputs=[out], device=device)
    assert out.numpy().tolist() == [2.0, 2.0, 2.0]
    # the same for a struct with a Fabric array field, nested or not: declared, refused in a kernel
    holder = kernel_module("""
        @wp.struct
        class FabricHolder:
            values: wp.fabricarray[float]
            count: int

        @wp.struct
        class Outer:
            inner: FabricHolder

        @wp.kernel
        def uses_outer(o: Outer, out: wp.array[float]):
            out[0] = float(o.inner.count)
    """)
    assert [f.name for f in holder.FabricHolder.fields] == ["count"]
    with pytest.raises(RuntimeError, match=r"\.py:\d+: error: struct field 'values' of .*FabricHolder: .*Fabric arrays"):
        wp.launch(holder.uses_outer, dim=1, inputs=[holder.Outer(), out], device=device)
    # a vector type far past what a kernel can hold is a type in Python, refused by the daemon
    huge = kernel_module("""
        from weft.types import Vector
        V = Vector[float, 2 ** 31]

        @wp.kernel
        def k(a: wp.array[float]):
            v = V()
            a[0] = v[0]
    """)
    with pytest.raises(RuntimeError, match=r"\.py:\d+:\d+: error: 'V': bad type string 'vec\(2147483648,float32\)'"):
        wp.launch(huge.k, dim=1, inputs=[wp.zeros(1, dtype=float)])
    # a func taking a tile takes tiles of its shape, nothing else
    mod = kernel_module("""
        @wp.func
        def passthrough(t: wp.tile[float, 8, 4]) -> wp.tile[float, 8, 4]:
            return t

        @wp.kernel
        def plain(out: wp.array[float]):
            out[wp.tid()] = 1.0

        @wp.kernel
        def uses_tile(out: wp.array[float]):
            passthrough(out)
    """)
    out = wp.zeros(4, dtype=float)
    wp.launch(mod.plain, dim=4, inputs=[out])      # the same module without the bad call builds
    np.testing.assert_array_equal(out.numpy(), np.ones(4))
    with pytest.raises(RuntimeError, match=r"\.py:\d+:\d+: error: .*passthrough.*array\(float32,1\)"):
        wp.launch(mod.uses_tile, dim=4, inputs=[out])


def test_launch_arguments_that_are_not_arrays_are_refused(device):
    out = wp.zeros(3, dtype=float)
    for bad in ([1.0, 2.0, 3.0], (1.0, 2.0, 3.0), 3.0, "abc", {"x": 1}):
        with pytest.raises(RuntimeError, match=r"argument 'x'.*expects an array of type "
                                               r"array\(ndim=1, dtype=float32\), but passed value has type"):
            wp.launch(axpy_subscript, dim=3, inputs=[bad, out, 1.0, out])
    with pytest.raises(RuntimeError, match=r"dtype float32, got an array of dtype int32"):
        wp.launch(axpy_subscript, dim=3, inputs=[wp.zeros(3, dtype=int), out, 1.0, out])
    with pytest.raises(RuntimeError, match=r"2 dimension\(s\), got 1"):
        wp.launch(rows_dot, dim=(1, 1), inputs=[wp.zeros(3, dtype=wp.vec3d), wp.zeros(3, dtype=wp.vec3d),
                                                wp.zeros((1, 1), dtype=wp.float64)])
