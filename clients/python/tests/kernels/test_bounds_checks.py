"""Out-of-bounds reads and writes: a clear error at the next sync naming the kernel, the
array, the index and the source line; nothing is written out of bounds (a neighbouring
allocation is unchanged); the daemon stays alive and this and other sessions keep working."""
import inspect
import sys
import textwrap

import numpy as np
import pytest

import weft as wp


@wp.kernel
def oob_write(data: wp.array(dtype=float), n: int):
    i = wp.tid()
    data[i + n] = 7.0


@wp.kernel
def oob_read(data: wp.array(dtype=float), out: wp.array(dtype=float), n: int):
    i = wp.tid()
    out[i] = data[i * n]


@wp.kernel
def oob_2d(grid: wp.array2d(dtype=float)):
    i, j = wp.tid()
    grid[i, j + 1] = 1.0


@wp.kernel
def fill_ok(data: wp.array(dtype=float)):
    data[wp.tid()] = 3.0


def _line(func, needle):
    lines, start = inspect.getsourcelines(func)
    return start + next(k for k, t in enumerate(lines) if needle in t)


def _check_message(message, kernel_name, array_name, index, line):
    assert kernel_name in message, message
    assert array_name in message, message
    assert str(index) in message, message
    assert f"{__file__}:{line}" in message or f"test_bounds_checks.py:{line}" in message, message


def test_out_of_bounds_write(wp):
    data = wp.zeros(8, dtype=float)
    neighbour = wp.full(8, 5.0, dtype=float)
    wp.launch(oob_write, dim=8, inputs=[data, 4])
    with pytest.raises(wp.WeftError) as info:
        wp.synchronize()
    _check_message(str(info.value), "oob_write", "data", 8, _line(oob_write.func, "data[i + n]"))
    np.testing.assert_array_equal(neighbour.numpy(), 5.0)     # nothing written past the end
    assert np.all(data.numpy()[4:] == 7.0) or np.all(data.numpy() == 0.0)


def test_out_of_bounds_read(wp):
    data = wp.array(np.arange(10, dtype=np.float32))
    out = wp.zeros(10, dtype=float)
    wp.launch(oob_read, dim=10, inputs=[data, out, 3])
    with pytest.raises(wp.WeftError) as info:
        wp.synchronize()
    _check_message(str(info.value), "oob_read", "data", 12, _line(oob_read.func, "data[i * n]"))


def test_out_of_bounds_2d(wp):
    grid = wp.zeros((4, 4), dtype=float)
    wp.launch(oob_2d, dim=(4, 4), inputs=[grid])
    with pytest.raises(wp.WeftError) as info:
        wp.synchronize()
    assert "oob_2d" in str(info.value) and "grid" in str(info.value)


def test_session_keeps_working_after_an_error(wp):
    data = wp.zeros(8, dtype=float)
    wp.launch(oob_write, dim=8, inputs=[data, 1])
    with pytest.raises(wp.WeftError):
        wp.synchronize()
    ok = wp.zeros(16, dtype=float)
    wp.launch(fill_ok, dim=16, inputs=[ok])
    np.testing.assert_array_equal(ok.numpy(), 3.0)


def test_other_session_unaffected(wp, run_script):
    data = wp.zeros(8, dtype=float)
    wp.launch(oob_write, dim=8, inputs=[data, 100])
    child = run_script(textwrap.dedent('''
        import numpy as np
        import weft as wp

        @wp.kernel
        def fine(a: wp.array(dtype=float)):
            a[wp.tid()] = 2.0

        a = wp.zeros(32, dtype=float)
        wp.launch(fine, dim=32, inputs=[a])
        assert np.all(a.numpy() == 2.0)
        print("OTHER-SESSION-OK")
    '''))
    assert "OTHER-SESSION-OK" in child.stdout
    with pytest.raises(wp.WeftError):
        wp.synchronize()


def test_each_call_site_reports_its_own_line(wp):
    """The launch origin is cached per call site (code object and instruction, not per
    function): two launches of one loop body on neighbouring lines, and launches from code
    objects made again and again in other files and at other lines (the cache holds each code
    object it keys by id, so an id never names another) each report the line they were made
    on."""
    data = wp.zeros(8, dtype=float)
    for shift in (8, 9):
        wp.launch(oob_write, dim=8, inputs=[data, shift]); first = sys._getframe().f_lineno  # noqa: E702
        with pytest.raises(wp.WeftError) as info:
            wp.synchronize()
        assert f"test_bounds_checks.py:{first}" in str(info.value), str(info.value)
        wp.launch(oob_write, dim=8, inputs=[data, shift]); second = sys._getframe().f_lineno  # noqa: E702
        with pytest.raises(wp.WeftError) as info:
            wp.synchronize()
        assert f"test_bounds_checks.py:{second}" in str(info.value), str(info.value)
    for k in range(40):          # fresh code objects, each freed before the next is made
        blank = "\n" * (1 + k % 7)
        namespace = {"wp": wp, "oob_write": oob_write, "data": data}
        exec(compile(f"{blank}def go():\n    wp.launch(oob_write, dim=8, inputs=[data, 9])\n",
                     f"generated_{k % 3}.py", "exec"), namespace)
        namespace["go"]()
        del namespace
        with pytest.raises(wp.WeftError) as info:
            wp.synchronize()
        line = 1 + k % 7 + 2
        assert f"generated_{k % 3}.py:{line}" in str(info.value), (k, str(info.value))
