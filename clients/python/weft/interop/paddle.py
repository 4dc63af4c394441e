"""Paddle interop: wp.from_paddle / wp.to_paddle and the device/dtype helpers, through DLPack
(the same memory rules as weft.interop.dlpack: zero-copy for weft slabs, a copy of CPU tensors
that live in this process)."""
from __future__ import annotations

import numpy as np

from . import dlpack


def _paddle():
    import paddle  # noqa: PLC0415

    return paddle


def dtype_from_paddle(paddle_dtype):
    """The weft scalar dtype of a Paddle dtype."""
    from .. import types  # noqa: PLC0415

    name = str(paddle_dtype).split(".")[-1]
    if name == "bool":
        return types.bool
    weft_type = getattr(types, name, None)
    if weft_type is None or not types.is_dtype(weft_type):
        raise TypeError(f"Invalid or unsupported data type: {paddle_dtype}")
    return weft_type


def dtype_to_paddle(weft_dtype):
    """The Paddle dtype of a weft dtype (of its scalar components for vectors)."""
    from .. import types  # noqa: PLC0415
    from ..array import _canonical_dtype  # noqa: PLC0415

    dtype = _canonical_dtype(weft_dtype)
    if not types.is_dtype(dtype):
        raise TypeError(f"Cannot convert {weft_dtype} to a Paddle type")
    name = np.dtype(dtype._wp_scalar_type_._np_dtype_).name
    return getattr(_paddle(), name)


def device_from_paddle(paddle_device):
    """The weft Device of a Paddle place or device string ("cpu", "gpu:N")."""
    from ..device import get_device  # noqa: PLC0415

    text = str(paddle_device).lower()
    if "cpu" in text:
        return get_device("cpu")
    if "gpu" in text or "cuda" in text:
        digits = "".join(c for c in text.split(":")[-1] if c.isdigit())
        return get_device(f"cuda:{digits or 0}")
    raise RuntimeError(f"Paddle device {paddle_device} has no weft counterpart")


def device_to_paddle(device):
    """The Paddle device string ("cpu", "gpu:N") of a weft device."""
    from ..device import get_device  # noqa: PLC0415

    device = get_device(device)
    return "cpu" if device.is_cpu else f"gpu:{device.ordinal}"


def from_paddle(t, dtype=None):
    """A weft array of a Paddle tensor (through DLPack)."""
    paddle = _paddle()
    if not isinstance(t, paddle.Tensor):
        raise TypeError(f"wp.from_paddle expects a paddle.Tensor, got {type(t).__name__}")
    producer = t if hasattr(t, "__dlpack__") else paddle.utils.dlpack.to_dlpack(t)
    return dlpack.from_dlpack(producer, dtype=dtype)


def to_paddle(a):
    """A Paddle tensor over a weft array (through DLPack)."""
    return _paddle().utils.dlpack.from_dlpack(dlpack.to_dlpack(a))
