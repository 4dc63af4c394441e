"""Language: constant slices of vectors, matrices and transforms in kernels (Warp's
`z[0, :2] = v`, `z[:2, 1:] = m`, `z[1:-1, :2] += m[::-1, :-1]`, `y[3:1:-1] -= x[0:]`): reads
give a vector (one sliced dimension) or a matrix (two), writes and augmented writes go
component by component, and the adjoints flow through each component (checked against a
float64 reference and its finite differences). Slice bounds must be compile-time constants;
a bound known only at run time is an error at its line."""
import numpy as np
import pytest

import weft as wp
from weft._kernel.errors import WeftCompileError

mat23 = wp.types.matrix((2, 3), float)


@wp.kernel
def mat_slices(xs: wp.array[wp.vec2], ys: wp.array[mat23], zs: wp.array[wp.mat44], rows: wp.array[int],
               out: wp.array[wp.mat44]):
    i = wp.tid()
    x = xs[i]
    y = ys[i]
    z = zs[i]
    z[0, :2] = x
    z[:2, 1:] = y * x[1]
    z[:2, 3] += x[:2]
    z[1:-1, :2] += y[::-1, :-1]
    z[2:, 3] -= x[0:]
    z[3:, -1:] -= y[:1, :1]
    z[rows[i], 1::2] *= x[0]          # an integer index known at run time, a stepped slice
    r = z[::-1]                       # every column of the rows, last first
    out[i] = r + wp.outer(wp.vec4(z[1:3, 0][0], 1.0, 2.0, 3.0), wp.vec4(1.0, 0.0, 0.0, 0.0))


def mat_slices_ref(x, y, z, rows):
    z = z.copy()
    z[0, :2] = x
    z[:2, 1:] = y * x[1]
    z[:2, 3] += x[:2]
    z[1:-1, :2] += y[::-1, :-1]
    z[2:, 3] -= x[0:]
    z[3:, -1:] -= y[:1, :1]
    z[rows, 1::2] *= x[0]
    r = z[::-1].copy()
    r[0, 0] += z[1, 0]
    r[1, 0] += 1.0
    r[2, 0] += 2.0
    r[3, 0] += 3.0
    return r


@wp.kernel
def transform_slices(xs: wp.array[wp.vec2], ts: wp.array[wp.transform], out: wp.array[wp.transform],
                     tail: wp.array[wp.vec3]):
    i = wp.tid()
    x = xs[i]
    y = ts[i]
    y[:2] = x * x[1]
    y[1:-4] += x[:2]
    y[3:1:-1] -= x[0:]
    out[i] = y
    tail[i] = y[-3:] * y[0]


def transform_slices_ref(x, t):
    y = t.copy()
    y[:2] = x * x[1]
    y[1:-4] += x[:2]
    y[3:1:-1] -= x[0:]
    return y, y[-3:] * y[0]


def _fd_grad(f, args, k, upstream, h=1e-6):
    """d(sum(upstream * f(args)))/d(args[k]) by central differences in float64."""
    a = [np.array(v, dtype=np.float64) for v in args]
    g = np.zeros_like(a[k])
    for idx in np.ndindex(a[k].shape):
        plus = [v.copy() for v in a]
        minus = [v.copy() for v in a]
        plus[k][idx] += h
        minus[k][idx] -= h
        g[idx] = np.sum(upstream * (f(*plus) - f(*minus))) / (2 * h)
    return g


def test_matrix_slices_forward_and_adjoint(wp, rng):
    n = 6
    x = rng.uniform(0.5, 1.5, (n, 2)) * rng.choice([-1.0, 1.0], (n, 2))
    y = rng.uniform(0.5, 1.5, (n, 2, 3)) * rng.choice([-1.0, 1.0], (n, 2, 3))
    z = rng.uniform(0.5, 1.5, (n, 4, 4))
    rows = rng.integers(0, 4, n)
    up = rng.standard_normal((n, 4, 4))
    xa = wp.array(x.astype(np.float32), dtype=wp.vec2, requires_grad=True)
    ya = wp.array(y.astype(np.float32), dtype=mat23, requires_grad=True)
    za = wp.array(z.astype(np.float32), dtype=wp.mat44, requires_grad=True)
    out = wp.zeros(n, dtype=wp.mat44, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(mat_slices, n, inputs=[xa, ya, za, wp.array(rows.astype(np.int32), dtype=int)], outputs=[out])
    tape.backward(grads={out: wp.array(up.astype(np.float32), dtype=wp.mat44)})
    xr, yr, zr = (v.numpy().astype(np.float64) for v in (xa, ya, za))   # the float32 inputs
    for k in range(n):
        f = lambda a, b, c, r=rows[k]: mat_slices_ref(a, b, c, r)  # noqa: E731
        np.testing.assert_allclose(out.numpy()[k], f(xr[k], yr[k], zr[k]), rtol=1e-5, atol=1e-5)
        args = (xr[k], yr[k], zr[k])
        np.testing.assert_allclose(xa.grad.numpy()[k], _fd_grad(f, args, 0, up[k]), rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(ya.grad.numpy()[k], _fd_grad(f, args, 1, up[k]), rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(za.grad.numpy()[k], _fd_grad(f, args, 2, up[k]), rtol=1e-4, atol=1e-4)


def test_transform_slices_forward_and_adjoint(wp, rng):
    n = 5
    x = rng.uniform(0.5, 1.5, (n, 2)) * rng.choice([-1.0, 1.0], (n, 2))
    t = rng.uniform(0.5, 1.5, (n, 7))
    up_t = rng.standard_normal((n, 7))
    up_v = rng.standard_normal((n, 3))
    xa = wp.array(x.astype(np.float32), dtype=wp.vec2, requires_grad=True)
    ta = wp.array(t.astype(np.float32), dtype=wp.transform, requires_grad=True)
    out = wp.zeros(n, dtype=wp.transform, requires_grad=True)
    tail = wp.zeros(n, dtype=wp.vec3, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(transform_slices, n, inputs=[xa, ta], outputs=[out, tail])
    tape.backward(grads={out: wp.array(up_t.astype(np.float32), dtype=wp.transform),
                         tail: wp.array(up_v.astype(np.float32), dtype=wp.vec3)})
    xr, tr = xa.numpy().astype(np.float64), ta.numpy().astype(np.float64)
    for k in range(n):
        y_ref, tail_ref = transform_slices_ref(xr[k], tr[k])
        np.testing.assert_allclose(out.numpy()[k], y_ref, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(tail.numpy()[k], tail_ref, rtol=1e-5, atol=1e-5)

        def f(a, b, ut=up_t[k], uv=up_v[k]):
            yy, vv = transform_slices_ref(a, b)
            return np.sum(ut * yy) + np.sum(uv * vv)

        args = (xr[k], tr[k])
        np.testing.assert_allclose(xa.grad.numpy()[k], _fd_grad(f, args, 0, 1.0), rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(ta.grad.numpy()[k], _fd_grad(f, args, 1, 1.0), rtol=1e-4, atol=1e-4)


def test_slice_with_runtime_bound_is_an_error(wp, kernel_module):
    mod = kernel_module("""
        @wp.kernel
        def k(v: wp.vec4, n: int, out: wp.array[wp.vec2]):
            out[0] = v[n:n + 2]
    """)
    with pytest.raises(WeftCompileError) as info:
        wp.launch(mod.k, 1, inputs=[wp.vec4(), 1], outputs=[wp.zeros(1, dtype=wp.vec2)])
    line = next(k for k, text in enumerate(open(mod.__file__).read().splitlines(), 1) if "v[n:n + 2]" in text)
    assert f":{line}:" in str(info.value) and "compile-time constant" in str(info.value)


def test_slice_shape_mismatch_is_an_error(wp, kernel_module):
    mod = kernel_module("""
        @wp.kernel
        def k(m: wp.mat33, out: wp.array[wp.mat33]):
            z = m
            z[:2, 1:] = wp.vec2(1.0, 2.0)
            out[0] = z
    """)
    with pytest.raises(ValueError, match=r"The provided value is expected to be a matrix of shape \(2, 2\), "
                                         r"with dtype float32\.$"):
        wp.launch(mod.k, 1, inputs=[wp.mat33()], outputs=[wp.zeros(1, dtype=wp.mat33)])


@pytest.mark.parametrize("value, message", [
    ("wp.vec3d(5.0, 6.0, 7.0)", r"The provided vector is expected to be of length 3 with dtype float32\.$"),
    ("wp.float64(5.0)", r"The provided value is expected to be a vector of length 3, with dtype float32\.$"),
    ("wp.vec2(5.0, 6.0)", r"The length of the provided vector \(2\) isn't compatible with the given slice "
                          r"\(expected 3\)\.$"),
    ("wp.mat22d()", r"The provided matrix is expected to be of shape \(2, 2\) with dtype float32\.$"),
    ("wp.mat33()", r"The shape of the provided matrix \(\(3, 3\)\) isn't compatible with the given slice "
                   r"\(expected \(2, 2\)\)\.$"),
])
def test_slice_assignment_mismatches_use_warps_words(wp, kernel_module, value, message):
    """A value that does not fit the slice is a ValueError in Warp's words, at the line."""
    target = "v[1:]" if "vec" in value or "float64" in value else "m[1:, :2]"
    mod = kernel_module(f"""
        @wp.kernel
        def k(out: wp.array[float]):
            v = wp.vec4(1.0, 2.0, 3.0, 4.0)
            m = wp.mat33()
            {target} = {value}
            out[0] = v[0] + m[0, 0]
    """)
    with pytest.raises(ValueError, match=message) as info:
        wp.launch(mod.k, 1, outputs=[wp.zeros(1)])
    line = next(k for k, text in enumerate(open(mod.__file__).read().splitlines(), 1) if f"{target} = " in text)
    assert f":{line}:" in str(info.value)


vec0 = wp.types.vector(0, float)
vec1 = wp.types.vector(1, float)
mat00 = wp.types.matrix((0, 0), float)


@wp.kernel
def empty_slices(v: wp.vec4, m: wp.mat33, out: wp.array[int], sums: wp.array[float]):
    z = v[123:]                          # Python's rule: bounds are clamped, nothing selected
    out[0] = int(z == vec0())
    out[1] = int(v[:-123] == vec0())
    out[2] = int(v[::123] == vec1(v[0]))
    out[3] = wp.static(len(vec0()))
    e = m[3:, 1]                         # a matrix slice selecting no rows: a vec0
    out[4] = int(e == vec0())
    w = v
    w[4:] = vec0()                       # writing an empty slice changes nothing
    w[2:2] += vec0()
    out[5] = int(w == v)
    s = float(0.0)
    for i in range(len(z)):              # a loop over no components runs no iteration
        s += z[i]
    sums[0] = s + wp.length(v[:0]) + wp.dot(z, z)


def test_zero_length_slices(wp, rng):
    v = rng.uniform(-2, 2, size=4).astype(np.float32)
    out, sums = wp.zeros(6, dtype=int), wp.full(1, 5.0, dtype=float)
    wp.launch(empty_slices, 1, inputs=[wp.vec4(*v), wp.mat33(*rng.uniform(-1, 1, size=9)), out, sums])
    np.testing.assert_array_equal(out.numpy(), [1, 1, 1, 0, 1, 1])
    assert sums.numpy()[0] == 0.0


def test_zero_length_vector_is_kernel_local(wp, kernel_module):
    mod = kernel_module("""
        vec0 = wp.types.vector(0, float)

        @wp.kernel
        def k(v: vec0, out: wp.array[float]):
            out[0] = 1.0
    """)
    with pytest.raises(Exception, match="zero-length type vec\\(0,float32\\) exists only inside kernels"):
        wp.launch(mod.k, 1, inputs=[mod.vec0()], outputs=[wp.zeros(1)])


vec1 = wp.types.vector(1, float)
mat00 = wp.types.matrix((0, 0), float)


@wp.kernel
def rows_of_one(m: wp.array[wp.mat44], out: wp.array[int]):
    a = m[0]
    col = wp.matrix_from_rows(vec1(a[3, 0]), vec1(a[2, 0]), vec1(a[1, 0]), vec1(a[0, 0]))
    out[0] = wp.where(a[::-1, :1] == col, 1, 0)
    out[1] = wp.where(a[4:] == mat00(), 1, 0)   # both without elements


def test_one_component_rows_and_empty_slices_compare(rng):
    m = wp.array(rng.uniform(-10, 10, size=(1, 4, 4)).astype(np.float32), dtype=wp.mat44)
    out = wp.zeros(2, dtype=int)
    wp.launch(rows_of_one, dim=1, inputs=[m, out])
    assert out.numpy().tolist() == [1, 1]
