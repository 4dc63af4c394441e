"""Stochastic gradient descent with Warp's interface: optional momentum (with dampening and
Nesterov's variant) and weight decay (an L2 term added to the gradient); generic step kernels
(one for scalar, one for vector/matrix dtypes) compute in the parameter's own scalar type (the
coefficients arrive as float64), so float16, float32 and float64 parameters all work."""
from __future__ import annotations

from typing import Any

import weft as wp

from ..types import type_repr
from ._common import check_gradient, flat, state_like


@wp.func
def _sgd_update(p: Any, g: Any, b: Any, lr: Any, momentum: Any, dampening: Any, weight_decay: Any,
                nesterov: int, t: int):
    """(new parameter, new momentum buffer) of one element; the coefficients have the
    parameter's scalar type."""
    zero = lr - lr
    d = g
    if weight_decay != zero:
        d = d + weight_decay * p
    buf = b
    if momentum != zero:
        buf = d
        if t > 0:
            buf = momentum * b + (lr / lr - dampening) * d
        if nesterov != 0:
            d = d + momentum * buf
        else:
            d = buf
    return p - lr * d, buf


@wp.kernel
def _sgd_scalar(g: wp.array(dtype=Any), b: wp.array(dtype=Any), lr: wp.float64, momentum: wp.float64,
                dampening: wp.float64, weight_decay: wp.float64, nesterov: int, t: int,
                params: wp.array(dtype=Any)):
    i = wp.tid()
    p = params[i]
    s = type(p)
    new_p, new_b = _sgd_update(p, g[i], b[i], s(lr), s(momentum), s(dampening), s(weight_decay), nesterov, t)
    b[i] = new_b
    params[i] = new_p


@wp.kernel
def _sgd_vector(g: wp.array(dtype=Any), b: wp.array(dtype=Any), lr: wp.float64, momentum: wp.float64,
                dampening: wp.float64, weight_decay: wp.float64, nesterov: int, t: int,
                params: wp.array(dtype=Any)):
    i = wp.tid()
    p = params[i]
    s = p.dtype
    new_p, new_b = _sgd_update(p, g[i], b[i], s(lr), s(momentum), s(dampening), s(weight_decay), nesterov, t)
    b[i] = new_b
    params[i] = new_p


class SGD:
    """SGD over a list of arrays: `step(grads)` updates each array of `params` in place from the
    gradient array at the same position; `b` holds one momentum buffer per parameter array."""

    def __init__(self, params=None, lr=0.001, momentum=0.0, dampening=0.0, weight_decay=0.0,
                 nesterov=False):
        self.b = []
        self.set_params(params)
        self.lr = lr
        self.momentum = momentum
        self.dampening = dampening
        self.weight_decay = weight_decay
        self.nesterov = nesterov
        self.t = 0

    def set_params(self, params):
        """Sets the arrays to optimize; a momentum buffer that still fits its parameter is kept
        (moved with a parameter that changed device), else zeroed anew."""
        self.params = params
        if not isinstance(params, list) or not params:
            return
        if len(self.b) != len(params):
            self.b = [None] * len(params)
        for i, param in enumerate(params):
            self.b[i] = state_like(self.b[i], param, param.dtype, wp.zeros)

    def reset_internal_state(self):
        """Zeroes the momentum buffers and the step count."""
        for buffer in self.b:
            buffer.zero_()
        self.t = 0

    def step(self, grad):
        """One SGD step of every parameter array with the gradient arrays `grad` (same order)."""
        if self.params is None:
            raise RuntimeError("SGD parameters must be set before calling step(), got None")
        if len(grad) != len(self.params):
            raise ValueError(f"SGD.step expects {len(self.params)} gradient arrays (one per parameter "
                             f"array), got {len(grad)}")
        for i, param in enumerate(self.params):
            SGD.step_detail(grad[i], self.b[i], self.lr, self.momentum, self.dampening,
                            self.weight_decay, self.nesterov, self.t, param)
        self.t = self.t + 1

    @staticmethod
    def step_detail(g, b, lr, momentum, dampening, weight_decay, nesterov, t, params):
        """One SGD step of `params` with gradient `g` and momentum buffer `b` at step `t`."""
        check_gradient("SGD", params, g)
        if params.dtype != b.dtype:
            raise TypeError(f"SGD momentum buffer dtype must match parameter dtype "
                            f"{type_repr(params.dtype)}, got {type_repr(b.dtype)}")
        scalar = getattr(params.dtype, "_wp_scalar_type_", None)
        if scalar not in (wp.float16, wp.float32, wp.float64):
            raise TypeError(f"SGD updates arrays of float16, float32 or float64 scalars, vectors or "
                            f"matrices, got {type_repr(params.dtype)}")
        if params.size == 0:
            return
        kernel = _sgd_vector if getattr(params.dtype, "_shape_", ()) else _sgd_scalar
        wp.launch(kernel, dim=params.size,
                  inputs=[flat(g), flat(b), float(lr), float(momentum), float(dampening),
                          float(weight_decay), int(bool(nesterov)), int(t), flat(params)],
                  device=params.device)
