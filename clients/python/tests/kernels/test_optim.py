"""weft.optim (Warp's warp.optim): Adam and SGD steps against float64 NumPy implementations of
the same update rules on random parameters and gradients spanning several magnitudes, every
dtype each optimizer takes (float32, float16 with float32 moments, vec3; SGD generic), a
tape-driven optimization that must reach its known minimum, and the errors of bad inputs."""
import numpy as np
import pytest

import weft as wp
import weft.optim


def _adam_ref(p, grads, lr, b1, b2, eps):
    p = p.astype(np.float64).copy()
    m = np.zeros_like(p)
    v = np.zeros_like(p)
    for t, g in enumerate(grads):
        g = g.astype(np.float64)
        m = b1 * m + (1 - b1) * g
        v = b2 * v + (1 - b2) * g * g
        m_hat = m / (1 - b1 ** (t + 1))
        v_hat = v / (1 - b2 ** (t + 1))
        p = p - lr * m_hat / (np.sqrt(v_hat) + eps)
    return p, m, v


def _sgd_ref(p, grads, lr, momentum, dampening, weight_decay, nesterov):
    p = p.astype(np.float64).copy()
    b = np.zeros_like(p)
    for t, g in enumerate(grads):
        d = g.astype(np.float64)
        if weight_decay:
            d = d + weight_decay * p
        if momentum:
            b = d.copy() if t == 0 else momentum * b + (1 - dampening) * d
            d = d + momentum * b if nesterov else b
        p = p - lr * d
    return p, b


def _random(rng, shape):
    """Values of random sign with magnitudes from 1e-4 to 1e2."""
    return (rng.choice([-1.0, 1.0], size=shape) * 10.0 ** rng.uniform(-4, 2, size=shape)).astype(np.float32)


@pytest.mark.parametrize("shape,dtype", [((257,), wp.float32), ((9, 13), wp.float32), ((65,), wp.vec3)])
def test_adam_matches_float64(rng, shape, dtype):
    lanes = (3,) if dtype == wp.vec3 else ()
    p0 = _random(rng, shape + lanes)
    grads = [_random(rng, shape + lanes) for _ in range(6)]
    lr, b1, b2, eps = 0.05, 0.8, 0.99, 1e-6
    params = wp.array(p0, dtype=dtype)
    opt = weft.optim.Adam([params], lr=lr, betas=(b1, b2), eps=eps)
    for g in grads:
        opt.step([wp.array(g, dtype=dtype)])
    assert opt.t == len(grads)
    ref_p, ref_m, ref_v = _adam_ref(p0, grads, lr, b1, b2, eps)
    # each step moves a parameter by at most ~lr / (1 - b1); float32 rounding of the moments
    # and of the parameter itself bounds the error
    np.testing.assert_allclose(params.numpy(), ref_p, rtol=2e-6, atol=lr * 2e-5)
    # m sums gradients of random sign (cancellation): its error is relative to the gradients
    g_max = np.max(np.abs(np.array(grads, dtype=np.float64)), axis=0)
    np.testing.assert_array_less(np.abs(opt.m[0].numpy() - ref_m), 3e-6 * g_max + 1e-30)
    np.testing.assert_allclose(opt.v[0].numpy(), ref_v, rtol=2e-5, atol=1e-12)


def test_adam_float16_keeps_float32_moments(rng):
    p0 = rng.uniform(-4, 4, size=300).astype(np.float16)
    grads = [rng.uniform(-2, 2, size=300).astype(np.float16) for _ in range(4)]
    params = wp.array(p0, dtype=wp.float16)
    opt = weft.optim.Adam([params], lr=0.1)
    assert opt.m[0].dtype == wp.float32 and opt.v[0].dtype == wp.float32
    for g in grads:
        opt.step([wp.array(g, dtype=wp.float16)])
    ref_p, ref_m, _ = _adam_ref(p0, grads, 0.1, 0.9, 0.999, 1e-8)
    np.testing.assert_allclose(opt.m[0].numpy(), ref_m, rtol=1e-5, atol=1e-7)
    # the parameter is rounded to float16 after every step: 4 roundings of at most half an ulp
    np.testing.assert_allclose(params.numpy().astype(np.float64), ref_p, rtol=4e-3, atol=4e-3)


@pytest.mark.parametrize("momentum,dampening,weight_decay,nesterov", [
    (0.0, 0.0, 0.0, False), (0.9, 0.0, 0.0, False), (0.9, 0.3, 0.01, False), (0.8, 0.0, 0.05, True)])
def test_sgd_matches_float64(rng, momentum, dampening, weight_decay, nesterov):
    p0 = _random(rng, (200,))
    grads = [_random(rng, (200,)) for _ in range(5)]
    params = wp.array(p0, dtype=wp.float32)
    opt = weft.optim.SGD([params], lr=0.01, momentum=momentum, dampening=dampening,
                         weight_decay=weight_decay, nesterov=nesterov)
    for g in grads:
        opt.step([wp.array(g, dtype=wp.float32)])
    ref_p, ref_b = _sgd_ref(p0, grads, 0.01, momentum, dampening, weight_decay, nesterov)
    np.testing.assert_allclose(params.numpy(), ref_p, rtol=1e-5, atol=1e-5)
    if momentum:
        np.testing.assert_allclose(opt.b[0].numpy(), ref_b, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("dtype,lanes,np_dtype,tol", [(wp.float64, (), np.float64, 1e-12),
                                                     (wp.mat22d, (2, 2), np.float64, 1e-12),
                                                     (wp.vec2h, (2,), np.float16, 2e-2)])
def test_sgd_in_the_parameters_precision(rng, dtype, lanes, np_dtype, tol):
    p0 = rng.uniform(-2, 2, size=(50,) + lanes).astype(np_dtype)
    grads = [rng.uniform(-2, 2, size=(50,) + lanes).astype(np_dtype) for _ in range(3)]
    params = wp.array(p0, dtype=dtype)
    opt = weft.optim.SGD([params], lr=0.05, momentum=0.7, dampening=0.1, weight_decay=0.02)
    for g in grads:
        opt.step([wp.array(g, dtype=dtype)])
    ref = _sgd_ref(p0, grads, 0.05, 0.7, 0.1, 0.02, False)[0]
    np.testing.assert_allclose(params.numpy().astype(np.float64), ref, rtol=tol, atol=tol)


def test_sgd_vec3_and_two_params(rng):
    a0, b0 = _random(rng, (40, 3)), _random(rng, (17,))
    ga, gb = [_random(rng, (40, 3)) for _ in range(3)], [_random(rng, (17,)) for _ in range(3)]
    a, b = wp.array(a0, dtype=wp.vec3), wp.array(b0, dtype=float)
    opt = weft.optim.SGD([a, b], lr=0.02, momentum=0.5, weight_decay=0.1)
    for x, y in zip(ga, gb):
        opt.step([wp.array(x, dtype=wp.vec3), wp.array(y, dtype=float)])
    np.testing.assert_allclose(a.numpy(), _sgd_ref(a0, ga, 0.02, 0.5, 0.0, 0.1, False)[0], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(b.numpy(), _sgd_ref(b0, gb, 0.02, 0.5, 0.0, 0.1, False)[0], rtol=1e-5, atol=1e-5)


@wp.kernel
def _distance(p: wp.array(dtype=wp.vec3), target: wp.array(dtype=wp.vec3), loss: wp.array(dtype=float)):
    i = wp.tid()
    d = p[i] - target[i]
    wp.atomic_add(loss, 0, wp.dot(d, d))


@pytest.mark.parametrize("make", [lambda p: weft.optim.Adam([p], lr=0.05),
                                  lambda p: weft.optim.SGD([p], lr=0.1, momentum=0.5)])
def test_optimizer_with_tape_reaches_minimum(rng, make):
    target_np = rng.uniform(-3, 3, size=(32, 3)).astype(np.float32)
    target = wp.array(target_np, dtype=wp.vec3)
    p = wp.array(rng.uniform(-3, 3, size=(32, 3)).astype(np.float32), dtype=wp.vec3, requires_grad=True)
    loss = wp.zeros(1, dtype=float, requires_grad=True)
    opt = make(p)
    tape = wp.Tape()
    for _ in range(400):
        tape.reset()
        loss.zero_()
        with tape:
            wp.launch(_distance, dim=32, inputs=[p, target, loss])
        tape.backward(loss)
        opt.step([tape.gradients[p]])
    np.testing.assert_allclose(p.numpy(), target_np, atol=2e-3)


def test_set_params_keeps_fitting_state(rng):
    for dtype in (wp.float32, wp.float16, wp.vec3):
        p = wp.zeros(5, dtype=dtype)
        opt = weft.optim.Adam([p])
        m, v = opt.m[0], opt.v[0]
        m.fill_(1.0)
        opt.set_params([p])
        assert opt.m[0] is m and opt.v[0] is v
        assert (opt.m[0].numpy() == 1.0).all()
    s = weft.optim.SGD([p], momentum=0.9)
    buf = s.b[0]
    s.set_params([p])
    assert s.b[0] is buf
    s.set_params([wp.zeros(7, dtype=wp.vec3)])          # another shape: a new zeroed buffer
    assert s.b[0] is not buf and s.b[0].shape == (7,)
    opt = weft.optim.Adam([wp.zeros(3)])
    opt.reset_internal_state()
    assert opt.t == 0 and not opt.m[0].numpy().any()


def test_optimizer_errors():
    for cls in (weft.optim.Adam, weft.optim.SGD):
        name = cls.__name__
        with pytest.raises(RuntimeError, match=rf"{name} parameters must be set before calling step\(\), got None"):
            cls().step([])
        params = wp.zeros(2, dtype=wp.float32)
        opt = cls([params])
        with pytest.raises(TypeError, match=f"{name} gradient dtype must match parameter dtype float32, got int32"):
            opt.step([wp.zeros(2, dtype=wp.int32)])
        with pytest.raises(ValueError, match=rf"{name} gradient shape must match parameter shape \(2,\), got \(2, 1\)"):
            opt.step([wp.zeros((2, 1), dtype=wp.float32)])
        with pytest.raises(ValueError, match="expects 1 gradient arrays"):
            opt.step([])
        with pytest.raises(ValueError, match="no gradient"):
            opt.step([None])
        with pytest.raises(ValueError, match="contiguous"):   # a strided 2-D view cannot be flattened
            cls([wp.zeros((4, 4), dtype=wp.float32)[:, 1:3]]).step([wp.zeros((4, 2), dtype=wp.float32)])
    with pytest.raises(TypeError, match="SGD updates arrays of float16, float32 or float64"):
        weft.optim.SGD([wp.zeros(3, dtype=wp.int32)]).step([wp.zeros(3, dtype=wp.int32)])
    with pytest.raises(RuntimeError, match="Unsupported dtype for Warp Adam optimizer"):
        weft.optim.Adam([wp.zeros(3, dtype=wp.int32)])
    assert params.numpy().tolist() == [0.0, 0.0]      # nothing was launched by the refused steps
