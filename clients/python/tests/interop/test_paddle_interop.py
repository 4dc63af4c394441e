"""Paddle interop (skipped when paddle is not installed): from_paddle / to_paddle through
DLPack, the dtype and device helpers, against NumPy references."""
import numpy as np


def test_paddle_round_trip(wp, paddle, rng):
    values = rng.standard_normal((6, 3)).astype(np.float32)
    t = paddle.to_tensor(values, place=paddle.CPUPlace())
    a = wp.from_paddle(t, dtype=wp.vec3)
    assert a.shape == (6,) and a.dtype is wp.vec3
    np.testing.assert_array_equal(a.numpy(), values)
    back = wp.to_paddle(a)
    np.testing.assert_array_equal(back.numpy(), values)


def test_paddle_helpers(wp, paddle):
    assert wp.dtype_from_paddle(paddle.float32) is wp.float32
    assert wp.dtype_from_paddle(paddle.int64) is wp.int64
    assert wp.dtype_to_paddle(wp.float64) == paddle.float64
    assert wp.device_from_paddle("cpu").is_cpu
    assert wp.device_to_paddle("cpu") == "cpu"
