"""wp.config.verify_autograd_array_access (Warp's): which array parameters a kernel reads and
writes (kernel.adj.args[i].is_read / is_write, through @wp.func calls, views, atomics and
in-place operators), arrays marked read by recorded launches, and the warnings for an array
written after a recorded launch read it (by a kernel or by wp.copy, naming the call site) or
written after being read inside one kernel; backward() and reset() clear the marks. Attacks:
recursion between funcs, arrays passed positionally to funcs, the setting off (nothing marked)."""
import contextlib
import inspect
import io

import numpy as np
import pytest

import weft as wp


@wp.func
def read_it(a: wp.array(dtype=float), i: int):
    return a[i]


@wp.func
def write_it(a: wp.array(dtype=float), i: int, v: float):
    a[i] = v


@wp.func
def recurse(a: wp.array(dtype=float), i: int) -> float:
    if i <= 0:
        return a[0]
    return recurse(a, i - 1)


@wp.kernel
def mixed(r: wp.array(dtype=float), w: wp.array(dtype=float), at: wp.array(dtype=int),
          inplace: wp.array(dtype=float), viewed: wp.array2d(dtype=float), fr: wp.array(dtype=float),
          fw: wp.array(dtype=float), rec: wp.array(dtype=float), untouched: wp.array(dtype=float)):
    i = wp.tid()
    w[i] = r[i] * 2.0
    wp.atomic_add(at, 0, 1)
    inplace[i] += 1.0
    row = viewed[i]
    row[0] = read_it(fr, i)
    write_it(fw, i, recurse(rec, i))
    n = untouched.shape[0]


@wp.kernel
def square(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * x[i]


@wp.kernel
def overwrite(src: wp.array(dtype=float), dst: wp.array(dtype=float)):
    i = wp.tid()
    dst[i] = src[i]


@contextlib.contextmanager
def verify():
    saved = wp.config.verify_autograd_array_access
    wp.config.verify_autograd_array_access = True
    try:
        yield
    finally:
        wp.config.verify_autograd_array_access = saved


def test_kernel_parameter_access():
    flags = {a.label: (a.is_read, a.is_write) for a in mixed.adj.args}
    assert flags == {"r": (True, False), "w": (False, True), "at": (False, True),
                     "inplace": (False, True), "viewed": (False, True), "fr": (True, False),
                     "fw": (False, True), "rec": (True, False), "untouched": (False, False)}
    assert mixed.adj.fun_name == "mixed" and mixed.adj.filename == __file__
    assert mixed.adj.fun_lineno == inspect.getsourcelines(mixed.func)[1] + 1 or \
        mixed.adj.fun_lineno == inspect.getsourcelines(mixed.func)[1]


def test_write_after_recorded_read_warns(wp, rng):
    x = rng.standard_normal(4).astype(np.float32)
    with verify():
        a = wp.array(x, requires_grad=True)
        b = wp.zeros_like(a)
        c = wp.array(rng.standard_normal(4).astype(np.float32), requires_grad=True)
        tape = wp.Tape()
        with contextlib.redirect_stderr(io.StringIO()) as err:
            with tape:
                wp.launch(square, 4, inputs=[a], outputs=[b])
                assert a._is_read and not b._is_read
                wp.launch(overwrite, 4, inputs=[c], outputs=[a])
        assert "passed to argument dst in kernel overwrite" in err.getvalue()
        assert "is being written to but has already been read from in a previous launch" in err.getvalue()
        tape.backward(grads={a: wp.ones(4, dtype=float)})
        assert not a._is_read and not c._is_read      # backward consumed the reads
    np.testing.assert_allclose(b.numpy(), x.astype(np.float64) ** 2, rtol=1e-6)


def test_copy_after_read_names_the_call_site(wp):
    with verify():
        a = wp.array([1.0, 2.0, 3.0], dtype=float, requires_grad=True)
        b = wp.zeros_like(a)
        tape = wp.Tape()
        with contextlib.redirect_stderr(io.StringIO()) as err:
            with tape:
                wp.launch(square, 3, inputs=[a], outputs=[b])
                line = inspect.currentframe().f_lineno + 1
                wp.copy(a, b)
        assert f"is being written to by an array copy at {__file__}:{line}" in err.getvalue()
        assert b._is_read
        tape.reset()
        assert not a._is_read and not b._is_read


def test_write_after_read_inside_a_kernel_warns(wp):
    with verify(), contextlib.redirect_stderr(io.StringIO()) as err:
        @wp.kernel
        def read_then_write(a: wp.array(dtype=float), b: wp.array(dtype=float)):
            i = wp.tid()
            b[i] = a[i] * a[i]
            write_it(a, i, 1.0)

        a = wp.array([1.0, 2.0], dtype=float, requires_grad=True)
        b = wp.zeros_like(a)
        with wp.Tape():
            wp.launch(read_then_write, 2, inputs=[a, b])
    assert "argument a in kernel read_then_write" in err.getvalue()
    assert "is being written to after it has been read from within the same kernel" in err.getvalue()


def test_views_mark_their_parent_and_setting_off_marks_nothing(wp):
    with verify():
        a = wp.zeros((3, 3), dtype=float, requires_grad=True)
        c = a.view(dtype=int).flatten()
        c.mark_read()
        assert a._is_read and c._is_read
        a.mark_init()
        assert not a._is_read
    x = wp.zeros(3, dtype=float, requires_grad=True)
    y = wp.zeros_like(x)
    with wp.Tape():
        wp.launch(square, 3, inputs=[x], outputs=[y])
    assert not x._is_read            # the setting is off: no tracking


@pytest.mark.parametrize("n", [1, 3])
def test_access_analysis_does_not_change_results(wp, rng, n):
    v = rng.standard_normal(n).astype(np.float32)
    with verify():
        x = wp.array(v, requires_grad=True)
        y = wp.zeros(n, dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            wp.launch(square, n, inputs=[x], outputs=[y])
        tape.backward(grads={y: wp.ones(n, dtype=float)})
    np.testing.assert_allclose(x.grad.numpy(), 2.0 * v.astype(np.float64), rtol=1e-6)
