"""Stochastic gradient descent with Warp's interface: optional momentum (with dampening and
Nesterov's variant) and weight decay (an L2 term added to the gradient); one generic step kernel
computes in the parameter's own scalar type (the coefficients are passed as values of that type),
so float16, float32 and float64 parameters, vectors and matrices all work."""
from __future__ import annotations

from typing import Any

import weft as wp

from ..types import type_repr
from ._common import check_gradient, flat, state_like


@wp.kernel
def _sgd_step(g: wp.array(dtype=Any), b: wp.array(dtype=Any), lr: Any, momentum: Any, dampening: Any,
              weight_decay: Any, nesterov: int, t: int, params: wp.array(dtype=Any)):
    # the coefficients arrive as values of the parameters' scalar type
    i = wp.tid()
    zero = lr - lr
    p = params[i]
    d = g[i]
    if weight_decay != zero:
        d = d + weight_decay * p
    if momentum != zero:
        buf = d
        if t > 0:
            buf = momentum * b[i] + (lr / lr - dampening) * d
        b[i] = buf
        if nesterov != 0:
            d = d + momentum * buf
        else:
            d = buf
    params[i] = p - lr * d


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
        wp.launch(_sgd_step, dim=params.size,
                  inputs=[flat(g), flat(b), scalar(lr), scalar(momentum), scalar(dampening),
                          scalar(weight_decay), int(bool(nesterov)), int(t), flat(params)],
                  device=params.device)
