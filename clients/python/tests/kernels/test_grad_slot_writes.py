"""Adjoints of composite slot writes to array elements (`a[i].x = v`, `a[i].f = v`,
`a[i].f.y = v`, `a[i][r, c] = v`, `a[i].x += v`): Warp's semantics (adj_array_store_slot). An
overwrite moves the written slot's gradient into v and clears it; the element's other slots
keep their gradient (the write does not read the element); `+=` / `-=` pass the slot's gradient
through unchanged. Checked against float64 references computed by hand from random data."""
import numpy as np
import pytest

import weft as wp
from weft._kernel.errors import WeftCompileError


@wp.struct
class Pair:
    a: wp.float64
    b: wp.float64


@wp.struct
class Body:
    pos: wp.vec3d
    vel: wp.vec3d


@wp.kernel
def sequential_components(y: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i].x = x[i] * wp.float64(2.0)
    y[i].y = x[i] * x[i]
    y[i].z = wp.sin(x[i])


@wp.kernel
def struct_field(y: wp.array(dtype=Pair), x: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i].a = x[i] * x[i]


@wp.kernel
def nested_struct_component(y: wp.array(dtype=Body), x: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i].vel.y = wp.float64(3.0) * x[i]


@wp.kernel
def matrix_element_in_view(m: wp.array2d(dtype=wp.mat22d), x: wp.array(dtype=wp.float64)):
    i = wp.tid()
    row = m[i]
    row[0][1, 0] = x[i] * x[i]


@wp.kernel
def component_add_then_read(y: wp.array(dtype=wp.vec2d), x: wp.array(dtype=wp.float64),
                            out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i].x += x[i]
    y[i].y -= x[i]
    out[i] = y[i].x * y[i].y


@wp.kernel(module="unique")   # its adjoint is refused
def component_scale(y: wp.array(dtype=wp.vec2d), s: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i].y *= s[i]


@wp.kernel(module="unique", enable_backward=False)
def component_scale_forward_only(y: wp.array(dtype=wp.vec2d), s: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i].y *= s[i]


def test_sequential_component_writes_consume_each_slot(rng):
    n = 5
    xs = rng.uniform(0.5, 2.0, n)
    gs = rng.uniform(-2.0, 2.0, (n, 3))
    x = wp.array(xs, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(n, dtype=wp.vec3d, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(sequential_components, n, inputs=[y, x])
    y.grad = wp.array(gs, dtype=wp.vec3d)   # seeded after the launch (Warp's gh248)
    tape.backward()
    expected = gs[:, 0] * 2.0 + gs[:, 1] * 2.0 * xs + gs[:, 2] * np.cos(xs)
    np.testing.assert_allclose(x.grad.numpy(), expected, rtol=1e-12)
    # every slot was overwritten: its gradient was consumed
    np.testing.assert_array_equal(y.grad.numpy(), np.zeros((n, 3)))


def test_struct_field_write_keeps_other_fields_gradient(rng):
    n = 4
    xs = rng.uniform(-2.0, 2.0, n)
    ga, gb = rng.uniform(-2.0, 2.0, n), rng.uniform(-2.0, 2.0, n)
    x = wp.array(xs, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(n, dtype=Pair, requires_grad=True)
    seed = np.zeros(n, dtype=y.grad.numpy().dtype)
    seed["a"], seed["b"] = ga, gb
    y.grad.assign(seed)   # seeded before the tape (Warp's gh1174)
    tape = wp.Tape()
    with tape:
        wp.launch(struct_field, n, inputs=[y, x])
    tape.backward()
    np.testing.assert_allclose(x.grad.numpy(), ga * 2.0 * xs, rtol=1e-12)
    g = y.grad.numpy()
    np.testing.assert_array_equal(g["a"], np.zeros(n))
    np.testing.assert_array_equal(g["b"], gb)


def test_nested_struct_component_and_view_matrix_element(rng):
    n = 3
    xs = rng.uniform(-2.0, 2.0, n)
    x = wp.array(xs, dtype=wp.float64, requires_grad=True)
    y = wp.zeros(n, dtype=Body, requires_grad=True)
    gv = rng.uniform(-2.0, 2.0, (n, 3))
    seed = np.zeros(n, dtype=y.grad.numpy().dtype)
    seed["vel"] = gv
    y.grad.assign(seed)
    tape = wp.Tape()
    with tape:
        wp.launch(nested_struct_component, n, inputs=[y, x])
    tape.backward()
    np.testing.assert_allclose(x.grad.numpy(), 3.0 * gv[:, 1], rtol=1e-12)
    after = gv.copy()
    after[:, 1] = 0.0
    np.testing.assert_array_equal(y.grad.numpy()["vel"], after)
    np.testing.assert_allclose(y.numpy()["vel"][:, 1], 3.0 * xs, rtol=1e-12)

    m = wp.zeros((n, 2), dtype=wp.mat22d, requires_grad=True)
    gm = rng.uniform(-2.0, 2.0, (n, 2, 2, 2))
    x2 = wp.array(xs, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(matrix_element_in_view, n, inputs=[m, x2])
    m.grad = wp.array(gm, dtype=wp.mat22d)
    tape.backward()
    np.testing.assert_allclose(x2.grad.numpy(), gm[:, 0, 1, 0] * 2.0 * xs, rtol=1e-12)
    after = gm.copy()
    after[:, 0, 1, 0] = 0.0
    np.testing.assert_array_equal(m.grad.numpy(), after)


def test_component_add_passes_gradient_through(rng):
    n = 4
    y0 = rng.uniform(-2.0, 2.0, (n, 2))
    xs = rng.uniform(-2.0, 2.0, n)
    go = rng.uniform(-2.0, 2.0, n)
    y = wp.array(y0, dtype=wp.vec2d, requires_grad=True)
    x = wp.array(xs, dtype=wp.float64, requires_grad=True)
    out = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(component_add_then_read, n, inputs=[y, x, out])
    a, b = y0[:, 0] + xs, y0[:, 1] - xs
    np.testing.assert_allclose(out.numpy(), a * b, rtol=1e-12)
    tape.backward(grads={out: wp.array(go, dtype=wp.float64)})
    # out = (y0x + x)(y0y - x): d/dx = b - a, d/dy0x = b, d/dy0y = a
    np.testing.assert_allclose(x.grad.numpy(), go * (b - a), rtol=1e-12)
    np.testing.assert_allclose(y.grad.numpy(), np.stack([go * b, go * a], axis=1), rtol=1e-12)


def test_slot_write_adjoints_compile_for_cuda_without_a_gpu(wp, device):
    """The slot store / slot load adjoints and struct element reads compile under NVRTC
    (forward and adjoint), also on a machine without a GPU."""
    if device != "cpu":
        return   # one NVRTC compile is enough
    from test_grad_custom_adjoints import energies, gathers, reversed_slice_scale, scatter_by_counter, struct_reads

    for k in (sequential_components, struct_field, nested_struct_component, matrix_element_in_view,
              component_add_then_read, energies, gathers, struct_reads, reversed_slice_scale, scatter_by_counter):
        report = wp.compile(k, device="cuda", arch=90)
        assert report.kernel(k.name, adjoint=True).registers > 0


def test_slot_multiply_is_refused_unless_backward_is_disabled(rng):
    """`a[i].y *= s` has no adjoint (the replay no longer has the slot's old value): as in Warp,
    launching such a kernel raises while its module generates adjoints (enable_backward, the
    default); with enable_backward=False it runs."""
    n = 3
    y0, s0 = rng.uniform(-2.0, 2.0, (n, 2)), rng.uniform(-2.0, 2.0, n)
    y = wp.array(y0, dtype=wp.vec2d, requires_grad=True)
    s = wp.array(s0, dtype=wp.float64, requires_grad=True)
    with pytest.raises(WeftCompileError, match="Differentiable composite slot augmented assignments") as info:
        wp.launch(component_scale, n, inputs=[y, s])
    assert "y[i].y *= ..." in str(info.value)
    np.testing.assert_array_equal(y.numpy(), y0)   # nothing ran
    wp.launch(component_scale_forward_only, n, inputs=[y, s])
    np.testing.assert_allclose(y.numpy(), np.stack([y0[:, 0], y0[:, 1] * s0], axis=1), rtol=1e-14)
