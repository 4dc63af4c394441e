"""Tiles (Warp's tile programming, docs/tiles.md): wp.launch_tiled, tile_load / tile_store /
tile_atomic_add with offsets at and past the array's edges, element-wise operators on scalar and
vector tiles, tile_map / tile_reduce with builtins and @wp.funcs, sums, extrema, scans,
tile_matmul (both forms and `@`), transpose, broadcast, views, slices (steps of any sign) and
assignment, each forward against a float64 NumPy reference on fresh random data of mixed
magnitudes and backward against the analytic gradient. Attacks: offsets far outside the array
(nothing read or written there), element indices and view offsets outside the tile at run time
(a launch error at the line, the session goes on), shapes that are not constants, tiles too
large, tiles as kernel arguments, mismatched shapes and dtypes."""
import numpy as np
import pytest

import weft as wp

TM = wp.constant(8)
TN = wp.constant(4)


@wp.func
def soft(x: float):
    return x * x + wp.sin(x)


@wp.func
def larger(a: float, b: float):
    return wp.max(a, b)


@wp.kernel
def tile_math(a: wp.array2d[float], b: wp.array2d[float], out: wp.array2d[float], sums: wp.array[float],
              maxes: wp.array[float], scans: wp.array2d[float]):
    i, j = wp.tid()
    x = wp.tile_load(a, shape=(TM, TN), offset=(i * TM, j * TN))
    y = wp.tile_load(b, shape=(TM, TN), offset=(i * TM, j * TN))
    z = wp.tile_map(soft, x) * 2.0 - y / 4.0 + wp.tile_map(wp.mul, x, y)
    wp.tile_store(out, z, offset=(i * TM, j * TN))
    wp.tile_atomic_add(sums, wp.tile_sum(x * y))
    wp.tile_atomic_add(maxes, wp.tile_reduce(larger, y), offset=i * 2 + j)
    row = wp.tile_scan_inclusive(x[1])
    wp.tile_store(scans, wp.tile_reshape(row, shape=(1, TN)), offset=(i * 2 + j, 0))


def test_tile_math_forward_and_backward(device, rng):
    m, n = 3 * 8, 2 * 4
    a0 = (rng.standard_normal((m, n)) * np.exp(rng.uniform(-4, 4, (m, n)))).astype(np.float32)
    b0 = rng.standard_normal((m, n)).astype(np.float32)
    a = wp.array(a0, requires_grad=True)
    b = wp.array(b0, requires_grad=True)
    out = wp.zeros((m, n), dtype=float, requires_grad=True)
    sums = wp.zeros(1, dtype=float, requires_grad=True)
    maxes = wp.zeros(6, dtype=float, requires_grad=True)
    scans = wp.zeros((6, 4), dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_math, dim=[3, 2], inputs=[a, b, out, sums, maxes, scans], block_dim=64)
    x, y = a0.astype(np.float64), b0.astype(np.float64)
    want = (x * x + np.sin(x)) * 2 - y / 4 + x * y
    np.testing.assert_allclose(out.numpy(), want, rtol=2e-6, atol=1e-6 * np.abs(want).max())
    np.testing.assert_allclose(sums.numpy()[0], (x * y).sum(), rtol=1e-5, atol=1e-5 * np.abs(x * y).sum())
    blocks = y.reshape(3, 8, 2, 4).transpose(0, 2, 1, 3).reshape(6, 32)
    np.testing.assert_array_equal(maxes.numpy(), blocks.max(axis=1).astype(np.float32))
    rows = x.reshape(3, 8, 2, 4).transpose(0, 2, 1, 3)[:, :, 1, :].reshape(6, 4)
    np.testing.assert_allclose(scans.numpy(), np.cumsum(rows, axis=1), rtol=1e-5, atol=1e-6 * np.abs(rows).max())
    # backward: d out / d a = 2 (2x + cos x) + y, d out / d b = -1/4 + x
    out.grad = wp.ones_like(out)
    tape.backward()
    np.testing.assert_allclose(a.grad.numpy(), 2 * (2 * x + np.cos(x)) + y, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(b.grad.numpy(), x - 0.25, rtol=1e-5, atol=1e-6)
    tape.zero()
    sums.grad = wp.ones_like(sums)
    maxes.grad = wp.ones_like(maxes)
    tape.backward()
    g = y.copy()
    np.testing.assert_allclose(a.grad.numpy(), g, rtol=1e-6)
    hit = np.zeros((6, 32))
    hit[np.arange(6), blocks.argmax(axis=1)] = 1
    gb = x + hit.reshape(3, 2, 8, 4).transpose(0, 2, 1, 3).reshape(m, n)
    np.testing.assert_allclose(b.grad.numpy(), gb, rtol=1e-6)


@wp.kernel
def tile_gemm(a: wp.array2d[wp.float64], b: wp.array2d[wp.float64], c: wp.array2d[wp.float64],
              d: wp.array2d[wp.float64]):
    i, j = wp.tid()
    acc = wp.tile_zeros(shape=(4, 4), dtype=wp.float64)
    for k in range(3):
        ta = wp.tile_load(a, shape=(4, 5), offset=(i * 4, k * 5))
        tb = wp.tile_load(b, shape=(5, 4), offset=(k * 5, j * 4))
        wp.tile_matmul(ta, tb, acc)
    wp.tile_store(c, acc, offset=(i * 4, j * 4))
    t = wp.tile_load(a, shape=(4, 5), offset=(i * 4, 0))
    wp.tile_store(d, wp.tile_matmul(t, wp.tile_transpose(t), alpha=wp.float64(0.5)) + t @ wp.tile_transpose(t),
                  offset=(i * 4, j * 4))


def test_tile_matmul_against_float64(device, rng):
    # near-singular factors with magnitudes over six decades
    u = rng.standard_normal((8, 15)) * np.logspace(-3, 3, 15)
    v = rng.standard_normal((15, 8))
    v[:, 1] = v[:, 0] * (1 + 1e-12)
    a = wp.array(u, dtype=wp.float64, requires_grad=True)
    b = wp.array(v, dtype=wp.float64, requires_grad=True)
    c = wp.zeros((8, 8), dtype=wp.float64, requires_grad=True)
    d = wp.zeros((8, 8), dtype=wp.float64)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_gemm, dim=[2, 2], inputs=[a, b, c, d])
    np.testing.assert_allclose(c.numpy(), u @ v, rtol=1e-12, atol=1e-12 * np.abs(u @ v).max())
    blocks = [u[i * 4:(i + 1) * 4, :5] for i in range(2)]
    want = np.block([[1.5 * blk @ blk.T] * 2 for blk in blocks])
    np.testing.assert_allclose(d.numpy(), want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    w = rng.standard_normal((8, 8))
    c.grad = wp.array(w, dtype=wp.float64)
    tape.backward()
    np.testing.assert_allclose(a.grad.numpy(), w @ v.T, rtol=1e-11, atol=1e-11 * np.abs(w @ v.T).max())
    np.testing.assert_allclose(b.grad.numpy(), u.T @ w, rtol=1e-11, atol=1e-11 * np.abs(u.T @ w).max())


@wp.kernel
def tile_edges(a: wp.array[float], out: wp.array[float], shift: int):
    t = wp.tile_load(a, shape=16, offset=shift)
    wp.tile_store(out, t + 1.0, offset=shift)


def test_tile_loads_and_stores_stop_at_the_array_edges(device, rng):
    """Elements outside the array read as zero and are never written, whatever the offset
    (negative, past the end, near the int64 limit)."""
    x = rng.standard_normal(20).astype(np.float32)
    for shift in (-10, 12, 19, 20, -16, 2**31 - 5, -(2**31) + 3):
        a = wp.array(x)
        out = wp.full(20, -7.0, dtype=float)
        wp.launch_tiled(tile_edges, dim=1, inputs=[a, out, shift])
        want = np.full(20, -7.0, dtype=np.float32)
        lo, hi = max(shift, 0), min(shift + 16, 20)
        if lo < hi:
            want[lo:hi] = x[lo:hi] + 1
        np.testing.assert_array_equal(out.numpy(), want)


@wp.kernel
def tile_views(a: wp.array2d[float], out: wp.array2d[float], rev: wp.array2d[float], vec_out: wp.array[wp.vec3],
               vecs: wp.array[wp.vec3]):
    t = wp.tile_load(a, shape=(6, 8))
    t[1, 2] = 5.0
    t[0] = wp.tile_ones(shape=8, dtype=float) * 3.0
    t[2:4, 4:8] = wp.tile_zeros(shape=(2, 4), dtype=float)
    wp.tile_store(out, t)
    r = t[::-2, 1::3]
    wp.tile_store(rev, r)
    v = wp.tile_load(vecs, shape=4)
    s = wp.tile_load(a, shape=(1, 4))
    wp.tile_store(vec_out, v * 2.0 + v / wp.tile_reshape(s, shape=4))


def test_tile_views_slices_and_assignment(device, rng):
    x = rng.standard_normal((6, 8)).astype(np.float32)
    vx = rng.standard_normal((4, 3)).astype(np.float32)
    a = wp.array(x, requires_grad=True)
    out = wp.zeros((6, 8), dtype=float, requires_grad=True)
    rev = wp.zeros((3, 3), dtype=float)
    vecs = wp.array(vx, dtype=wp.vec3)
    vec_out = wp.zeros(4, dtype=wp.vec3)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_views, dim=1, inputs=[a, out, rev, vec_out, vecs])
    e = x.copy()
    e[1, 2] = 5
    e[0] = 3
    e[2:4, 4:8] = 0
    np.testing.assert_array_equal(out.numpy(), e)
    np.testing.assert_array_equal(rev.numpy(), e[::-2, 1::3])
    want = vx.astype(np.float64) * 2 + vx.astype(np.float64) / x[0, :4, None]
    scale = (np.abs(vx * 2) + np.abs(vx / x[0, :4, None])).max()
    np.testing.assert_allclose(vec_out.numpy(), want, rtol=1e-6, atol=4e-7 * scale)
    out.grad = wp.ones_like(out)
    tape.backward()
    g = np.ones((6, 8))
    g[1, 2] = 0
    g[0] = 0
    g[2:4, 4:8] = 0
    np.testing.assert_array_equal(a.grad.numpy(), g)


@wp.kernel
def tile_bad_index(a: wp.array[float], out: wp.array[float], k: int):
    t = wp.tile_load(a, shape=8)
    out[0] = t[k]
    v = wp.tile_view(t, offset=(k,), shape=(4,))
    wp.tile_store(out, v, offset=1)


def test_tile_indices_outside_the_tile_are_launch_errors(device, rng):
    a = wp.array(rng.standard_normal(8).astype(np.float32))
    out = wp.zeros(8, dtype=float)
    wp.launch_tiled(tile_bad_index, dim=1, inputs=[a, out, 3])
    np.testing.assert_array_equal(out.numpy()[:5], np.concatenate([[a.numpy()[3]], a.numpy()[3:7]]))
    line = tile_bad_index.func.__code__.co_firstlineno + 3
    for k in (8, -9, 2**31 - 1):   # -1 .. -8 count from the end (NumPy); -9 is outside
        with pytest.raises(wp.WeftError, match=rf"test_lang_tiles.py:{line}: kernel 'tile_bad_index'.*tile index out of range"):
            wp.launch_tiled(tile_bad_index, dim=1, inputs=[a, out, k])
            wp.synchronize()
    line += 1
    with pytest.raises(wp.WeftError, match=rf"test_lang_tiles.py:{line}: kernel 'tile_bad_index'.*tile view or assignment "
                                           r"out of bounds"):
        wp.launch_tiled(tile_bad_index, dim=1, inputs=[a, out, 5])   # 5 + 4 > 8
        wp.synchronize()
    wp.launch_tiled(tile_bad_index, dim=1, inputs=[a, out, 4])   # the session goes on
    np.testing.assert_array_equal(out.numpy()[1:5], a.numpy()[4:8])


@pytest.mark.parametrize("body, message", [
    ("n = a.shape[0]\nt = wp.tile_load(a, shape=n)", r"shape.*must be an integer constant"),
    ("t = wp.tile_zeros(shape=(512, 512), dtype=float)", r"a tile holds at most 65536 elements"),
    ("t = wp.tile_zeros(shape=(4, 0), dtype=float)", r"tile extents must be positive"),
    ("t = wp.tile_load(a, shape=(4, 4))", r"has 2 dimensions, the array 1"),
    ("t = wp.tile_zeros(shape=4, dtype=float) + wp.tile_zeros(shape=5, dtype=float)", r"tiles of different shapes"),
    ("t = wp.tile_matmul(wp.tile_zeros(shape=(2, 3), dtype=float), wp.tile_zeros(shape=(2, 3), dtype=float))",
     r"do not multiply"),
    ("wp.tile_store(a, wp.tile_zeros(shape=4, dtype=int))", r"the tile holds int32, the array float32"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nu = t[0:2, 1]\nt[0:2] = u", r"requires a tile of matching shape"),
    ("t = wp.tile_load(a, shape=4, offset=1.5)", r"offsets must be integers"),
    # work bounds: the ops whose cost grows with the square of a length
    ("t = wp.tile_zeros(shape=5000, dtype=wp.vec2)\nwp.tile_fft(t)", r"not a power of two may be at most 4096"),
    ("k = wp.tile_zeros(shape=8192, dtype=float)\nv = wp.tile_zeros(shape=8192, dtype=int)\nwp.tile_sort(k, v)",
     r"sorts at most 4096 elements"),
    # Warp's errors and messages
    ("t = wp.tile_zeros(shape=4, dtype=wp.vec3)\nu = t / wp.vec3(1.0, 2.0, 3.0)",
     r"Cannot divide tile<vec3f> by vec3f: at least one operand must be a scalar type"),
    ("t = wp.tile_zeros(shape=4, dtype=wp.vec3)\nu = wp.vec3(1.0, 2.0, 3.0) * t",
     r"Cannot multiply vec3f by tile<vec3f>: at least one operand must be a scalar type"),
    ("t = wp.tile_zeros(shape=4, dtype=wp.vec3)\nu = t * t", r"tile mul: one operand's element type must be scalar"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nu = wp.tile_view(t, offset=(-1,))", r"offset -1 is out of bounds"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nu = wp.tile_view(t, offset=(4,))", r"offset 4 is out of bounds"),
    ("t = wp.tile_broadcast(wp.tile_zeros(shape=1, dtype=float), shape=(1, 1, 1, 1, 1))",
     r"tile_broadcast\(\) output must have between one and four dimensions, got 5"),
    ("t = wp.tile_squeeze(wp.tile_zeros(shape=(1, 2, 1), dtype=float), axis=(-4,))",
     r"tile_squeeze\(\) axis -4 is out of bounds for tile with 3 dimensions"),
    ("s = wp.tile_stack(capacity=0, dtype=int)", r"capacity must be a positive integer"),
    ("s = wp.tile_stack(capacity=4, dtype=int)\nwp.tile_stack_push(s, 1.0, True)",
     r"the value's type float32 does not match the stack's element type int32"),
    ("t = wp.tile_arange(0.0, 1.0e300, dtype=wp.float32)", r"stop=1e\+300 is out of range for float32"),
    ("t = wp.tile_arange(0.0, 1.0, 5.0e-324, dtype=wp.float64)", r"spans more elements than can be counted"),
    ("t = wp.tile_arange(0, 1180591620717411303424, 18446744073709551616, dtype=wp.float32)",
     r"tile_arange\(\) stop=1180591620717411303424 is too wide to use as an integer bound"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nu = t[4, :]", r"tile index 4 is out of bounds for axis 0 with extent 4"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nu = t[1, -5]", r"tile index -5 is out of bounds for axis 1"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nt[0] += wp.tile_ones(shape=4, dtype=float)",
     r"Compound assignment to a tile view is not supported"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nt[0:2, :] -= wp.tile_ones(shape=(2, 4), dtype=float)",
     r"Compound assignment to a tile view is not supported"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nu = wp.tile_view(t, offset=(slice(0, 2, 1),), shape=(2, 4))",
     r"'shape' together with a slice"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nn = a.shape[0]\nu = wp.tile_view(t, offset=(slice(0, n, 1),))",
     r"slice bounds must be compile-time constant"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nu = wp.tile_view(t, offset=(1.5,))", r"must be integers or slices"),
    ("t = wp.tile_zeros(shape=(4, 4), dtype=float)\nu = wp.tile_view(t, offset=(slice(2, 2),))", r"an empty tile slice"),
    # thread memory: tiles and their adjoints over 2 MiB
    ("t = wp.tile_zeros(shape=(256, 256), dtype=wp.float64)\nu = t * 2.0 + t", r"take \d+ bytes of the thread's memory"),
])
def test_tile_misuse_is_a_compile_error(kernel_module, device, body, message):
    lines = "".join("    " + line.strip() + "\n" for line in body.split("\n"))
    mod = kernel_module("@wp.kernel\ndef k(a: wp.array[float]):\n" + lines)
    with pytest.raises(RuntimeError, match=message):
        wp.launch_tiled(mod.k, dim=1, inputs=[wp.zeros(4, dtype=float)])


def test_tiles_cannot_be_kernel_arguments(kernel_module, device):
    mod = kernel_module("""
        @wp.kernel
        def k(t: wp.tile[float, 4]):
            pass
    """)
    with pytest.raises(RuntimeError, match=r"tile"):
        wp.launch_tiled(mod.k, dim=1, inputs=[wp.zeros(4, dtype=float)])


def test_tile_kernels_compile_for_the_gpu_without_one():
    """NVRTC compiles every tile kernel of this file, forward and adjoint, for sm_90 (no GPU
    needed)."""
    report = wp.compile(tile_math, device="cuda", arch=90)   # the whole module
    text = str(report)
    for name in ("tile_math", "tile_gemm", "tile_edges", "tile_views", "tile_bad_index", "tile_struct_arithmetic",
                 "tile_struct_arithmetic_loss", "tile_scatter_outside", "tile_prints"):
        assert name in text


@wp.struct
class Particle:
    m: float
    v: wp.vec3


@wp.func
def push(p: Particle, f: wp.vec3):
    q = Particle()
    q.m = p.m
    q.v = p.v + f / p.m
    return q


@wp.kernel
def tile_structs(ps: wp.array[Particle], f: wp.vec3, out: wp.array[Particle]):
    i = wp.tid()
    t = wp.tile_load(ps, shape=4, offset=i * 4)
    wp.tile_store(out, wp.tile_map(push, t, f), offset=i * 4)


def test_tiles_of_structs_with_gradients(device, rng):
    n = 8
    m0 = rng.uniform(0.5, 2.0, n).astype(np.float32)
    v0 = rng.standard_normal((n, 3)).astype(np.float32)
    host = []
    for k in range(n):
        p = Particle()
        p.m = float(m0[k])
        p.v = wp.vec3(*v0[k])
        host.append(p)
    ps = wp.array(host, dtype=Particle, requires_grad=True)
    out = wp.zeros(n, dtype=Particle, requires_grad=True)
    f = wp.vec3(1.0, -2.0, 0.5)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_structs, dim=2, inputs=[ps, f, out])
    got = out.numpy()
    want_v = v0.astype(np.float64) + np.array([1.0, -2.0, 0.5]) / m0[:, None].astype(np.float64)
    # float32 sums: within a few ulps of the larger addend
    np.testing.assert_allclose(got["v"], want_v, rtol=1e-6, atol=4e-7 * (np.abs(v0) + 4.0 / m0[:, None]).max())
    np.testing.assert_array_equal(got["m"], m0)
    g = np.zeros(n, dtype=out.numpy().dtype)
    g["v"] = 1.0
    out.grad = wp.array(g, dtype=Particle)
    tape.backward()
    grad = ps.grad.numpy()
    np.testing.assert_allclose(grad["v"], np.ones((n, 3)), rtol=1e-6)
    np.testing.assert_allclose(grad["m"], -(1.0 - 2.0 + 0.5) / m0 ** 2, rtol=1e-5)


@wp.kernel
def tile_linalg(ga: wp.array2d[wp.float64], gl: wp.array2d[wp.float64], gy: wp.array[wp.float64],
                gx: wp.array[wp.float64], gz: wp.array2d[wp.float64], gu: wp.array2d[wp.float64]):
    a = wp.tile_load(ga, shape=(6, 6))
    l = wp.tile_cholesky(a)
    wp.tile_store(gl, l)
    wp.tile_store(gx, wp.tile_cholesky_solve(l, wp.tile_load(gy, shape=6)))
    z = wp.tile_load(gz, shape=(6, 3))
    wp.tile_lower_solve_inplace(l, z)
    wp.tile_store(gz, z)
    u = wp.tile_cholesky(a, fill_mode="upper")
    wp.tile_store(gu, wp.tile_upper_solve(u, wp.tile_load(gz, shape=(6, 3))))


def test_tile_cholesky_and_solves(device, rng):
    """A near-singular SPD matrix (condition ~1e8): factors and solves against float64 NumPy;
    the Cholesky adjoint in Warp's convention and the solve adjoints against their formulas."""
    q, _ = np.linalg.qr(rng.standard_normal((6, 6)))
    a0 = q @ np.diag(np.logspace(-4, 4, 6)) @ q.T
    a0 = 0.5 * (a0 + a0.T)
    y0 = rng.standard_normal(6)
    z0 = rng.standard_normal((6, 3))
    ga = wp.array(a0, dtype=wp.float64, requires_grad=True)
    gl = wp.zeros((6, 6), dtype=wp.float64, requires_grad=True)
    gy = wp.array(y0, dtype=wp.float64, requires_grad=True)
    gx = wp.zeros(6, dtype=wp.float64, requires_grad=True)
    gz = wp.array(z0, dtype=wp.float64)
    gu = wp.zeros((6, 3), dtype=wp.float64)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_linalg, dim=1, inputs=[ga, gl, gy, gx, gz, gu])
    l0 = np.linalg.cholesky(a0)
    # forward error of a backward-stable factorization: about cond(A) * eps relative
    np.testing.assert_allclose(gl.numpy(), l0, rtol=1e-6, atol=1e-12 * np.abs(l0).max())
    np.testing.assert_allclose(gx.numpy(), np.linalg.solve(a0, y0), rtol=1e-6)
    zl = np.linalg.solve(l0, z0)
    np.testing.assert_allclose(gz.numpy(), zl, rtol=1e-6, atol=1e-9 * np.abs(zl).max())
    np.testing.assert_allclose(gu.numpy(), np.linalg.solve(l0.T, zl), rtol=1e-6, atol=1e-7 * np.abs(zl).max())
    adj_l = rng.standard_normal((6, 6))
    tape.backward(grads={gl: wp.array(adj_l, dtype=wp.float64)})
    p = np.tril(l0.T @ adj_l)
    p[np.diag_indices(6)] *= 0.5
    s = p + p.T
    b = np.linalg.solve(l0.T, np.linalg.solve(l0.T, s).T)
    want = np.tril(b)
    want[np.diag_indices(6)] *= 0.5
    np.testing.assert_allclose(ga.grad.numpy(), want, rtol=1e-6, atol=1e-6 * np.abs(want).max())
    tape.zero()
    adj_x = rng.standard_normal(6)
    tape.backward(grads={gx: wp.array(adj_x, dtype=wp.float64)})
    np.testing.assert_allclose(gy.grad.numpy(), np.linalg.solve(a0, adj_x), rtol=1e-6)


@wp.kernel
def tile_spectra(gx: wp.array2d[wp.vec2d], gy: wp.array2d[wp.vec2d], gz: wp.array2d[wp.vec2d]):
    t = wp.tile_load(gx, shape=(3, 16))
    wp.tile_fft(t)
    wp.tile_store(gy, t)
    u = wp.tile_load(gx, shape=(3, 12))   # not a power of two: the direct sum
    wp.tile_ifft(u)
    wp.tile_store(gz, u)


def test_tile_fft_and_ifft(device, rng):
    x = rng.standard_normal((3, 16, 2)) * np.exp(rng.uniform(-3, 3, (3, 16, 1)))
    gx = wp.array(x, dtype=wp.vec2d, requires_grad=True)
    gy = wp.zeros((3, 16), dtype=wp.vec2d, requires_grad=True)
    gz = wp.zeros((3, 16), dtype=wp.vec2d, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_spectra, dim=1, inputs=[gx, gy, gz])
    xc = x[..., 0] + 1j * x[..., 1]
    as_c = lambda a: a[..., 0] + 1j * a[..., 1]   # noqa: E731
    want = np.fft.fft(xc, axis=-1)
    np.testing.assert_allclose(as_c(gy.numpy()), want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    want_i = np.fft.ifft(xc[:, :12], axis=-1) * 12
    np.testing.assert_allclose(as_c(gz.numpy())[:, :12], want_i, rtol=1e-12, atol=1e-12 * np.abs(want_i).max())
    adj = rng.standard_normal((3, 16, 2))
    tape.backward(grads={gy: wp.array(adj, dtype=wp.vec2d)})
    g = np.fft.ifft(as_c(adj), axis=-1) * 16
    np.testing.assert_allclose(as_c(gx.grad.numpy()), g, rtol=1e-12, atol=1e-12 * np.abs(g).max())


@wp.kernel
def tile_random(seed: int, ti: wp.array2d[int], tf: wp.array2d[float], ref_i: wp.array2d[int],
                ref_f: wp.array2d[float]):
    i = wp.tid()
    rng = wp.rand_init(seed, i)
    wp.tile_store(ti, wp.tile_reshape(wp.tile_randi(shape=(2, 3), rng=rng, min=-5, max=5), shape=(1, 6)), offset=(i, 0))
    wp.tile_store(tf, wp.tile_reshape(wp.tile_randf(shape=6, rng=rng), shape=(1, 6)), offset=(i, 0))
    # Warp's rule on one thread: the state advanced once, then one draw per element
    s = wp.rand_init(seed, i)
    wp.randi(s)
    t = wp.rand_init(seed, i)
    wp.randf(t)
    for k in range(6):
        ref_i[i, k] = wp.randi(s, -5, 5)
        ref_f[i, k] = wp.randf(t)


def test_tile_random_tiles_follow_warps_draw_order(device):
    ti = wp.zeros((4, 6), dtype=int)
    tf = wp.zeros((4, 6), dtype=float)
    ref_i = wp.zeros((4, 6), dtype=int)
    ref_f = wp.zeros((4, 6), dtype=float)
    wp.launch_tiled(tile_random, dim=4, inputs=[42, ti, tf, ref_i, ref_f])
    np.testing.assert_array_equal(ti.numpy(), ref_i.numpy())
    np.testing.assert_array_equal(tf.numpy(), ref_f.numpy())
    assert ti.numpy().min() >= -5 and ti.numpy().max() < 5
    # the values Warp's own test expects on the CPU (seed 42, tile (0, 0) of its 2 x 2 launch)
    x = wp.zeros((1, 4), dtype=int)
    mod_ref = [798497746, -1161279442, -169969590, -744808085]
    wp.launch_tiled(tile_random_warp_check, dim=1, inputs=[x])
    np.testing.assert_array_equal(x.numpy()[0], mod_ref)


@wp.kernel
def tile_random_warp_check(x: wp.array2d[int]):
    rng = wp.rand_init(42, 0)
    wp.tile_store(x, wp.tile_reshape(wp.tile_randi(shape=(2, 2), rng=rng), shape=(1, 4)))


@wp.kernel
def tile_stack_ops(out: wp.array[int], vals: wp.array[float]):
    s = wp.tile_stack(capacity=4, dtype=float)
    for q in range(6):
        out[q] = wp.tile_stack_push(s, float(q) * 1.5, q != 2)
    out[6] = wp.tile_stack_count(s)
    v, slot = wp.tile_stack_pop(s)
    vals[0] = v
    out[7] = slot
    wp.tile_stack_clear(s)
    out[8] = wp.tile_stack_count(s)
    e, none = wp.tile_stack_pop(s)
    vals[1] = e
    out[9] = none


def test_tile_stacks_push_pop_clear_within_capacity(device):
    out = wp.full(10, -7, dtype=int)
    vals = wp.full(2, -7.0, dtype=float)
    wp.launch_tiled(tile_stack_ops, dim=1, inputs=[out, vals])
    # pushes of 0, 1, 3, 4 fill the 4 slots (2: has_value False), 5 finds the stack full
    np.testing.assert_array_equal(out.numpy(), [0, 1, -1, 2, 3, -1, 4, 3, 0, -1])
    np.testing.assert_array_equal(vals.numpy(), [6.0, 0.0])


@wp.kernel
def tile_big_local(a: wp.array2d[float], out: wp.array2d[float]):
    t = wp.tile_load(a, shape=(256, 256))
    wp.tile_store(out, t * 2.0 - t)


def test_a_tile_kernel_with_large_thread_memory_runs_or_fails_cleanly(device, rng):
    """768 KiB of tiles per thread (within weft's 2 MiB bound): the CPU runs it; on a GPU,
    whose threads hold at most 512 KiB of local memory, the launch is refused with a clear error
    and the session goes on."""
    x = rng.standard_normal((256, 256)).astype(np.float32)
    a = wp.array(x)
    out = wp.zeros((256, 256), dtype=float)
    try:
        wp.launch_tiled(tile_big_local, dim=1, inputs=[a, out])
        wp.synchronize()
        np.testing.assert_array_equal(out.numpy(), x)
    except wp.WeftError as err:
        assert device.startswith("cuda"), err
        assert "bytes of local memory per GPU thread" in str(err) and "tile_big_local" in str(err), err
    small = wp.zeros(4, dtype=float)
    wp.launch_tiled(tile_edges, dim=1, inputs=[wp.array(np.ones(4, dtype=np.float32)), small, 0])
    np.testing.assert_array_equal(small.numpy(), np.full(4, 2.0, dtype=np.float32))


@wp.kernel
def tile_sorting(keys: wp.array[float], vals: wp.array[int]):
    k = wp.tile_load(keys, shape=16)
    v = wp.tile_load(vals, shape=16)
    for _ in range(2):   # sorting twice changes nothing: the pair is carried through the loop
        wp.tile_sort(k, v)
    wp.tile_store(keys, k)
    wp.tile_store(vals, v)


def test_tile_sort_is_stable_and_carries_values(device, rng):
    k0 = rng.integers(-4, 4, 16).astype(np.float32)   # many equal keys: stability shows
    keys = wp.array(k0)
    vals = wp.array(np.arange(16, dtype=np.int32))
    wp.launch_tiled(tile_sorting, dim=1, inputs=[keys, vals])
    order = np.argsort(k0, kind="stable")
    np.testing.assert_array_equal(keys.numpy(), k0[order])
    np.testing.assert_array_equal(vals.numpy(), order)


@wp.func
def add_five(t: wp.tile[float, 4]):
    t += wp.tile_ones(dtype=float, shape=4) * 5.0


@wp.func
def doubled_sum(t: wp.tile[float, 4]):
    t = t * 2.0   # rebinding: a local from here on, the caller's tile is unchanged
    return wp.tile_sum(t)[0]


@wp.func
def push_pair(s: wp.tile_stack(capacity=8, dtype=int), v: int):
    wp.tile_stack_push(s, v, True)
    wp.tile_stack_push(s, v + 1, True)


@wp.kernel
def tile_by_reference(a: wp.array[float], out: wp.array[float], stack: wp.array[int]):
    t = wp.tile_load(a, shape=4)
    add_five(t)
    add_five(t)
    add_five(wp.tile_zeros(shape=4, dtype=float))   # a temporary: nothing to write back
    stack[2] = int(doubled_sum(t))
    wp.tile_store(out, t * t)
    s = wp.tile_stack(capacity=8, dtype=int)
    push_pair(s, 10)
    push_pair(s, 20)
    stack[0] = wp.tile_stack_count(s)
    v, slot = wp.tile_stack_pop(s)
    stack[1] = v


def test_tiles_and_stacks_reach_funcs_by_reference(device, rng):
    """A @wp.func that updates a tile or pushes onto a stack changes the caller's (Warp passes
    tiles by reference); one that rebinds its parameter (`t = t * 2.0`) leaves the caller's
    alone, as Python does; the gradient flows through the update: d(t + 10)^2 / dt = 2 (t + 10)."""
    a_np = rng.standard_normal(4).astype(np.float32) * np.float32(3.0)
    a = wp.array(a_np, requires_grad=True)
    out = wp.zeros(4, dtype=float, requires_grad=True)
    stack = wp.zeros(3, dtype=int)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_by_reference, dim=1, inputs=[a, out, stack])
    shifted = a_np.astype(np.float64) + 10.0
    np.testing.assert_allclose(out.numpy(), shifted ** 2, rtol=1e-6)
    assert stack.numpy().tolist()[:2] == [4, 21]
    assert stack.numpy()[2] == int(np.float32(2.0 * shifted.sum()))
    tape.backward(grads={out: wp.ones(4, dtype=float)})
    np.testing.assert_allclose(a.grad.numpy(), 2.0 * shifted, rtol=1e-6)


@wp.struct
class Mixed:
    flag: wp.bool
    small: wp.int8
    value: float
    v: wp.vec3
    count: wp.int64
    ids: wp.vec2i


@wp.kernel
def tile_mixed_structs(inp: wp.array[Mixed], stored: wp.array[Mixed], added: wp.array[Mixed]):
    t = wp.tile_load(inp, shape=8)
    wp.tile_store(stored, t)
    wp.tile_atomic_add(added, t)
    wp.tile_atomic_add(added, t)


def test_tile_atomic_add_of_structs_adds_warps_accumulating_fields(device, rng):
    """tile_atomic_add of a struct tile adds the fields Warp accumulates atomically (twice here):
    float and [u]int32 / [u]int64 scalars and vectors; bool and int8 fields, which have no atomic
    add, keep the destination's values (Warp)."""
    data = []
    for i in range(8):
        s = Mixed()
        s.flag, s.small, s.value = bool(i % 2), wp.int8(i - 4), float(rng.standard_normal())
        s.v = wp.vec3(*rng.standard_normal(3).astype(np.float32))
        s.count = int(rng.integers(-2**40, 2**40))
        s.ids = wp.vec2i(*(int(x) for x in rng.integers(-1000, 1000, 2)))
        data.append(s)
    inp = wp.array(data, dtype=Mixed)
    stored = wp.zeros(8, dtype=Mixed)
    added = wp.zeros(8, dtype=Mixed)
    wp.launch_tiled(tile_mixed_structs, dim=1, inputs=[inp, stored, added])
    src, out, acc = inp.numpy(), stored.numpy(), added.numpy()
    for field in ("flag", "small", "value", "v", "count", "ids"):
        np.testing.assert_array_equal(out[field], src[field])
    np.testing.assert_allclose(acc["value"], 2.0 * src["value"], rtol=1e-6)
    np.testing.assert_allclose(acc["v"], 2.0 * src["v"], rtol=1e-6)
    np.testing.assert_array_equal(acc["count"], 2 * src["count"])
    np.testing.assert_array_equal(acc["ids"], 2 * src["ids"])
    assert not acc["flag"].any() and not acc["small"].any()


@wp.struct
class Body:
    mass: float
    count: wp.int32
    flag: wp.bool
    small: wp.int8
    vel: wp.vec3


@wp.kernel
def tile_struct_arithmetic(a: wp.array[Body], b: wp.array[Body], s: Body, k: int, add: wp.array[Body],
                           sub: wp.array[Body], neg: wp.array[Body], total: wp.array[Body], rows: wp.array[Body],
                           inplace: wp.array[Body], elem: wp.array[Body], scattered: wp.array[Body]):
    ta = wp.tile_load(a, shape=8)
    tb = wp.tile_load(b, shape=8)
    wp.tile_store(add, ta + tb)
    wp.tile_store(sub, ta - tb)
    wp.tile_store(neg, -ta)
    wp.tile_store(total, wp.tile_sum(ta))
    wp.tile_store(rows, wp.tile_sum(wp.tile_reshape(ta, shape=(2, 4)), axis=1))
    c = wp.tile_load(a, shape=8)
    c += tb
    c -= ta
    wp.tile_store(inplace, c)
    e = wp.tile_load(a, shape=8)
    e[k] += s
    e[0] -= s
    wp.tile_store(elem, e)
    z = wp.tile_zeros(shape=8, dtype=Body)
    wp.tile_scatter_add(z, k, s, True)
    wp.tile_scatter_add(z, k, s, True, atomic=False)
    wp.tile_scatter_add(z, k + 100, s, False)   # no value: the index is not looked at
    wp.tile_scatter_masked(z, 1, s, k != 1)
    wp.tile_store(scattered, z)


def random_bodies(rng, n):
    out = []
    for _ in range(n):
        p = Body()
        p.mass = float(rng.standard_normal() * 10.0 ** rng.integers(-3, 4))
        p.count = int(rng.integers(-1000, 1000))
        p.flag = bool(rng.integers(0, 2))
        p.small = wp.int8(int(rng.integers(-100, 100)))
        p.vel = wp.vec3(*(rng.standard_normal(3) * 10.0 ** rng.integers(-3, 4)).astype(np.float32))
        out.append(p)
    return out


def test_struct_tiles_add_field_by_field(device, rng):
    """Warp's struct tile arithmetic: t + u, t - u, -t, tile_sum (whole and along an axis),
    t += u, t[i] += s, tile_scatter_add / tile_scatter_masked add float and 32/64-bit integer
    fields (vectors included); bool and int8 fields keep the left operand's value (a sum's: its
    first element's). Against float64 sums; the integer fields exactly."""
    host_a, host_b = random_bodies(rng, 8), random_bodies(rng, 8)
    s = random_bodies(rng, 1)[0]
    a, b = wp.array(host_a, dtype=Body), wp.array(host_b, dtype=Body)
    outs = [wp.zeros(n, dtype=Body) for n in (8, 8, 8, 1, 2, 8, 8, 8)]
    k = 3
    wp.launch_tiled(tile_struct_arithmetic, dim=1, inputs=[a, b, s, k, *outs])
    add, sub, neg, total, rows, inplace, elem, scattered = (o.numpy() for o in outs)
    an, bn = a.numpy(), b.numpy()
    f64 = {f: an[f].astype(np.float64) for f in ("mass", "vel")}
    g64 = {f: bn[f].astype(np.float64) for f in ("mass", "vel")}

    def close(got, want, scale):   # float32 results of float64 sums: a few ulps of the addends
        err, bound = np.abs(got.astype(np.float64) - want), 4 * np.finfo(np.float32).eps * np.asarray(scale) + 1e-30
        assert np.all(err <= bound), (got, want, err / bound)

    def carried(got, src):
        np.testing.assert_array_equal(got["flag"], src["flag"])
        np.testing.assert_array_equal(got["small"], src["small"])

    for out, sign in ((add, 1), (sub, -1)):
        close(out["mass"], f64["mass"] + sign * g64["mass"], np.abs(f64["mass"]) + np.abs(g64["mass"]))
        close(out["vel"], f64["vel"] + sign * g64["vel"], np.abs(f64["vel"]) + np.abs(g64["vel"]))
        np.testing.assert_array_equal(out["count"], an["count"] + sign * bn["count"])
        carried(out, an)
    np.testing.assert_array_equal(neg["mass"], -an["mass"])
    np.testing.assert_array_equal(neg["vel"], -an["vel"])
    np.testing.assert_array_equal(neg["count"], -an["count"])
    carried(neg, an)
    for out, groups in ((total, [slice(0, 8)]), (rows, [slice(0, 4), slice(4, 8)])):
        for r, g in enumerate(groups):
            close(out["mass"][r], f64["mass"][g].sum(), 8 * np.abs(f64["mass"][g]).sum())
            close(out["vel"][r], f64["vel"][g].sum(axis=0), 8 * np.abs(f64["vel"][g]).sum(axis=0))
            assert out["count"][r] == an["count"][g].sum()
            assert out["flag"][r] == an["flag"][g.start] and out["small"][r] == an["small"][g.start]
    close(inplace["mass"], g64["mass"], 2 * (np.abs(f64["mass"]) + np.abs(g64["mass"])))
    close(inplace["vel"], g64["vel"], 2 * (np.abs(f64["vel"]) + np.abs(g64["vel"])))
    np.testing.assert_array_equal(inplace["count"], bn["count"])
    carried(inplace, an)
    s_mass, s_vel = np.float64(np.float32(s.mass)), np.array(s.vel, dtype=np.float32).astype(np.float64)
    want_mass, want_vel, want_count = f64["mass"].copy(), f64["vel"].copy(), an["count"].copy()
    want_mass[k] += s_mass
    want_vel[k] += s_vel
    want_count[k] += s.count
    want_mass[0] -= s_mass
    want_vel[0] -= s_vel
    want_count[0] -= s.count
    close(elem["mass"], want_mass, np.abs(f64["mass"]) + abs(s_mass))
    close(elem["vel"], want_vel, np.abs(f64["vel"]) + np.abs(s_vel))
    np.testing.assert_array_equal(elem["count"], want_count)
    carried(elem, an)
    want = np.zeros(8, dtype=scattered.dtype)
    want["mass"][k], want["vel"][k], want["count"][k] = 2 * s_mass, 2 * s_vel, 2 * s.count
    want["mass"][1], want["vel"][1], want["count"][1] = s_mass, s_vel, s.count
    want["flag"][1], want["small"][1] = s.flag, s.small
    for field in ("mass", "vel", "count", "flag", "small"):
        np.testing.assert_array_equal(scattered[field], want[field])


@wp.func
def body_energy(p: Body):
    return p.mass * p.mass + wp.dot(p.vel, p.vel)


@wp.kernel
def tile_struct_arithmetic_loss(a: wp.array[Body], b: wp.array[Body], loss: wp.array[float]):
    d = (wp.tile_load(a, shape=8) + wp.tile_load(a, shape=8)) - wp.tile_load(b, shape=8)
    wp.tile_atomic_add(loss, wp.tile_sum(wp.tile_map(body_energy, -d)))
    wp.tile_atomic_add(loss, wp.tile_map(body_energy, wp.tile_sum(d)))


def test_struct_tile_arithmetic_gradients(device, rng):
    """Adjoints of struct add, sub, neg and tile_sum: loss = sum_i E(-(2 a_i - b_i)) + E(sum_i d_i)
    with E(p) = mass^2 + |vel|^2, so dloss/da_i = 2 (2 d_i + 2 S) and dloss/db_i = -(2 d_i + 2 S)
    for the float fields (float64 reference)."""
    host_a, host_b = random_bodies(rng, 8), random_bodies(rng, 8)
    a = wp.array(host_a, dtype=Body, requires_grad=True)
    b = wp.array(host_b, dtype=Body, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_struct_arithmetic_loss, dim=1, inputs=[a, b, loss])
    tape.backward(loss)
    an, bn = a.numpy(), b.numpy()
    for field in ("mass", "vel"):
        d = 2 * an[field].astype(np.float64) - bn[field].astype(np.float64)
        g = 2 * d + 2 * d.sum(axis=0)
        scale = 8 * (np.abs(an[field]).max() + np.abs(bn[field]).max()) * 8
        np.testing.assert_allclose(a.grad.numpy()[field], 2 * g, rtol=0, atol=1e-5 * scale)
        np.testing.assert_allclose(b.grad.numpy()[field], -g, rtol=0, atol=1e-5 * scale)


@wp.kernel
def tile_scatter_outside(out: wp.array[float], k: int):
    z = wp.tile_zeros(shape=4, dtype=float)
    wp.tile_scatter_add(z, k, 1.0, True)
    wp.tile_store(out, z)


def test_tile_scatter_index_outside_the_tile_is_a_launch_error(device):
    out = wp.zeros(4, dtype=float)
    line = tile_scatter_outside.func.__code__.co_firstlineno + 3
    for k in (4, -1, 2**31 - 1):
        with pytest.raises(wp.WeftError, match=rf"test_lang_tiles.py:{line}: kernel 'tile_scatter_outside'.*"
                                               r"tile index out of range"):
            wp.launch_tiled(tile_scatter_outside, dim=1, inputs=[out, k])
            wp.synchronize()
    wp.launch_tiled(tile_scatter_outside, dim=1, inputs=[out, 2])   # the session goes on
    assert out.numpy().tolist() == [0.0, 0.0, 1.0, 0.0]


@pytest.mark.parametrize("body, message", [
    ("t = wp.tile_load(a, shape=4)\nt &= t", r"Tile bitwise inplace operators do not support Warp struct tile elements"),
    ("t = wp.tile_load(a, shape=4)\nt[0] |= a[1]", r"Tile bitwise inplace operators do not support Warp struct"),
    ("s = a[0] + a[1]", r"'add' of Warp structs is defined only on the elements of struct tiles"),
    ("s = -a[0]", r"'neg' of Warp structs is defined only on the elements of struct tiles"),
    ("t = wp.tile_reduce(wp.min, wp.tile_load(a, shape=4))",
     r"tile_reduce\(\) operator min has no overload accepting Warp struct tile element type"),
    ("t = wp.tile_min(wp.tile_load(a, shape=4))", r"tile_min\(\) does not support Warp struct tile elements"),
    ("t = wp.tile_load(a, shape=4)\nwp.tile_scatter_add(t, 0, 1.0, True)", r"the value's type float32 does not match"),
    ("t = wp.tile_load(a, shape=4)\nwp.tile_scatter_add(t, 0, a[0], True, atomic=a[0].count > 0)",
     r"atomic must be a constant"),
])
def test_struct_tile_misuse_is_a_compile_error(kernel_module, device, body, message):
    lines = "".join("    " + line.strip() + "\n" for line in body.split("\n"))
    mod = kernel_module("@wp.struct\nclass P:\n    m: float\n    count: int\n\n"
                        "@wp.kernel\ndef k(a: wp.array[P]):\n" + lines)
    with pytest.raises(RuntimeError, match=message):
        wp.launch_tiled(mod.k, dim=1, inputs=[wp.zeros(4, dtype=mod.P)])


@wp.kernel
def tile_negative_indices(a: wp.array2d[float], k: int, idx: wp.array[int], row: wp.array[float],
                          rows: wp.array2d[float], out: wp.array2d[float], elems: wp.array[float]):
    t = wp.tile_load(a, shape=(6, 5))
    wp.tile_store(row, t[k, :])
    wp.tile_store(rows, t[wp.tile_load(idx, shape=4), :])
    elems[0] = t[-1, -2]
    elems[1] = t[k, k]
    t[-2] = wp.tile_zeros(shape=5, dtype=float)
    t[k, 0] += 100.0
    wp.tile_store(out, t)


def test_tile_subscripts_count_negative_indices_from_the_end(device, rng):
    """NumPy's rule for integer subscripts of tiles, constant or runtime, in views, gathers,
    element reads and writes (Warp); the gradient of the gather lands on the wrapped rows."""
    a_np = rng.standard_normal((6, 5)).astype(np.float32)
    idx_np = np.array([-1, 0, -6, 3], dtype=np.int32)
    a = wp.array(a_np, requires_grad=True)
    row = wp.zeros(5, dtype=float)
    rows = wp.zeros((4, 5), dtype=float, requires_grad=True)
    out = wp.zeros((6, 5), dtype=float)
    elems = wp.zeros(2, dtype=float)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_negative_indices, dim=1, inputs=[a, -3, wp.array(idx_np), row, rows, out, elems])
    np.testing.assert_array_equal(row.numpy(), a_np[-3])
    np.testing.assert_array_equal(rows.numpy(), a_np[idx_np])
    np.testing.assert_array_equal(elems.numpy(), [a_np[-1, -2], a_np[-3, -3]])
    expected = a_np.copy()
    expected[-2] = 0.0
    expected[-3, 0] += 100.0
    np.testing.assert_allclose(out.numpy(), expected, rtol=1e-6)
    weights = rng.standard_normal((4, 5)).astype(np.float32)
    tape.backward(grads={rows: wp.array(weights)})
    grad = np.zeros((6, 5), dtype=np.float64)
    np.add.at(grad, idx_np, weights)
    np.testing.assert_allclose(a.grad.numpy(), grad, rtol=1e-6)


@wp.kernel
def tile_view_slices(a: wp.array2d[float], k: int, o1: wp.array[float], o2: wp.array2d[float],
                     o3: wp.array2d[float], o4: wp.array[float]):
    t = wp.tile_load(a, shape=(6, 8))
    wp.tile_store(o1, wp.tile_view(t, offset=(k, slice(0, -1, 1))))
    wp.tile_store(o2, wp.tile_view(t, offset=(slice(-3, 6, 1), slice(None, None, 3))))
    wp.tile_store(o3, wp.tile_view(t, offset=(slice(5, None, -2),)))
    wp.tile_store(o4, wp.tile_view(t, offset=(slice(1, 5), 2)))


def test_tile_view_takes_slices_in_the_offset(device, rng):
    """wp.tile_view(t, offset=(slice(a, b, c), i, ...)) names the sub-tile t[a:b:c, i, ...]
    (Python's slice rules against the tile's extents; dimensions after the offset are whole);
    gradients reach the viewed elements."""
    a_np = rng.standard_normal((6, 8)).astype(np.float32)
    a = wp.array(a_np, requires_grad=True)
    o1 = wp.zeros(7, dtype=float, requires_grad=True)
    o2 = wp.zeros((3, 3), dtype=float, requires_grad=True)
    o3 = wp.zeros((3, 8), dtype=float, requires_grad=True)
    o4 = wp.zeros(4, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_view_slices, dim=1, inputs=[a, 4, o1, o2, o3, o4])
    np.testing.assert_array_equal(o1.numpy(), a_np[4, 0:-1])
    np.testing.assert_array_equal(o2.numpy(), a_np[-3:6, ::3])
    np.testing.assert_array_equal(o3.numpy(), a_np[5::-2])
    np.testing.assert_array_equal(o4.numpy(), a_np[1:5, 2])
    tape.backward(grads={o1: wp.ones(7, dtype=float), o2: wp.ones((3, 3), dtype=float),
                         o3: wp.ones((3, 8), dtype=float), o4: wp.ones(4, dtype=float)})
    grad = np.zeros((6, 8))
    grad[4, 0:-1] += 1.0
    grad[-3:6, ::3] += 1.0
    grad[5::-2] += 1.0
    grad[1:5, 2] += 1.0
    np.testing.assert_array_equal(a.grad.numpy(), grad)


@wp.kernel
def tile_view_aliases(a: wp.array2d[float], out: wp.array2d[float], seen: wp.array[float], other: wp.array2d[float]):
    src = wp.tile_load(a, shape=(4, 6))
    b = wp.tile_zeros(shape=(4, 6), dtype=float)
    for i in range(4):
        row_src = src[i]
        row_dst = b[i]
        wp.tile_assign(row_dst, row_src)        # writes into b's row i
    corner = wp.tile_view(b, offset=(1, 2), shape=(2, 3))
    corner[0, 0] = 100.0                        # element write through the view
    corner += wp.tile_ones(shape=(2, 3), dtype=float)
    inner = corner[1]                           # a view of a view
    add_three(inner)                            # a func updating the view by reference
    b[3, 5] = -7.0
    last = b[3]
    seen[0] = last[5]                           # reads b as it is now
    c = wp.tile_zeros(shape=(4, 6), dtype=float)
    row = c[0]
    row = wp.tile_ones(shape=6, dtype=float)    # rebinding: row is a new tile, c unchanged
    wp.tile_assign(row, wp.tile_ones(shape=6, dtype=float) * 2.0)
    d = wp.tile_ones(shape=(4, 6), dtype=float)
    col = d[1]
    d += wp.tile_ones(shape=(4, 6), dtype=float)    # in place: col sees it
    d = wp.tile_zeros(shape=(4, 6), dtype=float)    # rebinding d: col keeps viewing the old tile
    c[3] = col                                      # c[3] = 2
    wp.tile_store(out, b)
    wp.tile_store(other, c)


@wp.func
def add_three(t: wp.tile[float, 3]):
    t += wp.tile_ones(shape=3, dtype=float) * 3.0


def test_tile_views_alias_their_tile(device, rng):
    """A name bound to a view of a tile (row = t[i], v = wp.tile_view(t, ...)) aliases it, as in
    Warp: writes through it (tile_assign, element writes, +=, a func's by-reference update,
    views of views) change the tile, reads see the tile as it is now (also after `t += x`),
    rebinding the name ends the alias, rebinding the tile leaves the view on the old one;
    gradients follow the writes."""
    a_np = rng.standard_normal((4, 6)).astype(np.float32)
    a = wp.array(a_np, requires_grad=True)
    out = wp.zeros((4, 6), dtype=float, requires_grad=True)
    seen = wp.zeros(1, dtype=float)
    other = wp.zeros((4, 6), dtype=float)
    tape = wp.Tape()
    with tape:
        wp.launch_tiled(tile_view_aliases, dim=1, inputs=[a, out, seen, other])
    expected = a_np.astype(np.float64).copy()
    expected[1, 2] = 100.0
    expected[1:3, 2:5] += 1.0
    expected[2, 2:5] += 3.0
    expected[3, 5] = -7.0
    np.testing.assert_allclose(out.numpy(), expected, rtol=1e-6)
    assert seen.numpy()[0] == -7.0
    expected_other = np.zeros((4, 6))
    expected_other[3] = 2.0
    np.testing.assert_array_equal(other.numpy(), expected_other)
    tape.backward(grads={out: wp.ones((4, 6), dtype=float)})
    grad = np.ones((4, 6))
    grad[1, 2] = 0.0   # overwritten
    grad[3, 5] = 0.0
    np.testing.assert_array_equal(a.grad.numpy(), grad)


@wp.kernel
def tile_nan_scans(x: wp.array2d[float], hi: wp.array2d[float], lo: wp.array2d[float]):
    i = wp.tid()
    t = wp.tile_load(x, shape=(1, 64), offset=(i, 0))
    wp.tile_store(hi, wp.tile_scan_max_inclusive(t), offset=(i, 0))
    wp.tile_store(lo, wp.tile_scan_min_inclusive(t), offset=(i, 0))


def test_tile_min_max_scans_skip_nan(device, rng):
    """Running max / min skip NaN elements (NumPy's fmax / fmin accumulate, Warp's rule): NaN
    only while every element so far is NaN; infinities are values."""
    rows = []
    for k in (0, 1, 31, 63):
        r = rng.uniform(-100, 100, 64).astype(np.float32)
        r[:k] = np.nan
        rows.append(r)
    rows.append(np.full(64, np.nan, dtype=np.float32))
    rows.append(rng.choice(np.array([np.nan, -np.inf, np.inf, -1.0, 1.0], dtype=np.float32), 64))
    sparse = rng.uniform(-1e30, 1e30, 64).astype(np.float32)
    sparse[rng.random(64) < 0.3] = np.nan
    rows.append(sparse)
    x_np = np.stack(rows)
    hi = wp.zeros(x_np.shape, dtype=float)
    lo = wp.zeros(x_np.shape, dtype=float)
    wp.launch_tiled(tile_nan_scans, dim=len(rows), inputs=[wp.array(x_np), hi, lo])
    with np.errstate(invalid="ignore"):
        np.testing.assert_array_equal(hi.numpy(), np.fmax.accumulate(x_np, axis=1))
        np.testing.assert_array_equal(lo.numpy(), np.fmin.accumulate(x_np, axis=1))


@wp.kernel
def tile_arange_rounded(f32: wp.array[float], f16: wp.array[wp.float16], f64: wp.array[wp.float64]):
    wp.tile_store(f32, wp.tile_arange(0.0, 3.0000001, 0.99999999, dtype=wp.float32))
    wp.tile_store(f16, wp.tile_arange(0.0, 2049.0, 1024.0001, dtype=wp.float16))
    wp.tile_store(f64, wp.tile_arange(0.0, 3.0000001, 0.99999999, dtype=wp.float64))


def test_tile_arange_counts_the_bounds_of_its_dtype(device):
    """tile_arange rounds its bounds to the element type before counting (Warp): in float32,
    [0, 3.0000001) by 0.99999999 is [0, 3) by 1 (3 elements); in float16, 2049 is 2048 and
    1024.0001 is 1024 (2 elements); float64 keeps the values (4 elements)."""
    f32 = wp.full(4, -1.0, dtype=float)
    f16 = wp.full(3, -1.0, dtype=wp.float16)
    f64 = wp.full(5, -1.0, dtype=wp.float64)
    wp.launch_tiled(tile_arange_rounded, dim=1, inputs=[f32, f16, f64])
    np.testing.assert_array_equal(f32.numpy(), [0.0, 1.0, 2.0, -1.0])
    np.testing.assert_array_equal(f16.numpy(), [0.0, 1024.0, -1.0])
    np.testing.assert_allclose(f64.numpy(), [0.0, 0.99999999, 1.99999998, 2.99999997, -1.0], rtol=1e-15)


TILE_HALF = wp.constant(8)


@wp.kernel
def tile_arange_quotients(a: wp.array[float], b: wp.array[float], c: wp.array[float], d: wp.array[float],
                          e: wp.array[float]):
    wp.tile_store(a, wp.tile_arange(0.0, 0.3, 0.1, dtype=float))
    wp.tile_store(b, wp.tile_arange(0.0, 2.0, 0.3, dtype=float))
    wp.tile_store(c, wp.tile_arange(0.0, 0.3, dtype=float))
    wp.tile_store(d, wp.tile_arange(0.3, dtype=float))
    wp.tile_store(e, wp.tile_arange(0.0, 1180591620717411303424.0, 18446744073709551616.0, dtype=float))


def test_tile_arange_counts_the_quotient_of_its_dtype(device):
    """The count is the ceiling of (stop - start) / step as the element type holds it, at least
    one (Warp, NumPy's half-open range): float32's 0.3 / 0.1 is 3, not 3.0000001 (3 elements, not
    4); (0, 0.3) and (0.3) with the implicit step 1 hold 0 alone; 2**70 by 2**64 is 64 elements."""
    outs = [wp.full(n, -1.0, dtype=float) for n in (5, 9, 3, 3, 66)]
    wp.launch_tiled(tile_arange_quotients, dim=1, inputs=outs)
    want = [np.arange(0.0, 0.3, 0.1), np.arange(0.0, 2.0, 0.3), [0.0], [0.0], np.arange(64) * 2.0**64]
    for out, w in zip(outs, want):
        got = out.numpy()
        np.testing.assert_allclose(got[:len(w)], np.asarray(w, dtype=np.float32), rtol=1e-7)
        assert (got[len(w):] == -1.0).all(), got


@wp.kernel
def tile_constant_shapes(a: wp.array2d[float], out: wp.array[float]):
    t = wp.tile_load(a, shape=(TILE_HALF // 2, TILE_HALF * 2 - 12), offset=(TILE_HALF % 3, -7 // 2 + 4))
    wp.tile_store(out, wp.tile_reshape(t, shape=(TILE_HALF // 2) * (TILE_HALF - 4)))


TYPED_U8 = wp.constant(wp.uint8(200))


@wp.kernel
def typed_constant_arithmetic(out: wp.array[wp.uint8], folded: wp.array[int]):
    out[0] = TYPED_U8 * 2          # uint8 arithmetic: wraps to 144
    folded[0] = -7 // 2 + TILE_HALF % 3 * 10


def test_typed_constants_keep_their_arithmetic(device):
    """Folding takes untyped integers only: a typed constant (wp.uint8) keeps its type's wrapping
    arithmetic; untyped ones fold with Python's floor division and modulo."""
    out, folded = wp.zeros(1, dtype=wp.uint8), wp.zeros(1, dtype=int)
    wp.launch(typed_constant_arithmetic, dim=1, inputs=[out, folded])
    assert out.numpy()[0] == 144 and folded.numpy()[0] == -7 // 2 + 8 % 3 * 10


def test_tile_shapes_take_integer_arithmetic_on_constants(device, rng):
    """+ - * // % of integer constants (wp.constant ints, literals) are constants, folded as
    Python computes them (floor division), so shapes and offsets may be spelled with them."""
    a_np = rng.standard_normal((8, 16)).astype(np.float32)
    out = wp.zeros(16, dtype=float)
    wp.launch_tiled(tile_constant_shapes, dim=1, inputs=[wp.array(a_np), out])
    np.testing.assert_array_equal(out.numpy(), a_np[2:6, 0:4].reshape(-1))


@wp.kernel
def tile_matmul_beta_zero(a: wp.array2d[float], b: wp.array2d[float], c: wp.array2d[float]):
    out = wp.tile_load(c, shape=(4, 4))
    wp.tile_matmul(wp.tile_load(a, shape=(4, 3)), wp.tile_load(b, shape=(3, 4)), out, alpha=2.0, beta=0.0)
    wp.tile_store(c, out)


def test_tile_matmul_with_beta_zero_does_not_read_out(device, rng):
    """out = alpha a b + beta out with beta 0 never reads out: NaN and infinities there vanish
    (Warp), against a float64 product."""
    a_np, b_np = rng.standard_normal((4, 3)), rng.standard_normal((3, 4))
    c_np = np.full((4, 4), np.nan, dtype=np.float32)
    c_np[::2] = np.inf
    c = wp.array(c_np)
    wp.launch_tiled(tile_matmul_beta_zero, dim=1, inputs=[wp.array(a_np, dtype=float), wp.array(b_np, dtype=float), c])
    want = 2.0 * a_np.astype(np.float32).astype(np.float64) @ b_np.astype(np.float32).astype(np.float64)
    np.testing.assert_allclose(c.numpy(), want, rtol=1e-5, atol=1e-5 * np.abs(want).max())


@wp.kernel
def tile_prints(x: wp.array[wp.int32], m: wp.array2d[float]):
    wp.print(wp.tile_load(x, shape=(8,)))
    wp.print(wp.tile_load(m, shape=(2, 3)))
    wp.print(wp.tile_reshape(wp.tile_load(x, shape=(8,)), shape=(2, 2, 2)))


def test_tiles_print_as_warp_prints_them(device, capfd):
    """wp.print(t): nested brackets (rows one per line, higher dimensions apart by a blank line),
    then ' = tile(shape=(...), storage=register)', as Warp's CPU prints a register tile."""
    x = wp.array(np.arange(1, 9, dtype=np.int32))
    m = wp.array(np.array([[0.5, -1.0, 2.0], [3.0, 4.25, -0.125]], dtype=np.float32))
    capfd.readouterr()
    wp.launch_tiled(tile_prints, dim=1, inputs=[x, m])
    wp.synchronize()
    out = capfd.readouterr().out
    assert "[1 2 3 4 5 6 7 8] = tile(shape=(8), storage=register)\n" in out, out
    assert "[[0.5 -1 2]\n [3 4.25 -0.125]] = tile(shape=(2,3), storage=register)\n" in out, out
    assert "[[[1 2]\n  [3 4]]\n\n [[5 6]\n  [7 8]]] = tile(shape=(2,2,2), storage=register)\n" in out, out


@wp.kernel
def tile_full_types(f: wp.array[float], i: wp.array[int], v: wp.array[wp.vec3], c: wp.array[float]):
    wp.tile_store(f, wp.tile_full(shape=(4,), value=1.5))
    wp.tile_store(i, wp.tile_full(4, value=7))
    wp.tile_store(v, wp.tile_full(shape=(4,), value=wp.vec3(1.0, 2.0, 3.0)))
    wp.tile_store(c, wp.tile_full(shape=(4,), value=7, dtype=float))


def test_tile_full_takes_the_type_of_its_value(device):
    """Without a dtype, tile_full's tile holds the fill value's type (a Python int: int32);
    with one, the value is converted (Warp)."""
    f, i = wp.zeros(4, dtype=float), wp.zeros(4, dtype=int)
    v, c = wp.zeros(4, dtype=wp.vec3), wp.zeros(4, dtype=float)
    wp.launch_tiled(tile_full_types, dim=1, inputs=[f, i, v, c])
    assert f.numpy().tolist() == [1.5] * 4 and i.numpy().tolist() == [7] * 4 and c.numpy().tolist() == [7.0] * 4
    np.testing.assert_array_equal(v.numpy(), np.tile([1.0, 2.0, 3.0], (4, 1)))


@pytest.mark.parametrize("dtype", ["wp.bool", "wp.int8", "wp.uint8", "wp.int16", "wp.uint16"])
def test_tile_atomic_add_refuses_types_without_an_atomic_add(device, kernel_module, dtype):
    """tile_atomic_add takes Warp's atomic scalar set ([u]int32, [u]int64, float16, bfloat16,
    float32, float64, and composites of them): other tiles are refused with Warp's message, as
    wp.atomic_add on such arrays is."""
    mod = kernel_module(f"""
        @wp.kernel
        def k(s: wp.array[{dtype}], d: wp.array[{dtype}]):
            wp.tile_atomic_add(d, wp.tile_load(s, shape=8))
    """)
    dt = eval(dtype, {"wp": wp})
    with pytest.raises(RuntimeError, match=r"tile_atomic_add\(\) only supports tiles with \[u\]int32, \[u\]int64"):
        wp.launch_tiled(mod.k, dim=1, inputs=[wp.zeros(8, dtype=dt), wp.zeros(8, dtype=dt)])
