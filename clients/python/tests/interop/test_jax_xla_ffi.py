"""weft's XLA FFI targets (weft/interop/xla_ffi.py, weft/interop/jax_ffi.py).

On the CPU, through JAX's real XLA FFI machinery: register_ffi_callback targets called with
jax.ffi.ffi_call inside jax.jit (weft kernels launched on XLA's buffers, against float64 NumPy
references on fresh random data), attributes of every kind XLA encodes, an exception in the
callback, weft's refusal of a wrong rank or element shape and a jax_kernel target's refusal of a
wrong dtype or shape becoming JAX errors with their messages, re-registration, jax_kernel /
jax_callable going through their FFI target (handler counter; vmap methods, in-out arrays,
zeroed outputs).
Attack tests: hand-made call frames (absurd rank, dimensions, counts, dtype codes, struct
sizes, attribute lengths, a dictionary attribute that contains itself) are refused with an XLA
error made through the frame's API table, the Python function never called; the metadata query
is answered without the command-buffer trait.
On a GPU (skipped with the reason where JAX has no CUDA device, weftd no GPU, or this client no
CUDA IPC): Warp's register_ffi_callback pattern (scale_kernel over a float array and a vec2
array), jax_kernel on JAX's CUDA buffers through the handler without host copies, a JAX op
consuming the kernel's output inside the same jit (ordering), and 100 calls on fresh data
(no stale reads)."""
import ctypes

import numpy as np
import pytest

import weft as wp
from weft.interop import jax_ffi, xla_ffi
from weft.jax_experimental.ffi import register_ffi_callback


@wp.kernel
def scale_kernel(a: wp.array(dtype=float), s: float, output: wp.array(dtype=float)):
    tid = wp.tid()
    output[tid] = a[tid] * s


@wp.kernel
def scale_vec_kernel(a: wp.array(dtype=wp.vec2), s: float, output: wp.array(dtype=wp.vec2)):
    tid = wp.tid()
    output[tid] = a[tid] * s


@wp.kernel
def sin_plus(a: wp.array(dtype=float), b: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = wp.sin(a[i]) + b[i]


def _names(request, stem):
    return f"weft_test_{stem}_{abs(hash(request.node.nodeid)) % 10**8}"


def _scale_callback(inputs, outputs, attrs, ctx):
    """Warp's example callback: float and vec2 arrays scaled by the attribute `scale`."""
    a, b = inputs
    c, d = outputs
    s = attrs["scale"]
    device = "cpu" if ctx.platform == "cpu" else f"cuda:{ctx.device_ordinal or 0}"
    stream = wp.Stream(device, cuda_stream=ctx.stream) if ctx.platform == "cuda" else None
    with wp.ScopedStream(stream):
        wp.launch(scale_kernel, dim=a.shape, inputs=[a, s], outputs=[c], device=device)
        wp.launch(scale_vec_kernel, dim=b.shape[0], inputs=[b, s], outputs=[d], device=device)


# ---- CPU: the real XLA FFI machinery --------------------------------------------------------


def _scale_case(jax, rng, name, sizes, put, rounds=1):
    """_scale_callback registered as `name` and called under jax.jit on fresh random inputs
    (an array of n floats and one of n/2 pairs, n drawn from `sizes`, placed by `put`), each
    round on new data through the same executable; checks both results against float64."""
    jnp = jax.numpy
    register_ffi_callback(name, _scale_callback)
    n = 2 * int(rng.integers(*sizes))
    s = float(rng.uniform(0.5, 3.0))
    s32 = np.float64(np.float32(s))
    call = jax.ffi.ffi_call(name, (jax.ShapeDtypeStruct((n,), jnp.float32),
                                   jax.ShapeDtypeStruct((n // 2, 2), jnp.float32)))
    f = jax.jit(lambda x, y: call(x, y, scale=np.float32(s)))
    for _ in range(rounds):
        a = rng.standard_normal(n).astype(np.float32)
        b = rng.standard_normal((n // 2, 2)).astype(np.float32)
        c, d = f(put(a), put(b))
        np.testing.assert_allclose(np.asarray(c), a.astype(np.float64) * s32, rtol=1e-6)
        np.testing.assert_allclose(np.asarray(d), b.astype(np.float64) * s32, rtol=1e-6)


def test_callback_launches_weft_kernels_on_xla_buffers(jax, rng, request):
    _scale_case(jax, rng, _names(request, "scale"), (8, 300), jax.numpy.asarray, rounds=2)


def test_attributes_of_every_kind(jax, request):
    jnp = jax.numpy
    name = _names(request, "attrs")
    seen = {}

    def record(inputs, outputs, attrs, ctx):
        seen.update(attrs=attrs, ctx=ctx, shapes=[(i.shape, i.dtype) for i in inputs])
        outputs[0].numpy()[...] = inputs[0].numpy()

    xla_ffi.register_ffi_callback(name, record)
    call = jax.ffi.ffi_call(name, jax.ShapeDtypeStruct((3,), jnp.float32))
    attrs = dict(f32=np.float32(1.5), f64=np.float64(-2.25), i32=np.int32(-7), i64=np.int64(2**40),
                 u8=np.uint8(200), flag=True, off=False, text="weft ✓",
                 ints=np.array([1, -2, 3], dtype=np.int64), floats=np.array([0.5, 4.0], dtype=np.float32),
                 nested={"k": np.int32(5), "name": "deep"})
    jax.block_until_ready(jax.jit(lambda x: call(x, **attrs))(jnp.zeros(3, jnp.float32)))
    got = seen["attrs"]
    assert got["f32"] == 1.5 and got["f64"] == -2.25 and got["i32"] == -7 and got["i64"] == 2**40
    assert got["u8"] == 200
    assert got["flag"] is True and got["off"] is False
    assert got["text"] == "weft ✓"
    assert got["ints"].dtype == np.int64 and got["ints"].tolist() == [1, -2, 3]
    assert got["floats"].dtype == np.float32 and got["floats"].tolist() == [0.5, 4.0]
    assert got["nested"] == {"k": 5, "name": "deep"}
    assert seen["ctx"].platform == "cpu" and seen["ctx"].stream is None
    assert seen["shapes"] == [((3,), np.dtype(np.float32))]


def test_an_exception_in_the_callback_is_a_jax_error(jax, request):
    jnp = jax.numpy
    name = _names(request, "raises")

    def fail(inputs, outputs, attrs, ctx):
        raise ValueError(f"refused value {attrs['code']}")

    xla_ffi.register_ffi_callback(name, fail)
    call = jax.ffi.ffi_call(name, jax.ShapeDtypeStruct((4,), jnp.float32))
    with pytest.raises(Exception, match=r"ValueError: refused value 17"):
        jax.block_until_ready(jax.jit(lambda x: call(x, code=np.int32(17)))(jnp.ones(4, jnp.float32)))
    # the target still works afterwards
    ok = _names(request, "after")
    xla_ffi.register_ffi_callback(ok, lambda i, o, a, c: o[0].numpy().__setitem__(..., 1.0))
    out = jax.jit(jax.ffi.ffi_call(ok, jax.ShapeDtypeStruct((4,), jnp.float32)))(jnp.ones(4, jnp.float32))
    np.testing.assert_array_equal(np.asarray(out), np.ones(4, np.float32))


def test_wrong_dtype_and_rank_are_refused_with_weft_messages(jax, request):
    jnp = jax.numpy
    name = _names(request, "wrong")
    xla_ffi.register_ffi_callback(name, lambda i, o, a, c: wp.launch(
        a["kernel"] == "vec" and scale_vec_kernel or scale_kernel, dim=i[0].shape[0], inputs=[i[0], 2.0],
        outputs=[o[0]], device="cpu"))
    call = jax.ffi.ffi_call(name, jax.ShapeDtypeStruct((6,), jnp.float32))
    with pytest.raises(Exception, match=r"argument 'a'.*dimension"):
        jax.block_until_ready(jax.jit(lambda x: call(x, kernel="scalar"))(jnp.ones((6, 2), jnp.float32)))
    with pytest.raises(Exception, match=r"argument 'a'.*vec\(2,float32\).*trailing dimensions must be \(2,\)"):
        jax.block_until_ready(jax.jit(lambda x: call(x, kernel="vec"))(jnp.ones(6, jnp.float32)))
    # a jax_kernel's own target, called with buffers its settings do not describe
    k = wp.jax_kernel(scale_kernel)
    x = jnp.ones(5, jnp.float32)
    jax.block_until_ready(jax.jit(lambda v: k(v, 2.0))(x))        # registers the target
    target = k._ffi_name
    bad = jax.ffi.ffi_call(target, jax.ShapeDtypeStruct((5,), jnp.float32))
    with pytest.raises(Exception, match=r"input 0: dtype float64, expected float32"):
        jax.block_until_ready(jax.jit(lambda v: bad(v, weft_call=np.int64(0)))(jnp.ones(5, jnp.float64)))
    with pytest.raises(Exception, match=r"input 0: shape \(4,\), expected \(5,\)"):
        jax.block_until_ready(jax.jit(lambda v: bad(v, weft_call=np.int64(0)))(jnp.ones(4, jnp.float32)))
    with pytest.raises(Exception, match=r"names no settings of this wrapper"):
        jax.block_until_ready(jax.jit(lambda v: bad(v, weft_call=np.int64(10**6)))(x))


def test_registering_a_name_again_replaces_the_function(jax, request):
    jnp = jax.numpy
    name = _names(request, "again")
    xla_ffi.register_ffi_callback(name, lambda i, o, a, c: o[0].numpy().__setitem__(..., 1.0))
    call = jax.jit(jax.ffi.ffi_call(name, jax.ShapeDtypeStruct((2,), jnp.float32)))
    assert np.asarray(call(jnp.zeros(2, jnp.float32))).tolist() == [1.0, 1.0]
    xla_ffi.register_ffi_callback(name, lambda i, o, a, c: o[0].numpy().__setitem__(..., 2.0))
    call = jax.jit(jax.ffi.ffi_call(name, jax.ShapeDtypeStruct((2,), jnp.float32)))
    assert np.asarray(call(jnp.ones(2, jnp.float32))).tolist() == [2.0, 2.0]
    with pytest.raises(TypeError):
        xla_ffi.register_ffi_callback("", lambda *a: None)
    with pytest.raises(TypeError):
        xla_ffi.register_ffi_callback(name, None)


def test_jax_kernel_and_callable_run_through_the_ffi_target_on_the_cpu(jax, rng):
    jnp = jax.numpy
    n = int(rng.integers(20, 500))
    a = rng.standard_normal(n).astype(np.float32)
    b = rng.standard_normal(n).astype(np.float32)
    k = wp.jax_kernel(sin_plus)
    before = jax_ffi.FFI_CALLS["cpu"]
    (out,) = jax.jit(k)(jnp.asarray(a), jnp.asarray(b))
    np.testing.assert_allclose(np.asarray(out), np.sin(a.astype(np.float64)) + b, rtol=1e-6, atol=1e-6)
    assert jax_ffi.FFI_CALLS["cpu"] == before + 1

    def twice_sin_plus(x: wp.array(dtype=float), y: wp.array(dtype=float), z: wp.array(dtype=float)):
        wp.launch(sin_plus, dim=x.shape, inputs=[x, y], outputs=[z], device="cpu")
        wp.launch(sin_plus, dim=x.shape, inputs=[z, y], outputs=[z], device="cpu")

    c = wp.jax_callable(twice_sin_plus)
    (z,) = jax.jit(c)(jnp.asarray(a), jnp.asarray(b))
    ref = np.sin(np.sin(a.astype(np.float64)) + b) + b
    np.testing.assert_allclose(np.asarray(z), ref, rtol=2e-6, atol=2e-6)
    assert jax_ffi.FFI_CALLS["cpu"] == before + 2


def test_vmap_methods_and_in_out_arrays_through_the_handler(jax, rng):
    """The handler's batch loop: broadcast_all, expand_dims (unbatched inputs keep a size-1
    axis), sequential_unrolled (one call per element), and in-out arrays aliased under vmap."""
    jnp = jax.numpy
    a = rng.standard_normal((3, 50)).astype(np.float32)
    b = rng.standard_normal(50).astype(np.float32)
    ref = np.sin(a.astype(np.float64)) + b
    for method in ("broadcast_all", "expand_dims", "sequential_unrolled"):
        k = wp.jax_kernel(sin_plus, vmap_method=method)
        before = jax_ffi.FFI_CALLS["cpu"]
        (out,) = jax.jit(jax.vmap(k, in_axes=(0, None)))(jnp.asarray(a), jnp.asarray(b))
        np.testing.assert_allclose(np.asarray(out), ref, rtol=1e-6, atol=1e-6, err_msg=method)
        assert jax_ffi.FFI_CALLS["cpu"] == before + (3 if method == "sequential_unrolled" else 1), method

    @wp.kernel
    def add_into(x: wp.array(dtype=float), acc: wp.array(dtype=float), twice: wp.array(dtype=float)):
        i = wp.tid()
        acc[i] = acc[i] + x[i]
        twice[i] = 2.0 * x[i]

    acc = rng.standard_normal((3, 50)).astype(np.float32)
    k = wp.jax_kernel(add_into, num_outputs=2, in_out_argnames=["acc"])
    new_acc, twice = jax.jit(jax.vmap(k))(jnp.asarray(a), jnp.asarray(acc))
    np.testing.assert_allclose(np.asarray(new_acc), acc.astype(np.float64) + a, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(twice), 2.0 * a, rtol=1e-7)


def test_outputs_start_zeroed(jax):
    jnp = jax.numpy

    @wp.kernel
    def every_other(a: wp.array(dtype=float), out: wp.array(dtype=float)):
        i = wp.tid()
        if i % 2 == 0:
            out[i] = a[i]

    k = wp.jax_kernel(every_other)
    for _ in range(3):        # XLA reuses buffers between calls; the odd elements stay zero
        (out,) = jax.jit(k)(jnp.full(8, 3.0, jnp.float32))
        assert np.asarray(out).tolist() == [3.0, 0.0] * 4


# ---- attack tests: hand-made call frames ------------------------------------------------------


class _FakeApi:
    """An XLA_FFI_Api table whose Error_Create records (code, message) and returns a marker
    pointer, and whose Stream_Get answers a fixed stream."""

    MARK = 0xE770

    def __init__(self, size=None):
        self.errors = []

        def create(args):
            self.errors.append((int(args.contents.errc), args.contents.message.decode()))
            return self.MARK

        def stream_get(args):
            args.contents.stream = 0x5EED
            return None

        self._create = xla_ffi._ERROR_CREATE(create)
        self._stream = xla_ffi._STREAM_GET(stream_get)
        self.api = xla_ffi.Api()
        self.api.struct_size = ctypes.sizeof(xla_ffi.Api) if size is None else size
        self.api.Error_Create = ctypes.cast(self._create, ctypes.c_void_p).value
        self.api.Stream_Get = ctypes.cast(self._stream, ctypes.c_void_p).value


class _Frame:
    """A call frame with one input buffer, one output buffer and the given attributes."""

    def __init__(self, api, rank=1, dims=(4,), dtype=11, attrs=None):
        self.keep = []
        self.data = (ctypes.c_float * 64)()
        self.dims = (ctypes.c_int64 * max(len(dims), 1))(*dims) if dims else None
        self.inp = xla_ffi.Buffer(xla_ffi.BUFFER_SIZE, None, dtype, ctypes.addressof(self.data), rank,
                                  ctypes.addressof(self.dims) if self.dims is not None else None)
        self.out_dims = (ctypes.c_int64 * 1)(4)
        self.out = xla_ffi.Buffer(xla_ffi.BUFFER_SIZE, None, 11, ctypes.addressof(self.data), 1,
                                  ctypes.addressof(self.out_dims))
        self.arg_types = (ctypes.c_int * 1)(xla_ffi.ARG_BUFFER)
        self.arg_ptrs = (ctypes.c_void_p * 1)(ctypes.addressof(self.inp))
        self.ret_types = (ctypes.c_int * 1)(xla_ffi.RET_BUFFER)
        self.ret_ptrs = (ctypes.c_void_p * 1)(ctypes.addressof(self.out))
        self.frame = xla_ffi.CallFrame()
        f = self.frame
        f.struct_size = xla_ffi.CALL_FRAME_SIZE
        f.api = ctypes.addressof(api.api)
        f.stage = xla_ffi.STAGE_EXECUTE
        f.args = xla_ffi.Args(xla_ffi.ARGS_SIZE, None, 1, ctypes.addressof(self.arg_types),
                              ctypes.addressof(self.arg_ptrs))
        f.rets = xla_ffi.Rets(xla_ffi.RETS_SIZE, None, 1, ctypes.addressof(self.ret_types),
                              ctypes.addressof(self.ret_ptrs))
        f.attrs = attrs if attrs is not None else xla_ffi.Attrs(xla_ffi.ATTRS_SIZE, None, 0, None, None, None)

    @property
    def address(self):
        return ctypes.addressof(self.frame)


def _attrs(entries, keep):
    """An XLA_FFI_Attrs of (kind, name, value address) entries."""
    n = len(entries)
    types = (ctypes.c_int * max(n, 1))(*[e[0] for e in entries])
    spans = [xla_ffi.ByteSpan(ctypes.cast(ctypes.c_char_p(e[1]), ctypes.c_void_p).value, len(e[1]))
             for e in entries]
    names = (ctypes.c_void_p * max(n, 1))(*[ctypes.addressof(s) for s in spans])
    values = (ctypes.c_void_p * max(n, 1))(*[e[2] for e in entries])
    keep.extend([types, spans, names, values, entries])
    return xla_ffi.Attrs(xla_ffi.ATTRS_SIZE, None, n, ctypes.addressof(types), ctypes.addressof(names),
                         ctypes.addressof(values))


@pytest.fixture
def handler():
    calls = []
    api = _FakeApi()
    h = xla_ffi.make_handler(lambda i, o, a, c: calls.append((i, o, a, c)), "cpu", "attack")
    return h, api, calls


def _refused(h, api, calls, frame, pattern):
    assert h(frame.address) == _FakeApi.MARK
    assert not calls, "the Python function ran on a refused frame"
    import re
    code, message = api.errors[-1]
    assert re.search(pattern, message), message
    assert message.startswith("attack: ")
    return code


def test_a_good_hand_made_frame_runs(handler):
    h, api, calls = handler
    frame = _Frame(api)
    assert h(frame.address) is None
    (inputs, outputs, attrs, ctx), = calls
    assert inputs[0].shape == (4,) and inputs[0].dtype == np.float32 and not inputs[0].writable
    assert outputs[0].writable and attrs == {} and ctx.platform == "cpu"
    cuda = xla_ffi.make_handler(lambda i, o, a, c: calls.append(c), "cuda", "attack")
    assert cuda(frame.address) is None
    assert calls[-1].stream == 0x5EED


@pytest.mark.parametrize("rank,dims,dtype,pattern", [
    (1000, (4,), 11, r"rank 1000 \(0 to 64\)"),
    (-1, (4,), 11, r"rank -1"),
    (3, (2**40, 2**40, 2**40), 11, r"larger than"),
    (2, (2**62, 2**62), 11, r"larger than"),
    (1, (-5,), 11, r"negative dimension"),
    (2, (), 11, r"rank 2 and no dimensions"),
    (1, (4,), 99, r"dtype code 99"),
    (1, (4,), 17, r"dtype code 17"),          # TOKEN
])
def test_absurd_buffers_are_refused(handler, rank, dims, dtype, pattern):
    h, api, calls = handler
    code = _refused(h, api, calls, _Frame(api, rank=rank, dims=dims, dtype=dtype), pattern)
    assert code in (xla_ffi.ERROR_INVALID_ARGUMENT, xla_ffi.ERROR_OUT_OF_RANGE)


def test_absurd_frames_are_refused(handler):
    h, api, calls = handler
    frame = _Frame(api)
    frame.frame.struct_size = 8
    _refused(h, api, calls, frame, r"XLA_FFI_CallFrame has struct_size 8")
    frame = _Frame(api)
    frame.frame.args.size = 10**12
    _refused(h, api, calls, frame, r"1000000000000 arguments")
    frame = _Frame(api)
    frame.frame.args.size = -3
    _refused(h, api, calls, frame, r"-3 arguments")
    frame = _Frame(api)
    frame.frame.args.args = None
    _refused(h, api, calls, frame, r"arguments is a null pointer")
    frame = _Frame(api)
    frame.arg_types[0] = 7
    _refused(h, api, calls, frame, r"argument 0 has kind 7")
    frame = _Frame(api)
    frame.arg_ptrs[0] = None
    _refused(h, api, calls, frame, r"argument 0 is a null pointer")
    frame = _Frame(api)
    frame.inp.struct_size = 16
    _refused(h, api, calls, frame, r"XLA_FFI_Buffer\) has struct_size 16")
    frame = _Frame(api)
    frame.inp.data = None
    _refused(h, api, calls, frame, r"null data pointer")
    frame = _Frame(api)
    frame.frame.stage = 1
    _refused(h, api, calls, frame, r"stage 1")
    frame = _Frame(api)
    frame.frame.rets.struct_size = 3
    _refused(h, api, calls, frame, r"results \(XLA_FFI_Rets\) has struct_size 3")


def test_absurd_attributes_are_refused(handler):
    h, api, calls = handler
    keep = []
    huge = xla_ffi.ByteSpan(ctypes.addressof(ctypes.create_string_buffer(8)), 2**40)
    keep.append(huge)
    frame = _Frame(api, attrs=_attrs([(xla_ffi.ATTR_STRING, b"s", ctypes.addressof(huge))], keep))
    _refused(h, api, calls, frame, r"attribute 's': 1099511627776 bytes")
    big = xla_ffi.Array(5, 2**50, ctypes.addressof(ctypes.create_string_buffer(8)))
    keep.append(big)
    frame = _Frame(api, attrs=_attrs([(xla_ffi.ATTR_ARRAY, b"arr", ctypes.addressof(big))], keep))
    _refused(h, api, calls, frame, r"'arr': 1125899906842624 elements")
    odd = xla_ffi.Scalar(77, ctypes.addressof(ctypes.c_int64(1)))
    keep.append(odd)
    frame = _Frame(api, attrs=_attrs([(xla_ffi.ATTR_SCALAR, b"x", ctypes.addressof(odd))], keep))
    _refused(h, api, calls, frame, r"'x': unsupported scalar dtype code 77")
    frame = _Frame(api, attrs=_attrs([(9, b"what", ctypes.addressof(odd))], keep))
    _refused(h, api, calls, frame, r"unknown attribute kind 9")
    frame = _Frame(api, attrs=_attrs([(xla_ffi.ATTR_SCALAR, b"nul", None)], keep))
    _refused(h, api, calls, frame, r"'nul': null scalar")
    # a dictionary that contains itself
    loop_types = (ctypes.c_int * 1)(xla_ffi.ATTR_DICTIONARY)
    loop_name = xla_ffi.ByteSpan(ctypes.cast(ctypes.c_char_p(b"d"), ctypes.c_void_p).value, 1)
    loop_names = (ctypes.c_void_p * 1)(ctypes.addressof(loop_name))
    loop_values = (ctypes.c_void_p * 1)()
    loop = xla_ffi.Attrs(xla_ffi.ATTRS_SIZE, None, 1, ctypes.addressof(loop_types),
                         ctypes.addressof(loop_names), ctypes.addressof(loop_values))
    loop_values[0] = ctypes.addressof(loop)
    keep.extend([loop_types, loop_name, loop_names, loop_values, loop])
    frame = _Frame(api, attrs=xla_ffi.Attrs(xla_ffi.ATTRS_SIZE, None, 1, ctypes.addressof(loop_types),
                                            ctypes.addressof(loop_names), ctypes.addressof(loop_values)))
    _refused(h, api, calls, frame, r"nested deeper than 16")
    frame = _Frame(api, attrs=xla_ffi.Attrs(xla_ffi.ATTRS_SIZE, None, 5000, None, None, None))
    _refused(h, api, calls, frame, r"5000 attributes")


def test_exceptions_and_bad_api_tables_never_raise_through_ctypes(capfd):
    api = _FakeApi()

    def boom(*_):
        raise KeyboardInterrupt

    h = xla_ffi.make_handler(boom, "cpu", "attack")
    frame = _Frame(api)
    assert h(frame.address) == _FakeApi.MARK
    assert api.errors[-1][1] == "attack: KeyboardInterrupt"
    assert api.errors[-1][0] == xla_ffi.ERROR_UNKNOWN
    small = _FakeApi(size=16)                   # no room for XLA_FFI_Error_Create
    frame = _Frame(small)
    assert h(frame.address) is None and not small.errors
    assert "cannot report an error to XLA" in capfd.readouterr().err
    assert h(0) is None
    # CUDA: a table without Stream_Get is refused with a message, not a crash
    no_stream = _FakeApi(size=xla_ffi.struct_size(xla_ffi.Api, "Handler_Register"))
    cuda = xla_ffi.make_handler(lambda *a: None, "cuda", "attack")
    assert cuda(_Frame(no_stream).address) == _FakeApi.MARK
    assert "no XLA_FFI_Stream_Get" in no_stream.errors[-1][1]


def test_the_metadata_query_is_answered_without_the_command_buffer_trait():
    api = _FakeApi()
    calls = []
    h = xla_ffi.make_handler(lambda *a: calls.append(a), "cuda", "meta")
    metadata = xla_ffi.Metadata()
    metadata.struct_size = xla_ffi.METADATA_SIZE
    metadata.traits = 0xFFFF
    extension = xla_ffi.MetadataExtension()
    extension.extension_base.struct_size = xla_ffi.METADATA_EXTENSION_SIZE
    extension.extension_base.type = xla_ffi.EXTENSION_METADATA
    extension.metadata = ctypes.addressof(metadata)
    frame = _Frame(api)
    frame.frame.extension_start = ctypes.addressof(extension)
    assert h(frame.address) is None and not calls and not api.errors
    assert metadata.traits == 0
    assert (metadata.api_version.major_version, metadata.api_version.minor_version) == \
        (xla_ffi.API_MAJOR, xla_ffi.API_MINOR)
    assert metadata.api_version.struct_size == xla_ffi.API_VERSION_SIZE
    metadata.struct_size = 4                    # an XLA whose metadata struct this handler overruns
    assert h(frame.address) == _FakeApi.MARK
    assert "XLA_FFI_Metadata has struct_size 4" in api.errors[-1][1]
    extension.metadata = None
    metadata.struct_size = xla_ffi.METADATA_SIZE
    assert h(frame.address) == _FakeApi.MARK
    assert "without metadata" in api.errors[-1][1]


# ---- GPU: JAX's CUDA buffers --------------------------------------------------------------


@pytest.fixture
def no_host_copies(monkeypatch, jgpu):
    """weft's host transfers of framework GPU memory fail the test while it runs (probes of
    the stream ordering made first)."""
    from weft import _cuda_ipc, _runtime
    from weft.interop import cuda_order

    cuda_order.enabled(_runtime.get_runtime(), {0})

    def refuse(*_args, **_kwargs):
        raise AssertionError("a host copy of GPU memory")

    monkeypatch.setattr(_cuda_ipc, "copy_to_host", refuse)
    monkeypatch.setattr(_cuda_ipc, "copy_from_host", refuse)


def test_gpu_register_ffi_callback_warp_pattern(jgpu, rng, request):
    jax, gpu, _ = jgpu
    before = jax_ffi.FFI_CALLS["cuda"]
    _scale_case(jax, rng, _names(request, "gpu_scale"), (64, 4096),
                lambda v: jax.device_put(v, gpu))
    assert jax_ffi.FFI_CALLS["cuda"] == before      # register_ffi_callback: not a jax_kernel


def test_gpu_jax_kernel_runs_through_the_handler_without_host_copies(jgpu, rng, no_host_copies):
    jax, gpu, _ = jgpu
    n = int(rng.integers(1000, 100_000))
    a = rng.standard_normal(n).astype(np.float32)
    b = rng.standard_normal(n).astype(np.float32)
    k = wp.jax_kernel(sin_plus)
    before = jax_ffi.FFI_CALLS["cuda"]
    (out,) = jax.jit(k)(jax.device_put(a, gpu), jax.device_put(b, gpu))
    out.block_until_ready()
    assert jax_ffi.FFI_CALLS["cuda"] == before + 1
    assert out.devices() == {gpu}
    np.testing.assert_allclose(np.asarray(out), np.sin(a.astype(np.float64)) + b, rtol=1e-5, atol=1e-6)


def test_gpu_a_jax_op_right_after_the_kernel_sees_its_output(jgpu, rng, no_host_copies):
    jax, gpu, _ = jgpu
    jnp = jax.numpy
    n = 1 << 20
    a = rng.standard_normal(n).astype(np.float32)
    b = rng.standard_normal(n).astype(np.float32)
    k = wp.jax_kernel(sin_plus)

    @jax.jit
    def chain(x, y):
        x = x * 3.0                            # XLA work before: the kernel must see it
        (z,) = k(x, y)
        (w,) = k(z, z * 0.5)                   # kernel after kernel, through XLA
        return jnp.cumsum(w) - 2.0 * w         # XLA work after: must see the kernel's output

    got = np.asarray(chain(jax.device_put(a, gpu), jax.device_put(b, gpu)))
    x = 3.0 * a.astype(np.float64)
    z = np.sin(x) + b
    w = np.sin(z) + 0.5 * z
    ref = np.cumsum(w) - 2.0 * w
    np.testing.assert_allclose(got, ref, rtol=1e-3, atol=1e-2 * np.sqrt(n))
    np.testing.assert_allclose(got[:1000], ref[:1000], rtol=1e-4, atol=1e-3)


def test_gpu_100_calls_on_fresh_data_never_read_stale_values(jgpu, rng, no_host_copies):
    jax, gpu, _ = jgpu
    k = wp.jax_kernel(sin_plus)
    f = jax.jit(lambda x, y: k(x * 1.0, y)[0] + 1.0)
    n = 4096
    before = jax_ffi.FFI_CALLS["cuda"]
    for i in range(100):
        a = rng.standard_normal(n).astype(np.float32) + i
        b = rng.standard_normal(n).astype(np.float32)
        got = np.asarray(f(jax.device_put(a, gpu), jax.device_put(b, gpu)))
        np.testing.assert_allclose(got, np.sin(a.astype(np.float64)) + b + 1.0, rtol=1e-5, atol=1e-5,
                                   err_msg=f"call {i}")
    assert jax_ffi.FFI_CALLS["cuda"] == before + 100
