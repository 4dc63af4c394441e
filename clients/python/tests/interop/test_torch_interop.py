"""PyTorch interop on the CPU: to_torch zero-copy (same data pointer, writes seen both ways),
from_torch of weft-made tensors zero-copy and of other tensors by moving their storage into a
slab once, gradients shared both ways (.grad is one allocation), dtype/device helpers, tensors
as launch arguments, streams on the CPU, and the errors (unsupported dtypes, element layout,
GPU tensors on a CPU launch)."""
import numpy as np
import pytest

import weft as wp


@wp.kernel
def square_sum(x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    wp.atomic_add(out, 0, x[i] * x[i])


@wp.kernel
def double_vec(v: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = 2.0 * v[i]


def test_dtype_and_device_helpers(wp, torch):
    pairs = [(torch.float16, wp.float16), (torch.float32, wp.float32), (torch.float64, wp.float64),
             (torch.int8, wp.int8), (torch.int16, wp.int16), (torch.int32, wp.int32),
             (torch.int64, wp.int64), (torch.uint8, wp.uint8), (torch.bool, wp.bool),
             (torch.bfloat16, wp.bfloat16)]
    for t, w in pairs:
        assert wp.dtype_from_torch(t) is w
        assert wp.dtype_to_torch(w) is t
    assert wp.dtype_to_torch(wp.vec3) is torch.float32
    with pytest.raises(TypeError, match="unsupported"):
        wp.dtype_from_torch(torch.complex64)
    assert wp.device_from_torch("cpu") == wp.get_device("cpu")
    assert wp.device_from_torch(torch.device("cpu")).is_cpu
    assert wp.device_to_torch("cpu") == "cpu"


def test_to_torch_is_zero_copy(wp, torch, rng):
    values = rng.standard_normal((10, 3)).astype(np.float32)
    a = wp.array(values, dtype=wp.vec3, device="cpu")
    t = wp.to_torch(a)
    assert t.shape == (10, 3) and t.dtype == torch.float32 and t.data_ptr() == a.ptr
    t[4] = torch.tensor([1.0, 2.0, 3.0])                 # Torch -> weft
    np.testing.assert_array_equal(a.numpy()[4], [1.0, 2.0, 3.0])
    out = wp.zeros(10, dtype=wp.vec3, device="cpu")
    to = wp.to_torch(out)
    wp.launch(double_vec, dim=10, inputs=[a, out], device="cpu")   # weft -> Torch
    expected = 2.0 * a.numpy().astype(np.float64)
    np.testing.assert_allclose(to.numpy(), expected, rtol=1e-6)


def test_from_torch_of_weft_tensor_is_the_same_memory(wp, torch, rng):
    a = wp.array(rng.standard_normal(12).astype(np.float32), device="cpu")
    t = wp.to_torch(a)
    b = wp.from_torch(t)
    assert b.ptr == a.ptr and b._handle == a._handle
    c = wp.from_torch(t[3:9])                            # a view of it: still in place
    assert c.ptr == a.ptr + 12 and c.shape == (6,)


def test_from_torch_moves_foreign_tensor_into_a_slab(wp, torch, rng):
    values = rng.standard_normal(50).astype(np.float32)
    t = torch.tensor(values)
    before = t.data_ptr()
    a = wp.from_torch(t)
    assert t.data_ptr() == a.ptr != before               # the tensor now lives in the slab
    np.testing.assert_array_equal(t.numpy(), values)
    t.mul_(2.0)                                          # Torch writes reach the kernel
    out = wp.zeros(1, dtype=float, device="cpu")
    wp.launch(square_sum, dim=50, inputs=[a, out], device="cpu")
    np.testing.assert_allclose(out.numpy()[0], np.sum((2.0 * values.astype(np.float64)) ** 2),
                               rtol=1e-5)
    assert wp.from_torch(t).ptr == a.ptr                 # later conversions are zero-copy


def test_gradients_are_shared_both_ways(wp, torch, rng):
    values = rng.standard_normal(40).astype(np.float32)
    x = torch.tensor(values, requires_grad=True)
    wx = wp.from_torch(x)
    assert wx.requires_grad and x.grad is not None
    assert x.grad.data_ptr() == wx.grad.ptr
    loss = wp.zeros(1, dtype=float, device="cpu", requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(square_sum, dim=40, inputs=[wx, loss], device="cpu")
    tape.backward(loss=loss)
    np.testing.assert_allclose(x.grad.numpy(), 2.0 * values.astype(np.float64), rtol=1e-6)
    # and from weft to Torch: to_torch(requires_grad) gives .grad over the array's gradient
    a = wp.array(values, device="cpu", requires_grad=True)
    ta = wp.to_torch(a)
    assert ta.requires_grad and ta.grad.data_ptr() == a.grad.ptr
    (ta * 3.0).sum().backward()                          # Torch accumulates into weft memory
    np.testing.assert_allclose(a.grad.numpy(), np.full(40, 3.0))


def test_existing_torch_grad_is_moved_and_kept(wp, torch, rng):
    x = torch.zeros(8, requires_grad=True)
    x.grad = torch.full((8,), 0.5)
    wx = wp.from_torch(x)
    assert x.grad.data_ptr() == wx.grad.ptr
    np.testing.assert_array_equal(wx.grad.numpy(), np.full(8, 0.5))


def test_torch_tensors_as_launch_arguments(wp, torch, rng):
    v = torch.tensor(rng.standard_normal((7, 3)).astype(np.float32))
    out = torch.zeros((7, 3))
    wp.launch(double_vec, dim=7, inputs=[v, out], device="cpu")
    np.testing.assert_allclose(out.numpy(), 2.0 * v.numpy().astype(np.float64), rtol=1e-6)


def test_streams_are_cuda_objects(wp, torch):
    with pytest.raises(RuntimeError, match="CUDA objects"):
        wp.stream_to_torch("cpu")


def test_errors(wp, torch):
    with pytest.raises(Exception, match="unsupported"):
        wp.from_torch(torch.zeros(3, dtype=torch.complex64))
    with pytest.raises(Exception, match=r"trailing dimensions must be \(3,\)"):
        wp.from_torch(torch.zeros(4, 2), dtype=wp.vec3)
    with pytest.raises(Exception, match="not contiguous"):
        wp.from_torch(torch.zeros(4, 6)[:, ::2], dtype=wp.vec3)
    with pytest.raises(Exception, match="incompatible dtypes"):
        wp.from_torch(torch.zeros(4, 3, dtype=torch.float64), dtype=wp.vec3)
    with pytest.raises(TypeError, match="torch.Tensor"):
        wp.from_torch(np.zeros(3))
    # a device weft does not have (Torch's meta device): clear errors, never a read
    meta = torch.zeros(3, device="meta")
    with pytest.raises(Exception, match="meta, which has no weft counterpart"):
        wp.from_torch(meta)
    out = wp.zeros(1, dtype=float, device="cpu")
    with pytest.raises(Exception, match="lives on meta but the kernel is launched on cpu"):
        wp.launch(square_sum, dim=3, inputs=[meta, out], device="cpu")


@wp.kernel
def square64(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64)):
    i = wp.tid()
    y[i] = x[i] * x[i]


def test_a_tensor_with_views_is_not_moved(wp, torch, rng):
    """A CPU tensor whose storage other tensors share (a view) keeps its memory: converting it
    copies, so writes through the view reach the next conversion (gradcheck writes each
    grad_output through a flat view of it)."""
    base = torch.from_numpy(rng.standard_normal(6))
    flat = base.view(-1)
    a = wp.from_torch(base)
    assert base.untyped_storage().data_ptr() == flat.untyped_storage().data_ptr()
    flat[2] = 123.5
    assert base[2].item() == 123.5
    np.testing.assert_array_equal(wp.from_torch(base).numpy(), base.numpy())
    np.testing.assert_array_equal(a.numpy()[[0, 1, 3]], base.numpy()[[0, 1, 3]])


def test_tape_backed_autograd_function_passes_gradcheck(wp, torch):
    class Square(torch.autograd.Function):
        @staticmethod
        def forward(ctx, x):
            xw = wp.from_torch(x.detach(), dtype=wp.float64, requires_grad=True)
            yw = wp.zeros(x.shape[0], dtype=wp.float64, device=xw.device, requires_grad=True)
            tape = wp.Tape()
            with tape:
                wp.launch(square64, dim=x.shape[0], inputs=[xw], outputs=[yw], device=xw.device)
            ctx.tape, ctx.xw, ctx.yw = tape, xw, yw
            return wp.to_torch(yw, requires_grad=False)

        @staticmethod
        def backward(ctx, adj_y):
            ctx.tape.backward(grads={ctx.yw: wp.from_torch(adj_y, dtype=wp.float64)})
            adj_x = wp.to_torch(ctx.xw.grad, requires_grad=False).clone()
            ctx.tape.zero()
            return adj_x

    x = torch.tensor([1.0, -2.0, 3.0e3, 1.0e-4], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(Square.apply, (x,), eps=1e-6, atol=1e-5)


def test_launch_writes_reach_a_tensor_with_views(wp, torch, rng):
    v = torch.tensor(rng.standard_normal((7, 3)).astype(np.float32))
    out = torch.zeros((7, 3))
    rows = out.view(21)                        # shares the storage: `out` is copied, not moved
    wp.launch(double_vec, dim=7, inputs=[v, out], device="cpu")
    np.testing.assert_allclose(out.numpy(), 2.0 * v.numpy().astype(np.float64), rtol=1e-6)
    np.testing.assert_array_equal(rows.numpy(), out.numpy().reshape(21))


@wp.kernel
def bf16_scale(x: wp.array(dtype=wp.bfloat16), out: wp.array(dtype=wp.float32)):
    i = wp.tid()
    out[i] = wp.float32(x[i]) * 2.0
    x[i] = wp.bfloat16(-1.0)


def test_bfloat16_both_ways_zero_copy(wp, torch, rng):
    values = rng.standard_normal(16).astype(np.float32) * 1e3
    t = torch.tensor(values, dtype=torch.bfloat16)
    a = wp.from_torch(t)
    assert a.dtype is wp.bfloat16 and a.ptr == t.data_ptr()     # the tensor moved into a slab
    out = wp.zeros(16, dtype=wp.float32)
    wp.launch(bf16_scale, dim=16, inputs=[a, out])
    ref = torch.tensor(values, dtype=torch.bfloat16).double().numpy()   # values as bfloat16 holds them
    np.testing.assert_array_equal(out.numpy(), (2.0 * ref).astype(np.float32))
    np.testing.assert_array_equal(t.float().numpy(), -1.0)                # the kernel's writes, in Torch
    b = wp.array(values, dtype=wp.types.vector(4, wp.bfloat16))
    tb = wp.to_torch(b)
    assert tb.dtype == torch.bfloat16 and tuple(tb.shape) == (4, 4) and tb.data_ptr() == b.ptr
    np.testing.assert_array_equal(tb.double().numpy().reshape(-1), ref)
    assert wp.dtype_from_torch(torch.bfloat16) is wp.bfloat16 and wp.dtype_to_torch(wp.bfloat16) == torch.bfloat16


def test_from_torch_retain_grad(wp, torch):
    t = torch.zeros(10, requires_grad=True)
    assert wp.from_torch(t, requires_grad=True, retain_grad=True).retain_grad
    assert not wp.from_torch(t, requires_grad=True).retain_grad
    with pytest.raises(ValueError, match="requires requires_grad"):
        wp.from_torch(torch.zeros(3), requires_grad=False, retain_grad=True)


@wp.kernel
def affine(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = 0.5 - 2.0 * x[i]


def test_copies_of_shared_tensors_stay_in_step_around_launches(wp, torch, rng):
    """from_torch of a tensor whose storage it cannot move (a view, `y.detach()` beside `y`)
    copies; a launch taking the copy first copies in what Torch wrote since (its version counter
    moved), then writes its results back into the tensor's memory, seen through every tensor
    sharing it, without moving Torch's version counter (as a kernel writing shared memory
    would). Against float64."""
    x = torch.tensor((rng.standard_normal(16) * 10.0 ** rng.integers(-3, 4, 16)).astype(np.float32))
    xv = x[2:10]                       # a view: copied
    y = torch.full((8,), -7.0)
    yd = y.detach()                    # shares y's storage: copied
    ax, ay = wp.from_torch(xv), wp.from_torch(yd)
    assert ay.ptr != y.data_ptr()
    version = y._version

    def expect(src):
        want = 0.5 - 2.0 * src.numpy().astype(np.float64)
        np.testing.assert_allclose(y.numpy(), want, rtol=2e-7, atol=1e-7)
        np.testing.assert_array_equal(yd.numpy(), y.numpy())

    wp.launch(affine, dim=8, inputs=[ax], outputs=[ay])
    expect(xv)
    assert y._version == version
    with torch.no_grad():
        x.mul_(3.0)                    # Torch writes the viewed memory in place
    wp.launch(affine, dim=8, inputs=[ax], outputs=[ay])
    expect(xv)
    # Warp's descriptor form takes the same path
    wp.launch(affine, dim=8, inputs=[wp.from_torch(xv, return_ctype=True)],
              outputs=[wp.from_torch(yd, return_ctype=True)])
    expect(xv)


def test_custom_autograd_function_over_detached_tensors(wp, torch):
    """Warp's custom-op pattern: forward writes into `y.detach()`, backward launches the adjoint
    into fresh tensors; the output and x.grad are Torch's (0.5 - 2x, -2)."""

    class Op(torch.autograd.Function):
        @staticmethod
        def forward(ctx, x):
            y = torch.empty_like(x)
            ctx.x, ctx.y = x.detach(), y.detach()
            wp.launch(affine, dim=len(x), inputs=[wp.from_torch(ctx.x)], outputs=[wp.from_torch(ctx.y)])
            return y

        @staticmethod
        def backward(ctx, adj_y):
            adj_x = torch.zeros_like(ctx.x)
            wp.launch(affine, dim=len(ctx.x), inputs=[wp.from_torch(ctx.x)], outputs=[wp.from_torch(ctx.y)],
                      adj_inputs=[wp.from_torch(adj_x)], adj_outputs=[wp.from_torch(adj_y)], adjoint=True)
            return adj_x

    x = torch.linspace(-3.0, 5.0, 16, requires_grad=True)
    y = Op.apply(x)
    np.testing.assert_allclose(y.detach().numpy(), 0.5 - 2.0 * x.detach().numpy().astype(np.float64), rtol=1e-6)
    y.sum().backward()
    np.testing.assert_array_equal(x.grad.numpy(), np.full(16, -2.0, dtype=np.float32))


def test_from_torch_return_ctype_is_warps_descriptor(wp, torch):
    """from_torch(..., return_ctype=True) gives Warp's array_t: the data address is the tensor's
    (its storage moved into weft memory), grad the explicit gradient's (a tensor or a weft
    array), shape and byte strides; a launch takes it as the array."""
    import ctypes

    for dt in (torch.float64, torch.float32, torch.float16, torch.int64, torch.int8, torch.uint8, torch.bool):
        t = torch.zeros(10, dtype=dt)
        a = wp.from_torch(t, return_ctype=True)
        size = ctypes.sizeof(wp.dtype_from_torch(dt)._type_)
        assert (a.data, a.grad, a.ndim, a.shape[0], a.strides[0]) == (t.data_ptr(), 0, 1, 10, size)
    t, g = torch.zeros((10, 2)), torch.zeros((10, 2))
    a = wp.from_torch(t, dtype=wp.vec2, grad=g, return_ctype=True)
    assert (a.data, a.grad, a.shape[0], a.strides[0]) == (t.data_ptr(), g.data_ptr(), 10, 8)
    ga = wp.zeros(10, dtype=wp.vec2)
    a = wp.from_torch(torch.zeros((10, 2)), dtype=wp.vec2, grad=ga, return_ctype=True)
    assert a.grad == ga.ptr
    with pytest.raises(ValueError, match="the gradient array has shape"):
        wp.from_torch(torch.zeros((10, 2)), dtype=wp.vec2, grad=wp.zeros(9, dtype=wp.vec2))


def test_bfloat16_copies_stay_in_step_too(wp, torch, rng):
    """The same for a bfloat16 view (weft reads and writes its bits): the kernel's writes reach
    the base tensor, Torch's later writes reach the next launch."""
    base = torch.tensor(rng.standard_normal(12).astype(np.float32) * 100.0, dtype=torch.bfloat16)
    view = base[2:10]
    a = wp.from_torch(view)
    out = wp.zeros(8, dtype=wp.float32)
    want = view.float().numpy().copy()
    wp.launch(bf16_scale, dim=8, inputs=[a, out])
    np.testing.assert_array_equal(out.numpy(), 2.0 * want)
    np.testing.assert_array_equal(base[2:10].float().numpy(), np.full(8, -1.0, dtype=np.float32))
    with torch.no_grad():
        base[2:10] = 3.0
    wp.launch(bf16_scale, dim=8, inputs=[a, out])
    np.testing.assert_array_equal(out.numpy(), np.full(8, 6.0, dtype=np.float32))


def test_launch_takes_descriptors_like_their_arrays(wp, torch, rng):
    """A launch given array_t descriptors (from_torch(..., return_ctype=True), a.__ctype__()) runs
    on their arrays, in the cached fast path as in the first launch, and refuses a descriptor of
    the wrong dtype with the array's own message."""
    x0 = rng.standard_normal(64).astype(np.float32) * np.float32(1e4)
    x, y = torch.tensor(x0), torch.zeros(64)
    for _ in range(3):                     # the first launch resolves, the later ones are cached
        wp.launch(affine, dim=64, inputs=[wp.from_torch(x, return_ctype=True)],
                  outputs=[wp.from_torch(y, return_ctype=True)])
        np.testing.assert_allclose(y.numpy(), 0.5 - 2.0 * x0.astype(np.float64), rtol=1e-6)
    w = wp.zeros(64, dtype=float)
    wp.launch(affine, dim=64, inputs=[wp.from_torch(x).__ctype__()], outputs=[w.__ctype__()])
    np.testing.assert_allclose(w.numpy(), 0.5 - 2.0 * x0.astype(np.float64), rtol=1e-6)
    wrong = wp.zeros(64, dtype=wp.float64)
    with pytest.raises(Exception) as by_array:
        wp.launch(affine, dim=64, inputs=[wrong], outputs=[w])
    with pytest.raises(Exception) as by_descriptor:
        wp.launch(affine, dim=64, inputs=[wrong.__ctype__()], outputs=[w])
    assert str(by_descriptor.value) == str(by_array.value) and "dtype" in str(by_array.value)


@pytest.fixture(params=["c", "python"])
def descriptor_lookup(request, monkeypatch):
    """The remembered-descriptor look-up of from_torch(return_ctype=True) in C
    (weft._torch_descriptor, skipped where it was not built) and in Python."""
    from weft.interop import torch as weft_torch

    if request.param == "c":
        if weft_torch._native_descriptor() is None:
            pytest.skip("weft._torch_descriptor is not built (Python development headers "
                        "missing) or WEFT_NATIVE_DESCRIPTOR=0")
    else:
        monkeypatch.setattr(weft_torch, "_NATIVE_DESCRIPTOR", None)
    return request.param


def test_cpu_descriptors_converted_again_follow_the_tensor(wp, torch, rng, descriptor_lookup,
                                                          descriptors_follow_the_tensor):
    """from_torch(return_ctype=True) of a CPU tensor converted before copies the remembered
    descriptor (as for CUDA tensors): a new object with the bytes a fresh conversion makes,
    taken by launches like its array; once the tensor changes (re-pointed, resized, another
    dtype asked for, a gradient set or asked for), the descriptor says so."""
    values = (rng.standard_normal(4096) * 10.0 ** rng.uniform(-15, 15, 4096)).astype(np.float32)
    t = torch.tensor(values)
    descs = [wp.from_torch(t, return_ctype=True) for _ in range(4)]
    assert len({id(d) for d in descs}) == 4
    assert {bytes(d) for d in descs} == {bytes(descs[0])}
    assert descs[-1].data == t.data_ptr() and descs[-1].shape[0] == 4096
    assert "_weft_last_ctype" in t.__dict__, "the descriptor was not remembered on the tensor"
    fresh = wp.from_torch(t).__ctype__()
    assert bytes(fresh) == bytes(descs[-1])
    total = wp.zeros(1, dtype=float, device="cpu")
    for d in descs:
        wp.launch(square_sum, dim=4096, inputs=[d, total], device="cpu")
    expected = 4.0 * np.sum(values.astype(np.float64) ** 2)
    # float32 atomic sums of 4 x 4096 terms in any order: within n * eps of the float64 sum
    assert abs(float(total.numpy()[0]) - expected) <= 4 * 4096 * 6e-8 * expected
    descriptors_follow_the_tensor(t, values, "cpu")


def test_the_c_descriptor_lookup_answers_as_the_python_one(wp, torch, rng):
    """weft._torch_descriptor.remembered against _last_descriptor, tensor by tensor: both give a
    new descriptor with the same bytes and array while the conversion holds, both None once
    the tensor changed (re-pointed, resized, requires_grad set, another dtype asked for, its
    array given a gradient); entries it did not write (junk under the names the
    client uses), a tensor whose methods raise and a non-tensor give None without raising."""
    from weft._runtime import get_runtime
    from weft.interop import torch as weft_torch

    native = weft_torch._native_descriptor()
    if native is None:
        pytest.skip("weft._torch_descriptor is not built or WEFT_NATIVE_DESCRIPTOR=0")

    def python(t, dtype=None, requires_grad=None):
        d = t.__dict__
        entry = d.get(weft_torch._LAST_CTYPE)
        return weft_torch._last_descriptor(t, d, entry, dtype, requires_grad) if entry else None

    def agree(t, dtype=None, requires_grad=None):
        c = native(t, dtype, requires_grad, get_runtime)
        p = python(t, dtype, requires_grad)
        assert (c is None) == (p is None)
        if c is not None:
            assert c is not p and bytes(c) == bytes(p) and c._weft_value is p._weft_value
        return c

    def converted(values):
        t = torch.tensor(values)
        wp.from_torch(t, return_ctype=True), wp.from_torch(t, return_ctype=True)
        return t

    values = (rng.standard_normal(64) * 10.0 ** rng.uniform(-30, 30, 64)).astype(np.float32)
    t = converted(values)
    d = agree(t)
    assert d is not None and d.data == t.data_ptr() and d.shape[0] == 64
    assert agree(t, requires_grad=True) is None
    assert agree(t, dtype=wp.float32) is None               # another dtype asked for: a new key
    t.resize_(32)
    assert agree(t) is None
    t = converted(values)
    t.set_(torch.tensor(values[:5]))
    assert agree(t) is None
    t = converted(values)
    t.requires_grad_(True)
    assert agree(t) is None
    assert agree(t, requires_grad=False) is not None       # asked for without: it holds
    t = converted(values)
    array = t.__dict__[weft_torch._LAST_CTYPE][0][1]
    array.grad = wp.zeros(64, dtype=float, device="cpu")
    assert agree(t) is None
    array.grad = None
    assert agree(t) is not None

    t = converted(values)
    entry = t.__dict__[weft_torch._LAST_CTYPE]
    for junk in ("junk", (1, 2), (entry[0], entry[1], 5), (None, entry[1], entry[2]),
                 ((1, 2, 3), entry[1], entry[2])):
        t.__dict__[weft_torch._LAST_CTYPE] = junk
        assert native(t, None, None, get_runtime) is None
    t.__dict__[weft_torch._LAST_CTYPE] = entry
    t.__dict__[entry[2]] = ("not", "the entry")
    assert native(t, None, None, get_runtime) is None

    class Raising:
        def __init__(self, entry):
            self._weft_last_ctype = entry
            self._weft_cpu_array = entry[0]
            self.requires_grad = False

        def data_ptr(self):
            raise RuntimeError("a tensor that raises")

    good = converted(values).__dict__[weft_torch._LAST_CTYPE]
    assert native(Raising(good), None, None, get_runtime) is None

    class Replacing:
        """Forwards a tensor's facts, but its requires_grad drops the remembered entries from
        its __dict__ (and frees them) while the look-up is under way."""
        def __init__(self, t):
            self._t = t
            self.__dict__.update(t.__dict__)
            self.shape, self.dtype = t.shape, t.dtype

        @property
        def requires_grad(self):
            for name in list(self.__dict__):
                if name.startswith("_weft_"):
                    del self.__dict__[name]
            t.__dict__.clear()
            import gc
            gc.collect()
            return False

        def data_ptr(self):
            return self._t.data_ptr()

        def stride(self):
            return self._t.stride()

    t = converted(values)
    expected = bytes(wp.from_torch(t, return_ctype=True))
    d = native(Replacing(t), None, None, get_runtime)
    assert d is not None and bytes(d) == expected           # what was read stayed alive
    assert native(42, None, None, get_runtime) is None
    with pytest.raises(TypeError):
        native(t, None, None, "not callable")
    with pytest.raises(TypeError):
        native(t, None, None)
