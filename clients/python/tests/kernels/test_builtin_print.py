"""Builtins: print() of scalars/vectors and wp.printf reach the launching client's stdout at
the next sync; wp.expect_eq is silent when equal and reports (kernel output) when not; output
of another session does not leak into this one."""
import re
import textwrap

import numpy as np

import pytest

import weft as wp


@wp.kernel
def say(x: wp.array(dtype=float)):
    i = wp.tid()
    print(i)
    wp.printf("weft-printf %d %.3f\n", i, x[i])
    print(wp.vec3(1.0, 2.0, 3.0))


@wp.kernel
def check(a: wp.array(dtype=int), b: wp.array(dtype=int)):
    i = wp.tid()
    wp.expect_eq(a[i], b[i])


@wp.kernel
def check_vec(a: wp.array(dtype=wp.vec3), b: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    wp.expect_near(a[i], b[i], 1.0e-3)


@wp.kernel
def check_mat(a: wp.array(dtype=wp.mat33), b: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    wp.expect_eq(a[i], b[i])


def test_print_and_printf_reach_stdout(wp, capfd):
    x = wp.array([0.5, 1.25, -2.0], dtype=float)
    wp.launch(say, dim=3, inputs=[x])
    wp.synchronize()
    out = capfd.readouterr().out
    for i, v in enumerate(["0.500", "1.250", "-2.000"]):
        assert f"weft-printf {i} {v}" in out, out
    assert len(re.findall(r"^\s*[012]\s*$", out, flags=re.M)) == 3, out
    assert out.count("1") >= 3 and re.search(r"1(\.0+)?,? +2(\.0+)?,? +3", out), out


def test_expect_eq(wp, capfd):
    a = wp.array([1, 2, 3], dtype=int)
    wp.launch(check, dim=3, inputs=[a, wp.array([1, 2, 3], dtype=int)])
    wp.synchronize()
    assert "expect_eq" not in capfd.readouterr().out
    wp.launch(check, dim=3, inputs=[a, wp.array([1, 5, 3], dtype=int)])
    # Warp prints "Error, expect_eq() failed" and goes on; weftd may instead report the failed
    # expectation as the launch's error at the sync. Either way it must name both values.
    try:
        wp.synchronize()
        report = capfd.readouterr().out
    except wp.WeftError as err:
        report = str(err)
    assert "expect_eq" in report and "2" in report and "5" in report, report


def _expect_failure(wp, capfd):
    """(the error text of the next synchronize, the kernel output before it)."""
    with pytest.raises(wp.WeftError) as err:
        wp.synchronize()
    return str(err.value), capfd.readouterr().out


def test_expect_near_names_the_values_and_the_line(wp, capfd, rng):
    a_np = rng.uniform(-100, 100, size=(4, 3)).astype(np.float32)
    b_np = a_np.copy()
    b_np[2, 1] += 0.5
    a = wp.array(a_np, dtype=wp.vec3)
    wp.launch(check_vec, dim=4, inputs=[a, wp.array(b_np, dtype=wp.vec3)])
    text, _ = _expect_failure(wp, capfd)
    assert "expect_near(" in text and "test_builtin_print.py" in text and "check_vec" in text, text
    shown = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?", text.split("expect_near(")[1])]
    for v in (a_np[2, 1], b_np[2, 1]):
        assert any(abs(s - v) <= 1e-3 * max(1.0, abs(v)) for s in shown), (v, text)


def test_expect_eq_of_large_values_reaches_the_user(wp, capfd, rng):
    """A mat33 pair is longer than a GPU error slot holds: the error says where the values are
    (the kernel output); on the CPU the error holds them. Either way the user sees both."""
    a_np = rng.integers(-9, 9, size=(2, 3, 3)).astype(np.float32)
    b_np = a_np.copy()
    b_np[1, 2, 2] = 77.0
    wp.launch(check_mat, dim=2, inputs=[wp.array(a_np, dtype=wp.mat33),
                                        wp.array(b_np, dtype=wp.mat33)])
    text, out = _expect_failure(wp, capfd)
    assert "expect failed" in text and "check_mat" in text, text
    assert "expect_eq(" in text + out and "77" in text + out, (text, out)


def test_output_stays_in_its_session(wp, run_script, capfd):
    child = run_script(textwrap.dedent('''
        import weft as wp

        @wp.kernel
        def shout():
            wp.printf("from-the-child\\n")

        wp.launch(shout, dim=2)
        wp.synchronize()
    '''))
    assert child.stdout.count("from-the-child") == 2, child.stdout
    wp.synchronize()
    assert "from-the-child" not in capfd.readouterr().out


GENERIC_PRINT = '''
import typing


@wp.struct
class Pair:
    x: float
    y: float


@wp.kernel
def show(x: typing.Any):
    print(x)


for t in (wp.int16, wp.vec2d, Pair):
    wp.overload(show, [t])
'''


def test_generic_kernel_instances_load_and_structs_print_a_placeholder(wp, kernel_module, capfd):
    mod = kernel_module(GENERIC_PRINT)
    wp.load_module(mod.__name__, device="cpu")        # compiles the instances, not the generic
    wp.launch(mod.show, dim=1, inputs=[wp.int16(-17)], device="cpu")
    wp.launch(mod.show, dim=1, inputs=[wp.vec2d(1.5, -2.0)], device="cpu")
    wp.launch(mod.show, dim=1, inputs=[mod.Pair()], device="cpu")
    wp.synchronize()
    out = capfd.readouterr().out
    assert "-17" in out and re.search(r"1\.5,? +-2", out), out
    assert "<type without print implementation>" in out, out


ADJOINT_PRINT = '''
import typing


@wp.kernel
def show(x: typing.Any):
    print(x)


for t in (wp.float32, wp.int16, wp.vec3, wp.mat22, wp.bool):
    wp.overload(show, [t])


@wp.kernel
def running(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    s = float(0.0)
    for k in range(3):
        s = s + x[0] * float(k)
        print(s)
    y[0] = s
'''


def test_print_in_adjoint_launches(wp, kernel_module, capfd):
    """Warp's adjoint printing: an adjoint launch replays print(x) (the forward value) and its
    reverse code prints "adj: <adjoint of x>", the adjoint starting from adj_inputs; a loop's
    prints replay once per iteration, not once per reverse step."""
    mod = kernel_module(ADJOINT_PRINT)
    cases = [(wp.float32(17.0), wp.float32(42.0), "17\nadj: 42\n"),
             (wp.int16(17), wp.int16(42), "17\nadj: 42\n"),
             (wp.vec3(0.0, 1.0, 2.0), wp.vec3(2.0, 1.0, 0.0), "0 1 2 \nadj: 2 1 0\n"),
             (wp.mat22(0.0, 1.0, 2.0, 3.0), wp.mat22(3.0, 2.0, 1.0, 0.0), "0 1 \n2 3 \nadj: 3 2\n     1 0\n"),
             (True, False, "True\nadj: False\n")]
    for value, adj, expected in cases:
        capfd.readouterr()
        wp.launch(mod.show, dim=1, inputs=[value], adj_inputs=[adj], adjoint=True)
        wp.synchronize()
        assert capfd.readouterr().out == expected, (value, expected)
    x = wp.array([2.0], dtype=float, requires_grad=True)
    y = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(mod.running, dim=1, inputs=[x, y])
    wp.synchronize()
    assert capfd.readouterr().out == "0\n2\n6\n"
    tape.backward(grads={y: wp.array([1.0], dtype=float)})
    wp.synchronize()
    assert capfd.readouterr().out == "0\n2\n6\nadj: 1\nadj: 1\nadj: 1\n"
    assert x.grad.numpy()[0] == 3.0
