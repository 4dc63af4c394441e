"""Builtins, atomics under parallel execution: atomic_add/sub/min/max/exch/cas on int32,
float32 and vec3 arrays with heavy contention (every thread hits few slots), 1-d and 2-d
indices; the returned old values form a permutation for exch/add counters."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def histogram(values: wp.array(dtype=int), bins: wp.array(dtype=int), ticket: wp.array(dtype=int),
              tickets: wp.array(dtype=int)):
    i = wp.tid()
    wp.atomic_add(bins, values[i], 1)
    tickets[i] = wp.atomic_add(ticket, 0, 1)      # old value: each thread gets a unique one


@wp.kernel
def float_reduce(x: wp.array(dtype=float), total: wp.array(dtype=float), lo: wp.array(dtype=float),
                 hi: wp.array(dtype=float), neg: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(total, 0, x[i])
    wp.atomic_min(lo, 0, x[i])
    wp.atomic_max(hi, 0, x[i])
    wp.atomic_sub(neg, i % 4, x[i])


@wp.kernel
def int_minmax(x: wp.array(dtype=int), lo: wp.array2d(dtype=int), hi: wp.array2d(dtype=int)):
    i = wp.tid()
    wp.atomic_min(lo, i % 3, i % 2, x[i])
    wp.atomic_max(hi, i % 3, i % 2, x[i])


@wp.kernel
def vec_add(v: wp.array(dtype=wp.vec3), total: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    wp.atomic_add(total, i % 2, v[i])


@wp.kernel
def exch_cas(slot: wp.array(dtype=int), old: wp.array(dtype=int), winner: wp.array(dtype=int),
             wins: wp.array(dtype=int)):
    i = wp.tid()
    old[i] = wp.atomic_exch(slot, 0, i)
    # exactly one thread sees -1 and replaces it
    if wp.atomic_cas(winner, 0, -1, i) == -1:
        wp.atomic_add(wins, 0, 1)


def test_int_histogram_and_tickets(wp, rng):
    n = 200_000
    values = rng.integers(0, 8, n).astype(np.int32)
    bins = wp.zeros(8, dtype=int)
    ticket = wp.zeros(1, dtype=int)
    tickets = wp.zeros(n, dtype=int)
    wp.launch(histogram, dim=n, inputs=[wp.array(values), bins, ticket, tickets])
    np.testing.assert_array_equal(bins.numpy(), np.bincount(values, minlength=8))
    assert ticket.numpy()[0] == n
    np.testing.assert_array_equal(np.sort(tickets.numpy()), np.arange(n))


def test_float_reductions(wp, rng):
    n = 100_000
    x = rng.standard_normal(n).astype(np.float32)
    total = wp.zeros(1, dtype=float)
    lo = wp.full(1, 1e30, dtype=float)
    hi = wp.full(1, -1e30, dtype=float)
    neg = wp.zeros(4, dtype=float)
    wp.launch(float_reduce, dim=n, inputs=[wp.array(x), total, lo, hi, neg])
    x64 = x.astype(np.float64)
    # float32 accumulation in any order: bounded by n * eps * sum|x|
    bound = n * np.finfo(np.float32).eps * np.abs(x64).sum()
    assert abs(total.numpy()[0] - x64.sum()) <= bound
    assert lo.numpy()[0] == x.min() and hi.numpy()[0] == x.max()
    ref = np.array([-x64[k::4].sum() for k in range(4)])
    assert np.all(np.abs(neg.numpy() - ref) <= bound)


def test_int_min_max_2d(wp, rng):
    n = 50_000
    x = rng.integers(-10**9, 10**9, n).astype(np.int32)
    lo = wp.full((3, 2), 2**31 - 1, dtype=int)
    hi = wp.full((3, 2), -2**31, dtype=int)
    wp.launch(int_minmax, dim=n, inputs=[wp.array(x), lo, hi])
    idx = np.arange(n)
    for a in range(3):
        for b in range(2):
            sel = (idx % 3 == a) & (idx % 2 == b)
            assert lo.numpy()[a, b] == x[sel].min()
            assert hi.numpy()[a, b] == x[sel].max()


def test_vec3_atomic_add(wp, rng):
    n = 20_000
    v = rng.integers(-5, 5, (n, 3)).astype(np.float32)     # integers: exact in float32
    total = wp.zeros(2, dtype=wp.vec3)
    wp.launch(vec_add, dim=n, inputs=[wp.array(v, dtype=wp.vec3), total])
    np.testing.assert_array_equal(total.numpy(), [v[0::2].sum(0), v[1::2].sum(0)])


def test_exch_and_cas(wp):
    n = 100_000
    slot = wp.full(1, -7, dtype=int)
    old = wp.zeros(n, dtype=int)
    winner = wp.full(1, -1, dtype=int)
    wins = wp.zeros(1, dtype=int)
    wp.launch(exch_cas, dim=n, inputs=[slot, old, winner, wins])
    # the exchanged values form a chain: old values = {-7} + all thread ids but the last one
    olds = np.sort(old.numpy())
    last = slot.numpy()[0]
    expected = np.sort(np.concatenate([[-7], np.setdiff1d(np.arange(n), [last])]))
    np.testing.assert_array_equal(olds, expected)
    assert wins.numpy()[0] == 1
    assert 0 <= winner.numpy()[0] < n


mat22i = wp.types.matrix((2, 2), wp.int32)


@wp.kernel
def component_updates(x: wp.array(dtype=float), bits: wp.array(dtype=wp.int32),
                      v: wp.array(dtype=wp.vec3), m: wp.array(dtype=wp.mat22),
                      mi: wp.array(dtype=mat22i)):
    i = wp.tid()
    v[0][1] += x[i]                        # a component of one element, from every thread
    v[0].z -= x[i]
    m[i % 2][1] += wp.vec2(x[i], 2.0 * x[i])   # a matrix row
    m[i % 2][0, 0] += 1.0
    mi[0][1] &= wp.vec2i(bits[i], bits[i] | 1)
    mi[0][0, 1] |= bits[i]


@wp.kernel
def component_square(x: wp.array(dtype=float), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[0][1] += x[i] * x[i]


def test_component_updates_of_array_elements_are_atomic(wp, rng):
    """`arr[i][j] += v`, `arr[i].z -= v`, a matrix row `m[i][r] += row`, `&=`/`|=` on integer
    matrix components, from every thread onto one element: atomic (Warp's composite-slot
    atomics), so the result is the float64/NumPy reduction whatever the interleaving; the
    adjoint reaches the value through the component."""
    n = 100_003
    x = rng.uniform(0.5, 1.5, n)
    bits = rng.integers(0, 2**31, size=n, dtype=np.int32)
    v = wp.zeros(1, dtype=wp.vec3)
    m = wp.zeros(2, dtype=wp.mat22)
    start = np.zeros((1, 2, 2), dtype=np.int32)
    start[0, 1, :] = -1
    mi = wp.array(start, dtype=mat22i)
    wp.launch(component_updates, dim=n, inputs=[wp.array(x.astype(np.float32)), wp.array(bits, dtype=wp.int32),
                                                v, m, mi])
    x32 = x.astype(np.float32).astype(np.float64)
    total = x32.sum()
    # float32 accumulation of 1e5 terms in any order: ~sqrt(n) * 2^-24 relative, 1e-4 stated;
    # a race loses whole updates (thousands of them on a GPU)
    tol = 1e-4 * total
    got = v.numpy()[0]
    assert got[0] == 0.0 and abs(got[1] - total) <= tol and abs(got[2] + total) <= tol
    mm = m.numpy()
    for r in range(2):
        part = x32[r::2].sum()
        assert mm[r, 0, 0] == len(x32[r::2]) and mm[r, 0, 1] == 0.0
        assert abs(mm[r, 1, 0] - part) <= tol and abs(mm[r, 1, 1] - 2.0 * part) <= 2 * tol
    got_i = mi.numpy()[0]
    assert got_i[0, 0] == 0 and got_i[0, 1] == np.bitwise_or.reduce(bits)
    assert got_i[1, 0] == np.bitwise_and.reduce(bits)
    assert got_i[1, 1] == np.bitwise_and.reduce(bits | 1)
    # adjoint: d/dx_i of (seed . out[0]) with out[0][1] += x_i^2 is seed[1] * 2 x_i
    xs = wp.array(x[:64].astype(np.float32), requires_grad=True)
    out = wp.zeros(1, dtype=wp.vec3, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(component_square, dim=64, inputs=[xs, out])
    tape.backward(grads={out: wp.array(np.array([[0.5, 3.0, -2.0]], np.float32), dtype=wp.vec3)})
    np.testing.assert_allclose(xs.grad.numpy(), 3.0 * 2.0 * x32[:64], rtol=1e-6)


@pytest.mark.parametrize("op,dtype,scalar", [
    ("atomic_add", "wp.int8", "int8"), ("atomic_add", "wp.vec3us", "uint16"),
    ("atomic_sub", "wp.uint8", "uint8"), ("atomic_min", "wp.float16", "float16"),
    ("atomic_max", "wp.vec2s", "int16"), ("atomic_exch", "wp.float16", "float16"),
])
def test_atomics_refuse_the_element_types_warp_refuses(kernel_module, op, dtype, scalar):
    """Warp's rule and words: atomics work on [u]int32, [u]int64, float32, float64 (add/sub also
    float16 and bfloat16, min/max bfloat16) as the scalar type; others are a compile error at
    the call's line. `arr[i] += v` on such an array stays allowed (as in Warp)."""
    mod = kernel_module(f"""
        @wp.kernel(module="unique")
        def k(arr: wp.array(dtype={dtype})):
            wp.{op}(arr, 0, arr[1])

        @wp.kernel(module="unique")
        def aug(arr: wp.array(dtype={dtype})):
            arr[0] += arr[1]
    """)
    import weft.types as wt

    t = eval(dtype, {"wp": wp})
    a = wp.zeros(2, dtype=t)
    pattern = (rf"\.py:\d+:\d+: error: {op}\(\) operations only work on arrays with .* as the "
               rf"underlying scalar types, but got {wt.type_repr(t)} \(with scalar type {scalar}\)")
    with pytest.raises(RuntimeError, match=pattern):
        wp.launch(mod.k, dim=1, inputs=[a])
    values = wp.zeros(2, dtype=t).numpy()
    values[0], values[1] = 2, 3
    b = wp.array(values, dtype=t)
    wp.launch(mod.aug, dim=1, inputs=[b])
    np.testing.assert_array_equal(np.asarray(b.numpy()[0], dtype=np.float64), np.full_like(values[0], 5.0))
