"""Python values the client resolves into kernel constants: members of Python enums
(IntEnum, IntFlag: MyEnum.A, MyEnum.A.value) and wp.static(expr) (evaluated in the function's
globals and closure when it is defined: constants, vectors, @wp.func objects, enum members,
struct values rebuilt field by field; what a kernel cannot hold is an error at its line),
against float64 references on random data; and `for i in reversed(range(...))` against
Python's own reversed(), with the gradient of a loop-carried sum."""
import enum

import numpy as np
import pytest

import weft as wp


class Color(enum.IntEnum):
    RED = 1
    GREEN = 2
    BLUE = 7


class Flags(enum.IntFlag):
    A = 1
    B = enum.auto()
    C = enum.auto()


SCALE = 2.5
OFFSET = wp.vec3(1.0, -2.0, 0.5)


@wp.func
def plus_one(x: float):
    return x + 1.0


@wp.func
def times_two(x: float):
    return x * 2.0


@wp.kernel
def enum_kernel(keys: wp.array(dtype=int), out: wp.array(dtype=int)):
    i = wp.tid()
    k = keys[i]
    r = 0
    if k & Flags.A:
        r += Color.RED
    if k & Flags.B.value:
        r += Color.GREEN.value
    if k & Flags.C:
        r += int(Color.BLUE) * 10
    out[i] = r + (Flags.A | Flags.C)


@wp.kernel
def static_kernel(x: wp.array(dtype=float), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    s = wp.static(SCALE * 2.0)
    v = wp.static(OFFSET * 2.0)
    out[i] = v * (x[i] * s) + wp.vec3(wp.static(plus_one)(x[i]), float(wp.static(Color.BLUE)),
                                      wp.static(
                                          Color.GREEN.value + 1))


def test_enum_members_are_constants(wp, rng, device):
    keys = rng.integers(0, 8, size=64).astype(np.int32)
    a = wp.array(keys, dtype=int, device=device)
    out = wp.zeros(64, dtype=int, device=device)
    wp.launch(enum_kernel, dim=64, inputs=[a, out], device=device)
    ref = (np.where(keys & 1, 1, 0) + np.where(keys & 2, 2, 0) + np.where(keys & 4, 70, 0) + 5)
    np.testing.assert_array_equal(out.numpy(), ref)


def test_static_expressions(wp, rng, device):
    x = rng.uniform(-3.0, 3.0, size=33)
    a = wp.array(x, dtype=float, device=device)
    out = wp.zeros(33, dtype=wp.vec3, device=device)
    wp.launch(static_kernel, dim=33, inputs=[a, out], device=device)
    xf = x.astype(np.float32).astype(np.float64)
    ref = np.outer(xf * 5.0, np.array([2.0, -4.0, 1.0])) + \
        np.stack([xf + 1.0, np.full_like(xf, 7.0), np.full_like(xf, 3.0)], axis=1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-5, atol=1e-5)
    # the definition's source names the values; lines are kept
    d = static_kernel.definition
    assert "wp.static" not in d.source
    assert d.source.count("\n") == d.last_line - d.first_line + 1


@pytest.mark.parametrize("chosen", ["plus_one", "times_two"])
def test_static_picks_a_func_per_kernel(wp, rng, device, chosen):
    op = {"plus_one": plus_one, "times_two": times_two}[chosen]

    @wp.kernel(module="unique")
    def apply(x: wp.array(dtype=float), out: wp.array(dtype=float)):
        i = wp.tid()
        out[i] = wp.static(op)(x[i])

    x = rng.uniform(-3.0, 3.0, size=20)
    a = wp.array(x, dtype=float, device=device)
    out = wp.zeros(20, dtype=float, device=device)
    wp.launch(apply, dim=20, inputs=[a, out], device=device)
    xf = x.astype(np.float32).astype(np.float64)
    np.testing.assert_allclose(out.numpy(), xf + 1.0 if chosen == "plus_one" else xf * 2.0,
                               rtol=1e-6)


def test_static_of_a_kernel_variable_is_an_error_at_its_line(wp, device):
    @wp.kernel(module="unique")
    def uses_local(out: wp.array(dtype=int)):
        i = wp.tid()
        out[i] = wp.static(i * 2)

    out = wp.zeros(4, dtype=int, device=device)
    with pytest.raises(wp.WeftCompileError, match=r"test_lang_enum_static\.py:\d+"):
        wp.launch(uses_local, dim=4, inputs=[out], device=device)
    assert wp.static(5) == 5          # Python scope: the value itself


@wp.struct
class StaticInner:
    m: wp.mat33d
    k: int


@wp.struct
class StaticOuter:
    inner: StaticInner
    q: wp.quatd
    s: float


@wp.func
def make_outer(m: wp.mat33d, k: int, q: wp.quatd, s: float):
    inner = StaticInner()
    inner.m = m
    inner.k = k
    o = StaticOuter()
    o.inner = inner
    o.q = q
    o.s = s
    return o


_STATIC_M = np.random.default_rng(7).standard_normal((3, 3)) * 1e12


@wp.kernel
def static_struct(out: wp.array(dtype=StaticOuter), mats: wp.array(dtype=wp.mat33d)):
    value = wp.static(make_outer(wp.mat33d(_STATIC_M), 42, wp.quat_rpy(0.1, -0.2, 0.3), 1.0e-30))
    out[0] = value
    mats[0] = value.inner.m * wp.float64(2.0)


def test_static_struct_values_are_rebuilt_in_the_kernel(wp, device):
    """wp.static(expr) returning a struct (nested structs, matrices, quaternions): the kernel
    gets the same field values, bit for bit, as the Python value."""
    out = wp.zeros(1, dtype=StaticOuter, device=device)
    mats = wp.zeros(1, dtype=wp.mat33d, device=device)
    wp.launch(static_struct, dim=1, inputs=[out, mats], device=device)
    got = out.numpy()[0]
    expected = make_outer(wp.mat33d(_STATIC_M), 42, wp.quat_rpy(0.1, -0.2, 0.3), 1.0e-30)
    np.testing.assert_array_equal(got["inner"]["m"], _STATIC_M)
    assert got["inner"]["k"] == 42
    np.testing.assert_array_equal(got["q"], np.asarray(expected.q, dtype=np.float64))
    assert got["s"] == np.float32(1.0e-30)
    np.testing.assert_array_equal(mats.numpy()[0], _STATIC_M * 2.0)


def test_static_values_a_kernel_cannot_hold_are_errors_at_their_line(wp, device, kernel_module):
    mod = kernel_module("""
        @wp.struct
        class Holder:
            data: wp.array(dtype=int)
            x: int

        def holder():
            h = Holder()
            h.data = wp.zeros(3, dtype=int, device="cpu")
            h.x = 1
            return h

        class Plain:
            pass

        def nothing():
            pass

        @wp.kernel(module="unique")
        def with_array(out: wp.array(dtype=int)):
            out[0] = wp.static(holder()).x

        @wp.kernel(module="unique")
        def with_object(out: wp.array(dtype=int)):
            v = wp.static(Plain())

        @wp.kernel(module="unique")
        def with_none(out: wp.array(dtype=int)):
            v = wp.static(nothing())
    """)
    out = wp.zeros(1, dtype=int, device=device)
    for kernel, pattern in ((mod.with_array, r"unsupported value: the returned Warp struct contains a data type that cannot be "
                                              r"constructed inside Warp kernels: a Warp array cannot be created "
                                              r"inside Warp kernels at Holder\.data"),
                            (mod.with_object, r"unsupported value: value of type .*Plain"),
                            (mod.with_none, r"unsupported value: None is returned")):
        with pytest.raises(wp.WeftCompileError, match=r"\.py:\d+:\d+: error: Static expression returns an " + pattern):
            wp.launch(kernel, dim=1, inputs=[out], device=device)


@wp.kernel
def reversed_range(start: int, end: int, step: int, count: wp.array(dtype=int),
                   values: wp.array(dtype=int), weights: wp.array(dtype=float),
                   acc: wp.array(dtype=float)):
    n = int(0)
    s = float(0.0)
    for i in reversed(range(start, end, step)):
        values[n] = i
        s = s * 0.5 + weights[0] * float(i)
        n += 1
    count[0] = n
    acc[0] = s


def test_reversed_range_matches_python(wp, rng, device):
    cases = [(-2, 8, 3), (9, -3, -2), (0, 0, 1), (5, 1, 1), (1, 5, -1), (0, 7, 1), (3, 4, 5)]
    cases += [tuple(int(x) for x in rng.integers(-20, 20, size=2)) + (int(rng.choice([-3, -1, 2, 4])),)
              for _ in range(6)]
    for start, end, step in cases:
        count = wp.zeros(1, dtype=int, device=device)
        values = wp.zeros(64, dtype=int, device=device)
        w = wp.array([rng.uniform(0.5, 2.0)], dtype=float, device=device, requires_grad=True)
        acc = wp.zeros(1, dtype=float, device=device, requires_grad=True)
        tape = wp.Tape()
        with tape:
            wp.launch(reversed_range, dim=1, inputs=[start, end, step, count, values, w, acc],
                      device=device)
        expected = list(reversed(range(start, end, step)))
        assert count.numpy()[0] == len(expected), (start, end, step)
        np.testing.assert_array_equal(values.numpy()[:len(expected)], expected)
        # acc = sum_k 0.5^(n-1-k) * w * x_k: d acc / d w against the float64 reference
        coeff = sum(0.5 ** (len(expected) - 1 - k) * x for k, x in enumerate(expected))
        np.testing.assert_allclose(acc.numpy()[0], coeff * float(w.numpy()[0]), rtol=1e-5, atol=1e-5)
        tape.backward(loss=acc)
        np.testing.assert_allclose(w.grad.numpy()[0], coeff, rtol=1e-5, atol=1e-5)


def _unique_scaler(v):
    @wp.kernel(module="unique")
    def scale(a: wp.array(dtype=wp.float64)):
        tid = wp.tid()
        a[tid] = a[tid] * wp.static(v * 2.0)

    return scale


def test_unique_kernels_redeclared_with_the_same_values_are_one_kernel(wp, rng, device):
    """module="unique" kernels declared from one code object bake their own wp.static values;
    declaring the same code with the same captured values again gives the same kernel (Warp's
    behaviour), a captured mutable object never does (its contents could differ)."""
    x = rng.uniform(0.5, 2.0, 4)
    k1, k2 = _unique_scaler(1.5), _unique_scaler(-0.75)
    assert k1 is not k2
    assert _unique_scaler(1.5) is k1 and _unique_scaler(-0.75) is k2
    assert _unique_scaler(1) is not _unique_scaler(1.0)          # an int is another value
    for k, factor in ((k1, 3.0), (k2, -1.5)):
        a = wp.array(x, dtype=wp.float64, device=device)
        wp.launch(k, dim=4, inputs=[a], device=device)
        np.testing.assert_allclose(a.numpy(), x * factor, rtol=1e-15)
    holder = [2.0]

    def mutable_capture():
        @wp.kernel(module="unique")
        def k(a: wp.array(dtype=wp.float64)):
            tid = wp.tid()
            a[tid] = a[tid] * wp.float64(wp.static(holder[0]))

        return k

    first = mutable_capture()
    holder[0] = 5.0
    second = mutable_capture()
    assert first is not second
    a = wp.array(x, dtype=wp.float64, device=device)
    wp.launch(second, dim=4, inputs=[a], device=device)
    np.testing.assert_allclose(a.numpy(), x * 5.0, rtol=1e-15)
