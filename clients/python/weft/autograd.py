"""Gradient debugging (Warp's `warp.autograd`): Jacobians by autodiff and by finite differences,
gradient checks of kernels, of Python functions that launch kernels and of recorded tapes, and
Jacobian plots.

`function` is a @wp.kernel (launched with `dim`, `inputs`, `outputs`; inputs precede outputs in
its parameters) or a Python function that takes `inputs` and returns a weft array or a list of
them. Only weft arrays with requires_grad=True take part in a Jacobian; a Jacobian of input `i`
and output `o` is a weft array of shape (scalars of `o`, elements of `i`) with `i`'s dtype, and
rows (autodiff) or columns (finite differences) left out by max_outputs_per_var /
max_inputs_per_var are NaN.

Autodiff rows come from adjoint launches of the kernel (wp.launch(adjoint=True)) or backward
passes of a wp.Tape recorded around the function, one per output scalar, seeded with a unit
gradient. Finite differences are central differences: each input scalar is moved by -eps and
+eps (in the input's precision), the difference quotient is taken in the output's precision and
stored in the Jacobian's. Both run only forward and adjoint launches, no kernels of their own.
"""
from __future__ import annotations

import dataclasses
import inspect
import itertools
import re
from collections.abc import Callable, Sequence
from typing import Optional

import numpy as np

__all__ = [
    "FunctionMetadata",
    "gradcheck",
    "gradcheck_tape",
    "jacobian",
    "jacobian_fd",
    "jacobian_plot",
]


def _wp():
    """The weft package (imported on use: this module is imported by weft/__init__.py)."""
    import weft  # noqa: PLC0415

    return weft


# --------------------------------------------------------------------------------------------
# Arrays, kernels and devices
# --------------------------------------------------------------------------------------------

def _is_array(x) -> bool:
    return isinstance(x, _wp().array)


def _is_kernel(x) -> bool:
    return isinstance(x, _wp().Kernel)


def _differentiable(x) -> bool:
    """A weft array that takes part in Jacobians (requires_grad=True)."""
    return _is_array(x) and bool(getattr(x, "requires_grad", False))


def _component_count(dtype) -> Optional[int]:
    """Scalars per element of `dtype` (1 for scalars), None for a dtype without one (Any)."""
    count = getattr(dtype, "_length_", None)
    return int(count) if isinstance(count, (int, np.integer)) else None


def _scalar_count(x) -> int:
    """Scalars in a weft array (elements times scalars per element)."""
    return int(x.size) * (_component_count(x.dtype) or 1)


def _element_shape(x) -> tuple:
    """The NumPy shape of one element of a weft array's dtype (() for scalars)."""
    shape = getattr(x.dtype, "_shape_", None)
    if shape is not None:
        return tuple(shape)
    count = _component_count(x.dtype) or 1
    return () if count == 1 else (count,)


def _np_scalar_dtype(dtype) -> np.dtype:
    """The NumPy dtype of one scalar of a weft dtype."""
    np_dtype = getattr(dtype, "_np_dtype_", None)
    if np_dtype is None:
        scalar = getattr(dtype, "_wp_scalar_type_", None)
        np_dtype = getattr(scalar, "_np_dtype_", None)
    return np.dtype(np_dtype if np_dtype is not None else np.float32)


def _flat_values(x) -> np.ndarray:
    """A weft array's scalars as a 1D NumPy array (a copy), in the array's index order."""
    return np.array(x.numpy(), copy=True).reshape(-1)


def _backward_enabled(kernel) -> bool:
    """Whether `kernel` has a backward pass: the kernel's own enable_backward option, else its
    module's, else wp.config.enable_backward (the options weft builds the kernel with)."""
    try:
        from ._kernel.module import build_options  # noqa: PLC0415

        return bool(build_options(kernel).get("enable_backward", True))
    except Exception:  # noqa: BLE001 - fall back to reading the options directly
        pass
    value = kernel.options.get("enable_backward")
    if value is None:
        value = kernel.module.options.get("enable_backward")
    if value is None:
        value = _wp().config.enable_backward
    return bool(value)


def _struct_fields(x) -> list:
    """The field values of a struct instance ([] for other values)."""
    values = getattr(x, "_values", None)
    return list(values.values()) if isinstance(values, dict) else []


def infer_device(xs: Sequence):
    """The device of the first weft array among `xs` (or in a struct among them), else the
    preferred device."""
    for x in xs:
        if _is_array(x):
            return x.device
        for field in _struct_fields(x):
            if _is_array(field):
                return field.device
    return _wp().get_preferred_device()


def zero_grads(arrays: Sequence) -> None:
    """Sets the gradients of the differentiable weft arrays among `arrays` to zero."""
    for x in arrays:
        if _differentiable(x) and x.grad is not None:
            x.grad.zero_()


def _kernel_param_kind(kernel, i: int) -> Optional[str]:
    """The kind of the kernel's i-th parameter ("array", "scalar", ...), None when unknown."""
    try:
        from ._kernel import typestr  # noqa: PLC0415

        return typestr.parse(kernel.param_types[i]).kind
    except Exception:  # noqa: BLE001 - an annotation weft cannot describe
        return None


# --------------------------------------------------------------------------------------------
# Restoring the inputs of Python functions
# --------------------------------------------------------------------------------------------

def _snapshot_array_inputs(inputs: Sequence) -> list:
    """For each top-level weft array input: a device copy of its data and its read flag
    (wp.config.verify_autograd_array_access); None for other inputs."""
    wp = _wp()
    return [(wp.clone(x, requires_grad=False), bool(getattr(x, "_is_read", False)))
            if _is_array(x) else None for x in inputs]


def _restore_array_inputs(inputs: Sequence, snapshot: Optional[Sequence]) -> None:
    """Writes the snapshot's data back into the inputs and gives them back their read flags:
    the reads made by this module's own evaluations are forgotten, those of a caller's pending
    tape are kept. Called outside any tape of this module, so the copies are not recorded."""
    if snapshot is None:
        return
    for x, saved in zip(inputs, snapshot):
        if saved is None:
            continue
        data, was_read = saved
        x.assign(data)
        x._is_read = was_read


def _as_output_list(outputs) -> list:
    if _is_array(outputs):
        return [outputs]
    if outputs is None:
        return []
    return list(outputs)


def _evaluate(function, inputs: Sequence, snapshot, tape=None) -> list:
    """Runs a Python function on `inputs` (under `tape` when given) and returns its outputs as
    a list; restores the inputs from `snapshot` when the function raises."""
    try:
        if tape is not None:
            with tape:
                outputs = function(*inputs)
        else:
            outputs = function(*inputs)
    except BaseException:
        _restore_array_inputs(inputs, snapshot)
        raise
    return _as_output_list(outputs)


# --------------------------------------------------------------------------------------------
# Metadata
# --------------------------------------------------------------------------------------------

@dataclasses.dataclass
class FunctionMetadata:
    """Names, strides and dtypes of the inputs and outputs of a kernel or Python function, as
    gradient checks and Jacobian plots label them. A dtype of None marks a non-array argument."""

    key: Optional[str] = None
    input_labels: Optional[list] = None
    output_labels: Optional[list] = None
    input_strides: Optional[list] = None
    output_strides: Optional[list] = None
    input_dtypes: Optional[list] = None
    output_dtypes: Optional[list] = None

    @property
    def is_empty(self) -> bool:
        return self.key is None

    def input_is_array(self, i: int) -> bool:
        return self.input_dtypes[i] is not None

    def output_is_array(self, i: int) -> bool:
        return self.output_dtypes[i] is not None

    def update_from_kernel(self, kernel, inputs: Sequence, outputs: Optional[Sequence] = None):
        """Fills the metadata from a kernel's parameters: the first len(inputs) are its inputs,
        the rest its outputs. Array dtypes and strides come from the given values, else from
        the parameter's annotation."""
        names = list(kernel.param_names)
        n_inputs = len(inputs)
        annotations = getattr(getattr(kernel, "definition", None), "annotations", {}) or {}
        self.key = kernel.key
        self.input_labels = names[:n_inputs]
        self.output_labels = names[n_inputs:]
        self.input_strides, self.input_dtypes = [], []
        self.output_strides, self.output_dtypes = [], []
        values = list(inputs) + list(outputs or [])
        for i, name in enumerate(names):
            value = values[i] if i < len(values) else None
            kind = _kernel_param_kind(kernel, i)
            is_array = kind == "array" or (kind is None and _is_array(value))
            if not is_array:
                strides, dtype = None, None
            elif _is_array(value):
                strides, dtype = tuple(value.strides), value.dtype
            else:
                annotation = annotations.get(name)
                strides, dtype = None, getattr(annotation, "dtype", None)
            if i < n_inputs:
                self.input_strides.append(strides)
                self.input_dtypes.append(dtype)
            else:
                self.output_strides.append(strides)
                self.output_dtypes.append(dtype)
        return self

    def update_from_function(self, function: Callable, inputs: Sequence,
                             outputs: Optional[Sequence] = None):
        """Fills the metadata from a Python function: inputs named by its parameters, outputs
        `output_<i>`; evaluates the function when `outputs` is not given."""
        self.key = getattr(function, "__name__", None) or type(function).__name__
        try:
            self.input_labels = list(inspect.signature(function).parameters.keys())
        except (TypeError, ValueError):
            self.input_labels = []
        # parameters the signature does not name (*args) get positional labels
        self.input_labels += [f"input_{i}" for i in range(len(self.input_labels), len(inputs))]
        if outputs is None:
            outputs = function(*inputs)
        outputs = _as_output_list(outputs)
        self.output_labels = [f"output_{i}" for i in range(len(outputs))]
        self.input_strides = [tuple(x.strides) if _is_array(x) else None for x in inputs]
        self.input_dtypes = [x.dtype if _is_array(x) else None for x in inputs]
        self.output_strides = [tuple(y.strides) if _is_array(y) else None for y in outputs]
        self.output_dtypes = [y.dtype if _is_array(y) else None for y in outputs]
        return self


def _resolve_mask(mask, metadata: FunctionMetadata, n_inputs: int) -> set:
    """The (input index, output index) pairs of an input/output mask whose entries are indices
    or argument names."""
    labels = list(metadata.input_labels or []) + list(metadata.output_labels or [])

    def index_of(name, offset):
        if isinstance(name, (int, np.integer)):
            return int(name)
        if name not in labels:
            raise ValueError(f"input_output_mask names {name!r}, which is not an argument of "
                             f"{metadata.key} (arguments: {', '.join(map(str, labels))})")
        return labels.index(name) - offset

    return {(index_of(i, 0), index_of(o, n_inputs)) for i, o in (mask or [])}


def _pairs(inputs: Sequence, outputs: Sequence, mask: set):
    """The (input index, output index) pairs to compute Jacobians for, inputs outer."""
    for input_i, output_i in itertools.product(range(len(inputs)), range(len(outputs))):
        if mask and (input_i, output_i) not in mask:
            continue
        if _differentiable(inputs[input_i]) and _differentiable(outputs[output_i]):
            yield input_i, output_i


def _new_jacobian(rows: int, x):
    """A NaN-filled NumPy Jacobian for input array `x`: (rows, x.size, *element shape)."""
    return np.full((rows, int(x.size), *_element_shape(x)), np.nan, dtype=_np_scalar_dtype(x.dtype))


def _to_weft(jac: np.ndarray, x):
    """The NumPy Jacobian of input `x` as a weft array with x's dtype on x's device."""
    return _wp().array(jac, dtype=x.dtype, device=x.device)


# --------------------------------------------------------------------------------------------
# Jacobians
# --------------------------------------------------------------------------------------------

def jacobian(
    function,
    dim=None,
    inputs: Optional[Sequence] = None,
    outputs: Optional[Sequence] = None,
    input_output_mask: Optional[list] = None,
    device=None,
    max_blocks: int = 0,
    block_dim: Optional[int] = None,
    max_outputs_per_var: int = -1,
    plot_jacobians: bool = False,
    metadata: Optional[FunctionMetadata] = None,
    restore_inputs: bool = True,
    kernel=None,
) -> dict:
    """Jacobians of a kernel or Python function by autodiff, {(input index, output index):
    weft array of shape (output scalars, input elements)}, one per pair of differentiable
    input and output (or per pair of `input_output_mask`, given by index or name).

    A kernel's adjoint is launched once per output scalar with `dim`, `max_blocks`,
    `block_dim` and `device`; a Python function runs once under a wp.Tape whose backward pass
    runs once per output scalar. Rows past `max_outputs_per_var` (when > 0) are NaN. With
    `restore_inputs`, a Python function's top-level array inputs get their values back before
    returning (also when it raises). Raises ValueError for a kernel (or a kernel launched by the
    function) without a backward pass (enable_backward=False on the kernel or its module)."""
    if function is None:
        function = kernel
    if inputs is None:
        raise ValueError("The inputs argument must be provided")
    inputs = list(inputs)
    if metadata is None:
        metadata = FunctionMetadata()
    wp = _wp()

    if _is_kernel(function):
        if not _backward_enabled(function):
            raise ValueError("Kernel must have backward pass enabled to compute Jacobians")
        if not outputs:
            raise ValueError("A list of output arguments must be provided to compute kernel Jacobians")
        outputs = list(outputs)
        if device is None:
            device = infer_device(inputs + outputs)
        if metadata.is_empty:
            metadata.update_from_kernel(function, inputs, outputs)
        snapshot = None
        tape = None

        def backward():
            adj_inputs = [x.grad if _differentiable(x) else None for x in inputs]
            adj_outputs = [y.grad if _differentiable(y) else None for y in outputs]
            wp.launch(function, dim=dim, inputs=inputs, outputs=outputs, adj_inputs=adj_inputs,
                      adj_outputs=adj_outputs, adjoint=True, device=device,
                      max_blocks=max_blocks, block_dim=block_dim)
    else:
        snapshot = _snapshot_array_inputs(inputs) if restore_inputs else None
        tape = wp.Tape()
        outputs = _evaluate(function, inputs, snapshot, tape)

        def backward():
            if tape.launches:       # a function that launched nothing has nothing to replay
                tape.backward()

    try:
        if tape is not None:
            for entry in tape.launches:
                launched = _launch_kernel(entry)
                if launched is not None and not _backward_enabled(launched):
                    raise ValueError("Kernel must have backward pass enabled to compute Jacobians")
            if metadata.is_empty:
                metadata.update_from_function(function, inputs, outputs)
        mask = _resolve_mask(input_output_mask, metadata, len(inputs))

        def clear_grads():
            # every row starts from zero gradients: a function's intermediate arrays too,
            # which would otherwise carry the previous row's adjoints into this one
            if tape is not None and tape.launches:
                tape.zero()
            zero_grads(inputs)
            zero_grads(outputs)

        clear_grads()
        jacobians = {}
        for input_i, output_i in _pairs(inputs, outputs, mask):
            x, y = inputs[input_i], outputs[output_i]
            rows = _scalar_count(y)
            jac = _new_jacobian(rows, x)
            computed = rows if max_outputs_per_var <= 0 else min(rows, max_outputs_per_var)
            seed = np.zeros(rows, dtype=_np_scalar_dtype(y.dtype))
            for r in range(computed):
                # a unit gradient on output scalar r gives row r: d y[r] / d x
                seed[r] = 1
                y.grad.assign(seed)
                seed[r] = 0
                backward()
                jac[r] = x.grad.numpy().reshape(jac.shape[1:])
                clear_grads()
            jacobians[input_i, output_i] = _to_weft(jac, x)
    finally:
        if snapshot is not None:
            _restore_array_inputs(inputs, snapshot)

    if plot_jacobians:
        jacobian_plot(jacobians, metadata)
    return jacobians


def jacobian_fd(
    function,
    dim=None,
    inputs: Optional[Sequence] = None,
    outputs: Optional[Sequence] = None,
    input_output_mask: Optional[list] = None,
    device=None,
    max_blocks: int = 0,
    block_dim: Optional[int] = None,
    max_inputs_per_var: int = -1,
    eps: float = 1e-4,
    plot_jacobians: bool = False,
    metadata: Optional[FunctionMetadata] = None,
    restore_inputs: bool = True,
    kernel=None,
) -> dict:
    """Jacobians of a kernel or Python function by central finite differences, in the layout of
    jacobian(): column j of the (input, output) Jacobian is (f(x + eps e_j) - f(x - eps e_j)) /
    (2 eps) for input scalar j. Only forward launches run, so kernels without a backward pass
    are fine. A kernel writes into copies of its outputs (the given outputs keep their values);
    a Python function is evaluated anew for each probe. Columns past `max_inputs_per_var`
    (when > 0) are NaN. Inputs get their values back after each probe; with `restore_inputs`
    a Python function's array inputs are restored in full before each evaluation (so one that
    mutates its inputs is probed from the original values) and before returning."""
    if function is None:
        function = kernel
    if inputs is None:
        raise ValueError("The inputs argument must be provided")
    inputs = list(inputs)
    if metadata is None:
        metadata = FunctionMetadata()
    wp = _wp()
    is_kernel = _is_kernel(function)

    if is_kernel:
        if not outputs:
            raise ValueError("A list of output arguments must be provided to compute kernel Jacobians")
        outputs = list(outputs)
        if device is None:
            device = infer_device(inputs + outputs)
        if metadata.is_empty:
            metadata.update_from_kernel(function, inputs, outputs)
        snapshot = None
    else:
        snapshot = _snapshot_array_inputs(inputs) if restore_inputs else None
        outputs = _evaluate(function, inputs, snapshot)
        try:
            if metadata.is_empty:
                metadata.update_from_function(function, inputs, outputs)
        finally:
            _restore_array_inputs(inputs, snapshot)

    try:
        mask = _resolve_mask(input_output_mask, metadata, len(inputs))
        jacobians = {}
        for input_i, output_i in _pairs(inputs, outputs, mask):
            x, y = inputs[input_i], outputs[output_i]
            out_np_dtype = _np_scalar_dtype(y.dtype)
            rows = _scalar_count(y)
            jac = _new_jacobian(rows, x)
            columns = jac.reshape(rows, -1)         # a view: column j is input scalar j
            n_scalars = columns.shape[1]
            probed = n_scalars if max_inputs_per_var <= 0 else min(n_scalars, max_inputs_per_var)
            initial = left_outputs = right_outputs = None
            if is_kernel:
                # the kernel writes into copies of the outputs, reset to the outputs' values
                # before every launch; the other outputs' copies are written but not read
                initial = y.numpy()
                left_outputs = [wp.clone(o) if _is_array(o) else o for o in outputs]
                right_outputs = [wp.clone(o) if _is_array(o) else o for o in outputs]
            original = _flat_values(x)
            step = np.asarray(eps, dtype=original.dtype)

            def evaluate(side_outputs):
                """The probed output's scalars from the current input values."""
                if is_kernel:
                    side_outputs[output_i].assign(initial)
                    wp.launch(function, dim=dim, inputs=inputs, outputs=side_outputs,
                              device=device, max_blocks=max_blocks, block_dim=block_dim)
                    return _flat_values(side_outputs[output_i])
                return _flat_values(_evaluate(function, inputs, snapshot)[output_i])

            for j in range(probed):
                values = []
                for sign, side in ((-1, left_outputs), (1, right_outputs)):
                    moved = original.copy()
                    moved[j] = original[j] + sign * step      # in the input's precision
                    x.assign(moved)
                    values.append(evaluate(side))
                    # the next probe starts from the original inputs
                    if snapshot is not None:
                        _restore_array_inputs(inputs, snapshot)
                    else:
                        x.assign(original)
                left, right = (np.asarray(v, dtype=out_np_dtype) for v in values)
                # the difference quotient in the output's precision, stored in the Jacobian's
                quotient = (right - left) / (out_np_dtype.type(2.0) * out_np_dtype.type(eps))
                columns[:, j] = quotient.astype(columns.dtype)
            jacobians[input_i, output_i] = _to_weft(jac, x)
    finally:
        if snapshot is not None:
            _restore_array_inputs(inputs, snapshot)

    if plot_jacobians:
        jacobian_plot(jacobians, metadata)
    return jacobians


# --------------------------------------------------------------------------------------------
# Gradient checks
# --------------------------------------------------------------------------------------------

_GREEN, _RED, _RESET = "\033[92m", "\033[91m", "\033[0m"


def print_table(headers: Sequence, cells: Sequence) -> None:
    """Prints rows of cells under headers, columns padded to their widest cell (terminal color
    codes do not count towards a cell's width)."""

    def width(s) -> int:
        return len(re.sub(r"\033\[\d+m", "", str(s)))

    rows = [list(map(str, headers))] + [list(map(str, row)) for row in cells]
    widths = [max(width(row[c]) for row in rows) for c in range(len(headers))]

    def line(row) -> str:
        return "".join(cell + " " * (w - width(cell)) + " | " for cell, w in zip(row, widths))

    print(line(rows[0]))
    print("-" * (sum(widths) + 3 * len(widths) - 1))
    for row in rows[1:]:
        print(line(row))


def _error_jacobians(jac_ad: np.ndarray, jac_fd: np.ndarray):
    """Relative error (ad - fd) / ad (with |ad| < 1e-8 taken as 1e-8) and absolute error
    |ad - fd|, elementwise in the Jacobian's dtype."""
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = np.where(np.abs(jac_ad) < 1e-8, jac_ad.dtype.type(1e-8), jac_ad)
        relative = ((jac_ad - jac_fd) / denom).astype(jac_ad.dtype)
    absolute = np.abs(jac_ad - jac_fd).astype(jac_ad.dtype)
    return relative, absolute


def _summary_row(input_label, output_label, ad: np.ndarray, fd: np.ndarray, matches: bool,
                 has_nan: bool) -> list:
    """One row of gradcheck()'s table: the largest |AD - FD| and where, AD and FD there, the
    largest relative error |AD - FD| / |FD + 1e-8|, and the verdict."""
    difference = np.abs(ad - fd)
    if difference.size and not np.isnan(difference).all():
        at = np.unravel_index(np.nanargmax(difference), difference.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            max_rel = np.nanmax(np.abs((ad - fd) / (fd + 1e-8)))
        max_abs, ad_at, fd_at = difference[at], ad[at], fd[at]
    else:
        at, max_abs, ad_at, fd_at, max_rel = (), np.nan, np.nan, np.nan, np.nan
    verdict = _RED + "NaN" if has_nan else _GREEN + "PASS" if matches else _RED + "FAIL"
    return [input_label, output_label, f"{max_abs:.3e} at {tuple(int(k) for k in at)}",
            f"{ad_at:.3e}", f"{fd_at:.3e}", f"{max_rel:.3e}", verdict + _RESET]


def gradcheck(
    function,
    dim=None,
    inputs: Optional[Sequence] = None,
    outputs: Optional[Sequence] = None,
    *,
    eps: float = 1e-4,
    atol: float = 1e-3,
    rtol: float = 1e-2,
    raise_exception: bool = True,
    input_output_mask: Optional[list] = None,
    device=None,
    max_blocks: int = 0,
    block_dim: Optional[int] = None,
    max_inputs_per_var: int = -1,
    max_outputs_per_var: int = -1,
    plot_relative_error: bool = False,
    plot_absolute_error: bool = False,
    show_summary: bool = True,
    restore_inputs: bool = True,
) -> bool:
    """Whether the autodiff Jacobians of a kernel or Python function (jacobian()) match its
    finite-difference Jacobians (jacobian_fd()): every pair has no NaN in the autodiff
    Jacobian and |AD - FD| <= atol + rtol * |FD| over the rows and columns both computed.
    Prints a table of the errors per pair with `show_summary`; plots the relative / absolute
    errors with the plot flags (matplotlib); raises ValueError on failure with
    `raise_exception`, else returns False."""
    if inputs is None:
        raise ValueError("The inputs argument must be provided")
    metadata = FunctionMetadata()
    jacs_ad = jacobian(function, dim=dim, inputs=inputs, outputs=outputs,
                       input_output_mask=input_output_mask, device=device,
                       max_blocks=max_blocks, block_dim=block_dim,
                       max_outputs_per_var=max_outputs_per_var, plot_jacobians=False,
                       metadata=metadata, restore_inputs=restore_inputs)
    jacs_fd = jacobian_fd(function, dim=dim, inputs=inputs, outputs=outputs,
                          input_output_mask=input_output_mask, device=device,
                          max_blocks=max_blocks, block_dim=block_dim,
                          max_inputs_per_var=max_inputs_per_var, eps=eps, plot_jacobians=False,
                          metadata=metadata, restore_inputs=restore_inputs)

    relative_jacs, absolute_jacs = {}, {}
    summary = []
    success = True
    first_mismatch = first_nan = None
    for (input_i, output_i), jac_fd_wp in jacs_fd.items():
        jac_ad_wp = jacs_ad[input_i, output_i]
        full_ad, full_fd = jac_ad_wp.numpy(), jac_fd_wp.numpy()
        if plot_relative_error or plot_absolute_error:
            relative, absolute = _error_jacobians(full_ad, full_fd)
            relative_jacs[input_i, output_i] = _to_weft(relative, inputs[input_i])
            absolute_jacs[input_i, output_i] = _to_weft(absolute, inputs[input_i])
        # compare the rows and columns both Jacobians computed, as 2D scalar matrices
        ad = full_ad.reshape(full_ad.shape[0], full_ad.shape[1], -1)
        fd = full_fd.reshape(ad.shape)
        if max_outputs_per_var > 0:
            ad, fd = ad[:max_outputs_per_var], fd[:max_outputs_per_var]
        if max_inputs_per_var > 0:
            ad, fd = ad[:, :max_inputs_per_var], fd[:, :max_inputs_per_var]
        ad = ad.reshape(ad.shape[0], -1)
        fd = fd.reshape(ad.shape)
        matches = bool(np.allclose(ad, fd, atol=atol, rtol=rtol))
        has_nan = bool(np.any(np.isnan(ad)))
        if not matches and first_mismatch is None:
            first_mismatch = (input_i, output_i)
        if has_nan and first_nan is None:
            first_nan = (input_i, output_i)
        success = success and matches and not has_nan

        if show_summary:
            summary.append(_summary_row(metadata.input_labels[input_i],
                                        metadata.output_labels[output_i], ad, fd, matches,
                                        has_nan))

    if show_summary:
        print_table(["Input", "Output", "Max Abs Error", "AD at MAE", "FD at MAE",
                     "Max Rel Error", "Pass"], summary)
        verdict = "passed" if success else "failed"
        print((_GREEN if success else _RED) + f"Gradient check for kernel {metadata.key} {verdict}"
              + _RESET)
    if plot_relative_error:
        jacobian_plot(relative_jacs, metadata, title=f"{metadata.key} kernel Jacobian relative error")
    if plot_absolute_error:
        jacobian_plot(absolute_jacs, metadata, title=f"{metadata.key} kernel Jacobian absolute error")

    if raise_exception:
        # a NaN gradient also fails the comparison: it is the more telling report
        if first_nan is not None:
            input_i, output_i = first_nan
            raise ValueError(f"Gradient check failed for kernel {metadata.key}, input "
                             f"{metadata.input_labels[input_i]}, output "
                             f"{metadata.output_labels[output_i]}: gradient contains NaN values")
        if first_mismatch is not None:
            input_i, output_i = first_mismatch
            raise ValueError(f"Gradient check failed for kernel {metadata.key}, input "
                             f"{metadata.input_labels[input_i]}, output "
                             f"{metadata.output_labels[output_i]}: finite difference and autodiff "
                             f"gradients do not match")
    return success


def _launch_kernel(entry):
    """The kernel of a tape entry (a recorded launch, or Warp's launch tuple), None for other
    entries (record_func callbacks)."""
    if isinstance(entry, (tuple, list)):
        return entry[0] if entry and _is_kernel(entry[0]) else None
    kernel = getattr(entry, "kernel", None)
    return kernel if _is_kernel(kernel) else None


def _split_recorded_args(kernel, args: list):
    """Inputs and outputs of a recorded launch, which keeps the arguments in one list: the
    outputs are the trailing parameters the kernel writes (inputs precede outputs, as the
    gradient checks require)."""
    try:
        written = [bool(arg.is_write) for arg in kernel.adj.args]
    except Exception:  # noqa: BLE001 - no access analysis: the last argument is the output
        written = [False] * (len(args) - 1) + [True]
    n_inputs = len(args)
    while n_inputs > 0 and n_inputs <= len(written) and written[n_inputs - 1]:
        n_inputs -= 1
    return list(args[:n_inputs]), list(args[n_inputs:])


def _recorded_launch(entry):
    """(kernel, dim, max_blocks, inputs, outputs, device, block_dim) of a tape entry."""
    if isinstance(entry, (tuple, list)):
        kernel, dim, max_blocks, inputs, outputs, device, block_dim = entry[:7]
        return kernel, dim, max_blocks, list(inputs), list(outputs), device, block_dim
    kernel = entry.kernel
    inputs, outputs = _split_recorded_args(kernel, list(entry.args))
    lanes = int(getattr(entry, "lanes", 1) or 1)
    return (kernel, tuple(entry.dims), 0, inputs, outputs, entry.device,
            lanes if lanes > 1 else None)


def gradcheck_tape(
    tape,
    *,
    eps: float = 1e-4,
    atol: float = 1e-3,
    rtol: float = 1e-2,
    raise_exception: bool = True,
    input_output_masks: Optional[dict] = None,
    blacklist_kernels: Optional[list] = None,
    whitelist_kernels: Optional[list] = None,
    max_inputs_per_var: int = -1,
    max_outputs_per_var: int = -1,
    plot_relative_error: bool = False,
    plot_absolute_error: bool = False,
    show_summary: bool = True,
    reverse_launches: bool = False,
    skip_to_launch_index: int = 0,
) -> bool:
    """gradcheck() of every kernel launch recorded on `tape` (record_func callbacks are not
    checked), with the launch's arguments, dim and device. Launches of kernels without a
    backward pass are skipped, as are those before `skip_to_launch_index` (counted in the
    order checked: newest first with `reverse_launches`), those of `blacklist_kernels` and,
    when `whitelist_kernels` is given, those of other kernels. `input_output_masks` maps kernel
    keys to masks. Returns whether every check passed."""
    masks = input_output_masks or {}
    blacklist = set(blacklist_kernels or [])
    whitelist = set(whitelist_kernels or [])
    launches = list(tape.launches)
    if reverse_launches:
        launches.reverse()
    overall = True
    for i, entry in enumerate(launches):
        if i < skip_to_launch_index:
            continue
        kernel = _launch_kernel(entry)
        if kernel is None:
            continue
        if (whitelist and kernel.key not in whitelist) or kernel.key in blacklist:
            continue
        if not _backward_enabled(kernel):
            continue
        kernel, dim, max_blocks, inputs, outputs, device, block_dim = _recorded_launch(entry)
        if not outputs:
            continue
        passed = gradcheck(kernel, dim, inputs, outputs, eps=eps, atol=atol, rtol=rtol,
                           raise_exception=raise_exception,
                           input_output_mask=masks.get(kernel.key), device=device,
                           max_blocks=max_blocks, block_dim=block_dim,
                           max_inputs_per_var=max_inputs_per_var,
                           max_outputs_per_var=max_outputs_per_var,
                           plot_relative_error=plot_relative_error,
                           plot_absolute_error=plot_absolute_error, show_summary=show_summary)
        overall = overall and passed
    return overall


# --------------------------------------------------------------------------------------------
# Plots
# --------------------------------------------------------------------------------------------

def _checked_plot_metadata(metadata: FunctionMetadata, input_indices, output_indices) -> dict:
    """Checks that every plotted input has a label and an array dtype with a component count
    and every plotted output a label; returns {input index: components per element}."""
    input_labels = metadata.input_labels or []
    input_dtypes = metadata.input_dtypes or []
    output_labels = metadata.output_labels or []
    components = {}
    for i in input_indices:
        if not 0 <= i < len(input_labels):
            raise ValueError(f"Invalid Jacobian input index {i}: plotting metadata defines "
                             f"{len(input_labels)} inputs")
        if input_labels[i] is None:
            raise ValueError(f"Invalid plotting metadata for Jacobian input index {i}: missing label")
        if i >= len(input_dtypes) or input_dtypes[i] is None:
            raise ValueError(f"Invalid plotting metadata for Jacobian input index {i}: missing "
                             f"array dtype")
        count = _component_count(input_dtypes[i])
        if count is None:
            raise ValueError(f"Invalid plotting metadata for Jacobian input index {i}: array "
                             f"dtype has no component count")
        components[i] = count
    for o in output_indices:
        if not 0 <= o < len(output_labels):
            raise ValueError(f"Invalid Jacobian output index {o}: plotting metadata defines "
                             f"{len(output_labels)} outputs")
        if output_labels[o] is None:
            raise ValueError(f"Invalid plotting metadata for Jacobian output index {o}: missing "
                             f"label")
    return components


def jacobian_plot(
    jacobians: dict,
    kernel,
    inputs: Optional[Sequence] = None,
    show_plot: bool = True,
    show_colorbar: bool = True,
    scale_colors_per_submatrix: bool = False,
    title: Optional[str] = None,
    colormap: str = "coolwarm",
    log_scale: bool = False,
):
    """Draws the Jacobians of jacobian() / jacobian_fd() as one grid of images (matplotlib):
    a column per input, a row per output, each cell as wide as the input's scalars and as
    tall as the output's; pairs without a Jacobian are blank. `kernel` is the kernel (then
    `inputs` are required) or a FunctionMetadata. Colors span all Jacobians, or each one with
    `scale_colors_per_submatrix`; `log_scale` draws log10(|J| + 1e-8). Returns the figure
    (None when there is nothing to draw); plt.show() runs with `show_plot`."""
    if _is_kernel(kernel):
        if inputs is None:
            raise ValueError("inputs must be provided when kernel is a Warp kernel")
        metadata = FunctionMetadata().update_from_kernel(kernel, list(inputs))
    elif isinstance(kernel, FunctionMetadata):
        metadata = kernel
    else:
        raise ValueError("Invalid kernel argument: must be a Warp kernel or a FunctionMetadata object")

    import matplotlib.pyplot as plt  # noqa: PLC0415
    from matplotlib.ticker import MaxNLocator  # noqa: PLC0415

    # outputs outer, inputs inner: the order the cells are drawn in
    ordered = dict(sorted(jacobians.items(), key=lambda item: (item[0][1], item[0][0])))
    input_indices = sorted({i for i, _ in ordered})
    output_indices = sorted({o for _, o in ordered})
    if not input_indices or not output_indices:
        return None
    components = _checked_plot_metadata(metadata, input_indices, output_indices)
    column_of = {i: c for c, i in enumerate(input_indices)}
    row_of = {o: r for r, o in enumerate(output_indices)}

    width_ratios = [next(j for (i, _), j in ordered.items() if i == input_i).shape[1]
                    * components[input_i] for input_i in input_indices]
    height_ratios = [next(j for (_, o), j in ordered.items() if o == output_i).shape[0]
                     for output_i in output_indices]
    matrices = {key: np.asarray(j.numpy()).reshape(j.shape[0], j.shape[1] * components[key[0]])
                for key, j in ordered.items()}

    n_rows, n_cols = len(output_indices), len(input_indices)
    fig, axs = plt.subplots(ncols=n_cols, nrows=n_rows, figsize=(7, 7), layout="constrained",
                            sharex="col", sharey="row", squeeze=False,
                            gridspec_kw={"wspace": 0.1, "hspace": 0.1,
                                         "width_ratios": width_ratios,
                                         "height_ratios": height_ratios},
                            subplot_kw={"aspect": 1})
    if title is None:
        title = f"{metadata.key or 'unknown'} kernel Jacobian"
    fig.suptitle(title)
    manager = getattr(fig.canvas, "manager", None)
    if manager is not None:
        manager.set_window_title(title)

    vmin = vmax = 0.0
    if not scale_colors_per_submatrix:
        finite = [m[~np.isnan(m)] for m in matrices.values()]
        finite = [m for m in finite if m.size]
        if finite:
            vmin = min(float(m.min()) for m in finite)
            vmax = max(float(m.max()) for m in finite)

    present = np.zeros((n_rows, n_cols), dtype=bool)
    for input_i, output_i in ordered:
        present[row_of[output_i], column_of[input_i]] = True
    for r in range(n_rows):
        for c in range(n_cols):
            if not present[r, c]:
                axs[r, c].axis("off")

    for (input_i, output_i), matrix in matrices.items():
        r, c = row_of[output_i], column_of[input_i]
        ax = axs[r, c]
        ax.tick_params(which="major", width=1, length=7)
        ax.tick_params(which="minor", width=1, length=4, color="gray")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        low, high = vmin, vmax
        if scale_colors_per_submatrix:
            finite = matrix[~np.isnan(matrix)]
            low, high = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
        image = ax.imshow(np.log10(np.abs(matrix) + 1e-8) if log_scale else matrix,
                          cmap=colormap, aspect="auto", interpolation="nearest",
                          extent=[0, matrix.shape[1], 0, matrix.shape[0]], vmin=low, vmax=high)
        # the input's name under the lowest cell of its column, the output's name left of the
        # first cell of its row
        if not present[r + 1:, c].any():
            ax.set_xlabel(metadata.input_labels[input_i])
        if not present[r, :c].any():
            ax.set_ylabel(metadata.output_labels[output_i])
        ax.grid(color="gray", which="minor", linestyle="--", linewidth=0.5)
        ax.grid(color="black", which="major", linewidth=1.0)
        if show_colorbar and scale_colors_per_submatrix:
            plt.colorbar(image, ax=ax, orientation="vertical", pad=0.02)

    if show_colorbar and not scale_colors_per_submatrix:
        mappable = plt.cm.ScalarMappable(cmap=colormap)
        mappable.set_array([vmin, vmax])
        mappable.set_clim(vmin, vmax)
        plt.colorbar(mappable, ax=axs, orientation="vertical", pad=0.02)

    if show_plot:
        plt.show()
    return fig
