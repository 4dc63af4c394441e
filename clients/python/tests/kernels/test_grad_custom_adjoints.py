"""wp.adjoint[...] forms of Warp's custom gradients (@wp.func_grad) beyond a plain parameter:
a struct parameter's fields (`wp.adjoint[s.f] += ...`, `wp.adjoint[s.v][k] += ...`,
`wp.adjoint[s.v].y = ...`) and an array parameter's gradient array (`wp.adjoint[a][i] += ...`,
written in place); the adjoint of reading a struct element of an array (fieldwise into the
gradient array); and gradients through negative-step array slices. Float64 references on random
data; misuse of wp.adjoint is a compile error at its line."""
import numpy as np
import pytest

import weft as wp
from weft._kernel.errors import WeftCompileError


@wp.struct
class Params:
    k: wp.float64
    v: wp.vec3d
    tag: wp.int32


@wp.func
def energy(p: Params):
    return p.k * p.v[0] * p.v[1] + wp.sin(p.v[2]), p.k * p.k


@wp.func_grad(energy)
def adj_energy(p: Params, adj_e: wp.float64, adj_q: wp.float64):
    # the true gradient, written through struct fields and components
    wp.adjoint[p.k] += adj_e * p.v[0] * p.v[1] + adj_q * wp.float64(2.0) * p.k
    wp.adjoint[p.v][0] += adj_e * p.k * p.v[1]
    wp.adjoint[p.v][1] += adj_e * p.k * p.v[0]
    wp.adjoint[p.v].z = adj_e * wp.cos(p.v[2])


@wp.kernel
def energies(ps: wp.array(dtype=Params), e: wp.array(dtype=wp.float64), q: wp.array(dtype=wp.float64)):
    i = wp.tid()
    a, b = energy(ps[i])
    e[i] = a
    q[i] = b


@wp.func
def gather_scaled(values: wp.array(dtype=wp.float64), i: int, s: wp.float64):
    return values[i] * s


@wp.func_grad(gather_scaled)
def adj_gather_scaled(values: wp.array(dtype=wp.float64), i: int, s: wp.float64, adj_ret: wp.float64):
    # the gradient array of `values` is updated in place, `s` through its slot
    wp.adjoint[values][i] += wp.float64(3.0) * s * adj_ret
    wp.adjoint[s] += values[i] * adj_ret


@wp.kernel
def gathers(values: wp.array(dtype=wp.float64), idx: wp.array(dtype=wp.int32), s: wp.array(dtype=wp.float64),
            out: wp.array(dtype=wp.float64)):
    t = wp.tid()
    out[t] = gather_scaled(values, idx[t], s[t])


@wp.kernel
def struct_reads(ps: wp.array(dtype=Params), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    p = ps[i]
    out[i] = p.k * wp.dot(p.v, p.v) + wp.float64(p.tag)


@wp.kernel
def reversed_slice_scale(a: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64), start: int, stop: int,
                         step: int):
    i = wp.tid()
    view = a[start:stop:step]
    out[i] = view[i] * view[i]


def _params(rng, n):
    ps = []
    for _ in range(n):
        p = Params()
        p.k = float(rng.uniform(0.5, 2.0))
        p.v = wp.vec3d(*rng.uniform(-2.0, 2.0, 3))
        p.tag = int(rng.integers(0, 9))
        ps.append(p)
    return ps


def test_custom_gradient_writes_struct_fields(rng):
    n = 5
    ps = wp.array(_params(rng, n), dtype=Params, requires_grad=True)
    e = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    q = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(energies, n, inputs=[ps], outputs=[e, q])
    ge, gq = rng.uniform(-1.0, 1.0, n), rng.uniform(-1.0, 1.0, n)
    tape.backward(grads={e: wp.array(ge, dtype=wp.float64), q: wp.array(gq, dtype=wp.float64)})
    p = ps.numpy()
    k, v = p["k"], p["v"]
    g = ps.grad.numpy()
    np.testing.assert_allclose(g["k"], ge * v[:, 0] * v[:, 1] + gq * 2.0 * k, rtol=1e-12)
    expected_v = np.stack([ge * k * v[:, 1], ge * k * v[:, 0], ge * np.cos(v[:, 2])], axis=1)
    np.testing.assert_allclose(g["v"], expected_v, rtol=1e-12)
    np.testing.assert_array_equal(g["tag"], np.zeros(n))


def test_custom_gradient_updates_an_array_parameters_gradient(rng):
    m, n = 6, 20
    values = wp.array(rng.uniform(-2.0, 2.0, m), dtype=wp.float64, requires_grad=True)
    idx_np = rng.integers(0, m, n).astype(np.int32)
    s_np = rng.uniform(-2.0, 2.0, n)
    s = wp.array(s_np, dtype=wp.float64, requires_grad=True)
    out = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(gathers, n, inputs=[values, wp.array(idx_np, dtype=wp.int32), s], outputs=[out])
    seed = rng.uniform(-1.0, 1.0, n)
    tape.backward(grads={out: wp.array(seed, dtype=wp.float64)})
    expected = np.zeros(m)
    np.add.at(expected, idx_np, 3.0 * s_np * seed)   # many threads share an element: atomic
    np.testing.assert_allclose(values.grad.numpy(), expected, rtol=1e-12)
    np.testing.assert_allclose(s.grad.numpy(), values.numpy()[idx_np] * seed, rtol=1e-12)


def test_reading_struct_elements_differentiates_their_fields(rng):
    n = 4
    ps = wp.array(_params(rng, n), dtype=Params, requires_grad=True)
    out = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(struct_reads, n, inputs=[ps], outputs=[out])
    seed = rng.uniform(-1.0, 1.0, n)
    tape.backward(grads={out: wp.array(seed, dtype=wp.float64)})
    p, g = ps.numpy(), ps.grad.numpy()
    np.testing.assert_allclose(g["k"], seed * np.sum(p["v"] ** 2, axis=1), rtol=1e-12)
    np.testing.assert_allclose(g["v"], 2.0 * (seed * p["k"])[:, None] * p["v"], rtol=1e-12)
    np.testing.assert_array_equal(g["tag"], np.zeros(n))


@pytest.mark.parametrize("start,stop,step", [(5, None, -2), (4, -7, -1), (-1, 0, -3), (2, 9, -1)])
def test_negative_step_slice_values_and_gradients(rng, start, stop, step):
    n = 6
    a_np = rng.uniform(-2.0, 2.0, n)
    picked = np.arange(n)[slice(start, stop, step)]
    a = wp.array(a_np, dtype=wp.float64, requires_grad=True)
    out = wp.zeros(max(len(picked), 1), dtype=wp.float64, requires_grad=True)
    stop_arg = -n - 1 if stop is None else stop   # "before the first element", as Python's None
    tape = wp.Tape()
    with tape:
        wp.launch(reversed_slice_scale, len(picked), inputs=[a, out, start, stop_arg, step])
    np.testing.assert_allclose(out.numpy()[:len(picked)], a_np[picked] ** 2, rtol=1e-14)
    if len(picked) == 0:   # an empty view: nothing launched, nothing recorded
        return
    tape.backward(grads={out: wp.ones(out.shape[0], dtype=wp.float64)})
    expected = np.zeros(n)
    expected[picked] = 2.0 * a_np[picked]
    np.testing.assert_allclose(a.grad.numpy(), expected, rtol=1e-14)


def _compile_error(kernel):
    with pytest.raises(WeftCompileError) as info:
        wp.launch(kernel, 1, inputs=[wp.zeros(1, dtype=wp.float64), wp.zeros(1, dtype=wp.float64)])
    return str(info.value)


def test_misused_adjoint_forms_are_compile_errors():
    @wp.func
    def f_whole(values: wp.array(dtype=wp.float64)):
        return values[0]

    @wp.func_grad(f_whole)
    def adj_f_whole(values: wp.array(dtype=wp.float64), adj: wp.float64):
        wp.adjoint[values] = values   # the gradient array itself cannot be rebound

    @wp.kernel(module="unique")
    def k_whole(a: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
        out[0] = f_whole(a)

    assert "assign its elements" in _compile_error(k_whole)

    @wp.func
    def f_field(p: Params):
        return p.k

    @wp.func_grad(f_field)
    def adj_f_field(p: Params, adj: wp.float64):
        wp.adjoint[p.missing] += adj

    @wp.kernel(module="unique")
    def k_field(a: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
        p = Params()
        p.k = a[0]
        out[0] = f_field(p)

    assert "has no field 'missing'" in _compile_error(k_field)

    @wp.kernel(module="unique")
    def k_outside(a: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
        wp.adjoint[a][0] += 1.0

    assert "only available in a gradient function" in _compile_error(k_outside)


@wp.func
def take_slot(counter: wp.array(dtype=wp.int32), slots: wp.array(dtype=wp.int32), t: int):
    s = wp.atomic_add(counter, 0, 1)   # which slot a thread gets depends on the schedule
    slots[t] = s
    return s


@wp.func_replay(take_slot)
def replay_take_slot(counter: wp.array(dtype=wp.int32), slots: wp.array(dtype=wp.int32), t: int):
    return slots[t]   # the backward pass reads back the slot the forward pass took


@wp.kernel
def scatter_by_counter(x: wp.array(dtype=wp.float64), w: wp.array(dtype=wp.float64), counter: wp.array(dtype=wp.int32),
                       slots: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.float64)):
    t = wp.tid()
    s = take_slot(counter, slots, t)
    out[s] = wp.sin(x[s]) * w[t]


def test_func_replay_recomputes_results_in_the_backward_pass(rng):
    """Without the replay function the backward pass would replay the atomic (which returns 0
    in a replay, as in Warp) and route every thread's gradient to slot 0."""
    n = 64
    x_np, w_np = rng.uniform(-2.0, 2.0, n), rng.uniform(-2.0, 2.0, n)
    x = wp.array(x_np, dtype=wp.float64, requires_grad=True)
    w = wp.array(w_np, dtype=wp.float64, requires_grad=True)
    counter = wp.zeros(1, dtype=wp.int32)
    slots = wp.zeros(n, dtype=wp.int32)
    out = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(scatter_by_counter, n, inputs=[x, w, counter, slots, out])
    seed = rng.uniform(-1.0, 1.0, n)
    tape.backward(grads={out: wp.array(seed, dtype=wp.float64)})
    s = slots.numpy()
    assert sorted(s) == list(range(n))
    gx, gw = np.zeros(n), np.zeros(n)
    gx[s] = seed[s] * np.cos(x_np[s]) * w_np
    gw[:] = seed[s] * np.sin(x_np[s])
    np.testing.assert_allclose(x.grad.numpy(), gx, rtol=1e-12)
    np.testing.assert_allclose(w.grad.numpy(), gw, rtol=1e-12)
    assert counter.numpy()[0] == n   # the replay did not run the atomic again


def test_func_replay_must_take_the_funcs_parameters():
    with pytest.raises(TypeError, match="does not match any overload"):
        @wp.func_replay(take_slot)
        def bad_replay(counter: wp.array(dtype=wp.int32), t: int):
            return t
