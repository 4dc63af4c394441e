"""Paddle interop on the CPU (skipped with the reason when paddle is not importable):
to_paddle zero-copy (same data pointer, writes seen both ways, the tensor keeps the memory
alive), from_paddle of weft-made tensors zero-copy and of other whole tensors by moving their
memory into a slab once (views are copied), gradients shared both ways (stop_gradient=False,
.grad is one allocation), the dtype/device/stream helpers, Adam optimizations through a weft
Tape in both directions, DLPack and launch arguments, a remote session (copies), and the
errors (unsupported dtypes, element shapes, non-contiguous elements, incompatible dtypes)."""
import gc

import numpy as np
import pytest

import weft as wp


@wp.kernel
def scale_add(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = 3.0 * x[i] + 1.0


@wp.kernel
def double_vec(v: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    v[i] = 2.0 * v[i]


@wp.kernel
def double_f64(v: wp.array(dtype=wp.float64)):
    i = wp.tid()
    v[i] = wp.float64(2.0) * v[i]


@wp.kernel
def double_i32(v: wp.array(dtype=wp.int32)):
    i = wp.tid()
    v[i] = 2 * v[i]


@wp.kernel
def square_sum(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(out, 0, x[i] * x[i])


@wp.kernel
def points_loss(xs: wp.array(dtype=float, ndim=2), l: wp.array(dtype=float)):
    tid = wp.tid()
    wp.atomic_add(l, 0, xs[tid, 0] ** 2.0 + xs[tid, 1] ** 2.0)


@wp.struct
class Pair:
    a: float
    b: int


# (name, weft dtype, NumPy dtype of the data, Paddle dtype name, kernel doubling it, shape)
CASES = {
    "float32": (wp.float32, np.float32, "float32", None, (7, 5)),
    "float64": (wp.float64, np.float64, "float64", double_f64, (13,)),
    "int32": (wp.int32, np.int32, "int32", double_i32, (11,)),
    "vec3": (wp.vec3, np.float32, "float32", double_vec, (9, 3)),
}


def _data(rng, np_dtype, shape):
    if np.dtype(np_dtype).kind == "i":
        return rng.integers(-1000, 1000, size=shape).astype(np_dtype)
    return rng.standard_normal(shape).astype(np_dtype)


@pytest.mark.parametrize("name", list(CASES))
def test_from_paddle_moves_a_tensor_into_a_slab_once(wp, paddle, rng, name):
    dtype, np_dtype, pname, kernel, shape = CASES[name]
    values = _data(rng, np_dtype, shape)
    t = paddle.to_tensor(values, place=paddle.CPUPlace())
    assert t.dtype == getattr(paddle, pname)
    before = t.data_ptr()
    a = wp.from_paddle(t, dtype=dtype if name == "vec3" else None)
    assert a.dtype is dtype and a.device.is_cpu
    assert a.shape == (shape[:-1] if name == "vec3" else shape)
    np.testing.assert_array_equal(a.numpy(), values)
    # the same Tensor object now reads and writes the slab: zero-copy from here on
    assert t.data_ptr() == a.ptr != before
    np.testing.assert_array_equal(t.numpy(), values)
    again = wp.from_paddle(t, dtype=dtype)
    assert again.ptr == a.ptr and again._handle == a._handle
    # Paddle -> weft
    t.set_value(paddle.ones_like(t))
    np.testing.assert_array_equal(a.numpy(), np.ones(shape, np_dtype))
    # weft -> Paddle
    t.set_value(paddle.to_tensor(values))
    if kernel is not None:
        wp.launch(kernel, dim=a.shape[0], inputs=[a], device="cpu")
        np.testing.assert_array_equal(t.numpy(), values * 2)
    else:
        out = paddle.zeros(shape, dtype="float32")
        wp.launch(scale_add, dim=a.size, inputs=[a.flatten(), wp.from_paddle(out).flatten()],
                  device="cpu")
        np.testing.assert_allclose(out.numpy(), 3.0 * values + 1.0, rtol=1e-6)


@pytest.mark.parametrize("name", list(CASES))
def test_to_paddle_is_zero_copy_both_ways(wp, paddle, rng, name):
    dtype, np_dtype, pname, kernel, shape = CASES[name]
    values = _data(rng, np_dtype, shape)
    a = wp.array(values, dtype=dtype, device="cpu")
    t = wp.to_paddle(a)
    assert t.dtype == getattr(paddle, pname) and list(t.shape) == list(shape)
    assert t.data_ptr() == a.ptr and t.place.is_cpu_place()
    assert t.stop_gradient
    np.testing.assert_array_equal(t.numpy(), values)
    back = wp.from_paddle(t, dtype=dtype)
    assert back.ptr == a.ptr and back._handle == a._handle and back.dtype is dtype
    fresh = _data(rng, np_dtype, shape)
    t.set_value(paddle.to_tensor(fresh))                 # Paddle -> weft
    np.testing.assert_array_equal(a.numpy(), fresh)
    if kernel is not None:                              # weft -> Paddle
        wp.launch(kernel, dim=a.shape[0], inputs=[a], device="cpu")
        np.testing.assert_array_equal(t.numpy(), fresh * 2)


def test_more_dtypes_round_trip(wp, paddle, rng):
    """Every dtype both frameworks have, in place both ways; weft's unsigned types wider than 8
    bits reach Paddle as the signed type of their size (its bits), as in Warp."""
    cases = [(wp.float16, np.float16, "float16"), (wp.int8, np.int8, "int8"),
             (wp.int16, np.int16, "int16"), (wp.int64, np.int64, "int64"),
             (wp.uint8, np.uint8, "uint8"), (wp.bool, np.bool_, "bool"),
             (wp.uint16, np.uint16, "int16"), (wp.uint32, np.uint32, "int32"),
             (wp.uint64, np.uint64, "int64")]
    for dtype, np_dtype, pname in cases:
        values = (rng.integers(0, 200, size=10) if np.dtype(np_dtype).kind in "iub"
                  else rng.standard_normal(10)).astype(np_dtype)
        a = wp.array(values, dtype=dtype, device="cpu")
        t = wp.to_paddle(a)
        assert t.dtype == getattr(paddle, pname) and t.data_ptr() == a.ptr, dtype
        np.testing.assert_array_equal(t.numpy().view(np_dtype), values)
        b = wp.from_paddle(t, dtype=dtype)
        assert b.ptr == a.ptr and b.dtype is dtype
        c = wp.from_paddle(paddle.to_tensor(t.numpy()))     # a tensor of its own: moved
        assert c.dtype is wp.dtype_from_paddle(getattr(paddle, pname))
        np.testing.assert_array_equal(c.numpy().view(np_dtype), values)


def test_bfloat16_both_ways_zero_copy(wp, paddle, rng):
    values = rng.standard_normal(8).astype(np.float32)
    t = paddle.to_tensor(values).astype(paddle.bfloat16)
    a = wp.from_paddle(t)
    assert a.dtype is wp.bfloat16 and t.data_ptr() == a.ptr
    expected = t.astype(paddle.float32).numpy()
    np.testing.assert_array_equal(np.asarray(a.numpy(), dtype=np.float32), expected)
    back = wp.to_paddle(a)
    assert back.dtype == paddle.bfloat16 and back.data_ptr() == a.ptr
    np.testing.assert_array_equal(back.astype(paddle.float32).numpy(), expected)


def test_common_tensors_are_moved(wp, paddle):
    """What Paddle's creation routines, parameters and op results give covers its whole memory
    block, so each moves into a slab (and stays one Tensor object)."""
    layer = paddle.nn.Linear(3, 5)
    made = [paddle.randn([100, 2]), paddle.zeros([7], dtype="int64"), paddle.ones([4, 3]) * 2.0,
            paddle.create_parameter([5, 3], "float32"), layer.weight, layer.bias,
            paddle.arange(12, dtype="float32").reshape([3, 4]) + 1.0]
    for t in made:
        values = t.numpy().copy()
        a = wp.from_paddle(t)
        assert t.data_ptr() == a.ptr, t
        np.testing.assert_array_equal(a.numpy(), values)
    assert layer.weight.data_ptr() == wp.from_paddle(layer.weight).ptr
    np.testing.assert_allclose(layer(paddle.ones([1, 3])).numpy(),
                               np.ones((1, 3), np.float32) @ layer.weight.numpy()
                               + layer.bias.numpy(), rtol=1e-5, atol=1e-6)


def test_to_paddle_keeps_the_memory_alive(wp, paddle, rng):
    values = rng.standard_normal(64)
    a = wp.array(values, dtype=wp.float64, device="cpu")
    t = wp.to_paddle(a)
    ptr = a.ptr
    del a
    gc.collect()
    assert t.data_ptr() == ptr
    np.testing.assert_array_equal(t.numpy(), values)
    # a moved tensor keeps its slab too, and converts to the same allocation again
    u = paddle.to_tensor(values)
    b = wp.from_paddle(u)
    handle = b._handle
    del b
    gc.collect()
    np.testing.assert_array_equal(u.numpy(), values)
    assert wp.from_paddle(u)._handle == handle


def test_views_are_copied_and_their_base_is_not_moved(wp, paddle, rng):
    values = rng.standard_normal((4, 6)).astype(np.float32)
    base = paddle.to_tensor(values)
    ptr = base.data_ptr()
    strided = base[:, ::2]                               # a strided view of base's memory
    assert not strided.is_contiguous()
    a = wp.from_paddle(strided)
    np.testing.assert_array_equal(a.numpy(), values[:, ::2])
    assert a.ptr != strided.data_ptr() and base.data_ptr() == ptr == strided.data_ptr()
    row = base[2]                                        # contiguous, part of base's memory
    b = wp.from_paddle(row)
    np.testing.assert_array_equal(b.numpy(), values[2])
    assert b.ptr != row.data_ptr() and base.data_ptr() == ptr
    transposed = base.T                                  # strided scalars are fine
    c = wp.from_paddle(transposed)
    np.testing.assert_array_equal(c.numpy(), values.T)
    # views made of a tensor before it moves keep the old memory (Paddle shows no count of a
    # block's users, so the move cannot see them: docs/interop.md, "Paddle"); tensors sharing
    # its Paddle tensor object (detach(), t[:]) move with it
    whole = paddle.to_tensor(values)
    before, detached, reshaped = whole.data_ptr(), whole.detach(), whole.reshape([24])
    assert reshaped._is_shared_buffer_with(whole)
    moved = wp.from_paddle(whole)
    assert whole.data_ptr() == moved.ptr == detached.data_ptr() != before
    assert reshaped.data_ptr() == before
    whole.set_value(paddle.zeros_like(whole))
    np.testing.assert_array_equal(detached.numpy(), np.zeros_like(values))
    np.testing.assert_array_equal(reshaped.numpy(), values.reshape(24))
    # views of weft memory stay in place
    w = wp.array(values, device="cpu")
    tw = wp.to_paddle(w)
    d = wp.from_paddle(tw[1])
    assert d.ptr == w.ptr + 6 * 4
    e = wp.from_paddle(tw[:, 1:])
    assert e.ptr == w.ptr + 4 and e.strides == (24, 4)
    np.testing.assert_array_equal(e.numpy(), values[:, 1:])


def test_gradients_are_shared_both_ways(wp, paddle, rng):
    values = rng.standard_normal(16).astype(np.float32)
    x = paddle.to_tensor(values, stop_gradient=False)
    out = paddle.zeros([1])
    out.stop_gradient = False
    a = wp.from_paddle(x)
    o = wp.from_paddle(out)
    assert a.requires_grad and o.requires_grad and not x.stop_gradient
    assert a._info.grad_handle                           # a daemon-side gradient (tapes)
    assert x.grad is not None and x.grad.data_ptr() == a.grad.ptr     # one allocation
    np.testing.assert_array_equal(a.grad.numpy(), np.zeros(16, np.float32))
    tape = wp.Tape()
    with tape:
        wp.launch(square_sum, dim=16, inputs=[a, o], device="cpu")
    np.testing.assert_allclose(out.numpy(), [np.sum(values.astype(np.float64) ** 2)], rtol=1e-5)
    tape.backward(loss=o)                                # weft -> Paddle's .grad
    np.testing.assert_allclose(x.grad.numpy(), 2.0 * values, rtol=1e-6)
    tape.zero()        # queued like any weft command: Paddle reads after it need a sync
    wp.synchronize()
    np.testing.assert_array_equal(x.grad.numpy(), np.zeros(16, np.float32))
    (x * x * 0.5).sum().backward()                       # Paddle -> weft's .grad
    np.testing.assert_allclose(a.grad.numpy(), values, rtol=1e-6)

    # an existing Paddle gradient is copied in, and .grad then points at the weft one
    y = paddle.to_tensor(values, stop_gradient=False)
    (y * 3.0).sum().backward()
    b = wp.from_paddle(y)
    np.testing.assert_array_equal(b.grad.numpy(), np.full(16, 3.0, np.float32))
    assert y.grad.data_ptr() == b.grad.ptr

    # to_paddle of an array that requires grad: stop_gradient=False, .grad is the array's
    c = wp.array(values, dtype=float, device="cpu", requires_grad=True)
    tc = wp.to_paddle(c)
    assert not tc.stop_gradient and tc.grad.data_ptr() == c.grad.ptr
    (tc * 2.0).sum().backward()
    np.testing.assert_array_equal(c.grad.numpy(), np.full(16, 2.0, np.float32))
    assert wp.to_paddle(c, requires_grad=False).stop_gradient
    # and back: the same array and gradient
    back = wp.from_paddle(tc)
    assert back.ptr == c.ptr and back.grad.ptr == c.grad.ptr
    # requires_grad=False leaves gradients alone; requires_grad=True maps them regardless
    z = paddle.to_tensor(values, stop_gradient=False)
    assert not wp.from_paddle(z, requires_grad=False).requires_grad and z.grad is None
    s = paddle.to_tensor(values)
    d = wp.from_paddle(s, requires_grad=True)
    assert d.requires_grad and s.grad.data_ptr() == d.grad.ptr


def test_explicit_grad_and_return_ctype(wp, paddle, rng):
    values = rng.standard_normal(6).astype(np.float32)
    x = paddle.to_tensor(values)
    g = paddle.to_tensor(np.full(6, 2.0, np.float32))
    a = wp.from_paddle(x, grad=g)
    assert a.requires_grad and a.grad.ptr == g.data_ptr()     # g was moved too
    np.testing.assert_array_equal(a.grad.numpy(), np.full(6, 2.0, np.float32))
    ga = wp.zeros(6, dtype=float, device="cpu")
    b = wp.from_paddle(x, grad=ga)
    assert b.grad is ga
    with pytest.raises(ValueError, match="gradient"):
        wp.from_paddle(x, grad=wp.zeros(5, dtype=float, device="cpu"))
    desc = wp.from_paddle(x, return_ctype=True)
    assert desc.data == x.data_ptr() and desc.ndim == 1 and desc.shape[0] == 6
    out = paddle.zeros([6])
    wp.launch(scale_add, dim=6, inputs=[desc, wp.from_paddle(out, return_ctype=True)],
              device="cpu")
    np.testing.assert_allclose(out.numpy(), 3.0 * values + 1.0, rtol=1e-6)


def _adam_from_paddle(wp, paddle, rng, steps):
    xs = paddle.to_tensor(rng.standard_normal((100, 2)).astype(np.float32), stop_gradient=False)
    l = paddle.zeros([1])
    l.stop_gradient = False
    opt = paddle.optimizer.Adam(learning_rate=0.1, parameters=[xs])
    wp_xs = wp.from_paddle(xs)
    wp_l = wp.from_paddle(l)
    tape = wp.Tape()
    with tape:
        wp.launch(points_loss, dim=len(xs), inputs=[wp_xs], outputs=[wp_l], device=wp_xs.device)
    losses = []
    for _ in range(steps):
        tape.zero()
        tape.backward(loss=wp_l)                         # xs.grad is wp_xs.grad
        opt.step()                                       # updates xs, hence wp_xs, in place
        wp_l.zero_()
        wp.launch(points_loss, dim=len(xs), inputs=[wp_xs], outputs=[wp_l], device=wp_xs.device)
        losses.append(l.item())
    assert xs.data_ptr() == wp_xs.ptr and xs.grad.data_ptr() == wp_xs.grad.ptr
    return losses


def test_adam_optimization_with_from_paddle(wp, paddle, rng):
    """Warp's documented optimization pattern: a weft kernel computes the loss, a weft Tape its
    gradient into the Paddle tensor's .grad, a Paddle optimizer updates the tensor."""
    losses = _adam_from_paddle(wp, paddle, rng, 500)
    # sum of squares of 100 standard-normal 2-d points: ~200 at the start
    assert losses[0] > 10.0
    assert losses[-1] < 1e-3 * losses[0] and losses[-1] < 0.1


def test_adam_optimization_with_to_paddle(wp, paddle, rng):
    xs = wp.array(rng.standard_normal((100, 2)), dtype=float, device="cpu", requires_grad=True)
    l = wp.zeros(1, dtype=float, device="cpu", requires_grad=True)
    opt = paddle.optimizer.Adam(learning_rate=0.1, parameters=[wp.to_paddle(xs)])
    tape = wp.Tape()
    with tape:
        wp.launch(points_loss, dim=len(xs), inputs=[xs], outputs=[l], device="cpu")
    losses = []
    for _ in range(500):
        tape.zero()
        tape.backward(loss=l)
        opt.step()
        l.zero_()
        wp.launch(points_loss, dim=len(xs), inputs=[xs], outputs=[l], device="cpu")
        losses.append(float(l.numpy()[0]))
    assert losses[0] > 10.0
    assert losses[-1] < 1e-3 * losses[0] and losses[-1] < 0.1


def test_dtype_helpers(wp, paddle):
    pairs = [(paddle.float16, wp.float16), (paddle.float32, wp.float32),
             (paddle.float64, wp.float64), (paddle.int8, wp.int8), (paddle.int16, wp.int16),
             (paddle.int32, wp.int32), (paddle.int64, wp.int64), (paddle.uint8, wp.uint8),
             (paddle.bool, wp.bool), (paddle.bfloat16, wp.bfloat16)]
    for p, w in pairs:
        assert wp.dtype_from_paddle(p) is w
        assert wp.dtype_to_paddle(w) == p
    assert wp.dtype_from_paddle(paddle.uint16) is wp.uint16       # not bfloat16
    assert wp.dtype_from_paddle(paddle.uint32) is wp.uint32
    assert wp.dtype_from_paddle(paddle.uint64) is wp.uint64
    for w, p in [(wp.uint16, paddle.int16), (wp.uint32, paddle.int32), (wp.uint64, paddle.int64)]:
        assert wp.dtype_to_paddle(w) == p
    assert wp.dtype_to_paddle(wp.vec3) == paddle.float32
    assert wp.dtype_to_paddle(wp.mat22d) == paddle.float64
    assert wp.dtype_to_paddle(float) == paddle.float32
    bad_types = [paddle.complex64, paddle.complex128, "float32"]
    bad_types += [getattr(paddle, "float8_e4m3fn")] if hasattr(paddle, "float8_e4m3fn") else []
    for bad in bad_types:
        with pytest.raises(TypeError, match="Cannot convert"):
            wp.dtype_from_paddle(bad)
    with pytest.raises(TypeError, match="Cannot convert"):
        wp.dtype_to_paddle(Pair)


def test_device_helpers(wp, paddle):
    cpu = wp.get_device("cpu")
    for d in ("cpu", paddle.CPUPlace(), paddle.zeros([1]).place):
        assert wp.device_from_paddle(d) == cpu
    assert wp.device_to_paddle("cpu") == "cpu"
    assert wp.device_to_paddle(cpu) == "cpu"
    with pytest.raises(RuntimeError, match="xpu"):
        wp.device_from_paddle("xpu:0")
    with pytest.raises(TypeError, match="device_from_paddle"):
        wp.device_from_paddle(3)
    if any(d.is_cuda for d in wp.get_cuda_devices()):
        assert wp.device_from_paddle("gpu:0") == wp.get_device("cuda:0")
        assert wp.device_to_paddle("cuda:0") == "gpu:0"
    else:
        for name in ("gpu:0", "gpu"):
            with pytest.raises(RuntimeError, match="no weft counterpart"):
                wp.device_from_paddle(name)


def test_streams_are_cuda_objects(wp, paddle):
    for arg in ("cpu", paddle.CPUPlace()):
        with pytest.raises(RuntimeError, match="CUDA"):
            wp.stream_from_paddle(arg)
    if paddle.device.get_device() == "cpu":
        with pytest.raises(RuntimeError, match="CUDA"):
            wp.stream_from_paddle()


def test_dlpack_and_launch_arguments(wp, paddle, rng):
    values = rng.standard_normal(10).astype(np.float32)
    t = paddle.to_tensor(values)
    a = wp.from_dlpack(t)                                # Paddle gives no CPU device id
    np.testing.assert_array_equal(a.numpy(), values)
    w = wp.array(values, device="cpu")
    assert wp.from_dlpack(wp.to_paddle(w)).ptr == w.ptr
    # a Paddle tensor passed to a launch: read, and the kernel's writes copied back
    x = paddle.to_tensor(values)
    y = paddle.zeros([10])
    wp.launch(scale_add, dim=10, inputs=[x, y], device="cpu")
    np.testing.assert_allclose(y.numpy(), 3.0 * values + 1.0, rtol=1e-6)


def test_errors(wp, paddle, rng):
    c = paddle.to_tensor(np.ones(3, np.complex64))
    with pytest.raises(TypeError, match="complex64"):
        wp.from_paddle(c)
    with pytest.raises(TypeError, match="paddle.Tensor"):
        wp.from_paddle(np.zeros(3, np.float32))
    with pytest.raises(TypeError, match="weft array"):
        wp.to_paddle(paddle.zeros([3]))
    # element shapes and layouts (RuntimeError as in Warp, and weft's InteropError)
    with pytest.raises(RuntimeError, match=r"trailing dimensions must be \(3,\)"):
        wp.from_paddle(paddle.zeros([6, 4]), dtype=wp.vec3)
    non_contiguous = paddle.to_tensor(rng.standard_normal((3, 6)).astype(np.float32)).T
    assert list(non_contiguous.shape) == [6, 3] and not non_contiguous.is_contiguous()
    with pytest.raises(wp.interop.paddle.PaddleInteropError, match="not contiguous"):
        wp.from_paddle(non_contiguous, dtype=wp.vec3)
    with pytest.raises(RuntimeError, match="incompatible dtypes"):
        wp.from_paddle(paddle.zeros([3], dtype="float32"), dtype=wp.float64)
    with pytest.raises(RuntimeError, match="incompatible dtypes"):
        wp.from_paddle(paddle.zeros([3], dtype="int32"), dtype=wp.float32)
    with pytest.raises(RuntimeError, match="at most 4"):
        wp.from_paddle(paddle.zeros([1, 1, 1, 1, 2]))
    # integers alias across signedness, bool as uint8 (Warp's rule)
    np.testing.assert_array_equal(
        wp.from_paddle(paddle.to_tensor([-1, 2], dtype="int32"), dtype=wp.uint32).numpy(),
        np.array([2**32 - 1, 2], np.uint32))
    np.testing.assert_array_equal(
        wp.from_paddle(paddle.to_tensor([True, False]), dtype=wp.uint8).numpy(), [1, 0])
    with pytest.raises(RuntimeError, match="Pair"):
        wp.to_paddle(wp.zeros(3, dtype=Pair, device="cpu"))


def test_remote_session_copies(tcp_weftd, run_client, paddle):
    run_client("""
        import numpy as np
        import paddle
        import weft as wp
        import weft._runtime as rt
        wp.init()
        assert not rt.get_runtime().local
        values = np.random.default_rng().standard_normal(20).astype(np.float32)
        a = wp.array(values, device="cpu")
        t = wp.to_paddle(a)
        assert np.array_equal(t.numpy(), values)
        t.scale_(2.0)                                  # a copy: the array is unchanged
        assert np.array_equal(a.numpy(), values)
        u = paddle.to_tensor(values * 3.0)
        b = wp.from_paddle(u)
        assert np.array_equal(b.numpy(), values * 3.0)
        bf = wp.array(np.array([1.5, -2.25, 3.0], np.float32), dtype=wp.bfloat16, device="cpu")
        tb = wp.to_paddle(bf)
        assert tb.dtype == paddle.bfloat16
        assert tb.astype(paddle.float32).numpy().tolist() == [1.5, -2.25, 3.0]
        back = wp.from_paddle(tb)
        assert back.dtype is wp.bfloat16
        assert np.asarray(back.numpy(), dtype=np.float32).tolist() == [1.5, -2.25, 3.0]
        print("OK")
    """, env={"WEFT_ADDRESS": tcp_weftd.address, "WEFT_TOKEN": tcp_weftd.token}, timeout=180)
