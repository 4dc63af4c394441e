"""Warp-compatible behaviour at the edges: compile errors of constructors and builtins in Warp's
wording with the message ending the text (Warp's tests anchor their patterns at the end) and
Warp's exception classes; Warp's constants (wp.PI, wp.TAU, ...) in Python and in kernels at
float64 precision; tape.backward(grads=...) for an array created without a gradient (the
incoming gradient becomes its .grad); arrays of structs listed as struct instances; vectors
that take other attributes. Numbers against float64/NumPy references on random data."""
import math

import numpy as np
import pytest

import weft as wp


def _compile_error(wp, kernel, inputs=()):
    with pytest.raises(wp.WeftCompileError) as info:
        wp.launch(kernel, dim=1, inputs=list(inputs))
    return info.value


def test_constructor_errors_end_with_warps_message(wp):
    @wp.kernel(module="unique")
    def vec_copy_size():
        wp.types.vector(wp.types.vector(length=2, dtype=float), length=3, dtype=float)

    @wp.kernel(module="unique")
    def vec_count():
        wp.types.vector(1.0, 2.0, length=12345)

    @wp.kernel(module="unique")
    def vec_no_length():
        wp.types.vector()

    @wp.kernel(module="unique")
    def vec_mixed():
        wp.types.vector(1.0, 2)

    @wp.kernel(module="unique")
    def vec_typed(x: wp.float64):
        wp.vec2(x, x)

    @wp.kernel(module="unique")
    def mat_no_shape():
        wp.types.matrix(1.0, 2.0, 3.0)

    @wp.kernel(module="unique")
    def mat_fill(x: wp.float32):
        wp.types.matrix(x, shape=(3, 2), dtype=wp.float16)

    @wp.kernel(module="unique")
    def mat_count():
        wp.mat22(1.0, 2.0, 3.0)

    @wp.kernel(module="unique")
    def mat_copy_size():
        wp.mat33(wp.mat22(1.0, 2.0, 3.0, 4.0))

    @wp.kernel(module="unique")
    def overload(x: wp.float32, out: wp.array(dtype=int)):
        out[0] = wp.bit_count(x)

    @wp.kernel(module="unique")
    def printf_33():
        wp.printf("%d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d %d "
                  "%d %d %d\n", 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21,
                  22, 23, 24, 25, 26, 27, 28, 29, 30, 31, 32)

    cases = [
        (vec_copy_size, [], r"incompatible vector of length 3 given when copy constructing a vector of length 2$"),
        (vec_count, [], r"incompatible number of values given \(2\) when constructing a vector of length 12345$"),
        (vec_no_length, [], r"the `length` argument must be specified when zero-initializing a vector$"),
        (vec_mixed, [], r"all values given when constructing a vector must have the same type$"),
        (vec_typed, [wp.float64(1.0)], r"all values used to initialize this vector are expected to be of the type `float32`$"),
        (mat_no_shape, [], r"the `shape` argument must be specified when initializing a matrix by value$"),
        (mat_fill, [wp.float32(1.0)], r"the value used to fill this matrix is expected to be of the type `float16`$"),
        (mat_count, [], r"incompatible number of values given \(3\) when constructing a matrix of shape \(2, 2\)$"),
        (mat_copy_size, [], r"incompatible matrix of shape \(3, 3\) given when copy constructing a matrix of shape \(2, 2\)$"),
        (overload, [wp.float32(45.0), wp.zeros(1, dtype=int)], r"Couldn't find function overload for 'bit_count'"),
        (printf_33, [], r"the maximum number of variadic arguments that can be passed to `printf` is 32$"),
    ]
    for kernel, inputs, pattern in cases:
        err = _compile_error(wp, kernel, inputs)
        assert isinstance(err, RuntimeError)
        text = str(err)
        import re
        assert re.search(pattern, text), (pattern, text)
        assert f"{__file__}:" in text, text          # still located at the user's line
    # the typed ones are also TypeErrors, as Warp's WarpCodegenTypeError
    assert isinstance(_compile_error(wp, vec_typed, [wp.float64(1.0)]), TypeError)
    assert isinstance(_compile_error(wp, vec_mixed), wp.WarpCodegenTypeError)


@wp.kernel
def constants_kernel(out: wp.array(dtype=wp.float64), x: wp.array(dtype=wp.float64)):
    v = wp.vec3d(wp.PI, wp.E, wp.TAU)
    out[0] = v[0]
    out[1] = v[1]
    out[2] = v[2]
    out[3] = wp.float64(wp.HALF_PI) * x[0]
    out[4] = wp.float64(wp.LN2) + wp.float64(wp.LOG10E) * x[0]


def test_warp_constants_in_python_and_kernels(wp, rng):
    assert (wp.PI, wp.pi, wp.TAU, wp.E, wp.LN10) == (math.pi, math.pi, math.tau, math.e, math.log(10))
    assert math.isinf(wp.INF) and math.isnan(wp.NAN)
    x = rng.uniform(-5, 5, 1)
    out = wp.zeros(5, dtype=wp.float64)
    wp.launch(constants_kernel, dim=1, inputs=[out, wp.array(x, dtype=wp.float64)])
    ref = [math.pi, math.e, math.tau, math.pi / 2 * x[0], math.log(2) + math.log10(math.e) * x[0]]
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-15)


@wp.kernel
def scaled(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    i = wp.tid()
    b[i] = a[i] * a[i] + float(i)


def test_backward_grads_for_an_array_without_gradient(wp, rng):
    n = 16
    x = rng.standard_normal(n).astype(np.float32)
    xa = wp.array(x, requires_grad=True)
    y = wp.zeros(n, dtype=float)                        # no requires_grad
    seed = rng.standard_normal(n).astype(np.float32)
    tape = wp.Tape()
    with tape:
        wp.launch(scaled, dim=n, inputs=[xa], outputs=[y])
    tape.backward(grads={y: wp.array(seed)})
    np.testing.assert_allclose(tape.gradients[xa].numpy(), 2.0 * x.astype(np.float64) * seed, rtol=1e-6)
    assert y.grad is not None
    np.testing.assert_array_equal(y.grad.numpy(), seed)


@wp.struct
class Inner:
    a: int
    b: wp.vec2f


@wp.struct
class Outer:
    x: float
    y: wp.uint32
    s: Inner


@wp.kernel
def fill_structs(items: wp.array(dtype=Outer), v: wp.array(dtype=float)):
    i = wp.tid()
    items[i].x = v[i]
    items[i].y = wp.uint32(i * 3)
    items[i].s.a = i
    items[i].s.b = wp.vec2f(v[i], 2.0 * v[i])


def test_struct_array_list_gives_instances(wp, rng):
    n = 5
    v = rng.standard_normal(n).astype(np.float32)
    items = wp.zeros(n, dtype=Outer)
    wp.launch(fill_structs, dim=n, inputs=[items, wp.array(v)])
    listed = items.list()
    assert len(listed) == n
    for i, item in enumerate(listed):
        assert item.x == pytest.approx(float(v[i]))
        assert item.y == 3 * i and item.s.a == i
        assert item.s.b == wp.vec2f(v[i], 2.0 * v[i])


def test_vectors_take_other_attributes(wp):
    v = wp.vec3(1.0, 2.0, 3.0)
    v.foo = 123
    assert v.foo == 123 and v.x == 1.0
    m = wp.mat22(1.0, 2.0, 3.0, 4.0)
    m.tag = "a"
    assert m.tag == "a"
    with pytest.raises(AttributeError, match=r"'vec3f' object has no attribute 'bar'"):
        v.bar  # noqa: B018


def test_segmented_sort_rejects_strided_views(wp, rng):
    contiguous = wp.zeros(2, dtype=int)
    starts = wp.array((0,), dtype=int)
    with pytest.raises(RuntimeError, match="requires a contiguous segment_end_indices array"):
        wp.utils.segmented_sort_pairs(contiguous, contiguous, 1, starts, wp.array((1, 1), dtype=int)[::2])
    with pytest.raises(RuntimeError, match="requires a contiguous keys array"):
        wp.utils.segmented_sort_pairs(wp.zeros(4, dtype=int)[::2], contiguous, 1, starts)
    keys = rng.integers(-100, 100, 8).astype(np.int32)      # still sorts contiguous input
    k = wp.array(np.concatenate([keys, np.zeros(8, np.int32)]), dtype=int)
    v = wp.array(np.arange(16, dtype=np.int32), dtype=int)
    wp.utils.segmented_sort_pairs(k, v, 8, wp.array((0, 4), dtype=int), wp.array((4, 8), dtype=int))
    ref = np.concatenate([np.sort(keys[:4], kind="stable"), np.sort(keys[4:], kind="stable")])
    np.testing.assert_array_equal(k.numpy()[:8], ref)


def test_segmented_sort_invalid_ranges_by_device(wp, device):
    """Warp's rule: on the CPU a malformed segment range is a ValueError naming its index; on a
    GPU it is treated as empty (the valid segments are sorted, the storage around is untouched)."""
    keys = wp.array((2, 1, 4, 3, 0, 0, 0, 0), dtype=int)
    values = wp.array((20, 10, 40, 30, 0, 0, 0, 0), dtype=int)
    offsets = wp.array((0, 2, 5), dtype=int)        # [0, 2) valid, [2, 5) past count=4
    if device == "cpu":
        with pytest.raises(ValueError, match=r"Invalid segment range at index 1: \[2, 5\) with count 4"):
            wp.utils.segmented_sort_pairs(keys, values, 4, offsets)
        np.testing.assert_array_equal(keys.numpy()[:4], (2, 1, 4, 3))
    else:
        wp.utils.segmented_sort_pairs(keys, values, 4, offsets)
        np.testing.assert_array_equal(keys.numpy()[:4], (1, 2, 4, 3))
        np.testing.assert_array_equal(values.numpy()[:4], (10, 20, 40, 30))


def test_float_scalars_show_the_number_they_were_given(wp, device):
    """Warp's repr/str of a float scalar is the number it was made from (float16(-1),
    float32(0.1)); `.value` is the number the type holds (rounded to its precision)."""
    assert repr(wp.float16(-1)) == "float16(-1)" and repr(wp.float32(-1)) == "float32(-1)"
    assert repr(wp.float64(-1)) == "float64(-1)" and str(wp.float32(2.5)) == "2.5"
    assert repr(wp.float32(0.1)) == "float32(0.1)" and wp.float32(0.1).value != 0.1
    assert abs(wp.float32(0.1).value - 0.1) < 1e-8
    assert repr(wp.int8(-1)) == "int8(-1)" and repr(wp.uint64(2**64 - 1)) == "uint64(18446744073709551615)"
    assert repr(wp.bfloat16(1)) == "bfloat16(1)"


def test_unknown_component_is_an_attribute_error_and_mismatched_compare_a_type_error(wp):
    @wp.kernel(module="unique")
    def bad_component(out: wp.array(dtype=float)):
        v = wp.vec3(1.0, 2.0, 3.0)
        out[0] = v.foo

    err = _compile_error(wp, bad_component, [wp.zeros(1, dtype=float)])
    assert isinstance(err, AttributeError)
    assert "`foo` is not an attribute of 'v' (vec(3,float32))" in str(err)

    @wp.kernel(module="unique")
    def bad_compare():
        x = wp.int32(10)
        if x == True:  # noqa: E712
            pass

    err = _compile_error(wp, bad_compare)
    assert isinstance(err, TypeError) and "cannot compare int32 == bool" in str(err)


def test_struct_bool_field_holds_a_bool(wp):
    @wp.struct
    class Flags:
        on: wp.bool
        h: wp.handle

    f = Flags()
    f.on = 1
    f.h = 2 ** 63 + 5
    assert f.on is True and wp.handle is wp.uint64

    @wp.kernel(module="unique")
    def read(f: Flags, out: wp.array(dtype=int), h: wp.array(dtype=wp.uint64)):
        out[0] = wp.where(f.on, 1, 2)
        h[0] = f.h

    out = wp.zeros(1, dtype=int)
    h = wp.zeros(1, dtype=wp.uint64)
    wp.launch(read, dim=1, inputs=[f, out, h])
    assert out.numpy()[0] == 1 and int(h.numpy()[0]) == 2 ** 63 + 5
