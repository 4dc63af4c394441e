"""What Adam and SGD share: the checks of a gradient against its parameter array (Warp's
messages), the flat view a step kernel runs over, and moving an optimizer's state buffer to
the device of a parameter that moved."""
from __future__ import annotations

from ..types import type_repr


def check_gradient(name: str, params, grad) -> None:
    if grad is None:
        raise ValueError(f"{name} gradient is None: the parameter array has no gradient (was it "
                         f"created with requires_grad=True, and did a tape's backward reach it?)")
    if params.dtype != grad.dtype:
        raise TypeError(f"{name} gradient dtype must match parameter dtype {type_repr(params.dtype)}, "
                        f"got {type_repr(grad.dtype)}")
    if tuple(params.shape) != tuple(grad.shape):
        raise ValueError(f"{name} gradient shape must match parameter shape {tuple(params.shape)}, "
                         f"got {tuple(grad.shape)}")
    if str(params.device) != str(grad.device):
        raise ValueError(f"{name} gradient is on {grad.device}, its parameter array on {params.device}")


def flat(a):
    """`a` as a 1-D array over the same memory (a step updates every element, whatever the
    shape); a non-contiguous view cannot be flattened."""
    if a.ndim == 1:
        return a
    if not a.is_contiguous:
        raise ValueError(f"optimizer arrays must be contiguous to be updated in place, got an array "
                         f"of shape {tuple(a.shape)} with strides {tuple(a.strides)}")
    return a.flatten()


def state_like(buffer, param, dtype, zeros):
    """The state buffer for `param`: `buffer` kept when it fits (same shape and dtype; moved
    when the parameter moved to another device), else a new zeroed one."""
    if buffer is None or tuple(buffer.shape) != tuple(param.shape) or buffer.dtype != dtype:
        return zeros(shape=param.shape, dtype=dtype, device=param.device)
    if str(buffer.device) != str(param.device):
        return buffer.to(param.device)
    return buffer
