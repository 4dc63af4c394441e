"""Fixed-size arrays (wp.zeros(shape=..., dtype=...) in kernels and funcs, Warp's
wp.fixedarray): zero-initialized, indexed in 1-3 dimensions and through views, .shape and
len() as constants, passed to a func's array parameter (writes reach the caller's elements),
returned from funcs, arrays of structs and vectors, atomics; a NumPy float64 reference on random
data. Errors: a shape that is not a constant, a fixed array returned where an array is annotated,
an index outside the fixed shape (a bounds error, nothing written outside)."""
import numpy as np
import pytest

import weft as wp


@wp.func
def fill_rows(buf: wp.array2d(dtype=wp.float64), x: wp.array(dtype=wp.float64), i: int):
    for r in range(buf.shape[0]):
        for c in range(buf.shape[1]):
            buf[r, c] = x[i] * wp.float64(r + 1) + wp.float64(c)


@wp.func
def make_table(v: wp.float64) -> wp.fixedarray(shape=(3,), dtype=wp.float64):
    t = wp.zeros(shape=(3,), dtype=wp.float64)
    for k in range(3):
        t[k] = v * wp.float64(k + 2)
    return t


@wp.kernel
def fixed_kernel(x: wp.array(dtype=wp.float64), out: wp.array2d(dtype=wp.float64)):
    i = wp.tid()
    buf = wp.zeros(shape=(4, 3), dtype=wp.float64)
    fill_rows(buf, x, i)
    row = buf[2]
    tab = make_table(x[i])
    acc = wp.float64(0.0)
    for r in range(4):
        for c in range(3):
            acc += buf[r][c]
    out[i, 0] = acc
    out[i, 1] = row[1] + wp.float64(len(buf)) + wp.float64(buf.shape[1])
    out[i, 2] = tab[0] + tab[2]
    cnt = wp.zeros(shape=8, dtype=int)
    wp.atomic_add(cnt, i % 8, 3)
    out[i, 3] = wp.float64(cnt[i % 8])


@wp.struct
class Cell:
    n: int
    w: wp.vec3


@wp.kernel
def struct_kernel(out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    cells = wp.zeros(shape=(2, 2), dtype=Cell)
    for a in range(2):
        for b in range(2):
            cells[a][b].n = a * 2 + b + i
            cells[a, b].w = wp.vec3(float(a), float(b), float(i))
    out[i] = cells[1, 0].w * float(cells[1, 1].n)


def test_fixed_arrays(wp, rng):
    n = 17
    x = rng.standard_normal(n)
    out = wp.zeros((n, 4), dtype=wp.float64)
    wp.launch(fixed_kernel, dim=n, inputs=[wp.array(x, dtype=wp.float64), out])
    r = np.arange(1, 5, dtype=np.float64)[:, None]
    c = np.arange(3, dtype=np.float64)[None, :]
    buf = x[:, None, None] * r[None] + c[None]                         # (n, 4, 3)
    expect = np.stack([buf.sum(axis=(1, 2)), buf[:, 2, 1] + 4.0 + 3.0, x * 2.0 + x * 4.0,
                       np.full(n, 3.0)], axis=1)
    np.testing.assert_allclose(out.numpy(), expect, rtol=1e-13)


def test_fixed_array_of_structs(wp):
    out = wp.zeros(5, dtype=wp.vec3)
    wp.launch(struct_kernel, dim=5, inputs=[out])
    i = np.arange(5, dtype=np.float32)
    expect = np.stack([np.ones(5), np.zeros(5), i], axis=1) * (3.0 + i)[:, None]
    np.testing.assert_allclose(out.numpy(), expect, rtol=1e-6)


def test_shape_must_be_constant(kernel_module):
    mod = kernel_module('''
import weft as wp

@wp.kernel
def k(out: wp.array(dtype=int)):
    tid = wp.tid()
    a = wp.zeros(shape=(tid,), dtype=int)
    out[tid] = a[0]
''')
    with pytest.raises(RuntimeError, match="must be specified as a constant"):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=int)])


def test_fixed_return_needs_fixed_annotation(kernel_module):
    mod = kernel_module('''
import weft as wp

@wp.func
def f() -> wp.array(dtype=int):
    return wp.zeros(shape=(2,), dtype=int)

@wp.kernel
def k(out: wp.array(dtype=int)):
    a = f()
    out[0] = a[0]
''')
    with pytest.raises(wp.WarpCodegenError, match="returns a fixed-size array"):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=int)])


@wp.kernel
def fixed_oob(n: int, out: wp.array(dtype=float)):
    a = wp.zeros(shape=(4,), dtype=float)
    a[n] = 1.0
    out[0] = a[0]


def test_fixed_index_out_of_bounds(wp):
    out = wp.zeros(1, dtype=float)
    neighbour = wp.full(16, 2.0, dtype=float)
    wp.launch(fixed_oob, dim=1, inputs=[4, out])
    with pytest.raises(wp.WeftError, match="out of bounds"):
        wp.synchronize()
    np.testing.assert_array_equal(neighbour.numpy(), 2.0)


@wp.kernel
def slice_kernel(a: wp.array2d(dtype=wp.float64), out: wp.array(dtype=wp.float64), lo: int):
    s = a[lo:, ::2]
    t = a[1, -3:]
    f = wp.zeros(shape=(3, 4), dtype=wp.float64)
    for r in range(3):
        for c in range(4):
            f[r, c] = a[r, c]
    g = f[:2, 1:]
    out[0] = s[0, 0] + s[1, 2]
    out[1] = wp.float64(s.shape[0] * 10 + s.shape[1])
    out[2] = t[0] + t[2]
    out[3] = g[1, 2] + wp.float64(g.shape[0] * 10 + g.shape[1] + g.shape[2] * 100)


def test_slices(wp, rng):
    x = rng.standard_normal((5, 7))
    out = wp.zeros(4, dtype=wp.float64)
    wp.launch(slice_kernel, dim=1, inputs=[wp.array(x, dtype=wp.float64), out, 2])
    s = x[2:, ::2]
    t = x[1, -3:]
    g = x[:3, :4][:2, 1:]
    expect = [s[0, 0] + s[1, 2], s.shape[0] * 10 + s.shape[1], t[0] + t[2], g[1, 2] + 23.0]
    np.testing.assert_allclose(out.numpy(), expect, rtol=1e-15)


@wp.kernel
def runtime_step_slice(a: wp.array2d(dtype=wp.float64), start: int, stop: int, step: int,
                       out: wp.array(dtype=wp.float64)):
    view = a[start:stop:step, 1]
    out[0] = wp.float64(view.shape[0])
    for k in range(view.shape[0]):
        out[k + 1] = view[k]


@pytest.mark.parametrize("start,stop,step", [(1, 6, 2), (5, 0, -2), (-1, -7, -1), (0, 6, 4), (4, 2, 1)])
def test_slices_with_runtime_steps(wp, rng, start, stop, step):
    """Array slices whose bounds and step are kernel arguments follow Python's rules (NumPy as
    the reference, on random values): positive and negative steps, negative bounds, an empty
    result."""
    x = rng.standard_normal((6, 3))
    out = wp.full(8, -1.0, dtype=wp.float64)
    wp.launch(runtime_step_slice, dim=1, inputs=[wp.array(x, dtype=wp.float64), start, stop, step, out])
    want = x[start:stop:step, 1]
    got = out.numpy()
    assert got[0] == len(want)
    np.testing.assert_array_equal(got[1:1 + len(want)], want)


def test_slice_with_a_zero_runtime_step_is_a_launch_error(wp, rng):
    """A step of 0 cannot be checked at compile time when it is an argument: the launch fails
    with Warp's words at the slice's line, nothing is read through the slice, and the session
    keeps working."""
    x = rng.standard_normal((6, 3))
    a = wp.array(x, dtype=wp.float64)
    out = wp.full(8, -1.0, dtype=wp.float64)
    line = runtime_step_slice.func.__code__.co_firstlineno + 3
    with pytest.raises(wp.WeftError, match=rf"test_lang_fixed_arrays.py:{line}: kernel 'runtime_step_slice'"
                                           r".*slice step cannot be zero"):
        wp.launch(runtime_step_slice, dim=1, inputs=[a, 0, 6, 0, out])
        wp.synchronize()
    assert (out.numpy()[1:] == -1.0).all()
    wp.launch(runtime_step_slice, dim=1, inputs=[a, 0, 6, 3, out])
    np.testing.assert_array_equal(out.numpy()[:3], [2.0, x[0, 1], x[3, 1]])


@wp.kernel
def slice_grad(a: wp.array(dtype=float), y: wp.array(dtype=float)):
    s = a[1::2]
    i = wp.tid()
    y[i] = s[i] * s[i]


def test_slice_gradient(wp, rng):
    x = rng.standard_normal(10).astype(np.float32)
    a = wp.array(x, dtype=float, requires_grad=True)
    y = wp.zeros(5, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(slice_grad, dim=5, inputs=[a, y])
    tape.backward(grads={y: wp.ones(5, dtype=float)})
    expect = np.zeros(10, dtype=np.float32)
    expect[1::2] = 2.0 * x[1::2]
    np.testing.assert_allclose(a.grad.numpy(), expect, rtol=1e-6)


@wp.kernel
def reinterpret_kernel(x: wp.array(dtype=float), out: wp.array(dtype=wp.vec2)):
    buf = wp.zeros(shape=(8,), dtype=float)
    for k in range(8):
        buf[k] = x[k]
    pairs = wp.array(ptr=buf.ptr, shape=(4,), dtype=wp.vec2)
    for k in range(4):
        out[k] = pairs[k]


def test_array_over_fixed_array(wp, rng):
    x = rng.standard_normal(8).astype(np.float32)
    out = wp.zeros(4, dtype=wp.vec2)
    wp.launch(reinterpret_kernel, dim=1, inputs=[wp.array(x, dtype=float), out])
    np.testing.assert_array_equal(out.numpy(), x.reshape(4, 2))


@pytest.mark.parametrize("body,message", [
    ("v = wp.array(ptr=buf.ptr, shape=(5,), dtype=wp.vec2)", "do not fit"),
    ("v = wp.array(ptr=buf.ptr, shape=(1,), dtype=wp.vec2d)", "alignment"),
    ("v = wp.array(ptr=out.ptr, shape=(1,), dtype=float)", "not a fixed-size array"),
    ("v = wp.array(ptr=buf.ptr, shape=(n,), dtype=float)", "must be constant"),
])
def test_array_over_fixed_array_errors(kernel_module, body, message):
    mod = kernel_module(f'''
import weft as wp

@wp.kernel
def k(out: wp.array(dtype=float), n: int):
    buf = wp.zeros(shape=(8,), dtype=float)
    {body}
    out[0] = 1.0
''')
    with pytest.raises(wp.WarpCodegenError, match=message):
        wp.launch(mod.k, dim=1, inputs=[wp.zeros(1, dtype=float), 1])
