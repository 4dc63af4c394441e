"""Language: for over range(stop) / range(start, stop) / range(start, stop, step) including
negative steps and empty ranges, while loops, break and continue, nested loops, loops whose
bounds come from arrays; against Python references."""
import numpy as np

import weft as wp


@wp.kernel
def range_forms(n: wp.array(dtype=int), out: wp.array(dtype=int, ndim=2)):
    i = wp.tid()
    m = n[i]
    s0 = int(0)
    for k in range(m):
        s0 += k
    s1 = int(0)
    for k in range(2, m):
        s1 += k * k
    s2 = int(0)
    for k in range(m, -3, -2):
        s2 += k
    s3 = int(0)
    for k in range(1, m, 3):
        s3 += 1
    out[i, 0] = s0
    out[i, 1] = s1
    out[i, 2] = s2
    out[i, 3] = s3


@wp.kernel
def while_break_continue(n: wp.array(dtype=int), out: wp.array(dtype=int, ndim=2)):
    i = wp.tid()
    # Collatz steps with while
    x = n[i]
    steps = int(0)
    while x != 1:
        if x % 2 == 0:
            x = x // 2
        else:
            x = 3 * x + 1
        steps += 1
    out[i, 0] = steps
    # first multiple of 7 at or after n, with break
    found = int(-1)
    for k in range(n[i], n[i] + 100):
        if k % 7 == 0:
            found = k
            break
    out[i, 1] = found
    # sum of the odd numbers below n, with continue
    total = int(0)
    for k in range(n[i]):
        if k % 2 == 0:
            continue
        total += k
    out[i, 2] = total
    # nested loops with an inner break
    pairs = int(0)
    for a in range(5):
        for b in range(5):
            if b > a:
                break
            pairs += 1
    out[i, 3] = pairs


def _collatz(x):
    steps = 0
    while x != 1:
        x = x // 2 if x % 2 == 0 else 3 * x + 1
        steps += 1
    return steps


def test_range_forms(wp, rng):
    n = np.concatenate([rng.integers(0, 50, 200), [0, 1, 2, -5]]).astype(np.int32)
    out = wp.zeros((len(n), 4), dtype=int)
    wp.launch(range_forms, dim=len(n), inputs=[wp.array(n)], outputs=[out])
    ref = np.array([[sum(range(m)), sum(k * k for k in range(2, m)), sum(range(m, -3, -2)),
                     len(range(1, m, 3))] for m in n.tolist()])
    np.testing.assert_array_equal(out.numpy(), ref)


def test_while_break_continue(wp, rng):
    n = rng.integers(1, 10000, 300).astype(np.int32)
    out = wp.zeros((len(n), 4), dtype=int)
    wp.launch(while_break_continue, dim=len(n), inputs=[wp.array(n)], outputs=[out])
    ref = np.array([[_collatz(m), next(k for k in range(m, m + 100) if k % 7 == 0),
                     sum(k for k in range(m) if k % 2), 15] for m in n.tolist()])
    np.testing.assert_array_equal(out.numpy(), ref)
