"""weft._launch_frame (clients/python/native/launch_frame.c), the C path of wp.launch's common
case: for every argument kind it takes it builds the bytes the Python path builds
(weft/_kernel/launch.py launch_frame_bytes over _pack_fast's fields), byte for byte; for every
argument it does not take it answers None (and the Python path converts or raises); hostile
calls (garbage specs, wrong types, an argument whose attribute reads change the argument list)
raise or answer None, never crash; and launches through it compute what they should. Skipped
with the reason when the module was not built (no Python development headers)."""
import importlib
import math

import numpy as np
import pytest

import weft as wp_module
from weft import _runtime

launch_mod = importlib.import_module("weft._kernel.launch")


@pytest.fixture
def native(wp):
    module = launch_mod._native_module()
    if module is None:
        pytest.skip("weft._launch_frame is not built (Python development headers missing) or "
                    "WEFT_NATIVE_LAUNCH=0")
    return module


@wp_module.kernel
def frame_all_kinds(a: wp_module.array(dtype=float), b: wp_module.array(dtype=wp_module.int32, ndim=2),
                    f32: float, f64: wp_module.float64, i8: wp_module.int8, u8: wp_module.uint8,
                    i16: wp_module.int16, u16: wp_module.uint16, i32: int, u32: wp_module.uint32,
                    i64: wp_module.int64, u64: wp_module.uint64):
    i = wp_module.tid()
    a[i] = f32 + float(f64) + float(i8) + float(u8) + float(i16) + float(u16) + float(i32) + \
        float(u32) + float(i64) + float(u64) + float(b[0, 0])


@wp_module.kernel
def frame_saxpy(x: wp_module.array(dtype=float), y: wp_module.array(dtype=float), alpha: float):
    i = wp_module.tid()
    y[i] = alpha * x[i] + y[i]


@wp_module.kernel
def frame_vec(a: wp_module.array(dtype=float), v: wp_module.vec3):
    a[wp_module.tid()] = v[0]


_RANGES = {"i8": (-2**7, 2**7 - 1), "u8": (0, 2**8 - 1), "i16": (-2**15, 2**15 - 1),
           "u16": (0, 2**16 - 1), "i32": (-2**31, 2**31 - 1), "u32": (0, 2**32 - 1),
           "i64": (-2**63, 2**63 - 1), "u64": (0, 2**64 - 1)}


def _plan(wp, kernel, device="cpu"):
    return launch_mod._launch_plan(kernel, device, _runtime.get_runtime(), 1)


def _python_frame(kernel, plan, dims, args, device, origin_field):
    """The Python path's bytes for the same launch (None: it would not take the fast path
    for every argument)."""
    packed, packer, resolved, fields = launch_mod._pack_fast(kernel, plan, device, args)
    if packer is not None:
        return None
    return launch_mod.launch_frame_bytes(plan.template_bytes, dims, fields, origin_field)


def _random_args(wp, rng, a, b):
    vals = {}
    for name, (lo, hi) in _RANGES.items():
        pick = int(rng.integers(0, 5))
        vals[name] = (lo, hi, 0, int(rng.integers(lo, hi, dtype=np.int64 if hi < 2**63 else np.uint64)),
                      (lo + hi) // 2)[pick]
    f32 = float(rng.choice([rng.normal() * 10.0 ** rng.integers(-40, 38), 0.0, -0.0, math.inf,
                            -math.inf, 3.4028234663852886e38, 1e-45, int(rng.integers(-1000, 1000))]))
    f64 = rng.choice([rng.normal() * 10.0 ** rng.integers(-300, 300), math.nan, -math.inf, 5e-324])
    f64 = float(f64) if rng.integers(0, 4) else int(rng.integers(-(1 << 62), 1 << 62))
    return [a, b, f32, f64, vals["i8"], vals["u8"], vals["i16"], vals["u16"], vals["i32"],
            vals["u32"], vals["i64"], vals["u64"]]


def test_c_frames_are_the_python_frames_byte_for_byte(wp, native):
    """Random arguments of every scalar kind at their range ends, zero, signed zeros, float32
    infinities, its largest and smallest values, ints passed for floats, and dimensions whose
    varints take 1 to 6 bytes: the C bytes equal the Python path's and parse to the launch."""
    from weft.v1 import exec_pb2

    rng = np.random.default_rng()
    a = wp.array(rng.normal(size=64).astype(np.float32), device="cpu")
    b = wp.array(rng.integers(-9, 9, (4, 4)).astype(np.int32), device="cpu")
    plan = _plan(wp, frame_all_kinds)
    assert plan.native is not None
    assert native.frame(plan.native, [1], _random_args(wp, rng, a, b), "cpu", b"") is None  # not cached yet
    launch_mod._array_arg(a)             # what the first launch of an array caches
    launch_mod._array_arg(b)
    origin_field = launch_mod._field(launch_mod._COMMAND_ORIGIN, b"\x0a\x04f.py\x10\x07")
    checked = 0
    for _ in range(400):
        args = _random_args(wp, rng, a, b)
        dims = [int(d) for d in rng.choice([1, 64, 127, 128, 16384, 1 << 21, 1 << 35],
                                           int(rng.integers(1, 5)))]
        c_frame = native.frame(plan.native, dims, args, "cpu", origin_field)
        py_frame = _python_frame(frame_all_kinds, plan, dims, args, "cpu", origin_field)
        if py_frame is None:              # float32 overflow: the packer's conversion
            assert c_frame is None and not math.isfinite(np.float32(args[2]))
            continue
        assert c_frame == py_frame
        cmd = exec_pb2.SubmitRequest.FromString(c_frame).commands[0]
        assert list(cmd.launch.dim) == dims and len(cmd.launch.args) == 12
        assert cmd.launch.args[0].array.handle == a._handle
        checked += 1
    assert checked >= 300


def test_c_path_declines_what_the_python_path_converts_or_rejects(wp, native):
    """None (the Python path decides) for a bool or NumPy integer where an int is asked, a value
    outside the parameter's range, a float32 NaN or overflow, a NumPy scalar, an array of
    another dtype, ndim or device, a NumPy array, None, an array whose cached field is stale,
    a ctypes descriptor of no weft array or of one that does not match, the wrong argument count, and dimensions that are negative,
    not ints, empty or too many; the launches those arguments make through wp.launch raise the
    Python path's errors or convert as before."""
    rng = np.random.default_rng()
    a = wp.array(rng.normal(size=64).astype(np.float32), device="cpu")
    b = wp.array(rng.integers(-9, 9, (4, 4)).astype(np.int32), device="cpu")
    plan = _plan(wp, frame_all_kinds)
    origin_field = launch_mod._field(launch_mod._COMMAND_ORIGIN, b"")
    good = [a, b, 1.5, 2.5, 1, 2, 3, 4, 5, 6, 7, 8]
    launch_mod._array_arg(a)
    launch_mod._array_arg(b)
    assert native.frame(plan.native, [64], good, "cpu", origin_field) is not None

    def declines(index, value):
        args = list(good)
        args[index] = value
        return native.frame(plan.native, [64], args, "cpu", origin_field) is None

    for name_index, (lo, hi) in zip(range(4, 12), _RANGES.values()):
        assert declines(name_index, lo - 1) and declines(name_index, hi + 1)
        assert declines(name_index, True) and declines(name_index, np.int32(1))
        assert declines(name_index, 1.0)
    assert declines(2, math.nan) and declines(2, 1e39) and declines(2, -1e39)
    assert declines(2, np.float32(1.0)) and declines(2, 10 ** 400) and declines(2, "1")
    assert declines(3, np.float64(1.0)) and declines(3, 10 ** 400)
    assert declines(0, wp.zeros(64, dtype=wp.float64, device="cpu"))
    assert declines(0, wp.zeros((8, 8), dtype=float, device="cpu"))
    assert declines(1, wp.zeros(16, dtype=wp.int32, device="cpu"))
    assert declines(0, np.zeros(64, np.float32)) and declines(0, None)
    # an array's ctypes descriptor stands for its array, which replaces it in the list
    args = list(good)
    args[0] = a.__ctype__()
    assert native.frame(plan.native, [64], args, "cpu", origin_field) == \
        native.frame(plan.native, [64], good, "cpu", origin_field)
    assert args[0] is a
    wide = wp.zeros(64, dtype=wp.float64, device="cpu")
    assert declines(0, wide.__ctype__())                       # its array's dtype is not float32
    bare = type(a.__ctype__())()                               # describes no weft array
    args[0] = bare
    assert native.frame(plan.native, [64], args, "cpu", origin_field) is None and args[0] is bare
    assert native.frame(plan.native, [64], good, "cuda:0", origin_field) is None   # a's device
    stale = wp.array(rng.normal(size=64).astype(np.float32), device="cpu")
    launch_mod._array_arg(stale)                                 # cached
    stale.__dict__["_byte_offset"] = 4                           # no longer what the cache says
    assert declines(0, stale)
    for dims in ([-1], [1.0], [], [1] * 9, (64,), [1 << 64]):
        assert native.frame(plan.native, dims, good, "cpu", origin_field) is None
    assert native.frame(plan.native, [64], good[:-1], "cpu", origin_field) is None
    assert native.frame(plan.native, [64], tuple(good), "cpu", origin_field) is None

    # through wp.launch: the Python path's conversions and errors
    out = wp.zeros(64, dtype=float, device="cpu")
    wp.launch(frame_all_kinds, dim=64, inputs=[out, b, np.float32(0.5), 0.5, True, 0, 0, 0, 0, 0, 0, 0],
              device="cpu")
    np.testing.assert_allclose(out.numpy(), 2.0 + b.numpy()[0, 0])
    wp.launch(frame_all_kinds, dim=64, inputs=[out, b, 0.0, 0.0, 200, 0, 0, 0, 0, 0, 0, 0], device="cpu")
    np.testing.assert_allclose(out.numpy(), -56.0 + b.numpy()[0, 0])    # wrapped, as Warp's ctypes
    with pytest.raises(Exception, match="'a'"):
        wp.launch(frame_all_kinds, dim=64, inputs=[wp.zeros(64, dtype=wp.float64, device="cpu"), b,
                                                   0.0, 0.0, 0, 0, 0, 0, 0, 0, 0, 0], device="cpu")


def test_c_path_survives_hostile_calls(wp, native):
    """Specs of the wrong shape or kind raise TypeError/ValueError; frame() with the wrong
    number or types of arguments raises TypeError or answers None; an argument whose attribute
    reads empty the argument list and drop its own references mid-call answers without a
    crash."""
    for bad in ([("x",)], [(9,)], [(1, 5, 1)], [(4, 3, 0, 1)], [(4, 8, -1, 1 << 70)], [None], 5):
        with pytest.raises((TypeError, ValueError)):
            native.spec(b"", bad)
    with pytest.raises(TypeError):
        native.spec("not bytes", [])
    spec = native.spec(b"\x12\x01k", [(1, "float32", 1), (2,)])
    with pytest.raises(TypeError):
        native.frame(spec, [1], [])
    with pytest.raises((TypeError, ValueError)):
        native.frame(object(), [1], [], "cpu", b"")
    assert native.frame(spec, [1], [1, 2.0], "cpu", b"") is None
    assert native.frame(spec, [1], [None, 2.0], 5, b"") is None
    assert native.frame(spec, [1], [None, 2.0], "cpu", "str") is None

    args = []

    class Sneaky(wp.array):
        """An array whose `shape` read empties the launch's argument list."""

        @property
        def shape(self):
            args.clear()
            return self.__dict__["_sneaky_shape"]

    real = wp.zeros(8, dtype=float, device="cpu")
    sneaky = Sneaky.__new__(Sneaky)
    sneaky.__dict__.update(real.__dict__)
    sneaky.__dict__["_sneaky_shape"] = real.shape
    sneaky.__dict__.pop(launch_mod._REF_ATTR, None)
    cached = launch_mod._array_arg(real)
    sneaky.__dict__[launch_mod._REF_ATTR] = (cached[0], cached[1], real.shape) + cached[3:]
    args.extend([sneaky, 2.0])
    assert native.frame(spec, [1], args, "cpu", b"") is None    # the list lost its arguments
    assert args == []


def test_launches_through_the_c_path_compute_saxpy(wp, native, device):
    """saxpy through the C path (checked taken) against a float64 reference on hard values
    (huge, tiny, mixed signs), and a vector parameter's kernel through the Python path."""
    rng = np.random.default_rng()
    n = 4099
    x = (rng.normal(size=n) * 10.0 ** rng.integers(-30, 30, n)).astype(np.float32)
    y = (rng.normal(size=n) * 10.0 ** rng.integers(-30, 30, n)).astype(np.float32)
    alpha = float(rng.normal() * 1e3)
    xa, ya = wp.array(x, device=device), wp.array(y, device=device)
    plan = _plan(wp, frame_saxpy, device)
    wp.launch(frame_saxpy, dim=n, inputs=[xa, ya, alpha], device=device)   # caches the fields
    built = []
    frame = launch_mod._NATIVE.frame

    def spy(*a):
        got = frame(*a)
        built.append(got)
        return got

    launch_mod._NATIVE.frame = spy
    try:
        wp.launch(frame_saxpy, dim=n, inputs=[xa, ya, alpha], device=device)
    finally:
        launch_mod._NATIVE.frame = frame
    assert plan.native is not None and len(built) == 1 and built[0] is not None
    ref = y.astype(np.float64)
    for _ in range(2):
        ref = np.float64(np.float32(alpha)) * x.astype(np.float64) + ref
    got = ya.numpy().astype(np.float64)
    scale = np.abs(ref) + 2 * np.abs(np.float32(alpha) * x.astype(np.float64)) + np.abs(y)
    assert np.all(np.abs(got - ref) <= 4e-7 * scale + 1e-38)
    a = wp.zeros(16, dtype=float, device=device)
    assert _plan(wp, frame_vec, device).native is None             # a vector: the Python path
    wp.launch(frame_vec, dim=16, inputs=[a, wp.vec3(2.5, 0.0, 0.0)], device=device)
    np.testing.assert_array_equal(a.numpy(), 2.5)
