"""Warp-compatibility features of the kernel language: augmented assignment to array elements
(`y[i] += x[i]`, atomic as in Warp) in 1-D to 4-D arrays of scalars, vectors and transforms;
@wp.func overloads chosen by the arguments' own types (f(1) calls f(x: int)); keyword
arguments and defaults of @wp.func; negative component indices (v[-1]); against NumPy float64
references on fresh random data, gradients against float64 central finite differences."""
import numpy as np

import weft as wp


@wp.kernel
def add_1d(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] += x[i]


@wp.kernel
def sub_scaled_1d(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] -= wp.sin(x[i]) * x[i] + 2.0


@wp.kernel
def add_2d(a: wp.array2d(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    i, j = wp.tid()
    out[i, j] += a[i, j] * a[j, i]


@wp.kernel
def add_vec(v: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] += wp.cross(v[i], wp.vec3(1.0, 2.0, 3.0))


@wp.kernel
def histogram(keys: wp.array(dtype=int), counts: wp.array(dtype=int)):
    i = wp.tid()
    counts[keys[i] % 7] += 1


@wp.kernel
def square_accumulate(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] += x[i] * x[i] * wp.exp(x[i])


def test_augmented_array_assign_1d(wp, rng):
    n = 1000
    x = rng.standard_normal(n).astype(np.float32)
    y0 = rng.standard_normal(n).astype(np.float32)
    y = wp.array(y0)
    wp.launch(add_1d, dim=n, inputs=[wp.array(x), y])
    np.testing.assert_allclose(y.numpy(), y0.astype(np.float64) + x, rtol=1e-6, atol=1e-6)
    y = wp.array(y0)
    wp.launch(sub_scaled_1d, dim=n, inputs=[wp.array(x), y])
    x64 = x.astype(np.float64)
    np.testing.assert_allclose(y.numpy(), y0 - (np.sin(x64) * x64 + 2.0), rtol=1e-5, atol=1e-5)


def test_augmented_array_assign_2d_and_vectors(wp, rng):
    n = 17
    a = rng.standard_normal((n, n))
    out0 = rng.standard_normal((n, n))
    out = wp.array(out0, dtype=wp.float64)
    wp.launch(add_2d, dim=(n, n), inputs=[wp.array(a, dtype=wp.float64), out])
    np.testing.assert_allclose(out.numpy(), out0 + a * a.T, rtol=1e-12)

    m = 300
    v = rng.standard_normal((m, 3)).astype(np.float32)
    o0 = rng.standard_normal((m, 3)).astype(np.float32)
    o = wp.array(o0, dtype=wp.vec3)
    wp.launch(add_vec, dim=m, inputs=[wp.array(v, dtype=wp.vec3), o])
    ref = o0.astype(np.float64) + np.cross(v.astype(np.float64), np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(o.numpy(), ref, rtol=1e-5, atol=1e-5)


def test_augmented_array_assign_is_atomic(wp, rng):
    keys = rng.integers(0, 1 << 20, size=20000).astype(np.int32)
    counts = wp.zeros(7, dtype=int)
    wp.launch(histogram, dim=len(keys), inputs=[wp.array(keys, dtype=int), counts])
    np.testing.assert_array_equal(counts.numpy(), np.bincount(keys % 7, minlength=7))


def test_augmented_array_assign_gradient(wp, rng):
    n = 64
    x = rng.uniform(-1.5, 1.5, n)
    xa = wp.array(x, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square_accumulate, dim=n, inputs=[xa, y])
    tape.backward(grads={y: np.ones(n)})
    h = 1e-6

    def f(z):
        return z * z * np.exp(z)

    fd = (f(x + h) - f(x - h)) / (2 * h)
    np.testing.assert_allclose(xa.grad.numpy(), fd, rtol=1e-6, atol=1e-8)


@wp.func
def which(x: float):
    return 1


@wp.func
def which(x: int):
    return 2


@wp.func
def weighted(a: wp.float64, b: wp.float64 = wp.float64(2.0), c: int = 3):
    return a * b + wp.float64(c)


@wp.kernel
def overloads_and_keywords(n: int, x: wp.array(dtype=wp.float64), iout: wp.array(dtype=int),
                           fout: wp.array(dtype=wp.float64)):
    i = wp.tid()
    iout[0] = which(1)
    iout[1] = which(n)
    iout[2] = which(1.0)
    iout[3] = which(float(n))
    fout[i * 3 + 0] = weighted(x[i], c=n)
    fout[i * 3 + 1] = weighted(b=x[i], a=wp.float64(0.5))
    fout[i * 3 + 2] = weighted(x[i])


def test_func_overloads_by_argument_type_and_keywords(wp, rng):
    n = 50
    x = rng.standard_normal(n)
    k = int(rng.integers(-100, 100))
    iout = wp.zeros(4, dtype=int)
    fout = wp.zeros(3 * n, dtype=wp.float64)
    wp.launch(overloads_and_keywords, dim=n, inputs=[k, wp.array(x, dtype=wp.float64), iout, fout])
    np.testing.assert_array_equal(iout.numpy(), [2, 2, 1, 1])
    ref = np.stack([x * 2.0 + k, 0.5 * x + 3.0, x * 2.0 + 3.0], axis=1).reshape(-1)
    np.testing.assert_allclose(fout.numpy(), ref, rtol=1e-14)


@wp.kernel
def negative_components(v: wp.array(dtype=wp.vec4d), m: wp.array(dtype=wp.mat33d), k: int,
                        out: wp.array(dtype=wp.float64), vout: wp.array(dtype=wp.vec4d),
                        mout: wp.array(dtype=wp.mat33d)):
    i = wp.tid()
    a = v[i]
    b = m[i]
    out[i * 4 + 0] = a[-1] * wp.float64(10.0) + a[-4]
    out[i * 4 + 1] = b[-1, -2]
    out[i * 4 + 2] = b[-3][2]
    out[i * 4 + 3] = a[k]              # runtime negative index
    a[-2] = wp.float64(7.0)
    a[k - 1] = a[0] + a[1]
    b[-1, 0] = wp.float64(-1.0)
    b[-2] = wp.vec3d(1.0, 2.0, 3.0)
    vout[i] = a
    mout[i] = b


def test_negative_component_indices(wp, rng):
    n = 40
    v = rng.standard_normal((n, 4))
    m = rng.standard_normal((n, 3, 3))
    k = -3
    out = wp.zeros(4 * n, dtype=wp.float64)
    vout = wp.zeros(n, dtype=wp.vec4d)
    mout = wp.zeros(n, dtype=wp.mat33d)
    wp.launch(negative_components, dim=n,
              inputs=[wp.array(v, dtype=wp.vec4d), wp.array(m, dtype=wp.mat33d), k, out, vout, mout])
    ref = np.stack([v[:, 3] * 10.0 + v[:, 0], m[:, 2, 1], m[:, 0, 2], v[:, k]], axis=1).reshape(-1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-14)
    vref = v.copy()
    vref[:, 2] = 7.0
    vref[:, k - 1] = vref[:, 0] + vref[:, 1]
    np.testing.assert_allclose(vout.numpy(), vref, rtol=1e-14)
    mref = m.copy()
    mref[:, 2, 0] = -1.0
    mref[:, 1, :] = [1.0, 2.0, 3.0]
    np.testing.assert_allclose(mout.numpy(), mref, rtol=1e-14)


@wp.kernel
def accumulate_transforms(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.transformd)):
    i = wp.tid()
    s = x[i]
    q = wp.quat_from_axis_angle(wp.vec3d(0.0, 0.0, 1.0), s)
    t = wp.transformd(wp.vec3d(s * s, wp.sin(s), wp.float64(1.0)), q)
    out[i % 3] += t
    wp.atomic_sub(out, (i + 1) % 3, t * s)


def test_transform_atomics_and_gradient(wp, rng):
    n = 30
    x = rng.uniform(-1.0, 1.0, n)

    def forward(xv):
        acc = np.zeros((3, 7))
        for i, s in enumerate(xv):
            t = np.array([s * s, np.sin(s), 1.0, 0.0, 0.0, np.sin(s / 2), np.cos(s / 2)])
            acc[i % 3] += t
            acc[(i + 1) % 3] -= t * s
        return acc

    xa = wp.array(x, dtype=wp.float64, requires_grad=True)
    out = wp.zeros(3, dtype=wp.transformd, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(accumulate_transforms, dim=n, inputs=[xa, out])
    np.testing.assert_allclose(out.numpy(), forward(x), rtol=1e-12, atol=1e-12)
    seed = rng.standard_normal((3, 7))
    tape.backward(grads={out: seed})
    h = 1e-6
    fd = np.zeros(n)
    for i in range(n):
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        fd[i] = np.sum(seed * (forward(xp) - forward(xm))) / (2 * h)
    np.testing.assert_allclose(xa.grad.numpy(), fd, rtol=1e-6, atol=1e-8)


N_COMPONENTS = 3


@wp.kernel
def types_constructors(x: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    a = x[i]
    h = wp.types.vector(a, dtype=wp.float64)                 # conversion, length from a
    f = wp.types.vector(a[1], length=N_COMPONENTS)           # fill, length from a constant
    z = wp.types.vector(length=2, dtype=wp.float16)
    m = wp.types.matrix(h[0], h[1], 2.0, 3.0, shape=(2, 2), dtype=wp.float64)
    g = wp.matrix(m)
    flags = wp.types.vector(True, False, True)
    out[i * 5 + 0] = h[0] * h[1]
    out[i * 5 + 1] = wp.float64(f[0] + f[1] + f[2])
    out[i * 5 + 2] = wp.float64(z[1]) + g[1, 1] * wp.determinant(m)
    out[i * 5 + 3] = wp.float64(1.0) if flags[-1] and not flags[1] else wp.float64(-1.0)
    out[i * 5 + 4] = g[0, 1]


def test_types_vector_matrix_constructors(wp, rng):
    n = 64
    x = rng.standard_normal((n, 2)).astype(np.float32)
    out = wp.zeros(5 * n, dtype=wp.float64)
    wp.launch(types_constructors, dim=n, inputs=[wp.array(x, dtype=wp.vec2), out])
    a = x.astype(np.float64)
    det = a[:, 0] * 3.0 - a[:, 1] * 2.0
    ref = np.stack([a[:, 0] * a[:, 1], 3 * a[:, 1], 3.0 * det, np.ones(n), a[:, 1]], axis=1).reshape(-1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-6, atol=1e-6)


@wp.struct
class Body:
    pos: wp.vec3d
    mass: wp.float64
    tag: int


@wp.kernel
def struct_positional(p: wp.array(dtype=wp.vec3d), m: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    b = Body(p[i], m[i], i)
    c = Body(p[i] * wp.float64(2.0), tag=7)
    out[i] = b.mass * wp.length(b.pos) + wp.float64(b.tag + c.tag) + c.mass + c.pos[0]


def test_struct_positional_constructor(wp, rng):
    n = 50
    p = rng.standard_normal((n, 3))
    m = rng.uniform(0.5, 2.0, n)
    out = wp.zeros(n, dtype=wp.float64)
    wp.launch(struct_positional, dim=n,
              inputs=[wp.array(p, dtype=wp.vec3d), wp.array(m, dtype=wp.float64), out])
    ref = m * np.linalg.norm(p, axis=1) + np.arange(n) + 7 + 0.0 + 2 * p[:, 0]
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-12)


@wp.kernel
def svd_out_params(a: wp.array(dtype=wp.mat33d), u_out: wp.array(dtype=wp.mat33d), s_out: wp.array(dtype=wp.vec3d),
                   v_out: wp.array(dtype=wp.mat33d), angle_out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    U = wp.mat33d()
    sigma = wp.vec3d()
    V = wp.mat33d()
    wp.svd3(a[i], U, sigma, V)
    u_out[i] = U
    s_out[i] = sigma
    v_out[i] = V
    axis = wp.vec3d()
    angle = wp.float64(0.0)
    q = wp.quat_from_axis_angle(wp.normalize(wp.vec3d(1.0, 2.0, 3.0)), wp.float64(0.1) * wp.float64(i + 1))
    wp.quat_to_axis_angle(q, axis, angle)
    angle_out[i] = angle


def test_out_parameter_forms(wp, rng):
    n = 20
    a = rng.standard_normal((n, 3, 3))
    u = wp.zeros(n, dtype=wp.mat33d)
    s = wp.zeros(n, dtype=wp.vec3d)
    v = wp.zeros(n, dtype=wp.mat33d)
    ang = wp.zeros(n, dtype=wp.float64)
    wp.launch(svd_out_params, dim=n, inputs=[wp.array(a, dtype=wp.mat33d), u, s, v, ang])
    U, S, V = u.numpy(), s.numpy(), v.numpy()
    recon = np.einsum("nij,nj,nkj->nik", U, S, V)
    np.testing.assert_allclose(recon, a, rtol=1e-8, atol=1e-8)
    # singular values up to sign (Warp's svd3 keeps U and V rotations, so one may be negative)
    np.testing.assert_allclose(np.sort(np.abs(S), axis=1), np.sort(np.linalg.svd(a, compute_uv=False), axis=1),
                               rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(ang.numpy(), 0.1 * np.arange(1, n + 1), rtol=1e-10)


@wp.kernel
def vector_slices(x: wp.array(dtype=wp.vec4d), out: wp.array(dtype=wp.vec4d), head: wp.array(dtype=wp.vec3d)):
    i = wp.tid()
    v = x[i]
    w = wp.vec4d()
    w[:2] = v[2:]                  # w0, w1 = v2, v3
    w[1:-1] += v[:2] * v[3]        # w1 += v0 * v3, w2 += v1 * v3
    w[3:0:-2] -= v[::2]            # w3 -= v0, w1 -= v2
    out[i] = w
    head[i] = v[-1:-4:-1]          # v3, v2, v1


def _slices_reference(v):
    w = np.zeros_like(v)
    w[:, 0:2] = v[:, 2:]
    w[:, 1:3] += v[:, :2] * v[:, 3:4]
    w[:, 3:0:-2] -= v[:, ::2]
    return w


def test_vector_slices_and_gradient(wp, rng):
    n = 30
    v = rng.standard_normal((n, 4))
    xa = wp.array(v, dtype=wp.vec4d, requires_grad=True)
    out = wp.zeros(n, dtype=wp.vec4d, requires_grad=True)
    head = wp.zeros(n, dtype=wp.vec3d, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(vector_slices, dim=n, inputs=[xa, out, head])
    np.testing.assert_allclose(out.numpy(), _slices_reference(v), rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(head.numpy(), v[:, -1:-4:-1], rtol=1e-14)
    seed = rng.standard_normal((n, 4))
    tape.backward(grads={out: seed})
    h = 1e-6
    fd = np.zeros_like(v)
    for c in range(4):
        vp, vm = v.copy(), v.copy()
        vp[:, c] += h
        vm[:, c] -= h
        fd[:, c] = np.sum(seed * (_slices_reference(vp) - _slices_reference(vm)), axis=1) / (2 * h)
    np.testing.assert_allclose(xa.grad.numpy(), fd, rtol=1e-6, atol=1e-8)


@wp.kernel
def row_views(a: wp.array2d(dtype=wp.float64), b: wp.array3d(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    i = wp.tid()
    row = a[i]                     # a 1-D view of row i
    plane = b[i]                   # a 2-D view
    for j in range(row.shape[0]):
        out[i][j] = row[j] * plane[j, 1] + wp.sin(b[i][j][0])


def test_sub_array_views_and_gradient(wp, rng):
    n, m = 6, 5
    a = rng.standard_normal((n, m))
    b = rng.standard_normal((n, m, 2))
    aa = wp.array(a, dtype=wp.float64, requires_grad=True)
    bb = wp.array(b, dtype=wp.float64, requires_grad=True)
    out = wp.zeros((n, m), dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(row_views, dim=n, inputs=[aa, bb, out])
    np.testing.assert_allclose(out.numpy(), a * b[:, :, 1] + np.sin(b[:, :, 0]), rtol=1e-14)
    seed = rng.standard_normal((n, m))
    tape.backward(grads={out: seed})
    np.testing.assert_allclose(aa.grad.numpy(), seed * b[:, :, 1], rtol=1e-12)
    gb = np.stack([seed * np.cos(b[:, :, 0]), seed * a], axis=2)
    np.testing.assert_allclose(bb.grad.numpy(), gb, rtol=1e-12)


@wp.func
def clipped_sqrt(x: wp.float64):
    return wp.sqrt(wp.max(x, wp.float64(0.0)))


@wp.func_grad(clipped_sqrt)
def adj_clipped_sqrt(x: wp.float64, adj_ret: wp.float64):
    # the true derivative where x > 0, and 0 (not inf) at and below 0
    if x > wp.float64(0.0):
        wp.adjoint[x] += adj_ret / (wp.float64(2.0) * wp.sqrt(x))


@wp.func
def product_and_sum(a: wp.float64, b: wp.float64):
    return a * b, a + b


@wp.func_grad(product_and_sum)
def adj_product_and_sum(a: wp.float64, b: wp.float64, adj_p: wp.float64, adj_s: wp.float64):
    # deliberately not the true gradient, to show which one the backward pass uses
    wp.adjoint[a] += wp.float64(10.0) * adj_p
    wp.adjoint[b] += wp.float64(100.0) * adj_s


@wp.kernel
def custom_gradients(x: wp.array(dtype=wp.float64), w: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64),
                     z: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] = clipped_sqrt(x[i]) * wp.exp(x[i])
    p, s = product_and_sum(x[i], w[i])
    z[i] = p + s


def test_custom_gradient_func_grad(wp, rng):
    n = 40
    x = rng.uniform(0.2, 3.0, n)
    x[:5] = [-1.0, -0.5, 0.0, -2.0, 0.0]          # where the custom gradient differs from sqrt's
    w = rng.standard_normal(n)
    xa = wp.array(x, dtype=wp.float64, requires_grad=True)
    wa = wp.array(w, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    z = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(custom_gradients, dim=n, inputs=[xa, wa, y, z])
    f = lambda v: np.sqrt(np.maximum(v, 0.0)) * np.exp(v)  # noqa: E731
    np.testing.assert_allclose(y.numpy(), f(x), rtol=1e-14)
    # (x * w) + (x + w) against numpy's (x * w + x) + w: a few ulps of the operands apart where they cancel
    np.testing.assert_allclose(z.numpy(), x * w + x + w, rtol=1e-14, atol=1e-14)
    tape.backward(grads={y: np.ones(n)})
    # where x > 0 the custom gradient is the true one: central finite differences
    h = 1e-7
    fd = (f(x + h) - f(x - h)) / (2 * h)
    got = xa.grad.numpy()
    np.testing.assert_allclose(got[5:], fd[5:], rtol=1e-6)
    # at and below 0 only the exp factor's term remains (the sqrt factor is 0)
    np.testing.assert_allclose(got[:5], 0.0, atol=1e-15)
    tape.zero()
    seed = rng.standard_normal(n)
    tape.backward(grads={z: seed})
    np.testing.assert_allclose(xa.grad.numpy(), 10.0 * seed, rtol=1e-14)
    np.testing.assert_allclose(wa.grad.numpy(), 100.0 * seed, rtol=1e-14)


@wp.func
def logistic(x: wp.float64):
    return wp.float64(1.0) / (wp.float64(1.0) + wp.exp(-x))


@wp.func_grad(logistic)
def adj_logistic(x: wp.float64, adj: wp.float64):
    # the gradient calls the func it is the gradient of (Warp's adj_sigmoid)
    wp.adjoint[x] += adj * logistic(x) * (wp.float64(1.0) - logistic(x))


@wp.kernel
def logistic_of(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] = logistic(x[i]) * x[i]


def test_custom_gradient_may_call_its_func(wp, rng):
    n = 64
    x = rng.uniform(-30.0, 30.0, n)
    x[:3] = [0.0, 1e-8, -700.0]                    # tiny and saturated arguments
    xa = wp.array(x, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(logistic_of, dim=n, inputs=[xa, y])
    s = 1.0 / (1.0 + np.exp(-x))
    np.testing.assert_allclose(y.numpy(), s * x, rtol=1e-14, atol=1e-300)
    seed = rng.standard_normal(n)
    tape.backward(grads={y: seed})
    # d/dx [s(x) x] = s'(x) x + s(x), s' = s (1 - s): float64 throughout
    np.testing.assert_allclose(xa.grad.numpy(), seed * (s * (1.0 - s) * x + s), rtol=1e-12, atol=1e-300)


@wp.kernel
def rows_and_cols(v: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    a = v[i * 4 + 0]
    b = v[i * 4 + 1]
    c = v[i * 4 + 2]
    d = v[i * 4 + 3]
    r = wp.matrix_from_rows(a, b)              # 2x3
    k = wp.matrix_from_cols(a, b, c, d)        # 3x4
    p = r @ k                                  # 2x4
    out[i] = p[1, 3] + p[0, 0] * r[1, 2]


def _rows_and_cols_reference(v):
    v = v.reshape(-1, 4, 3)
    r = v[:, :2, :]
    k = np.transpose(v, (0, 2, 1))
    p = r @ k
    return p[:, 1, 3] + p[:, 0, 0] * r[:, 1, 2]


def test_matrix_from_any_number_of_rows_or_columns(wp, rng):
    n = 12
    v = rng.standard_normal((4 * n, 3))
    va = wp.array(v, dtype=wp.vec3d, requires_grad=True)
    out = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(rows_and_cols, dim=n, inputs=[va, out])
    np.testing.assert_allclose(out.numpy(), _rows_and_cols_reference(v), rtol=1e-12)
    tape.backward(grads={out: np.ones(n)})
    h = 1e-6
    fd = np.zeros_like(v)
    for j in range(v.shape[0]):
        for c in range(3):
            vp, vm = v.copy(), v.copy()
            vp[j, c] += h
            vm[j, c] -= h
            fd[j, c] = (np.sum(_rows_and_cols_reference(vp)) - np.sum(_rows_and_cols_reference(vm))) / (2 * h)
    np.testing.assert_allclose(va.grad.numpy(), fd, rtol=1e-6, atol=1e-8)
