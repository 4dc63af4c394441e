"""Warp's Python API names and behaviours beyond the basics, end to end against weftd:
wp.Kernel(func, key, module, options) and kernel.key/kernel.module, Module.load/hash_module,
wp.config (mode, verify_fp, print_launches, verbose), `a.grad = g` and `requires_grad` set after
creation reaching the daemon's backward, tapes (backward inside `with tape:`, no nesting, copies
and clones recorded), wp.launch(record_cmd=True) -> wp.Launch, wp.types.type_repr, wp.full's
dtype inference and wp.array(ptr=..., strides=...). Gradients are checked against float64
references computed with NumPy on fresh random data."""
import re
import sys

import numpy as np
import pytest

import weft as wp
from weft.v1 import exec_pb2, types_pb2

# kernels and the global the module-hash test rebinds
SCALE = 2.0


def scale_def(x: wp.array(dtype=float), s: float, y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * s


@wp.kernel
def square(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * x[i]


@wp.kernel
def weighted_sum(x: wp.array(dtype=float), w: wp.array(dtype=float),
                 loss: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(loss, 0, w[i] * x[i])


@wp.kernel
def times_global(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * SCALE


@wp.kernel
def log_of(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = wp.log(x[i])


TOL = dict(rtol=1e-5, atol=1e-6)     # float32 kernels against float64 references


# --- wp.Kernel, key, module -------------------------------------------------------------------

def test_kernel_constructor_keys_and_options(wp, rng):
    a = wp.Kernel(func=scale_def, key="scale_a")
    b = wp.Kernel(scale_def, key="scale_b", options={"enable_backward": False})
    assert (a.key, b.key, square.key) == ("scale_a", "scale_b", "square")
    assert a.module is wp.get_module(__name__) and square.module.name == __name__
    assert b.options == {"enable_backward": False}
    assert a.module.options["enable_backward"] is True      # Warp's module defaults
    x_np = rng.standard_normal(16)
    x = wp.array(x_np, dtype=float)
    y = wp.zeros(16, dtype=float)
    wp.launch(a, dim=16, inputs=[x, 3.0, y])
    np.testing.assert_allclose(y.numpy(), 3.0 * x_np.astype(np.float32), **TOL)
    wp.launch(b, dim=16, inputs=[x, -0.5, y])
    np.testing.assert_allclose(y.numpy(), -0.5 * x_np.astype(np.float32), **TOL)


def test_kernel_in_named_module_and_load(wp):
    k = wp.Kernel(func=scale_def, module=wp.get_module("weft_compat_isolated"))
    assert k.key == "scale_def" and k.module.name == "weft_compat_isolated"
    compiled = k.module.load("cpu", block_dim=1)
    assert compiled is not None and compiled.module_id
    assert k.module.load(wp.get_device("cpu")).module_id == compiled.module_id   # cached


def test_module_hash_follows_globals(wp):
    global SCALE
    module = times_global.module
    before = module.hash_module()
    assert module.hash_module() == before
    old = SCALE
    try:
        SCALE = 3.0
        assert module.hash_module() != before
    finally:
        SCALE = old
    assert module.hash_module() == before


# --- wp.config ------------------------------------------------------------------------------

def test_config_has_warp_settings(wp):
    with pytest.raises(ValueError, match="LaunchArrayAccessMode"):
        wp.config.launch_array_access_mode = 1
    for name in ("enable_cpu_blocks", "verify_autograd_array_access", "cache_kernels",
                 "kernel_cache_dir", "legacy_scalar_return_types", "optimization_level",
                 "launch_array_access_mode", "deterministic", "log_level"):
        assert hasattr(wp.config, name), name
    assert wp.config.version == "1.19.0"
    assert wp.config.LaunchArrayAccessMode.STRICT == 2


def test_config_mode_is_checked_and_part_of_the_module(wp, rng):
    before = square.module.hash_module()
    old = wp.config.mode
    try:
        wp.config.mode = "debug"
        assert square.module.hash_module() != before
        x_np = rng.random(8) + 0.5
        x = wp.array(x_np, dtype=float)
        y = wp.zeros(8, dtype=float)
        wp.launch(square, dim=8, inputs=[x, y])          # debug mode compiles and runs
        np.testing.assert_allclose(y.numpy(), x_np.astype(np.float32) ** 2, **TOL)
        wp.config.mode = "fastest"
        with pytest.raises(ValueError, match="release' or 'debug"):
            wp.launch(square, dim=8, inputs=[x, y])
    finally:
        wp.config.mode = old


def test_config_print_launches(wp, capsys, device):
    x = wp.ones(4, dtype=float)
    y = wp.zeros(4, dtype=float)
    wp.launch(square, dim=4, inputs=[x, y])
    assert capsys.readouterr().out == ""
    wp.config.print_launches = True
    try:
        wp.launch(square, dim=4, inputs=[x, y])
    finally:
        wp.config.print_launches = False
    out = capsys.readouterr().out
    assert out.startswith("kernel: square dim: 4 inputs: [") and f"device: {device}" in out


def test_config_verify_fp(wp, rng):
    x_np = rng.random(8) + 0.1
    x = wp.array(x_np, dtype=float)
    y = wp.zeros(8, dtype=float)
    wp.config.verify_fp = True
    try:
        wp.launch(log_of, dim=8, inputs=[x, y])          # finite: no error
        np.testing.assert_allclose(y.numpy(), np.log(x_np.astype(np.float32)), **TOL)
        x_np[3] = -1.0                                   # log(-1) = NaN
        bad = wp.array(x_np, dtype=float)
        with pytest.raises(FloatingPointError, match=r"kernel 'log_of'.*'y'.*NaN"):
            wp.launch(log_of, dim=8, inputs=[bad, y])
    finally:
        wp.config.verify_fp = False
    wp.launch(log_of, dim=8, inputs=[bad, y])            # off again: no check


def test_config_verbose_reports_real_compiles(wp, kernel_module, capsys, device):
    mod = kernel_module("""
        @wp.kernel
        def fresh(x: wp.array(dtype=float)):
            i = wp.tid()
            x[i] = x[i] + 41.0
    """)
    wp.config.verbose = True
    try:
        x = wp.zeros(2, dtype=float)
        wp.launch(mod.fresh, dim=2, inputs=[x])
        first = capsys.readouterr().out
        wp.launch(mod.fresh, dim=2, inputs=[x])
        second = capsys.readouterr().out
    finally:
        wp.config.verbose = False
    assert re.match(rf"Module {mod.__name__} \w+ load on device '{device}' took [0-9.]+ ms",
                    first)
    assert second == ""
    np.testing.assert_array_equal(x.numpy(), 82.0)


# --- gradients assigned after creation ---------------------------------------------------------

def _square_loss(wp, x, w):
    y = wp.zeros(x.shape[0], dtype=float, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square, dim=x.shape[0], inputs=[x, y])
        wp.launch(weighted_sum, dim=x.shape[0], inputs=[y, w, loss])
    tape.backward(loss)
    return tape


def test_grad_assigned_after_creation_receives_gradients(wp, rng):
    n = 64
    x_np, w_np = rng.standard_normal(n), rng.standard_normal(n)
    x = wp.array(x_np, dtype=float, requires_grad=True)
    w = wp.array(w_np, dtype=float)
    g = wp.zeros(n, dtype=float)
    x.grad = g
    assert x.grad is g and x.requires_grad
    _square_loss(wp, x, w)
    expected = 2.0 * x_np.astype(np.float32).astype(np.float64) * w_np.astype(np.float32)
    np.testing.assert_allclose(g.numpy(), expected, **TOL)


def test_requires_grad_set_after_creation(wp, rng):
    n = 32
    x_np, w_np = rng.standard_normal(n), rng.standard_normal(n)
    x = wp.array(x_np, dtype=float)
    w = wp.array(w_np, dtype=float)
    assert x.grad is None and not x.requires_grad
    x.requires_grad = True
    assert x.grad is not None and x.grad.shape == (n,)
    _square_loss(wp, x, w)
    expected = 2.0 * x_np.astype(np.float32).astype(np.float64) * w_np.astype(np.float32)
    np.testing.assert_allclose(x.grad.numpy(), expected, **TOL)
    x.requires_grad = False
    assert x.grad is None and not x.requires_grad
    tape = _square_loss(wp, x, w)                        # x gets no gradient now
    assert x.grad is None and tape is not None


def test_grad_assignment_checks(wp):
    x = wp.zeros(8, dtype=float, requires_grad=True)
    with pytest.raises(ValueError, match="expected shape"):
        x.grad = wp.zeros(4, dtype=float)
    with pytest.raises(ValueError, match="expected dtype"):
        x.grad = wp.zeros(8, dtype=wp.float64)
    with pytest.raises(ValueError, match="own gradient"):
        x.grad = x
    view = x[2:6]                                        # a view's gradient stays client side
    g = wp.zeros(4, dtype=float)
    view.grad = g
    assert view.grad is g and x.grad is not g


def test_set_grad_command_is_validated_by_the_daemon(wp):
    """A client sending a bad SetGradCommand gets an error at the next sync, not a changed
    gradient: a view, the array itself, a mismatched shape, an unknown handle."""
    from weft import _runtime

    rt = _runtime.get_runtime()
    a = wp.zeros(8, dtype=float, requires_grad=True)
    old_grad = a.grad
    short = wp.zeros(4, dtype=float)
    cases = [
        (a._ref(), a[2:6]._ref(), "whole array"),
        (a._ref(), a._ref(), "own gradient"),
        (a._ref(), short._ref(), "does not match"),
        (a._ref(), types_pb2.ArrayRef(handle=987654321), "unknown array handle"),
    ]
    for array_ref, grad_ref, message in cases:
        rt.submit(exec_pb2.Command(set_grad=exec_pb2.SetGradCommand(array=array_ref,
                                                                    grad=grad_ref)))
        with pytest.raises(wp.WeftError, match=message):
            wp.synchronize()
    assert a.grad is old_grad
    old_grad.fill_(5.0)
    np.testing.assert_array_equal(a.grad.numpy(), 5.0)


def test_gradient_with_a_gradient_of_its_own(wp, rng):
    """Warp's `y.grad = wp.ones_like(y)` where y requires grad: the new gradient has a gradient
    of its own, and only its data is y's gradient (the daemon's backward reads it)."""
    n = 12
    x_np = rng.uniform(0.5, 2.0, n)
    seed_np = rng.uniform(-1.0, 1.0, n)
    x = wp.array(x_np, dtype=float, requires_grad=True)
    y = wp.zeros(n, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square, dim=n, inputs=[x, y])
    g = wp.array(seed_np, dtype=float, requires_grad=True)
    assert g.grad is not None
    y.grad = g
    assert y.grad is g
    tape.backward()
    np.testing.assert_allclose(x.grad.numpy(), 2.0 * x_np * seed_np, rtol=1e-5)


def test_set_grad_refuses_a_gradient_cycle(wp):
    """Arrays that would own each other through their gradients are refused: a.grad = b while
    b's gradient chain reaches a."""
    from weft import _runtime

    rt = _runtime.get_runtime()
    a = wp.zeros(8, dtype=float, requires_grad=True)
    b = wp.zeros(8, dtype=float, requires_grad=True)
    c = wp.zeros(8, dtype=float, requires_grad=True)
    b.grad = a                       # allowed: a has a gradient of its own, b is not on its chain
    c.grad = b                       # c -> b -> a -> a's own gradient
    wp.synchronize()
    for array, grad in ((a, b), (a, c), (b, c)):
        rt.submit(exec_pb2.Command(set_grad=exec_pb2.SetGradCommand(array=array._ref(),
                                                                    grad=grad._ref())))
        with pytest.raises(wp.WeftError, match="gradient cycle"):
            wp.synchronize()


# --- tapes -------------------------------------------------------------------------------------

def test_backward_inside_with_tape_and_no_nesting(wp, rng):
    n = 16
    x_np, w_np = rng.standard_normal(n), rng.standard_normal(n)
    x = wp.array(x_np, dtype=float, requires_grad=True)
    w = wp.array(w_np, dtype=float)
    y = wp.zeros(n, dtype=float, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square, dim=n, inputs=[x, y])
        wp.launch(weighted_sum, dim=n, inputs=[y, w, loss])
        tape.backward(loss)
        with pytest.raises(RuntimeError, match="already active"):
            with wp.Tape():
                pass
    expected = 2.0 * x_np.astype(np.float32).astype(np.float64) * w_np.astype(np.float32)
    np.testing.assert_allclose(x.grad.numpy(), expected, **TOL)
    assert len(tape.launches) == 2                       # the backward was not recorded


def test_copy_clone_and_assign_are_recorded(wp, rng):
    n = 12
    x_np, w_np = rng.standard_normal(n), rng.standard_normal(n)
    w = wp.array(w_np, dtype=float)
    w32 = w_np.astype(np.float32).astype(np.float64)
    for how in ("clone", "copy", "assign"):
        x = wp.array(x_np, dtype=float, requires_grad=True)
        loss = wp.zeros(1, dtype=float, requires_grad=True)
        tape = wp.Tape()
        with tape:
            if how == "clone":
                c = wp.clone(x)
            else:
                c = wp.zeros(n, dtype=float, requires_grad=True)
                wp.copy(c, x) if how == "copy" else c.assign(x)
            wp.launch(weighted_sum, dim=n, inputs=[x, w, loss])   # x read directly too
            wp.launch(weighted_sum, dim=n, inputs=[c, w, loss])
        tape.backward(loss)
        np.testing.assert_allclose(x.grad.numpy(), 2.0 * w32, **TOL, err_msg=how)


def test_windowed_copy_of_a_strided_column_is_recorded(wp, rng):
    base_np = rng.standard_normal((5, 4))
    w_np = rng.standard_normal(3)
    base = wp.array(base_np, dtype=float, requires_grad=True)
    dst = wp.zeros(3, dtype=float, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.copy(dst, base[:, 1], src_offset=2, count=3)
        wp.launch(weighted_sum, dim=3, inputs=[dst, wp.array(w_np, dtype=float), loss])
    tape.backward(loss)
    np.testing.assert_allclose(dst.numpy(), base_np[2:, 1].astype(np.float32))
    expected = np.zeros((5, 4))
    expected[2:, 1] = w_np.astype(np.float32)
    np.testing.assert_allclose(base.grad.numpy(), expected, **TOL)


# --- record_cmd ---------------------------------------------------------------------------------

def test_record_cmd_returns_a_launch(wp, rng):
    n = 10
    x_np = rng.standard_normal(n)
    x = wp.array(x_np, dtype=float)
    y = wp.zeros(n, dtype=float)
    cmd = wp.launch(wp.Kernel(scale_def, key="scale_cmd"), dim=n, inputs=[x, 2.0, y],
                    record_cmd=True)
    assert isinstance(cmd, wp.Launch)
    np.testing.assert_array_equal(y.numpy(), 0.0)        # recorded, not run
    cmd.launch()
    np.testing.assert_allclose(y.numpy(), 2.0 * x_np.astype(np.float32), **TOL)
    cmd.set_param_at_index(1, -3.0)
    cmd.set_dim(4)
    cmd.launch()
    expected = 2.0 * x_np.astype(np.float32)
    expected[:4] = -3.0 * x_np[:4].astype(np.float32)
    np.testing.assert_allclose(y.numpy(), expected, **TOL)
    cmd.set_param_by_name("s", 0.25)
    cmd.set_params([x, 0.5, y])
    cmd.launch()
    expected[:4] = 0.5 * x_np[:4].astype(np.float32)
    np.testing.assert_allclose(y.numpy(), expected, **TOL)
    with pytest.raises(TypeError, match="Invalid argument 's'"):
        cmd.set_param_at_index(1, x)
    with pytest.raises(KeyError):
        cmd.set_param_by_name("nope", 1.0)


# --- types and arrays ---------------------------------------------------------------------------

def test_type_repr(wp):
    tr = wp.types.type_repr
    assert [tr(t) for t in (wp.float32, wp.vec3, wp.vec2d, wp.mat33, wp.mat22h, wp.quat,
                            wp.transformd, wp.uint8, float, int, bool)] == [
        "float32", "vec3f", "vec2d", "mat33f", "mat22h", "quatf", "transformd", "uint8",
        "float", "int", "bool"]
    assert tr(wp.types.vector(5, wp.float64)) == "vector(length=5, dtype=float64)"
    assert tr(wp.types.matrix((2, 5), wp.int32)) == "matrix(shape=(2, 5), dtype=int32)"
    assert tr(wp.array(dtype=wp.vec3, ndim=2)) == "array(ndim=2, dtype=vec3f)"
    assert tr(wp.zeros((2, 3), dtype=float)) == "array(shape=(2, 3), dtype=float32)"
    assert tr(wp.types.Any) == "Any"


def test_full_infers_dtype_like_warp(wp):
    assert wp.full(3, 7).dtype is wp.int32
    assert wp.full(3, 7.5).dtype is wp.float32
    v = wp.full(3, [1.0, 2.0, 3.0])                      # Python floats: float64 components
    assert v.dtype is wp.vec3d
    np.testing.assert_array_equal(v.numpy(), [[1.0, 2.0, 3.0]] * 3)
    m = wp.full(2, np.array([[1, 2], [3, 4]], dtype=np.int16))
    assert m.dtype is wp.types.matrix((2, 2), wp.int16)
    assert wp.full(2, np.float16(1.5)).dtype is wp.float16
    with pytest.raises(ValueError, match="more than two dimensions"):
        wp.full(2, np.zeros((2, 2, 2)))


def test_array_from_ptr_is_a_view(wp, rng):
    data = rng.standard_normal(24).astype(np.float32)
    a = wp.array(data, dtype=float)
    b = wp.array(ptr=a.ptr + 4 * 4, shape=(2, 5), dtype=wp.float32)
    np.testing.assert_array_equal(b.numpy(), data[4:14].reshape(2, 5))
    c = wp.array(ptr=a.ptr + 4, shape=(4,), strides=(20,), dtype=wp.float32)
    np.testing.assert_array_equal(c.numpy(), data[1::5][:4])
    v = wp.array(ptr=a.ptr, shape=(8,), dtype=wp.vec3)
    np.testing.assert_array_equal(v.numpy(), data.reshape(8, 3))
    b.fill_(0.0)                                         # the same memory
    assert not a.numpy()[4:14].any()
    with pytest.raises(RuntimeError, match="exceeds the allocation"):
        wp.array(ptr=a.ptr + 4, shape=(24,), dtype=wp.float32)
    other = np.zeros(4, dtype=np.float32)
    with pytest.raises(RuntimeError, match="only wrap memory of weft arrays"):
        wp.array(ptr=other.ctypes.data, shape=(4,), dtype=wp.float32)


# --- wp.utils array algorithms -------------------------------------------------------------------

def test_utils_scan_sum_inner_against_numpy(wp, rng):
    for dtype, np_dtype, tol in ((wp.int32, np.int32, 0), (wp.float64, np.float64, 1e-12),
                                 (wp.float32, np.float32, 1e-5)):
        if np_dtype is np.int32:
            values_np = rng.integers(-1000, 1000, size=500).astype(np_dtype)
        else:
            values_np = rng.uniform(-10, 10, size=500).astype(np_dtype)
        reference = np.cumsum(values_np.astype(np.float64))
        values = wp.array(values_np, dtype=dtype)
        inclusive, exclusive = wp.zeros_like(values), wp.zeros_like(values)
        wp.utils.array_scan(values, inclusive, True)
        wp.utils.array_scan(values, exclusive, False)
        scale = np.abs(reference).max()
        assert np.abs(inclusive.numpy() - reference).max() <= tol * scale
        assert exclusive.numpy()[0] == 0
        assert np.abs(exclusive.numpy()[1:] - reference[:-1]).max() <= tol * scale
    x_np, y_np = rng.standard_normal((40, 3)), rng.standard_normal((40, 3))
    x, y = wp.array(x_np, dtype=wp.vec3d), wp.array(y_np, dtype=wp.vec3d)
    np.testing.assert_allclose(wp.utils.array_inner(x, y), (x_np * y_np).sum(), rtol=1e-12)
    s = wp.array(x_np[:, 0], dtype=wp.float64)
    np.testing.assert_allclose(wp.utils.array_sum(s), x_np[:, 0].sum(), rtol=1e-12)
    out = wp.empty(1, dtype=wp.float64)
    wp.utils.array_sum(s, out=out)
    np.testing.assert_allclose(out.numpy()[0], x_np[:, 0].sum(), rtol=1e-12)
    with pytest.raises(RuntimeError, match=r"^Unsupported data type: int32$"):
        wp.utils.array_sum(wp.zeros(3, dtype=int))
    with pytest.raises(RuntimeError, match=r"In and out array data types do not match"):
        wp.utils.array_scan(wp.zeros(3, dtype=int), wp.zeros(3, dtype=float))
    with pytest.raises(ValueError, match=r"must have the same shape, got \(2,\) and \(3,\)"):
        wp.utils.array_inner(wp.zeros(2, dtype=float), wp.zeros(3, dtype=float))
    # Warp 1.19's axis reductions: the axis is kept with size 1, a count takes its first
    # entries, out is returned, an axis outside [-ndim, ndim) is an IndexError.
    m_np, n_np = rng.standard_normal((4, 5, 3)), rng.standard_normal((4, 5, 3))
    m, n = wp.array(m_np, dtype=wp.float64), wp.array(n_np, dtype=wp.float64)
    for axis in (0, 1, 2, -1, -3):
        for count in (None, 2):
            sl = [slice(None)] * 3
            if count is not None:
                sl[axis] = slice(0, count)
            ref = m_np[tuple(sl)].sum(axis=axis, keepdims=True)
            got = wp.utils.array_sum(m, axis=axis, value_count=count)
            assert got.shape == ref.shape
            np.testing.assert_allclose(got.numpy(), ref, rtol=1e-12)
            ref_inner = (m_np * n_np)[tuple(sl)].sum(axis=axis, keepdims=True)
            out = wp.empty(ref_inner.shape, dtype=wp.float64)
            assert wp.utils.array_inner(m, n, out=out, count=count, axis=axis) is out
            np.testing.assert_allclose(out.numpy(), ref_inner, rtol=1e-12)
    v = wp.array(x_np, dtype=wp.vec3d)
    np.testing.assert_allclose(wp.utils.array_sum(v), x_np.sum(axis=0), rtol=1e-12)   # a NumPy vector
    np.testing.assert_allclose(wp.utils.array_sum(v, value_count=7), x_np[:7].sum(axis=0), rtol=1e-12)
    for bad in (3, -4, 2**63):
        with pytest.raises(IndexError, match="out of bounds for an array with 3 dimensions"):
            wp.utils.array_sum(m, axis=bad)


def test_utils_sorts_and_run_length(wp, rng):
    n = 300
    keys_np = rng.integers(-2**40, 2**40, size=n)
    values_np = np.arange(n, dtype=np.int32)
    keys = wp.array(np.concatenate([keys_np, np.zeros(n, np.int64)]), dtype=wp.int64)
    values = wp.array(np.concatenate([values_np, np.zeros(n, np.int32)]), dtype=wp.int32)
    wp.utils.radix_sort_pairs(keys, values, n)
    order = np.argsort(keys_np, kind="stable")
    np.testing.assert_array_equal(keys.numpy()[:n], keys_np[order])
    np.testing.assert_array_equal(values.numpy()[:n], values_np[order])
    fkeys_np = rng.standard_normal(n).astype(np.float32)
    fkeys = wp.array(np.concatenate([fkeys_np, np.zeros(n, np.float32)]), dtype=wp.float32)
    values = wp.array(np.concatenate([values_np, np.zeros(n, np.int32)]), dtype=wp.int32)
    bounds = np.array([0, 100, 250, n], dtype=np.int32)
    wp.utils.segmented_sort_pairs(fkeys, values, n, wp.array(bounds[:-1], dtype=int),
                                  wp.array(bounds[1:], dtype=int))
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        seg = np.argsort(fkeys_np[lo:hi], kind="stable")
        np.testing.assert_array_equal(fkeys.numpy()[lo:hi], fkeys_np[lo:hi][seg])
        np.testing.assert_array_equal(values.numpy()[lo:hi], values_np[lo:hi][seg])
    with pytest.raises(RuntimeError, match=r"2\*count elements$"):
        wp.utils.radix_sort_pairs(wp.zeros(3, dtype=int), wp.zeros(3, dtype=int), 3)
    runs_np = np.repeat(rng.integers(0, 5, size=30), rng.integers(1, 4, size=30))
    run_values = wp.zeros(runs_np.size, dtype=int)
    run_lengths = wp.zeros(runs_np.size, dtype=int)
    count = wp.utils.runlength_encode(wp.array(runs_np, dtype=int), run_values, run_lengths)
    starts = np.concatenate([[0], np.nonzero(np.diff(runs_np))[0] + 1])
    assert count == starts.size
    np.testing.assert_array_equal(run_values.numpy()[:count], runs_np[starts])
    np.testing.assert_array_equal(run_lengths.numpy()[:count],
                                  np.diff(np.concatenate([starts, [runs_np.size]])))


def test_utils_array_cast(wp, rng):
    x_np = rng.uniform(-100, 100, size=(3, 4))
    x = wp.array(x_np, dtype=wp.float64)
    out = wp.zeros((3, 4), dtype=wp.int32)
    wp.utils.array_cast(x, out)
    np.testing.assert_array_equal(out.numpy(), x_np.astype(np.int32))   # C truncation
    v = wp.array(((1, 2), (3, 4)), dtype=wp.vec2)
    flat = wp.zeros(4, dtype=wp.float64)
    wp.utils.array_cast(v, flat, count=1)
    np.testing.assert_array_equal(flat.numpy(), [1.0, 2.0, 0.0, 0.0])
    with pytest.raises(RuntimeError, match=r"Array shapes do not match"):
        wp.utils.array_cast(x, wp.zeros((4, 3), dtype=wp.int32))


def test_array_factories_take_the_legacy_length_keyword(wp, rng):
    """Warp's wp.zeros(n=...), wp.empty(n=...), wp.ones/full(n=...): a 1-D array of length n."""
    n = int(rng.integers(1, 50))
    value = float(rng.uniform(1.0, 2.0))
    assert wp.empty(n=n, dtype=float).shape == (n,)
    z = wp.zeros(n=n, dtype=wp.vec3, requires_grad=True)
    assert z.shape == (n,) and z.grad is not None
    np.testing.assert_array_equal(z.numpy(), 0.0)
    np.testing.assert_array_equal(wp.ones(n=n, dtype=float).numpy(), 1.0)
    np.testing.assert_allclose(wp.full(n=n, value=value, dtype=float).numpy(), value, rtol=1e-6)


def test_unique_kernel_module_load_raises_its_compile_error(wp, kernel_module):
    """A module="unique" kernel has a module of its own (Warp): kernel.module.load() compiles
    that kernel alone and raises its error; the file's module still loads its other kernels."""
    m = kernel_module("""
        @wp.kernel
        def fine(a: wp.array(dtype=float)):
            a[wp.tid()] = 1.0

        @wp.kernel(module="unique")
        def broken(dst: wp.array(dtype=wp.vec3)):
            dst[0.5].x = 1.0

        @wp.kernel(module="unique")
        def alone(a: wp.array(dtype=float)):
            a[wp.tid()] = 2.0
    """)
    with pytest.raises(TypeError, match="Array slot write indices must be integers"):
        m.broken.module.load(device="cpu")
    assert m.alone.module.load(device="cpu") is not None
    assert m.alone.module.name == m.fine.module.name
    assert wp.get_module(m.__name__).load(device="cpu") is not None


@wp.kernel
def launch_defaults(out: wp.array(dtype=wp.float64), v: wp.vec3d, q: wp.quatd, s: wp.float64, n: int):
    i = wp.tid()
    out[i] = wp.float64(i) + v[0] + v[2] + q[0] + q[3] + s + wp.float64(n)


def test_launch_object_without_params_starts_at_zero(wp, rng):
    """wp.Launch(kernel, device): every parameter starts at zero (a quaternion too, as in Warp;
    arrays None) and is set by name later; launching before an array is set fails clearly."""
    out = wp.zeros(8, dtype=wp.float64)
    cmd = wp.Launch(launch_defaults, wp.get_device())
    cmd.set_dim(8)
    with pytest.raises(wp.WeftError, match="array 'out' which is None"):
        cmd.launch()
        wp.synchronize()
    cmd.set_param_by_name("out", out)
    cmd.set_dim(5)
    cmd.launch()
    np.testing.assert_array_equal(out.numpy(), [0, 1, 2, 3, 4, 0, 0, 0])
    x = rng.standard_normal(3) * 1e8
    cmd.set_param_by_name("v", wp.vec3d(*x))
    cmd.set_param_by_name("n", 7)
    cmd.set_dim(8)
    cmd.launch()
    np.testing.assert_allclose(out.numpy(), np.arange(8) + (x[0] + x[2]) + 7.0, rtol=1e-15)


@wp.struct
class CmdParams:
    i: int
    f: float


@wp.kernel
def cmd_from_ctypes(p: CmdParams, i: int, v: wp.vec3, out: wp.array(dtype=float)):
    t = wp.tid()
    out[t] = float(p.i) * 100.0 + p.f * 10.0 + float(i) + v[0] + v[2]


def test_launch_params_in_warps_order_and_zero_adjoints(wp):
    """Launch.params is Warp's list: the bounds, the forward arguments, then (adjoint launches)
    the adjoint ones, which start at zero for vectors and quaternions (arrays None)."""
    out = wp.zeros(8, dtype=wp.float64)
    cmd = wp.Launch(launch_defaults, wp.get_device(), adjoint=True)
    params = cmd.params
    assert len(params) == 1 + 2 * 5
    assert cmd.fwd_args[0] is None and params[1] is None          # out
    np.testing.assert_array_equal(np.array(params[1 + 5 + 1]), [0.0, 0.0, 0.0])   # adjoint v
    np.testing.assert_array_equal(np.array(params[1 + 5 + 2]), [0.0, 0.0, 0.0, 0.0])  # adjoint q
    assert params[1 + 5 + 3] == 0 and params[1 + 5 + 4] == 0
    fwd = wp.Launch(launch_defaults, wp.get_device())
    fwd.set_param_by_name("out", out)
    fwd.set_dim(3)
    assert len(fwd.params) == 6 and fwd.params[0] == (3,) and fwd.params[1] is out


def test_launch_set_params_from_ctypes(wp):
    """set_param_*_from_ctype takes a struct's __ctype__() (the struct as it was then), an
    array's __ctype__(), Python and ctypes scalars and vectors, as Warp's wp.Launch does."""
    import ctypes

    p = CmdParams()
    p.i, p.f = 3, 0.5
    out = wp.zeros(4, dtype=float)
    cmd = wp.launch(cmd_from_ctypes, dim=4, inputs=[CmdParams(), 0, wp.vec3(), None],
                    record_cmd=True)
    snapshot = p.__ctype__()
    assert isinstance(snapshot, ctypes.Structure)
    p.i = 9                                  # after __ctype__(): not in the snapshot
    desc = out.__ctype__()
    assert isinstance(desc, ctypes.Structure)
    assert desc.data == out.ptr and desc.ndim == 1 and desc.shape[0] == 4 and desc.strides[0] == 4
    cmd.set_param_at_index_from_ctype(0, snapshot)
    cmd.set_param_at_index_from_ctype(1, ctypes.c_int32(7))
    cmd.set_param_at_index_from_ctype(2, wp.vec3(1.0, 2.0, 4.0))
    cmd.set_param_by_name_from_ctype("out", desc)
    cmd.launch()
    np.testing.assert_array_equal(out.numpy(), [300.0 + 5.0 + 7.0 + 5.0] * 4)


@wp.struct
class CopyGradStruct:
    a: float
    v: wp.vec3


@wp.kernel
def sum_into(x: wp.array(dtype=float), total: wp.array(dtype=float)):
    wp.atomic_add(total, 0, x[wp.tid()])


@wp.kernel
def sum_struct_a(xs: wp.array(dtype=CopyGradStruct), total: wp.array(dtype=float)):
    wp.atomic_add(total, 0, xs[wp.tid()].a)


def test_copy_adjoint_overwrites_where_gradients_cannot_accumulate(wp):
    """Warp's byte-copy adjoint for copies on a tape whose gradients cannot be accumulated
    (overlapping windows of one array, struct dtypes): backward overwrites the source
    window's gradient with the destination window's and leaves the destination's, with a
    UserWarning naming the pattern."""
    n = 4
    y = wp.array(np.arange(1.0, n + 1), dtype=float, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.copy(y, y, dest_offset=1, src_offset=0, count=3)
        wp.launch(sum_into, dim=n, inputs=[y, loss])
    np.testing.assert_array_equal(y.numpy(), [1.0, 1.0, 2.0, 3.0])
    sys.modules["weft.array"]._WARNED_COPY_REASONS.discard("overlapping copy")   # once each
    with pytest.warns(UserWarning, match=r"cannot yet be fully tracked \(overlapping copy\)"):
        tape.backward(loss)
    np.testing.assert_array_equal(y.grad.numpy(), [1.0, 1.0, 1.0, 1.0])   # not [2, 1, 1, 0]

    xs = wp.zeros(n, dtype=CopyGradStruct, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    tape = wp.Tape()
    with tape:
        cloned = wp.clone(xs)
        wp.launch(sum_struct_a, dim=n, inputs=[cloned, loss])
    tape.backward(loss)
    np.testing.assert_array_equal(xs.grad.numpy()["a"], np.ones(n, dtype=np.float32))
    np.testing.assert_array_equal(cloned.grad.numpy()["a"], np.ones(n, dtype=np.float32))
