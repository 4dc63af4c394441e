"""Warp's constant locals: a name assigned once from a numeric literal converts as that literal
in typed constructors (wp.vec3d(x, ...), wp.float64(x): the literal's float64 value, not the
float32 one) and is a constant integer where one is needed (slice bounds); a name assigned more
than once is an ordinary float32/int32 variable. Also: lerp of transforms, and @wp.func
reached through a Python object's attribute (foo.compute() where foo is a closure variable)."""
import numpy as np
import pytest

import weft as wp


def test_literal_local_converts_as_its_literal(wp, kernel_module, rng):
    lit = float(rng.uniform(0.01, 10.0))
    text = repr(lit)
    n = int(rng.integers(1, 4))
    m = kernel_module(f"""
        @wp.kernel
        def k(values: wp.array(dtype=wp.float64), counts: wp.array(dtype=wp.int32)):
            x = {text}
            n = {n}
            d = wp.vec3d(x, 0.0, 0.0)
            values[0] = d[0]
            values[1] = wp.float64(x)
            f = wp.vec3f(4.0, 5.0, 6.0)
            s = f[0:n]
            counts[0] = n
            counts[1] = wp.int32(s[n - 1])
    """)
    values = wp.zeros(2, dtype=wp.float64)
    counts = wp.zeros(2, dtype=wp.int32)
    wp.launch(m.k, dim=1, inputs=[values, counts])
    got = values.numpy()
    assert got[0] == np.float64(lit) and got[1] == np.float64(lit)
    np.testing.assert_array_equal(counts.numpy(), [n, 4 + n - 1])


def test_reassigned_local_is_a_variable(wp, kernel_module):
    m = kernel_module("""
        @wp.kernel
        def k(values: wp.array(dtype=wp.float64)):
            x = 0.5
            x = x + 1.0
            d = wp.vec3d(x, 0.0, 0.0)
            values[0] = d[0]
    """)
    values = wp.zeros(1, dtype=wp.float64)
    with pytest.raises(wp.WarpCodegenTypeError, match="expected to be of the type `float64`"):
        wp.launch(m.k, dim=1, inputs=[values])


@wp.kernel
def lerp_transforms(a: wp.array(dtype=wp.transform), b: wp.array(dtype=wp.transform), t: wp.array(dtype=float),
                    out: wp.array(dtype=wp.transform)):
    i = wp.tid()
    out[i] = wp.lerp(a[i], b[i], t[i])


def test_lerp_of_transforms_and_its_adjoint(wp, rng):
    n = 16
    a_np, b_np = rng.standard_normal((n, 7)), rng.standard_normal((n, 7))
    t_np = rng.uniform(0.0, 1.0, n)
    a = wp.array(a_np.astype(np.float32), dtype=wp.transform, requires_grad=True)
    b = wp.array(b_np.astype(np.float32), dtype=wp.transform, requires_grad=True)
    t = wp.array(t_np.astype(np.float32), dtype=float, requires_grad=True)
    out = wp.zeros(n, dtype=wp.transform, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(lerp_transforms, dim=n, inputs=[a, b, t, out])
    want = a_np * (1 - t_np[:, None]) + b_np * t_np[:, None]
    np.testing.assert_allclose(out.numpy(), want, rtol=1e-5, atol=1e-5)
    seed = rng.standard_normal((n, 7))
    tape.backward(grads={out: wp.array(seed.astype(np.float32), dtype=wp.transform)})
    np.testing.assert_allclose(a.grad.numpy(), seed * (1 - t_np[:, None]), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(b.grad.numpy(), seed * t_np[:, None], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(t.grad.numpy(), ((b_np - a_np) * seed).sum(1), rtol=1e-4, atol=1e-4)


class _Holder:
    @wp.func
    def twice(x: float):
        return 2.0 * x


def _make_kernel(holder, scale):
    def body(x: wp.array(dtype=float), y: wp.array(dtype=float)):
        i = wp.tid()
        y[i] = holder.twice(x[i]) * holder.scale

    holder.scale = scale
    return wp.Kernel(func=body)


def test_func_through_an_object_attribute(wp, rng):
    n = 10
    holder = _Holder()
    scale = float(rng.uniform(1.0, 3.0))
    k = _make_kernel(holder, scale)
    x_np = rng.standard_normal(n)
    x = wp.array(x_np, dtype=float)
    y = wp.zeros(n, dtype=float)
    wp.launch(k, dim=n, inputs=[x, y])
    np.testing.assert_allclose(y.numpy(), 2.0 * x_np * scale, rtol=1e-5)
