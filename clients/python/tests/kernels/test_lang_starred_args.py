"""Language: `*x` as a call argument expands x into its components (Warp's unpacking): vectors,
quaternions, matrices (their rows), constant slices of those, and constant slices of 1-D
arrays (`*a[:3]`), mixed with other arguments, into constructors, builtins and @wp.func. Results
against NumPy float64 references on fresh random data; gradients through the expansion against
the analytic derivative. Attacks: a non-constant slice bound, a missing upper bound, negative
bounds and steps on arrays, a scalar, `**kwargs`: each a compile error of Warp's exception class
(WarpCodegenValueError / WarpCodegenTypeError) at the user's line."""
import inspect

import numpy as np
import pytest

import weft as wp


@wp.func
def weighted3(a: float, b: float, c: float):
    return a + 2.0 * b + 3.0 * c


@wp.kernel
def unpack_vectors(v: wp.array(dtype=wp.vec3), q: wp.array(dtype=wp.quat), out: wp.array2d(dtype=float)):
    i = wp.tid()
    a = v[i]
    v4 = wp.vec4(*a, 7.0)               # components then one more
    v4b = wp.vec4(1.5, *a[1:], 2.5)     # slice of a vector in the middle
    v5 = wp.vector(*a, *a[:2])          # two starred arguments
    out[i, 0] = v4[0] + 10.0 * v4[3]
    out[i, 1] = v4b[0] + v4b[1] * v4b[2]
    out[i, 2] = v5[4] - v5[0] * v5[2]
    out[i, 3] = wp.max(*a[1:])          # into a builtin
    out[i, 4] = weighted3(*a)           # into a @wp.func
    qq = q[i]
    qv = wp.vec4(*qq)                   # a quaternion
    out[i, 5] = qv[0] - qv[3]
    out[i, 6] = wp.vec2(*qq[-2:])[0]    # negative slice bounds count from the end


@wp.kernel
def unpack_matrix(m: wp.array(dtype=wp.mat33), out: wp.array(dtype=wp.mat33), top: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    a = m[i]
    out[i] = wp.matrix_from_cols(*a)    # rows become columns: the transpose
    r = wp.matrix_from_rows(*a[1:])     # a 2x3 matrix of the last two rows
    top[i] = r[0] + r[1]


@wp.kernel
def unpack_array_slice(a: wp.array(dtype=int), out: wp.array(dtype=wp.vec3i), m: wp.array(dtype=int)):
    v = wp.vec3i(*a[:3])
    w = wp.vec3i(*a[1:7:2])
    out[0] = v
    out[1] = w
    m[0] = wp.max(*a[2:4])


@wp.kernel
def unpack_grad(v: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = weighted3(*v[i]) * v[i][0]


def test_starred_vectors_and_quaternions(wp, rng):
    n = 64
    v = rng.standard_normal((n, 3)).astype(np.float32)
    q = rng.standard_normal((n, 4)).astype(np.float32)
    out = wp.zeros((n, 7), dtype=float)
    wp.launch(unpack_vectors, dim=n, inputs=[wp.array(v, dtype=wp.vec3), wp.array(q, dtype=wp.quat), out])
    a = v.astype(np.float64)
    qd = q.astype(np.float64)
    ref = np.stack([a[:, 0] + 70.0, 1.5 + a[:, 1] * a[:, 2], a[:, 1] - a[:, 0] * a[:, 2], a[:, 1:].max(axis=1),
                    a[:, 0] + 2 * a[:, 1] + 3 * a[:, 2], qd[:, 0] - qd[:, 3], qd[:, 2]], axis=1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-5, atol=1e-5)


def test_starred_matrix_rows(wp, rng):
    n = 16
    m = rng.standard_normal((n, 3, 3)).astype(np.float32)
    out = wp.zeros(n, dtype=wp.mat33)
    top = wp.zeros(n, dtype=wp.vec3)
    wp.launch(unpack_matrix, dim=n, inputs=[wp.array(m, dtype=wp.mat33), out, top])
    md = m.astype(np.float64)
    np.testing.assert_allclose(out.numpy(), np.transpose(md, (0, 2, 1)), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(top.numpy(), md[:, 1] + md[:, 2], rtol=1e-5, atol=1e-5)


def test_starred_array_slice(wp, rng):
    a = rng.integers(-1000, 1000, size=9).astype(np.int32)
    out = wp.zeros(2, dtype=wp.vec3i)
    m = wp.zeros(1, dtype=int)
    wp.launch(unpack_array_slice, dim=1, inputs=[wp.array(a, dtype=int), out, m])
    np.testing.assert_array_equal(out.numpy(), np.stack([a[:3], a[1:7:2]]))
    assert m.numpy()[0] == max(a[2], a[3])


def test_starred_array_slice_is_bounds_checked(wp):
    with pytest.raises(RuntimeError, match="out of|bounds"):
        wp.launch(unpack_array_slice, dim=1, inputs=[wp.array([1, 2], dtype=int), wp.zeros(2, dtype=wp.vec3i),
                                                     wp.zeros(1, dtype=int)])
        wp.synchronize()


def test_starred_gradient(wp, rng):
    n = 32
    v = rng.standard_normal((n, 3)).astype(np.float32)
    va = wp.array(v, dtype=wp.vec3, requires_grad=True)
    out = wp.zeros(n, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(unpack_grad, dim=n, inputs=[va, out])
    tape.backward(grads={out: wp.ones(n, dtype=float)})
    a = v.astype(np.float64)
    s = a[:, 0] + 2 * a[:, 1] + 3 * a[:, 2]
    ref = np.stack([s + a[:, 0], 2 * a[:, 0], 3 * a[:, 0]], axis=1)   # d(s * x0)/dv
    np.testing.assert_allclose(va.grad.numpy(), ref, rtol=1e-5, atol=1e-5)


def _line_of(kernel, needle):
    lines, start = inspect.getsourcelines(kernel.func)
    return start + next(k for k, t in enumerate(lines) if needle in t)


def test_starred_errors(wp):
    @wp.kernel(module="unique")
    def non_constant(arr: wp.array(dtype=int), n: int):
        v = wp.vec3i(*arr[:n])

    @wp.kernel(module="unique")
    def no_stop(arr: wp.array(dtype=int)):
        v = wp.vec3i(*arr[0:])

    @wp.kernel(module="unique")
    def negative_index(arr: wp.array(dtype=int)):
        v = wp.vec3i(*arr[:-3])

    @wp.kernel(module="unique")
    def negative_step(arr: wp.array(dtype=int)):
        v = wp.vec3i(*arr[5:2:-1])

    @wp.kernel(module="unique")
    def scalar(arr: wp.array(dtype=int)):
        x = 42
        v = wp.vec3i(*x)

    a = wp.zeros(10, dtype=int)
    cases = [(non_constant, [a, 3], wp.WarpCodegenValueError, "Slice component must be a compile-time constant"),
             (no_stop, [a], wp.WarpCodegenValueError, "requires explicit upper bound"),
             (negative_index, [a], wp.WarpCodegenValueError, "cannot be negative for arrays"),
             (negative_step, [a], wp.WarpCodegenValueError, "step cannot be negative"),
             (scalar, [a], wp.WarpCodegenTypeError, "Starred expressions are only supported for")]
    for kernel, inputs, cls, text in cases:
        with pytest.raises(cls, match=text) as info:
            wp.launch(kernel, dim=1, inputs=inputs)
        assert isinstance(info.value, wp.WeftCompileError)
        line = _line_of(kernel, "*")
        assert f"{__file__}:{line}" in str(info.value), str(info.value)
        # the message ends the text (Warp's tests anchor their patterns at the end)
        assert text in str(info.value).splitlines()[-1], str(info.value)
