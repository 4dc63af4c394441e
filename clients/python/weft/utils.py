"""wp.utils: Warp's Python-scope helpers: ScopedTimer, transform_expand, and the array algorithms array_scan,
array_sum, array_inner, array_cast, radix_sort_pairs, segmented_sort_pairs and
runlength_encode. The algorithms wait for the arrays' pending commands, compute on the arrays'
contents (zero-copy NumPy views for local CPU arrays) and write the results back into the
output arrays; they check their arguments with Warp's messages."""
from __future__ import annotations

import functools
import inspect
import operator
import threading
import time

import numpy as np

__all__ = ["ScopedLogLevel", "ScopedLogger", "ScopedTimer", "array_cast", "array_inner", "array_scan", "array_sum",
           "radix_sort_pairs", "runlength_encode", "segmented_sort_pairs", "transform_expand"]


def transform_expand(t):
    """A transform (float32) from a flat sequence of 7 values: position, then quaternion
    (x, y, z, w), as Warp's helper."""
    from .types import transformf  # noqa: PLC0415 - weft.types imports this module's package

    values = [float(x) for x in t]
    if len(values) != 7:
        raise ValueError(f"transform_expand expects 7 values (position, quaternion), got {len(values)}")
    return transformf(p=values[0:3], q=values[3:7])


class ScopedLogger:
    """`with wp.ScopedLogger(logger):` makes `logger` (None: the default one) the active logger
    (weft.logger) inside the block and restores the previous one after it."""

    def __init__(self, logger):
        from . import logger as _logger  # noqa: PLC0415

        if logger is not None:
            _logger._validate(logger)
        self.logger = logger

    def __enter__(self):
        from . import logger as _logger  # noqa: PLC0415

        self.saved = _logger.get_logger()
        _logger.set_logger(self.logger if self.logger is not None else _logger.LoggerBasic())
        return self

    def __exit__(self, exc_type, exc_value, traceback):
        from . import logger as _logger  # noqa: PLC0415

        # Assigned back without validation: a TypeError here would hide the block's exception.
        _logger._active_logger = self.saved


class ScopedLogLevel:
    """`with wp.ScopedLogLevel(level):` sets wp.config.log_level inside the block and restores it
    after."""

    def __init__(self, log_level: int):
        self.log_level = log_level

    def __enter__(self):
        from . import config  # noqa: PLC0415

        self.saved = config.log_level
        config.log_level = self.log_level
        return self

    def __exit__(self, exc_type, exc_value, traceback):
        from . import config  # noqa: PLC0415

        config.log_level = self.saved


class ScopedTimer:
    """`with wp.ScopedTimer("name"):` prints the block's wall time in ms (Warp's helper).
    synchronize=True waits for the daemon's commands before reading the clock. cuda_filter
    (TIMING_* flags) times the block's GPU operations (weft.timing): `timing_results` holds
    them after the block, and print=True prints them through report_func (timing_print)."""

    indent = -1
    enabled = True

    def __init__(self, name, active=True, print=True, detailed=False, dict=None,
                 use_nvtx=False, color="rapids", synchronize=False, cuda_filter=0,
                 report_func=None, skip_tape=False):
        self.name = name
        self.active = active and self.enabled
        self.print = print
        self.dict = dict
        self.synchronize = synchronize
        self.cuda_filter = cuda_filter
        self.report_func = report_func
        self.elapsed = 0.0
        self.timing_results = []
        if self.dict is not None and name not in self.dict:
            self.dict[name] = []

    def _sync(self):
        if self.synchronize:
            from .device import synchronize

            synchronize()

    def __enter__(self):
        if self.active:
            self._sync()
            if self.cuda_filter:
                from .timing import timing_begin  # noqa: PLC0415

                timing_begin(self.cuda_filter, synchronize=not self.synchronize)
            ScopedTimer.indent += 1
            self.start = time.perf_counter_ns()
        return self

    def __exit__(self, exc_type, exc_value, traceback):
        if not self.active:
            return
        sync_error = None   # raised after the scope is closed, never in place of the block's own
        try:
            self._sync()
        except Exception as error:  # noqa: BLE001
            sync_error = error
        self.elapsed = (time.perf_counter_ns() - self.start) / 1e6
        self.timing_results = []
        if self.cuda_filter:
            from .timing import timing_end  # noqa: PLC0415

            try:
                self.timing_results = timing_end(synchronize=not self.synchronize)
            except Exception as error:  # noqa: BLE001
                sync_error = sync_error or error
        if self.dict is not None:
            self.dict[self.name].append(self.elapsed)
        indent = "  " * ScopedTimer.indent
        if self.print and self.timing_results:
            if self.report_func is not None:
                self.report_func(self.timing_results, indent)
            else:
                from .timing import timing_print  # noqa: PLC0415

                timing_print(self.timing_results, indent)
        if self.print:   # through the active logger, whatever wp.config.log_level (as Warp)
            from .logger import get_logger  # noqa: PLC0415

            get_logger().info(f"{indent}{self.name} took {self.elapsed:.2f} ms")
        ScopedTimer.indent -= 1
        if sync_error is not None and exc_type is None:
            raise sync_error


# ------------------------------------------------------------------------------------------
# Array algorithms


def _types():
    from . import types  # noqa: PLC0415 - weft.types imports nothing from here

    return types


def _name(dtype) -> str:
    return _types().type_repr(dtype)


def _scalar(dtype):
    return getattr(dtype, "_wp_scalar_type_", dtype)


def _length(dtype) -> int:
    return int(getattr(dtype, "_length_", 1))


class _ChecksPassed(Exception):
    """Raised by _values while a captured call is only being checked (_capturable)."""


_checking = threading.local()


def _values(a) -> np.ndarray:
    """The array's elements as NumPy, components last (vec3 -> (..., 3))."""
    if getattr(_checking, "on", False):
        raise _ChecksPassed
    return np.asarray(a.numpy())


def _write(out, values) -> None:
    out.assign(np.asarray(values))


def _same_dtype(a, b) -> bool:
    t = _types()
    return t.type_str(a) == t.type_str(b)


def _captured_device(value) -> bool:
    from .graph import is_capturing  # noqa: PLC0415

    device = getattr(value, "device", None)
    return getattr(device, "alias", None) is not None and is_capturing(device)


def _capturable(name: str, host_value: str | None = None):
    """These algorithms run on the host (NumPy) in weft. While this thread captures a graph on
    the device of one of the call's arrays, the call is checked now (the function runs until it
    would first read an array: a bad argument raises here, as when Warp captures it) and becomes
    a host step of the graph (weft.graph.HostStep), run at its place in the graph's order by each
    wp.capture_launch. `host_value`: the argument that must then be given (without it the call
    returns a value on the host computed from data the graph has not produced yet)."""

    def wrap(fn):
        signature = inspect.signature(fn)

        @functools.wraps(fn)
        def call(*args, **kwargs):
            from . import _runtime  # noqa: PLC0415

            if not _runtime.get_runtime().captures:
                return fn(*args, **kwargs)
            bound = signature.bind(*args, **kwargs)
            if not any(_captured_device(v) for v in bound.arguments.values()):
                return fn(*args, **kwargs)
            if host_value is not None and bound.arguments.get(host_value) is None:
                raise RuntimeError(f"wp.utils.{name} without {host_value}= returns a value on the "
                                   f"host, which a graph cannot give: pass {host_value}= (an "
                                   f"array) inside a graph capture")
            from .graph import record_host_step  # noqa: PLC0415

            _checking.on = True
            try:
                result = fn(*args, **kwargs)
            except _ChecksPassed:
                record_host_step(f"wp.utils.{name}", functools.partial(fn, *args, **kwargs))
                return bound.arguments.get(host_value) if host_value else None
            finally:
                _checking.on = False
            return result                 # nothing to do (an empty count): no step

        return call

    return wrap


@_capturable("array_scan")
def array_scan(in_array, out_array, inclusive: bool = True) -> None:
    """Prefix sum of in_array into out_array (inclusive or exclusive), per vector component.
    int32, int64, float32, float64 and vectors of them."""
    if in_array.device != out_array.device:
        raise RuntimeError(f"In and out array storage devices do not match "
                           f"({in_array.device} vs {out_array.device})")
    if in_array.size != out_array.size:
        raise RuntimeError(f"In and out array storage sizes do not match "
                           f"({in_array.size} vs {out_array.size})")
    if not _same_dtype(in_array.dtype, out_array.dtype):
        raise RuntimeError(f"In and out array data types do not match "
                           f"({_name(in_array.dtype)} vs {_name(out_array.dtype)})")
    t = _types()
    if _scalar(in_array.dtype) not in (t.int32, t.int64, t.float32, t.float64):
        raise RuntimeError(f"Unsupported data type: {_name(in_array.dtype)}")
    if in_array.size == 0:
        return
    n = _length(in_array.dtype)
    flat = _values(in_array).reshape(in_array.size, n)
    result = np.cumsum(flat, axis=0, dtype=flat.dtype)
    if not inclusive:
        result = np.concatenate([np.zeros_like(result[:1]), result[:-1]])
    _write(out_array, result.reshape(_values(out_array).shape))


def _reduce_checks(name, dtype, out, expected_shape):
    t = _types()
    if _scalar(dtype) not in t.float_types:
        raise RuntimeError(f"Unsupported data type: {_name(dtype)}")
    if out is not None:
        if not _same_dtype(out.dtype, dtype):
            raise RuntimeError(f"out array should have type {_name(dtype)}")
        if tuple(out.shape) != tuple(expected_shape):
            raise RuntimeError(f"out array should have shape {tuple(expected_shape)}")


def _reduction_axis(name, axis, ndim):
    """Warp 1.19's rule: an int in [-ndim, ndim), negative counting from the last dimension."""
    if axis is None:
        return None
    axis = operator.index(axis)
    if axis < -ndim or axis >= ndim:
        raise IndexError(f"{name}() axis {axis} is out of bounds for an array with {ndim} dimensions")
    return axis % ndim


def _reduced_shape(shape, axis):
    """(1,) for a whole-array reduction; else the shape with the reduced axis kept at size 1."""
    if axis is None:
        return (1,)
    return tuple(1 if i == axis else n for i, n in enumerate(shape))


def _first(comp, axis, ndim, count):
    """The first `count` entries along `axis` (None: all) of comp (ndim leading dims)."""
    if count is None:
        return comp
    count = max(0, int(count))
    index = [slice(None)] * comp.ndim
    index[axis] = slice(0, count)
    return comp[tuple(index)]


@_capturable("array_sum", host_value="out")
def array_sum(values, out=None, value_count=None, axis=None):
    """Sum of a float array (of scalars or vectors): over all elements (the first value_count
    of them) or along `axis` (its first value_count entries; the result keeps the axis with
    size 1, as Warp 1.19). Returns the sum (a NumPy scalar or vector; an array along an axis),
    or writes it to out and returns out."""
    if out is not None and out.device != values.device:
        raise RuntimeError(f"out array storage device ({out.device}) does not match the values "
                           f"array ({values.device})")
    axis = _reduction_axis("array_sum", axis, values.ndim)
    shape = _reduced_shape(values.shape, axis)
    _reduce_checks("array_sum", values.dtype, out, shape)
    data = _values(values)
    n = _length(values.dtype)
    comp = data.reshape(tuple(values.shape) + ((n,) if n > 1 else ()))
    if axis is None:
        flat = comp.reshape((values.size,) + comp.shape[values.ndim:])
        flat = _first(flat, 0, 1, value_count)
        result = flat.sum(axis=0, dtype=comp.dtype).reshape((1,) + comp.shape[values.ndim:])
    else:
        part = _first(comp, axis, values.ndim, value_count)
        result = part.sum(axis=axis, keepdims=True, dtype=comp.dtype)
    if out is not None:
        _write(out, result.reshape(_values(out).shape))
        return out
    if axis is None:
        return result[0]     # as Warp's out.numpy()[0]: a NumPy scalar, or a NumPy vector
    from .array import array  # noqa: PLC0415

    return array(result, dtype=values.dtype, device=values.device)


@_capturable("array_inner", host_value="out")
def array_inner(a, b, out=None, count=None, axis=None):
    """Inner product of two float arrays of one shape and dtype (vectors: the sum of the
    componentwise products): over all elements (the first `count`) or along `axis` (its first
    `count` entries; the result keeps the axis with size 1, as Warp 1.19). Returns it, or
    writes it to out and returns out."""
    if tuple(a.shape) != tuple(b.shape):
        raise ValueError(f"array_inner() arguments must have the same shape, got "
                         f"{tuple(a.shape)} and {tuple(b.shape)}")
    if a.device != b.device:
        raise RuntimeError(f"A and b array storage devices do not match ({a.device} vs "
                           f"{b.device})")
    if out is not None and out.device != a.device:
        raise RuntimeError(f"out array storage device ({out.device}) does not match the "
                           f"input arrays ({a.device})")
    if not _same_dtype(a.dtype, b.dtype):
        raise RuntimeError(f"A and b array data types do not match ({_name(a.dtype)} vs "
                           f"{_name(b.dtype)})")
    scalar = _scalar(a.dtype)
    axis = _reduction_axis("array_inner", axis, a.ndim)
    shape = _reduced_shape(a.shape, axis)
    _reduce_checks("array_inner", a.dtype, None, shape)
    if out is not None:
        _reduce_checks("array_inner", scalar, out, shape)
    n = _length(a.dtype)
    x = _values(a).reshape(tuple(a.shape) + (n,))
    y = _values(b).reshape(tuple(b.shape) + (n,))
    products = (x * y).sum(axis=-1, dtype=x.dtype)
    if axis is None:
        products = _first(products.reshape(-1), 0, 1, count)
        result = products.sum(dtype=x.dtype).reshape(1)
    else:
        result = _first(products, axis, a.ndim, count).sum(axis=axis, keepdims=True, dtype=x.dtype)
    if out is not None:
        _write(out, result.reshape(_values(out).shape))
        return out
    if axis is None:
        return result[0]
    from .array import array  # noqa: PLC0415

    return array(result, dtype=scalar, device=a.device)


@_capturable("array_cast")
def array_cast(in_array, out_array, count=None) -> None:
    """Converts in_array's scalars to out_array's scalar type (C casts: floats truncate to
    ints). Arrays of several dimensions need one shape; 1-d arrays convert the first `count`
    elements (default: all of in_array), component by component."""
    if in_array.device != out_array.device:
        raise RuntimeError(f"Array storage devices do not match ({in_array.device} vs "
                           f"{out_array.device})")
    multi = in_array.ndim > 1 and out_array.ndim > 1
    if multi and tuple(in_array.shape) != tuple(out_array.shape):
        raise RuntimeError(f"Array shapes do not match ({tuple(in_array.shape)} vs "
                           f"{tuple(out_array.shape)})")
    if count is not None and (in_array.ndim > 1 or out_array.ndim > 1):
        raise RuntimeError("Partial cast is not supported for arrays with more than one "
                           "dimension")
    n_in = _length(in_array.dtype)
    n_out = _length(out_array.dtype)
    if count is None:
        count = in_array.size
    count = int(count)
    if count > in_array.size or count * n_in > out_array.size * n_out:
        raise RuntimeError(f"Cast count ({count}) exceeds the input size ({in_array.size}) or "
                           f"output size ({out_array.size})")
    if count == 0:
        return
    t = _types()
    src = _values(in_array).reshape(-1)[:count * n_in]
    target = np.dtype(t.np_scalar_dtype(_scalar(out_array.dtype)))
    converted = src.astype(target)
    if count * n_in == out_array.size * n_out:
        _write(out_array, converted.reshape(_values(out_array).shape))
        return
    current = np.array(_values(out_array)).reshape(-1)
    current[:count * n_in] = converted
    _write(out_array, current.reshape(_values(out_array).shape))


_SORT_KEYS = ("int32", "uint32", "float32", "int64", "uint64", "float64")


def _orderable(keys: np.ndarray) -> np.ndarray:
    """Keys as unsigned integers whose order is the keys' numeric order (radix-sort keys)."""
    bits = keys.dtype.itemsize * 8
    unsigned = np.dtype(f"uint{bits}")
    raw = keys.view(unsigned)
    sign = unsigned.type(1 << (bits - 1))
    if keys.dtype.kind == "i":
        return raw ^ sign
    if keys.dtype.kind == "f":
        negative = (raw & sign) != 0
        return np.where(negative, ~raw, raw | sign)
    return raw


def _check_contiguous(what, name, array, keys, values):
    if not array.is_contiguous:
        raise RuntimeError(f"{what}() requires a contiguous {name} array, got non-contiguous "
                           f"{name} with data types: {_name(keys.dtype)}, {_name(values.dtype)}")


@_capturable("radix_sort_pairs")
def radix_sort_pairs(keys, values, count: int, begin_bit: int = 0, end_bit=None) -> None:
    """Sorts the first `count` keys (stable, by bits [begin_bit, end_bit) of their numeric
    order) and moves the values with them. Like Warp's, both arrays must hold 2*count elements
    (the second half is scratch space)."""
    if keys.device != values.device:
        raise RuntimeError(f"Keys and values array storage devices do not match "
                           f"({keys.device} vs {values.device})")
    _check_contiguous("radix_sort_pairs", "keys", keys, keys, values)
    _check_contiguous("radix_sort_pairs", "values", values, keys, values)
    if keys.size < 2 * count or values.size < 2 * count:
        raise RuntimeError("Keys and values array storage must be large enough to contain "
                           "2*count elements")
    key_name, value_name = _name(keys.dtype), _name(values.dtype)
    if key_name not in _SORT_KEYS or value_name not in _SORT_KEYS:
        raise RuntimeError(f"Unsupported keys and values data types: {key_name}, {value_name}")
    bits = _types().type_size_in_bytes(keys.dtype) * 8
    end = bits if end_bit is None else int(end_bit)
    if not 0 <= int(begin_bit) <= end <= bits:
        raise RuntimeError(f"Invalid radix sort bit range [{begin_bit}, {end}) for {bits}-bit "
                           f"keys")
    if count == 0:
        return
    k = _values(keys).reshape(-1)
    v = _values(values).reshape(-1)
    ordered = _orderable(np.ascontiguousarray(k[:count]))
    width = end - int(begin_bit)
    digits = (ordered >> ordered.dtype.type(int(begin_bit)))
    if width < bits:
        digits = digits & ordered.dtype.type((1 << width) - 1)
    order = np.argsort(digits, kind="stable")
    new_keys, new_values = k.copy(), v.copy()
    new_keys[:count] = k[:count][order]
    new_values[:count] = v[:count][order]
    _write(keys, new_keys)
    _write(values, new_values)


def _check_count(count) -> int:
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)):
        raise TypeError(f"count must be an integer, got {type(count).__name__}")
    count = int(count)
    if count < 0:
        raise ValueError(f"count must be non-negative, got {count}")
    if count > 2**31 - 1:
        raise ValueError(f"count must not exceed {2**31 - 1}, got {count}")
    return count


def _strides_contiguous(arr) -> bool:
    """Warp's rule for the sorts: the strides are exactly the packed ones (a one-element view
    with a step, a[::2] of two elements, counts as strided)."""
    itemsize = _types().type_size_in_bytes(arr.dtype)
    return arr.is_contiguous and (not arr.ndim or arr.strides[-1] == itemsize)


@_capturable("segmented_sort_pairs")
def segmented_sort_pairs(keys, values, count: int, segment_start_indices,
                         segment_end_indices=None) -> None:
    """Sorts each segment [start[i], end[i]) of the first `count` keys (stable; int32 or
    float32 keys with int32 values) and moves the values with them. Without end indices,
    segment i ends where segment i+1 starts (the last start only closes the one before).
    Both arrays must hold 2*count elements."""
    starts, ends = segment_start_indices, segment_end_indices
    devices = {keys.device, values.device, starts.device} | (
        {ends.device} if ends is not None else set())
    if len(devices) > 1:
        raise RuntimeError("Keys, values, and segment index array storage devices must match")
    count = _check_count(count)
    for name, arr in (("keys", keys), ("values", values), ("segment_start_indices", starts),
                      ("segment_end_indices", ends)):
        if arr is not None and not _strides_contiguous(arr):
            raise RuntimeError(f"segmented_sort_pairs() requires a contiguous {name} array")
    if starts.ndim != 1:
        raise RuntimeError("segment_start_indices must be one-dimensional")
    if ends is not None and ends.ndim != 1:
        raise RuntimeError("segment_end_indices must be one-dimensional")
    if ends is not None and starts.size != ends.size:
        raise RuntimeError(f"segment_start_indices and segment_end_indices must have the same "
                           f"size ({starts.size} vs {ends.size})")
    if keys.size < 2 * count or values.size < 2 * count:
        raise RuntimeError("Array storage must be large enough to contain 2*count elements")
    if (_name(keys.dtype) not in ("int32", "float32")) or _name(values.dtype) != "int32":
        raise RuntimeError(f"Unsupported data type: {_name(keys.dtype)}")
    if count == 0:
        return
    s = _values(starts).astype(np.int64).reshape(-1)
    if ends is None:
        e = s[1:]
        s = s[:-1]
    else:
        e = _values(ends).astype(np.int64).reshape(-1)
    # Warp's rule: the CPU reports a malformed range, CUDA treats it as empty (its kernels do
    # not copy the offsets back to check them).
    on_gpu = bool(getattr(keys.device, "is_cuda", False))
    valid = []
    for i, (lo, hi) in enumerate(zip(s, e)):
        if lo < 0 or hi < lo or hi > count:
            if on_gpu:
                continue
            raise ValueError(f"Invalid segment range at index {i}: [{lo}, {hi}) with count "
                             f"{count}")
        valid.append((lo, hi))
    if not valid:
        return
    k = _values(keys).reshape(-1).copy()
    v = _values(values).reshape(-1).copy()
    for lo, hi in valid:
        order = np.argsort(k[lo:hi], kind="stable")
        k[lo:hi] = k[lo:hi][order]
        v[lo:hi] = v[lo:hi][order]
    _write(keys, k)
    _write(values, v)


@_capturable("runlength_encode", host_value="run_count")
def runlength_encode(values, run_values, run_lengths, run_count=None, value_count=None):
    """Run-length encodes the first value_count values (default: all): run_values gets each
    run's value, run_lengths its length. Returns the number of runs when run_count is None,
    else writes it to run_count[0]."""
    if run_values.device != values.device or run_lengths.device != values.device:
        raise RuntimeError("Values, run values and run lengths must live on one device")
    if not _same_dtype(run_values.dtype, values.dtype):
        raise RuntimeError(f"values and run_values data types do not match "
                           f"({_name(values.dtype)} vs {_name(run_values.dtype)})")
    if _name(run_lengths.dtype) != "int32":
        raise RuntimeError(f"run_lengths array must be of type int32, got "
                           f"{_name(run_lengths.dtype)}")
    n = values.size if value_count is None else int(value_count)
    if n > values.size:
        raise RuntimeError(f"value_count ({n}) exceeds the values array size ({values.size})")
    data = _values(values).reshape(values.size, -1)[:n]
    if n == 0:
        runs = 0
    else:
        change = np.any(data[1:] != data[:-1], axis=1)
        starts = np.concatenate([[0], np.nonzero(change)[0] + 1])
        lengths = np.diff(np.concatenate([starts, [n]]))
        runs = int(starts.size)
        if runs > run_values.size or runs > run_lengths.size:
            raise RuntimeError(f"run_values and run_lengths must hold {runs} runs")
        rv = np.array(_values(run_values)).reshape(run_values.size, -1)
        rl = np.array(_values(run_lengths)).reshape(-1)
        rv[:runs] = data[starts]
        rl[:runs] = lengths
        _write(run_values, rv.reshape(_values(run_values).shape))
        _write(run_lengths, rl)
    if run_count is None:
        return runs
    _write(run_count, np.array([runs], dtype=np.int32).reshape(_values(run_count).shape))
    return None
