"""Language: `and`, `or` and `x if c else y` evaluate an operand only when Python would: an array
access or a call in an operand that is not chosen never runs (no bounds error, no read of a None
array, no side effect), the chosen one is still checked, and gradients flow through the branch
taken."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def guarded_reads(arr: wp.array(dtype=int), idx: int, vals: wp.array(dtype=float), out: wp.array(dtype=float),
                  res: wp.array(dtype=int)):
    tid = wp.tid()
    first = 2.0 if idx < 0 else vals[idx]        # vals[-1] must not be read
    second = vals[idx] if idx >= 0 else 3.0      # a literal branch takes the other's type
    out[tid] = first + second
    if arr and tid >= 0 and arr[tid] == 0:       # arr[tid] must not be read when arr is None
        res[tid] = -1
        return
    if not arr or arr[tid] == 5:
        res[tid] = 7
        return
    res[tid] = 1


@wp.kernel
def counted(flags: wp.array(dtype=int), counter: wp.array(dtype=int), out: wp.array(dtype=int)):
    i = wp.tid()
    # the atomic in the second operand runs only where the first does not decide the result
    a = flags[i] != 0 and wp.atomic_add(counter, 0, 1) >= 0
    b = flags[i] != 0 or wp.atomic_add(counter, 1, 1) >= 0
    out[i] = int(a) + 2 * int(b)


@wp.kernel
def chosen_branch_is_checked(vals: wp.array(dtype=float), idx: int, out: wp.array(dtype=float)):
    out[0] = vals[idx] if idx > 100 else 1.0


@wp.kernel
def branch_gradient(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * x[i] * x[i] if x[i] > 0.0 else wp.sin(x[i])


def test_unchosen_operands_never_run(device):
    vals = wp.array(np.array([1.5, -4.0], dtype=np.float32), device=device)
    out = wp.zeros(1, dtype=float, device=device)
    res = wp.zeros(1, dtype=int, device=device)
    wp.launch(guarded_reads, dim=1, inputs=[None, -1, vals, out, res], device=device)
    assert out.numpy()[0] == 5.0 and res.numpy()[0] == 7
    for arr, want in (([0], -1), ([5], 7), ([3], 1)):
        wp.launch(guarded_reads, dim=1, inputs=[wp.array(arr, dtype=int, device=device), 1, vals, out, res],
                  device=device)
        assert out.numpy()[0] == -8.0 and res.numpy()[0] == want


def test_side_effects_follow_short_circuit_rules(device, rng):
    flags = rng.integers(0, 2, size=257).astype(np.int32)
    counter = wp.zeros(2, dtype=int, device=device)
    out = wp.zeros(len(flags), dtype=int, device=device)
    wp.launch(counted, dim=len(flags), inputs=[wp.array(flags, device=device), counter, out], device=device)
    assert counter.numpy().tolist() == [int((flags != 0).sum()), int((flags == 0).sum())]
    np.testing.assert_array_equal(out.numpy(), np.where(flags != 0, 1, 0) + 2)


def test_the_chosen_operand_is_still_bounds_checked(device):
    vals = wp.array(np.ones(4, dtype=np.float32), device=device)
    out = wp.zeros(1, dtype=float, device=device)
    wp.launch(chosen_branch_is_checked, dim=1, inputs=[vals, 3, out], device=device)   # not chosen: fine
    assert out.numpy()[0] == 1.0
    with pytest.raises(wp.WeftError, match=r"index \[1000\] is out of bounds for array 'vals'"):
        wp.launch(chosen_branch_is_checked, dim=1, inputs=[vals, 1000, out], device=device)
        wp.synchronize()


def test_gradient_flows_through_the_chosen_branch(device, rng):
    x64 = np.concatenate([rng.uniform(-3, 3, 200), rng.uniform(-1e-3, 1e-3, 50), [0.0, 1e-30, -1e-30]])
    x = wp.array(x64.astype(np.float32), dtype=float, requires_grad=True, device=device)
    y = wp.zeros(len(x64), dtype=float, requires_grad=True, device=device)
    tape = wp.Tape()
    with tape:
        wp.launch(branch_gradient, dim=len(x64), inputs=[x, y], device=device)
    tape.backward(grads={y: wp.array(np.ones(len(x64), dtype=np.float32), device=device)})
    xf = x.numpy().astype(np.float64)
    want_y = np.where(xf > 0, xf ** 3, np.sin(xf))
    want_g = np.where(xf > 0, 3 * xf ** 2, np.cos(xf))
    np.testing.assert_allclose(y.numpy(), want_y, rtol=1e-5, atol=1e-6)    # float32 against float64
    np.testing.assert_allclose(x.grad.numpy(), want_g, rtol=1e-5, atol=1e-6)
