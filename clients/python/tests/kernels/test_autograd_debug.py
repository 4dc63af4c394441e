"""Gradient debugging tools (weft.autograd, Warp's warp.autograd): jacobian(), jacobian_fd()
and gradcheck() against analytic float64 Jacobians on fresh random data (vector and matrix
dtypes, a Python function of two launches, a near-singular solve, large magnitudes in float32);
wrong custom adjoints (wp.func_grad) and NaN gradients caught by gradcheck() and
gradcheck_tape(); masks and per-variable limits; kernels without a backward pass; inputs
restored after evaluation."""
import numpy as np
import pytest

import weft as wp
from weft.autograd import FunctionMetadata, gradcheck, gradcheck_tape, jacobian, jacobian_fd


# --- kernels -----------------------------------------------------------------------------------
@wp.kernel
def norm_and_scale_kernel(a: wp.array(dtype=wp.vec3d), s: wp.array(dtype=wp.float64),
                          norm_out: wp.array(dtype=wp.float64),
                          scaled_out: wp.array(dtype=wp.vec3d)):
    i = wp.tid()
    norm_out[i] = wp.dot(a[i], a[i]) * s[i]
    scaled_out[i] = a[i] * wp.sin(s[i])


@wp.kernel
def matvec_kernel(A: wp.array2d(dtype=wp.float64), x: wp.array(dtype=wp.float64),
                  y: wp.array(dtype=wp.float64)):
    i, k = wp.tid()
    wp.atomic_add(y, i, A[i, k] * x[k])


@wp.kernel
def tanh_kernel(y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64)):
    i = wp.tid()
    z[i] = wp.tanh(y[i])


@wp.kernel
def solve2_kernel(M: wp.array(dtype=wp.mat22d), b: wp.array(dtype=wp.vec2d),
                  x: wp.array(dtype=wp.vec2d)):
    i = wp.tid()
    x[i] = wp.inverse(M[i]) * b[i]


@wp.kernel
def cube_kernel(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = a[i] * a[i] * a[i]


@wp.func
def cube_wrong_adjoint(x: float):
    return x * x * x


@wp.func_grad(cube_wrong_adjoint)
def adj_cube_wrong_adjoint(x: float, adj: float):
    # 5% too large: d(x^3)/dx is 3 x^2
    wp.adjoint[x] += 3.15 * x * x * adj


@wp.kernel
def wrong_cube_kernel(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = cube_wrong_adjoint(a[i])


@wp.kernel
def sqrt_kernel(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp.sqrt(a[i])


@wp.kernel
def increment_kernel(x: wp.array(dtype=float)):
    i = wp.tid()
    x[i] = x[i] + 1.0


@wp.kernel
def square_kernel(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = x[i] * x[i]


_NO_BACKWARD_MODULE = "test_autograd_debug_no_backward"
wp.get_module(_NO_BACKWARD_MODULE).options["enable_backward"] = False


@wp.kernel(module=_NO_BACKWARD_MODULE)
def module_no_backward_kernel(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = 3.0 * a[i]


@wp.kernel(enable_backward=False)
def kernel_no_backward_kernel(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = 3.0 * a[i]


@wp.kernel(module=_NO_BACKWARD_MODULE, enable_backward=True)
def kernel_overrides_module_kernel(a: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = 3.0 * a[i]


# --- analytic Jacobians (float64, in the layout of jacobian(): output scalars x input elements
# x element components) -------------------------------------------------------------------------
def norm_and_scale_jacobians(a, s):
    n = len(s)
    jac = {(0, 0): np.zeros((n, n, 3)), (1, 0): np.zeros((n, n)),
           (0, 1): np.zeros((3 * n, n, 3)), (1, 1): np.zeros((3 * n, n))}
    for i in range(n):
        jac[0, 0][i, i] = 2.0 * a[i] * s[i]
        jac[1, 0][i, i] = a[i] @ a[i]
        for c in range(3):
            jac[0, 1][3 * i + c, i, c] = np.sin(s[i])
            jac[1, 1][3 * i + c, i] = a[i, c] * np.cos(s[i])
    return jac


def solve2_jacobians(M, b):
    n = len(b)
    jac_M, jac_b = np.zeros((2 * n, n, 2, 2)), np.zeros((2 * n, n, 2))
    for i in range(n):
        inv = np.linalg.inv(M[i])
        x = inv @ b[i]
        for r in range(2):
            jac_b[2 * i + r, i] = inv[r]
            # d(M^-1 b)_r / dM_jk = -(M^-1)_rj (M^-1 b)_k
            jac_M[2 * i + r, i] = -np.outer(inv[r], x)
    return {(0, 0): jac_M, (1, 0): jac_b}


def assert_jacobians(jacobians, expected, **tolerances):
    assert sorted(jacobians) == sorted(expected)
    for key, want in expected.items():
        got = jacobians[key].numpy()
        assert got.shape == want.shape, (key, got.shape, want.shape)
        np.testing.assert_allclose(got, want, err_msg=f"Jacobian {key}", **tolerances)


# --- Jacobians against analytic ones -----------------------------------------------------------
def test_kernel_jacobians_match_analytic(wp, rng):
    n = 5
    a_np, s_np = rng.uniform(-2.0, 2.0, (n, 3)), rng.uniform(-3.0, 3.0, n)
    a = wp.array(a_np, dtype=wp.vec3d, requires_grad=True)
    s = wp.array(s_np, dtype=wp.float64, requires_grad=True)
    norm_out = wp.zeros(n, dtype=wp.float64, requires_grad=True)
    scaled_out = wp.zeros(n, dtype=wp.vec3d, requires_grad=True)
    args = dict(dim=n, inputs=[a, s], outputs=[norm_out, scaled_out])
    expected = norm_and_scale_jacobians(a_np, s_np)

    assert_jacobians(jacobian(norm_and_scale_kernel, **args), expected, rtol=1e-12, atol=1e-12)
    assert_jacobians(jacobian_fd(norm_and_scale_kernel, eps=1e-6, **args), expected,
                     rtol=1e-7, atol=1e-8)
    assert gradcheck(norm_and_scale_kernel, eps=1e-6, atol=1e-7, rtol=1e-7, show_summary=False,
                     **args)
    # neither the inputs nor the given outputs were changed; gradients are left zeroed
    np.testing.assert_array_equal(a.numpy(), a_np)
    np.testing.assert_array_equal(s.numpy(), s_np)
    np.testing.assert_array_equal(norm_out.numpy(), np.zeros(n))
    np.testing.assert_array_equal(scaled_out.numpy(), np.zeros((n, 3)))
    assert not a.grad.numpy().any() and not s.grad.numpy().any()


def test_masks_and_per_variable_limits(wp, rng):
    n = 4
    a_np, s_np = rng.uniform(-2.0, 2.0, (n, 3)), rng.uniform(-3.0, 3.0, n)
    a = wp.array(a_np, dtype=wp.vec3d, requires_grad=True)
    s = wp.array(s_np, dtype=wp.float64, requires_grad=True)
    outputs = [wp.zeros(n, dtype=wp.float64, requires_grad=True),
               wp.zeros(n, dtype=wp.vec3d, requires_grad=True)]
    expected = norm_and_scale_jacobians(a_np, s_np)

    # pairs by name and by index; rows past max_outputs_per_var are NaN
    jac_ad = jacobian(norm_and_scale_kernel, dim=n, inputs=[a, s], outputs=outputs,
                      input_output_mask=[("a", "scaled_out"), (1, 0)], max_outputs_per_var=5)
    assert sorted(jac_ad) == [(0, 1), (1, 0)]
    np.testing.assert_allclose(jac_ad[0, 1].numpy()[:5], expected[0, 1][:5], rtol=1e-12)
    assert np.isnan(jac_ad[0, 1].numpy()[5:]).all()
    np.testing.assert_allclose(jac_ad[1, 0].numpy(), expected[1, 0], rtol=1e-12)

    # columns (input scalars) past max_inputs_per_var are NaN: for a vec3 input, the first
    # 4 scalars are element 0 and the first component of element 1
    jac_fd = jacobian_fd(norm_and_scale_kernel, dim=n, inputs=[a, s], outputs=outputs,
                         input_output_mask=[("a", "norm_out")], max_inputs_per_var=4, eps=1e-6)
    got = jac_fd[0, 0].numpy().reshape(n, 3 * n)
    want = expected[0, 0].reshape(n, 3 * n)
    np.testing.assert_allclose(got[:, :4], want[:, :4], rtol=1e-7, atol=1e-8)
    assert np.isnan(got[:, 4:]).all()

    with pytest.raises(ValueError, match="bogus"):
        jacobian(norm_and_scale_kernel, dim=n, inputs=[a, s], outputs=outputs,
                 input_output_mask=[("bogus", 0)])


def test_function_of_two_launches_matches_analytic(wp, rng):
    m, n = 3, 4
    A_np, x_np = rng.uniform(-1.0, 1.0, (m, n)), rng.uniform(-1.0, 1.0, n)
    A = wp.array(A_np, dtype=wp.float64, requires_grad=True)
    x = wp.array(x_np, dtype=wp.float64, requires_grad=True)

    def pipeline(A, x):
        y = wp.zeros(A.shape[0], dtype=wp.float64, requires_grad=True)
        wp.launch(matvec_kernel, dim=A.shape, inputs=[A, x], outputs=[y])
        z = wp.zeros(A.shape[0], dtype=wp.float64, requires_grad=True)
        wp.launch(tanh_kernel, dim=len(y), inputs=[y], outputs=[z])
        return z

    sech2 = 1.0 - np.tanh(A_np @ x_np) ** 2
    jac_x = sech2[:, None] * A_np
    jac_A = np.zeros((m, m * n))
    for i in range(m):
        jac_A[i, i * n:(i + 1) * n] = sech2[i] * x_np
    expected = {(0, 0): jac_A, (1, 0): jac_x}

    assert_jacobians(jacobian(pipeline, inputs=[A, x]), expected, rtol=1e-12, atol=1e-14)
    assert_jacobians(jacobian_fd(pipeline, inputs=[A, x], eps=1e-6), expected, rtol=1e-7,
                     atol=1e-9)
    assert gradcheck(pipeline, inputs=[A, x], eps=1e-6, atol=1e-8, rtol=1e-6,
                     show_summary=False)


def test_near_singular_solve_matches_analytic(wp, rng):
    # M = R [[1, 1], [1, 1 + d]] with d ~ 1e-3: |M^-1| ~ 1e3, entries of dx/dM up to ~1e6
    n = 4
    M_np = np.empty((n, 2, 2))
    for i in range(n):
        d = rng.uniform(0.5e-3, 1e-3) * rng.choice([-1.0, 1.0])
        t = rng.uniform(0.0, 2.0 * np.pi)
        R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        M_np[i] = R @ np.array([[1.0, 1.0], [1.0, 1.0 + d]])
    b_np = rng.uniform(-1.0, 1.0, (n, 2))
    M = wp.array(M_np, dtype=wp.mat22d, requires_grad=True)
    b = wp.array(b_np, dtype=wp.vec2d, requires_grad=True)
    x = wp.zeros(n, dtype=wp.vec2d, requires_grad=True)
    expected = solve2_jacobians(M_np, b_np)
    assert np.abs(expected[0, 0]).max() > 1e5

    assert_jacobians(jacobian(solve2_kernel, dim=n, inputs=[M, b], outputs=[x]), expected,
                     rtol=1e-8, atol=1e-6)
    # the step must stay far below d: the Jacobian varies on the scale of d
    assert_jacobians(jacobian_fd(solve2_kernel, dim=n, inputs=[M, b], outputs=[x], eps=1e-8),
                     expected, rtol=1e-4, atol=1e-2)
    assert gradcheck(solve2_kernel, dim=n, inputs=[M, b], outputs=[x], eps=1e-8, atol=1e-2,
                     rtol=1e-4, show_summary=False)
    # a step comparable to d breaks the finite differences, and gradcheck says so
    assert not gradcheck(solve2_kernel, dim=n, inputs=[M, b], outputs=[x], eps=1e-3, atol=1e-2,
                         rtol=1e-4, raise_exception=False, show_summary=False)


def test_large_magnitudes_in_float32(wp, rng):
    n = 6
    a_np = (rng.uniform(300.0, 1000.0, n) * rng.choice([-1.0, 1.0], n)).astype(np.float32)
    a = wp.array(a_np, dtype=float, requires_grad=True)
    out = wp.zeros(n, dtype=float, requires_grad=True)
    expected = {(0, 0): np.diag(3.0 * a_np.astype(np.float64) ** 2)}    # up to 3e6

    assert_jacobians(jacobian(cube_kernel, dim=n, inputs=[a], outputs=[out]), expected,
                     rtol=1e-5, atol=0)
    # the step must be well above float32's spacing at |a| ~ 1e3 (6e-5)
    assert_jacobians(jacobian_fd(cube_kernel, dim=n, inputs=[a], outputs=[out], eps=0.1),
                     expected, rtol=1e-3, atol=0)
    assert gradcheck(cube_kernel, dim=n, inputs=[a], outputs=[out], eps=0.1, atol=1.0, rtol=1e-3,
                     show_summary=False)


# --- wrong custom adjoints ----------------------------------------------------------------------
def test_gradcheck_detects_wrong_custom_adjoint(wp, rng, capsys):
    n = 5
    a_np = rng.uniform(0.5, 2.0, n).astype(np.float32) * rng.choice([-1.0, 1.0], n).astype(np.float32)
    a = wp.array(a_np, dtype=float, requires_grad=True)
    out = wp.zeros(n, dtype=float, requires_grad=True)
    args = dict(dim=n, inputs=[a], outputs=[out])
    exact = np.diag(3.0 * a_np.astype(np.float64) ** 2)

    # the autodiff Jacobian follows the custom adjoint, the finite differences the function
    np.testing.assert_allclose(jacobian(wrong_cube_kernel, **args)[0, 0].numpy(), 1.05 * exact,
                               rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(jacobian_fd(wrong_cube_kernel, eps=1e-3, **args)[0, 0].numpy(),
                               exact, rtol=1e-3, atol=1e-3)

    assert not gradcheck(wrong_cube_kernel, raise_exception=False, show_summary=True, **args)
    printed = capsys.readouterr().out
    assert "FAIL" in printed and "Gradient check for kernel wrong_cube_kernel failed" in printed
    with pytest.raises(ValueError, match="do not match"):
        gradcheck(wrong_cube_kernel, show_summary=False, **args)
    # the same function with its generated adjoint passes
    assert gradcheck(cube_kernel, eps=1e-3, show_summary=False, **args)


def test_gradcheck_reports_nan_gradients(wp, rng):
    # d sqrt(a)/da is infinite at a = 0: the adjoint's other rows get 0 * inf = NaN there
    a_np = rng.uniform(0.5, 2.0, 4).astype(np.float32)
    a_np[rng.integers(0, 4)] = 0.0
    a = wp.array(a_np, dtype=float, requires_grad=True)
    out = wp.zeros(4, dtype=float, requires_grad=True)
    assert np.isnan(jacobian(sqrt_kernel, dim=4, inputs=[a], outputs=[out])[0, 0].numpy()).any()
    assert not gradcheck(sqrt_kernel, dim=4, inputs=[a], outputs=[out], raise_exception=False,
                         show_summary=False)
    with pytest.raises(ValueError, match="NaN"):
        gradcheck(sqrt_kernel, dim=4, inputs=[a], outputs=[out], show_summary=False)


def test_gradcheck_tape_checks_each_recorded_launch(wp, rng):
    n = 4
    a = wp.array(rng.uniform(0.5, 2.0, n).astype(np.float32), dtype=float, requires_grad=True)
    good = wp.zeros(n, dtype=float, requires_grad=True)
    bad = wp.zeros(n, dtype=float, requires_grad=True)
    disabled = wp.zeros(n, dtype=float, requires_grad=True)
    with wp.Tape() as tape:
        wp.launch(cube_kernel, dim=n, inputs=[a], outputs=[good])
        wp.launch(wrong_cube_kernel, dim=n, inputs=[a], outputs=[bad])
        wp.launch(kernel_no_backward_kernel, dim=n, inputs=[a], outputs=[disabled])
    a_before = a.numpy().copy()

    assert not gradcheck_tape(tape, eps=1e-3, raise_exception=False, show_summary=False)
    with pytest.raises(ValueError):
        gradcheck_tape(tape, eps=1e-3, show_summary=False)
    assert gradcheck_tape(tape, eps=1e-3, blacklist_kernels=["wrong_cube_kernel"],
                          raise_exception=False, show_summary=False)
    assert gradcheck_tape(tape, eps=1e-3, whitelist_kernels=["cube_kernel"],
                          raise_exception=False, show_summary=False)
    # the wrong launch is the second: skipping past it in reverse order leaves the first only
    assert gradcheck_tape(tape, eps=1e-3, reverse_launches=True, skip_to_launch_index=2,
                          raise_exception=False, show_summary=False)
    np.testing.assert_array_equal(a.numpy(), a_before)


# --- backward passes turned off -----------------------------------------------------------------
def test_kernels_without_backward(wp, rng):
    n = 3
    a_np = rng.uniform(-1.0, 1.0, n).astype(np.float32)
    for kernel in (module_no_backward_kernel, kernel_no_backward_kernel):
        a = wp.array(a_np, dtype=float, requires_grad=True)
        out = wp.zeros(n, dtype=float, requires_grad=True)
        with pytest.raises(ValueError, match="backward pass enabled"):
            jacobian(kernel, dim=n, inputs=[a], outputs=[out])

        def function(x, kernel=kernel):
            y = wp.zeros_like(x, requires_grad=True)
            wp.launch(kernel, dim=len(x), inputs=[x], outputs=[y])
            return y

        with pytest.raises(ValueError, match="backward pass enabled"):
            jacobian(function, inputs=[a])
        # finite differences need forward launches only
        np.testing.assert_allclose(jacobian_fd(kernel, dim=n, inputs=[a], outputs=[out],
                                               eps=1e-2)[0, 0].numpy(), 3.0 * np.eye(n),
                                   rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(jacobian_fd(function, inputs=[a], eps=1e-2)[0, 0].numpy(),
                                   3.0 * np.eye(n), rtol=1e-4, atol=1e-4)

    # the kernel's own option wins over its module's
    a = wp.array(a_np, dtype=float, requires_grad=True)
    out = wp.zeros(n, dtype=float, requires_grad=True)
    np.testing.assert_allclose(jacobian(kernel_overrides_module_kernel, dim=n, inputs=[a],
                                        outputs=[out])[0, 0].numpy(), 3.0 * np.eye(n))


# --- inputs restored ----------------------------------------------------------------------------
def test_inputs_restored_for_mutating_functions(wp, rng):
    n = 4
    x_np = rng.uniform(0.5, 2.0, n).astype(np.float32)

    def increment_then_square(x):
        wp.launch(increment_kernel, dim=len(x), inputs=[x])
        y = wp.zeros_like(x, requires_grad=True)
        wp.launch(square_kernel, dim=len(x), inputs=[x], outputs=[y])
        return y

    # y = (x + 1)^2 when each evaluation starts from the original x
    expected = np.diag(2.0 * (x_np.astype(np.float64) + 1.0))
    x = wp.array(x_np, dtype=float, requires_grad=True)
    np.testing.assert_allclose(jacobian(increment_then_square, inputs=[x])[0, 0].numpy(),
                               expected, rtol=1e-6)
    np.testing.assert_array_equal(x.numpy(), x_np)
    np.testing.assert_allclose(jacobian_fd(increment_then_square, inputs=[x], eps=1e-3)[0, 0]
                               .numpy(), expected, rtol=1e-3, atol=1e-3)
    np.testing.assert_array_equal(x.numpy(), x_np)
    assert gradcheck(increment_then_square, inputs=[x], eps=1e-3, show_summary=False)
    np.testing.assert_array_equal(x.numpy(), x_np)

    # without restoration every evaluation drifts x, and the check fails
    x = wp.array(x_np, dtype=float, requires_grad=True)
    assert not gradcheck(increment_then_square, inputs=[x], eps=1e-3, restore_inputs=False,
                         raise_exception=False, show_summary=False)
    assert (x.numpy() > x_np + 1.5).all()

    # a function that raises after mutating its input leaves it as it was
    def increment_then_raise(x):
        wp.launch(increment_kernel, dim=len(x), inputs=[x])
        raise RuntimeError("failed after the launch")

    x = wp.array(x_np, dtype=float, requires_grad=True)
    for compute in (jacobian, jacobian_fd):
        with pytest.raises(RuntimeError, match="failed after the launch"):
            compute(increment_then_raise, inputs=[x])
        np.testing.assert_array_equal(x.numpy(), x_np)


def test_function_metadata(wp):
    a = wp.zeros(3, dtype=wp.vec3d)
    s = wp.zeros(3, dtype=wp.float64)
    meta = FunctionMetadata().update_from_kernel(norm_and_scale_kernel, [a, s])
    assert meta.key == "norm_and_scale_kernel" and not meta.is_empty
    assert meta.input_labels == ["a", "s"] and meta.output_labels == ["norm_out", "scaled_out"]
    assert meta.input_dtypes == [wp.vec3d, wp.float64]
    assert meta.input_is_array(0) and meta.output_is_array(1)
    assert FunctionMetadata().is_empty
