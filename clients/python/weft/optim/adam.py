"""Adam (Kingma & Ba) with Warp's interface: first and second moment estimates of the
gradient, bias-corrected, one step kernel per parameter array. Parameters may be float32,
float16 (moments kept in float32) or vec3 arrays, as in Warp."""
from __future__ import annotations

from typing import Any

import weft as wp

from ._common import check_gradient, flat, state_like


@wp.func
def _square(g: float):
    return g * g


@wp.func
def _square(g: wp.vec3):  # noqa: F811 - the vec3 overload
    return wp.cw_mul(g, g)


@wp.func
def _ratio(m_hat: float, v_hat: float, eps: float):
    return m_hat / (wp.sqrt(v_hat) + eps)


@wp.func
def _ratio(m_hat: wp.vec3, v_hat: wp.vec3, eps: float):  # noqa: F811 - the vec3 overload
    return wp.cw_div(m_hat, wp.vec3(wp.sqrt(v_hat[0]) + eps, wp.sqrt(v_hat[1]) + eps, wp.sqrt(v_hat[2]) + eps))


@wp.func
def _adam_update(m: Any, v: Any, g: Any, beta1: float, beta2: float, t: float, eps: float):
    """The new moments and the bias-corrected step direction (to be scaled by lr)."""
    mi = beta1 * m + (1.0 - beta1) * g
    vi = beta2 * v + (1.0 - beta2) * _square(g)
    return mi, vi, _ratio(mi / (1.0 - wp.pow(beta1, t + 1.0)), vi / (1.0 - wp.pow(beta2, t + 1.0)), eps)


@wp.kernel
def _adam_step(g: wp.array(dtype=Any), m: wp.array(dtype=Any), v: wp.array(dtype=Any), lr: float, beta1: float,
               beta2: float, t: float, eps: float, params: wp.array(dtype=Any)):
    i = wp.tid()
    mi, vi, d = _adam_update(m[i], v[i], g[i], beta1, beta2, t, eps)
    m[i] = mi
    v[i] = vi
    params[i] = params[i] - lr * d


@wp.kernel
def _adam_step_half(g: wp.array(dtype=wp.float16), m: wp.array(dtype=wp.float32), v: wp.array(dtype=wp.float32),
                    lr: float, beta1: float, beta2: float, t: float, eps: float,
                    params: wp.array(dtype=wp.float16)):
    i = wp.tid()
    mi, vi, d = _adam_update(m[i], v[i], float(g[i]), beta1, beta2, t, eps)
    m[i] = mi
    v[i] = vi
    params[i] = wp.float16(float(params[i]) - lr * d)


# parameter dtype -> (moment dtype, step kernel)
_KERNELS = {
    wp.float32: (wp.float32, _adam_step),
    wp.float16: (wp.float32, _adam_step_half),
    wp.vec3: (wp.vec3, _adam_step),
}


def _moment_dtype(param):
    entry = _KERNELS.get(param.dtype)
    if entry is None:
        raise RuntimeError(f"Unsupported dtype for Warp Adam optimizer: {param.dtype} (Adam updates "
                           f"float32, float16 and vec3 arrays)")
    return entry[0]


class Adam:
    """Adam over a list of arrays: `step(grads)` updates each array of `params` in place from
    the gradient array at the same position. `lr`, `beta1`, `beta2`, `eps` and the step count
    `t` are plain attributes read at each step."""

    def __init__(self, params=None, lr=0.001, betas=(0.9, 0.999), eps=1e-08):
        self.m = []
        self.v = []
        self.set_params(params)
        self.lr = lr
        self.beta1 = betas[0]
        self.beta2 = betas[1]
        self.eps = eps
        self.t = 0

    def set_params(self, params):
        """Sets the arrays to optimize; moment buffers that still fit a parameter (same shape and
        moment dtype) are kept, moved with a parameter that changed device, else zeroed anew."""
        self.params = params
        if not isinstance(params, list) or not params:
            return
        if len(self.m) != len(params):
            self.m = [None] * len(params)
        if len(self.v) != len(params):
            self.v = [None] * len(params)
        for i, param in enumerate(params):
            dtype = _moment_dtype(param)
            self.m[i] = state_like(self.m[i], param, dtype, wp.zeros)
            self.v[i] = state_like(self.v[i], param, dtype, wp.zeros)

    def reset_internal_state(self):
        """Zeroes the moments and the step count."""
        for buffer in (*self.m, *self.v):
            buffer.zero_()
        self.t = 0

    def step(self, grad):
        """One Adam step of every parameter array with the gradient arrays `grad` (same order)."""
        if self.params is None:
            raise RuntimeError("Adam parameters must be set before calling step(), got None")
        if len(grad) != len(self.params):
            raise ValueError(f"Adam.step expects {len(self.params)} gradient arrays (one per parameter "
                             f"array), got {len(grad)}")
        for i, param in enumerate(self.params):
            Adam.step_detail(grad[i], self.m[i], self.v[i], self.lr, self.beta1, self.beta2, self.t,
                             self.eps, param)
        self.t = self.t + 1

    @staticmethod
    def step_detail(g, m, v, lr, beta1, beta2, t, eps, params):
        """One Adam step of `params` with gradient `g` and moments `m`, `v` at step `t`."""
        check_gradient("Adam", params, g)
        entry = _KERNELS.get(params.dtype)
        if entry is None:
            raise RuntimeError("Params data type not supported in Adam step kernels.")
        kernel = entry[1]
        if params.size == 0:
            return
        wp.launch(kernel, dim=params.size,
                  inputs=[flat(g), flat(m), flat(v), float(lr), float(beta1), float(beta2), float(t),
                          float(eps), flat(params)],
                  device=params.device)
