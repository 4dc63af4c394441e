"""Language: wp.ref[T] parameters of @wp.func (Warp 1.19). What the function does to such a
parameter reaches the caller's argument: a local, an array element, a struct field, a vector
or matrix component; a reference forwards to another wp.ref parameter; early returns keep the
value at the return. weft passes the value in and writes the final value back to the argument
after the call (so the adjoint flows through it: checked against a float64 reference); the
argument must be such a place: a literal, a call's result or an untyped literal local
(`x = 0`, as in Warp) is an error at its line."""
import numpy as np
import pytest

import weft as wp
from weft._kernel.errors import WeftCompileError


@wp.struct
class Body:
    mass: float
    vel: wp.vec3


@wp.func
def scale_add(x: wp.ref[float], k: float, d: float):
    x = x * k + d


@wp.func
def clamp_up(x: wp.ref[float], hi: float) -> int:
    if x > hi:
        x = hi
        return 1
    x += 0.5
    return 0


@wp.func
def forward(x: wp.ref[float], k: float):
    scale_add(x, k, 1.0)
    scale_add(x, k, -1.0)


@wp.func
def swap(a: wp.ref[float], b: wp.ref[float]):
    a, b = b, a


@wp.func
def count(n: wp.ref[wp.int32], step: wp.int32):
    for _ in range(3):
        n += step


@wp.kernel
def ref_places(xs: wp.array[float], ks: wp.array[float], bodies: wp.array[Body], vs: wp.array[wp.vec3],
               ms: wp.array[wp.mat22], out: wp.array[float], flags: wp.array[wp.int32], ns: wp.array[wp.int32]):
    i = wp.tid()
    k = ks[i]
    local = xs[i]
    forward(local, k)                      # a local, through a forwarded reference
    out[i] = local
    scale_add(xs[i], k, 2.0)               # an array element
    b = bodies[i]
    scale_add(b.mass, k, 0.25)             # a struct field of a local
    bodies[i] = b
    v = vs[i]
    swap(v[0], v[2])                       # vector components
    scale_add(v[1], k, 0.0)
    vs[i] = v
    m = ms[i]
    scale_add(m[1, 0], k, 3.0)             # a matrix component
    ms[i] = m
    flags[i] = clamp_up(out[i], 0.5)       # a return value and an early return
    n = wp.int32(i)
    count(n, 2)
    count(ns[i], n)


def test_ref_parameters_write_back(wp, rng):
    n = 32
    x = rng.uniform(-2.0, 2.0, n)
    k = rng.uniform(0.5, 1.5, n) * rng.choice([-1.0, 1.0], n)
    mass = rng.uniform(0.5, 2.0, n)
    vel = rng.uniform(-1.0, 1.0, (n, 3))
    m = rng.uniform(-1.0, 1.0, (n, 2, 2))
    bodies = wp.zeros(n, dtype=Body)
    bnp = bodies.numpy()
    bnp["mass"] = mass.astype(np.float32)
    bnp["vel"] = vel.astype(np.float32)
    bodies = wp.array(bnp, dtype=Body)
    xa = wp.array(x.astype(np.float32), dtype=float)
    vs = wp.array(vel.astype(np.float32), dtype=wp.vec3)
    ms = wp.array(m.astype(np.float32), dtype=wp.mat22)
    out = wp.zeros(n, dtype=float)
    flags = wp.zeros(n, dtype=wp.int32)
    ns = wp.array(np.arange(n, dtype=np.int32), dtype=wp.int32)
    x32 = x.astype(np.float32).astype(np.float64)
    k32 = k.astype(np.float32).astype(np.float64)
    wp.launch(ref_places, n, inputs=[xa, wp.array(k.astype(np.float32), dtype=float), bodies, vs, ms],
              outputs=[out, flags, ns])

    local = (x32 * k32 + 1.0) * k32 - 1.0
    ref_flags = (local > 0.5).astype(np.int32)
    ref_out = np.where(local > 0.5, 0.5, local + 0.5)
    np.testing.assert_allclose(out.numpy(), ref_out, rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(flags.numpy(), ref_flags)
    # a * k + c in float32 (fused or not) is within two roundings of its terms' magnitude: the
    # bound, not a relative tolerance, holds where the sum cancels (mass * k near -0.25)
    def f32_bound(a, c):
        return 4 * 2.0 ** -24 * (np.abs(a * k32) + abs(c))

    x_ref = x32 * k32 + 2.0
    assert np.all(np.abs(xa.numpy() - x_ref) <= f32_bound(x32, 2.0))
    m32 = mass.astype(np.float32).astype(np.float64)
    assert np.all(np.abs(bodies.numpy()["mass"] - (m32 * k32 + 0.25)) <= f32_bound(m32, 0.25))
    v32 = vel.astype(np.float32).astype(np.float64)
    ref_v = np.stack([v32[:, 2], v32[:, 1] * k32, v32[:, 0]], axis=1)
    np.testing.assert_allclose(vs.numpy(), ref_v, rtol=1e-6, atol=0)
    ref_m = m.astype(np.float32).astype(np.float64)
    ref_m[:, 1, 0] = ref_m[:, 1, 0] * k32 + 3.0
    got_m = ms.numpy()
    assert np.all(np.abs(got_m[:, 1, 0] - ref_m[:, 1, 0]) <= f32_bound(m.astype(np.float32)[:, 1, 0].astype(np.float64), 3.0))
    np.testing.assert_array_equal(np.delete(got_m.reshape(n, 4), 2, axis=1),
                                  np.delete(ref_m.reshape(n, 4), 2, axis=1))
    i = np.arange(n)
    np.testing.assert_array_equal(ns.numpy(), i + 3 * (i + 6))


@wp.func
def add_square(x: wp.ref[float], d: float):
    x += d * d


@wp.kernel
def ref_grad(a: wp.array[float], b: wp.array[float], out: wp.array[float]):
    i = wp.tid()
    s = a[i] * 2.0
    add_square(s, b[i])
    out[i] = s * a[i]


def test_ref_parameter_adjoint(wp, rng):
    n = 16
    a = rng.uniform(0.5, 2.0, n) * rng.choice([-1.0, 1.0], n)
    b = rng.uniform(0.5, 2.0, n) * rng.choice([-1.0, 1.0], n)
    up = rng.standard_normal(n)
    aa = wp.array(a.astype(np.float32), dtype=float, requires_grad=True)
    ba = wp.array(b.astype(np.float32), dtype=float, requires_grad=True)
    out = wp.zeros(n, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(ref_grad, n, inputs=[aa, ba], outputs=[out])
    tape.backward(grads={out: wp.array(up.astype(np.float32), dtype=float)})
    a64, b64 = aa.numpy().astype(np.float64), ba.numpy().astype(np.float64)
    up = up.astype(np.float32).astype(np.float64)

    # float32 against float64: 1e-5 of the terms' magnitude (2a + b*b may cancel)
    def close(got, want, scale):
        assert np.all(np.abs(got - want) <= 1e-5 * scale), np.max(np.abs(got - want) / scale)

    close(out.numpy(), (2 * a64 + b64 * b64) * a64, (2 * np.abs(a64) + b64 * b64) * np.abs(a64))
    close(aa.grad.numpy(), up * (4 * a64 + b64 * b64), np.abs(up) * (4 * np.abs(a64) + b64 * b64))
    close(ba.grad.numpy(), up * 2 * b64 * a64, np.abs(up * 2 * b64 * a64))


@pytest.mark.parametrize("body,needle", [
    ("bump(wp.int32(5))", "must be a variable, an array element"),
    ("bump(make())", "must be a variable, an array element"),
    ("x = 0\n    bump(x)", "x = wp.int32(0)"),
])
def test_ref_argument_must_be_a_place(wp, kernel_module, body, needle):
    mod = kernel_module(f"""
@wp.func
def bump(x: wp.ref[wp.int32]):
    x += 1

@wp.func
def make() -> wp.int32:
    return wp.int32(1)

@wp.kernel
def k(out: wp.array[wp.int32]):
    {body}
    out[0] = 1
""")
    with pytest.raises(WeftCompileError) as info:
        wp.launch(mod.k, 1, outputs=[wp.zeros(1, dtype=wp.int32)])
    line = next(k for k, text in enumerate(open(mod.__file__).read().splitlines(), 1) if "bump(" in text and "def" not in text)
    assert f":{line}:" in str(info.value) and needle in str(info.value)
