"""Language: wp.static(...) reading the variable of a range loop with constant bounds (Warp
unrolls the loop and evaluates the expression per iteration; weft evaluates it per iteration,
to the same value), with `continue` and its adjoint; a wp.static expression reading another
kernel variable is an error at its line. And the value of a for loop's variable after the
loop (Python's rule: the last value it took, the value at a `break`, unchanged when the loop
does not run), next to user locals named like compiler temporaries."""
import numpy as np
import pytest

import weft as wp
from weft._kernel.errors import WeftCompileError


@wp.kernel
def static_skip(x: wp.array[float], out: wp.array[float]):
    tid = wp.tid()
    value = float(0.0)
    for i in range(20):
        if wp.static(i % 3 == 0 or i == 7):
            continue
        value += float(i) * x[tid] * x[tid]
    for j in range(1, 9, 2):
        if wp.static(j > 4):
            break
        value += float(j) * x[tid]
    out[tid] = value


def test_static_loop_variable_with_continue_and_adjoint(wp, rng):
    n = 16
    x = rng.uniform(0.5, 2.0, n) * rng.choice([-1.0, 1.0], n)
    xa = wp.array(x.astype(np.float32), dtype=float, requires_grad=True)
    out = wp.zeros(n, dtype=float, requires_grad=True)
    up = rng.standard_normal(n)
    with wp.Tape() as tape:
        wp.launch(static_skip, n, inputs=[xa], outputs=[out])
    tape.backward(grads={out: wp.array(up.astype(np.float32), dtype=float)})
    x64 = xa.numpy().astype(np.float64)
    kept = sum(i for i in range(20) if not (i % 3 == 0 or i == 7))
    linear = 1 + 3          # j = 1, 3 (j = 5 breaks)
    np.testing.assert_allclose(out.numpy(), kept * x64 * x64 + linear * x64, rtol=1e-5)
    np.testing.assert_allclose(xa.grad.numpy(), up * (2 * kept * x64 + linear), rtol=1e-5)


@wp.kernel(enable_backward=False)
def loop_variable_after(gates: wp.array[int], n: int, out: wp.array[int]):
    _wp_continue_0 = int(7)
    _wp_continue_1 = int(11)
    total = int(0)
    for i in range(4):
        total += _wp_continue_0
        if gates[i] != 0:
            continue
        total += _wp_continue_1
    out[0] = total
    out[1] = i                  # 3: the last value iterated
    for k in range(10):
        if gates[k % 4] * k > 4:
            break
    out[2] = k                  # the value at the break
    m = int(-5)
    for m in range(n, n):       # does not run: m keeps its value
        out[6] = 1
    out[3] = m
    for r in reversed(range(2, n)):
        total += r
    out[4] = r                  # 2: reversed ends at its first bound
    out[5] = total + _wp_continue_0 + _wp_continue_1


def test_loop_variable_after_the_loop(wp, rng):
    g = rng.integers(0, 2, 4)
    n = int(rng.integers(4, 9))
    out = wp.zeros(7, dtype=int)
    wp.launch(loop_variable_after, 1, inputs=[wp.array(g.astype(np.int32), dtype=int), n, out])
    total = 0
    for i in range(4):
        total += 7
        if g[i] != 0:
            continue
        total += 11
    brk = next((k for k in range(10) if g[k % 4] * k > 4), 9)
    ref_total = total
    for r in reversed(range(2, n)):
        total += r
    np.testing.assert_array_equal(out.numpy(), [ref_total, 3, brk, -5, 2, total + 18, 0])


def test_static_reading_a_runtime_variable_is_an_error(wp, kernel_module):
    mod = kernel_module("""
        @wp.kernel
        def k(n: int, out: wp.array[int]):
            for i in range(n):
                if wp.static(i % 2 == 0):
                    out[i] = 1
    """)
    with pytest.raises(WeftCompileError) as info:
        wp.launch(mod.k, 1, inputs=[4, wp.zeros(4, dtype=int)])
    line = next(k for k, text in enumerate(open(mod.__file__).read().splitlines(), 1) if "wp.static(" in text)
    assert f":{line}:" in str(info.value) and "name 'i' is not defined" in str(info.value)


shadowed_idx = 999   # a global of the loop variable's name: wp.static reads the loop variable


@wp.kernel
def static_reads_loop_not_global(out: wp.array[int]):
    for shadowed_idx in range(3):
        out[shadowed_idx] = wp.static(shadowed_idx * 2 + 1)
    for shadowed_idx in range(2):
        for shadowed_idx in range(5):  # noqa: B020 - shadowing on purpose (Python's rule after it)
            pass
        out[3 + shadowed_idx] = wp.static(shadowed_idx)


def test_static_reads_the_loop_variable_not_a_global(wp):
    out = wp.zeros(8, dtype=int)
    wp.launch(static_reads_loop_not_global, 1, outputs=[out])
    np.testing.assert_array_equal(out.numpy(), [1, 3, 5, 0, 0, 0, 0, 4])


@pytest.mark.parametrize("expr,needle", [
    ("1.0 / 0.0", "Error evaluating static expression: float division by zero"),
    ("wp.zeros(3)", "Static expression returns an unsupported value: a Warp array"),
])
def test_static_expression_failing_in_python_is_an_error(wp, kernel_module, expr, needle):
    mod = kernel_module(f"""
@wp.kernel
def k(out: wp.array[float]):
    out[0] = float(wp.static({expr}))
""")
    with pytest.raises(WeftCompileError) as info:
        wp.launch(mod.k, 1, outputs=[wp.zeros(1, dtype=float)])
    line = next(k for k, text in enumerate(open(mod.__file__).read().splitlines(), 1) if "wp.static(" in text)
    assert f":{line}:" in str(info.value) and needle in str(info.value)
