"""wp.Tape: records the launches made inside `with wp.Tape() as tape:` and replays their
adjoint kernels in reverse order on backward(); zero(), reset(), gradients[a] as in Warp.

Two modes, one API:
  "daemon"  the session's tape in weftd (TapeCommand BEGIN/END/BACKWARD/ZERO/RESET/FREE in the
            command batch); the default when the daemon supports it.
  "client"  the recording is kept in this process (= this session) and backward() submits one
            adjoint LaunchCommand per recorded launch, in reverse order. Used when the daemon
            answers a tape command with UNIMPLEMENTED (probed once per session), or when
            WEFT_TAPE=client is set.
A record_func callback on a daemon tape is a marker in the daemon's records (TapeCommand MARK);
backward() then runs the adjoints in segments: BACKWARD down to the newest marker, the
callback, BACKWARD from that marker down to the next, and so on.
"""
from __future__ import annotations

import itertools
import os
import threading

import numpy as np

from .launch import adjoint_arguments, caller_origin, is_weft_array, pack_arguments
from .structs import StructInstance

_state = threading.local()


def _stack() -> list:
    stack = getattr(_state, "stack", None)
    if stack is None:
        stack = _state.stack = []
    return stack


def _begin_for_frameworks():
    """Gradients may live in memory Torch/JAX hold (weft.interop): the backward pass waits
    for the frameworks' GPU work on it. Returns what _finish_for_frameworks needs."""
    from weft import _runtime  # noqa: PLC0415
    from weft.interop import cuda_order, memory  # noqa: PLC0415

    if not memory.any_shared():
        return False
    return cuda_order.begin_for_frameworks(_runtime.get_runtime())


def _finish_for_frameworks(begun):
    """Then the frameworks see the pass's results: their streams wait for it on the GPU
    (interprocess events), or it finishes before returning (CPU memory, no events)."""
    from weft import _runtime  # noqa: PLC0415
    from weft.interop import cuda_order, memory  # noqa: PLC0415

    if begun is False and not memory.any_shared():
        return
    cuda_order.finish_for_frameworks(_runtime.get_runtime(), begun or None)


def active_tape():
    stack = _stack()
    return stack[-1] if stack else None


_tape_ids = itertools.count(1)
_daemon_support: dict = {}      # id(runtime) -> bool


def _daemon_tapes_supported(rt) -> bool:
    """Whether this session's daemon runs TapeCommands (probed once with a sync)."""
    from weft.v1 import exec_pb2  # noqa: PLC0415

    if os.environ.get("WEFT_TAPE", "").lower() == "client":
        return False
    if not hasattr(exec_pb2, "TapeCommand"):
        return False
    known = _daemon_support.get(id(rt))
    if known is not None:
        return known
    rt.synchronize()            # errors of earlier commands surface here, not in the probe
    probe_id = next(_tape_ids)
    rt.submit(exec_pb2.Command(tape=exec_pb2.TapeCommand(op=exec_pb2.TapeCommand.FREE,
                                                         tape_id=probe_id)))
    try:
        rt.synchronize()
        supported = True
    except Exception as err:  # noqa: BLE001 - UNIMPLEMENTED or an unknown command kind
        code = getattr(err, "code", None)
        supported = code not in ("UNIMPLEMENTED", "INVALID_ARGUMENT", "INTERNAL", "UNKNOWN", None)
    _daemon_support[id(rt)] = supported
    return supported


class _RecordedLaunch:
    def __init__(self, kernel, dims, args, device, temps, lanes=1):
        self.kernel = kernel
        self.dims = list(dims)
        self.args = list(args)
        self.device = device
        self.temps = list(temps)       # keeps temporary arrays alive for the backward pass
        self.lanes = lanes             # cooperative CPU blocks of this many threads (1: none)


class _RecordedFunc:
    def __init__(self, backward, arrays, marker=0):
        self.backward = backward
        self.arrays = list(arrays)
        self.marker = marker           # daemon tapes: the marker at its place in the records


def _struct_gradients(value):
    """A struct instance of `value`'s type whose array fields are the fields' gradients
    (nested structs likewise; other fields keep their defaults)."""
    out = StructInstance(value._struct_type)
    for name, field_value in value._values.items():
        if isinstance(field_value, StructInstance):
            out._values[name] = _struct_gradients(field_value)
        elif is_weft_array(field_value) and getattr(field_value, "grad", None) is not None:
            out._values[name] = field_value.grad
    return out


class _Gradients(dict):
    """tape.gradients: array -> its gradient array (arrays are keyed by identity)."""

    def __missing__(self, array):
        if isinstance(array, StructInstance):   # Warp: a struct of its fields' gradients
            return _struct_gradients(array)
        grad = getattr(array, "grad", None)
        if grad is None:
            raise KeyError(f"array {array!r} has no gradient (create it with requires_grad=True)")
        return grad

    def __hash__(self):  # pragma: no cover - dicts of arrays only
        return id(self)


class Tape:
    """Records kernel launches for reverse-mode differentiation."""

    def __init__(self):
        self.launches: list = []
        self._scopes: list = []        # (first launch, end launch, depth, name), closed scopes
        self._open_scopes: list = []   # (first launch, name) of scopes still open
        self.gradients = _Gradients()
        self.loss = None
        self.tape_id = next(_tape_ids)
        self._mode = None          # "daemon" | "client", chosen at first use
        self._runtime = None

    def _choose_mode(self):
        if self._mode is None:
            from weft import _runtime  # noqa: PLC0415

            self._runtime = _runtime.get_runtime()
            self._mode = "daemon" if _daemon_tapes_supported(self._runtime) else "client"
        return self._mode

    @property
    def mode(self) -> str:
        return self._choose_mode()

    def _tape_command(self, op, loss=None, seeds=(), marker=0):
        from weft.v1 import exec_pb2  # noqa: PLC0415

        cmd = exec_pb2.TapeCommand(op=op, tape_id=self.tape_id, marker=marker)
        if loss is not None:
            cmd.loss.CopyFrom(loss._ref())
        for array, grad in seeds:
            cmd.seeds.append(exec_pb2.TapeCommand.Seed(array=array._ref(), grad=grad._ref()))
        self._runtime.submit(exec_pb2.Command(tape=cmd, origin=caller_origin()))

    def __enter__(self):
        if _stack():
            raise RuntimeError("Warp: Error, entering a tape while one is already active "
                               "(weft tapes do not nest)")
        if self._choose_mode() == "daemon":
            from weft.v1 import exec_pb2  # noqa: PLC0415

            self._tape_command(exec_pb2.TapeCommand.BEGIN)
        _stack().append(self)
        return self

    def __exit__(self, exc_type, exc, tb):
        stack = _stack()
        if stack and stack[-1] is self:
            stack.pop()
        elif self in stack:
            stack.remove(self)
        if self._mode == "daemon":
            from weft.v1 import exec_pb2  # noqa: PLC0415

            self._tape_command(exec_pb2.TapeCommand.END)
            if stack and stack[-1]._mode == "daemon":   # resume the enclosing tape
                stack[-1]._tape_command(exec_pb2.TapeCommand.BEGIN)
        return False

    def pause_recording(self):
        """Stops the daemon from recording (launches with record_tape=False)."""
        if self._mode == "daemon":
            from weft.v1 import exec_pb2  # noqa: PLC0415

            self._tape_command(exec_pb2.TapeCommand.END)

    def resume_recording(self):
        if self._mode == "daemon":
            from weft.v1 import exec_pb2  # noqa: PLC0415

            self._tape_command(exec_pb2.TapeCommand.BEGIN)

    def __del__(self):
        try:
            if self._mode == "daemon" and self._runtime is not None and not self._runtime.closed:
                from weft.v1 import exec_pb2  # noqa: PLC0415

                self._runtime.submit_from_finalizer(exec_pb2.Command(tape=exec_pb2.TapeCommand(
                    op=exec_pb2.TapeCommand.FREE, tape_id=self.tape_id)))
        except Exception:  # noqa: BLE001 - finalizer: never raise
            pass

    # --- recording ----------------------------------------------------------------------
    def record_launch(self, kernel, dims, args, device, temps=(), lanes=1):
        self.launches.append(_RecordedLaunch(kernel, dims, args, device, temps, lanes))

    def record_func(self, backward, arrays):
        """Records a Python callback to run at its place in the backward pass (Warp's API)."""
        if not callable(backward):
            raise TypeError("record_func expects a callable backward function")
        marker = 0
        if self._choose_mode() == "daemon":
            from weft.v1 import exec_pb2  # noqa: PLC0415
            marker = next(_tape_ids)
            self._tape_command(exec_pb2.TapeCommand.MARK, marker=marker)
        self.launches.append(_RecordedFunc(backward, arrays, marker))

    # --- scopes and visualization ---------------------------------------------------------
    def record_scope_begin(self, scope_name, metadata=None):
        """Opens a named scope around the launches recorded until record_scope_end."""
        self._open_scopes.append((len(self.launches), str(scope_name)))

    def record_scope_end(self, remove_scope_if_empty=True):
        if not self._open_scopes:
            raise RuntimeError("record_scope_end without record_scope_begin")
        first, name = self._open_scopes.pop()
        if first == len(self.launches) and remove_scope_if_empty:
            return
        self._scopes.append((first, len(self.launches), len(self._open_scopes), name))

    def visualize(self, filename=None, simplify_graph=True, hide_readonly_arrays=False,
                  array_labels=None, choose_longest_node_name=True, ignore_graph_scopes=False,
                  track_inputs=None, track_outputs=None, track_input_names=None,
                  track_output_names=None, graph_direction="LR"):
        """The recorded launches as GraphViz DOT text (written to `filename` when given)."""
        from .tape_dot import tape_dot  # noqa: PLC0415

        scopes = self._scopes
        if ignore_graph_scopes:
            self._scopes = []
        try:
            text = tape_dot(self, simplify_graph=simplify_graph, array_labels=array_labels,
                            graph_direction=graph_direction)
        finally:
            self._scopes = scopes
        if filename is not None:
            with open(filename, "w", encoding="utf-8") as f:
                f.write(text)
        return text

    # --- backward -----------------------------------------------------------------------
    def backward(self, loss=None, grads=None):
        """Seeds loss.grad with 1 (or each a.grad with grads[a]) and runs the adjoints of the
        recorded launches in reverse order."""
        from weft import _runtime  # noqa: PLC0415
        from weft.v1 import exec_pb2  # noqa: PLC0415

        from . import module as module_mod  # noqa: PLC0415

        if not self.launches:
            raise RuntimeError("wp.Tape.backward: the tape is empty (no launches were recorded "
                               "inside `with tape:`)")
        self._choose_mode()
        if loss is not None:
            if not is_weft_array(loss):
                raise TypeError(f"backward(loss=...) expects a weft array, got "
                                f"{type(loss).__name__}")
            if getattr(loss, "grad", None) is None:
                raise RuntimeError("backward(loss=...): the loss array has no gradient; create "
                                   "it with requires_grad=True")
            if int(np.prod(loss.shape)) != 1:
                raise RuntimeError(f"backward(loss=...): the loss must have exactly one "
                                   f"element, has shape {tuple(loss.shape)}")
            self.loss = loss
        seeds = []
        for array, grad in (grads or {}).items():
            target = getattr(array, "grad", None)
            if target is None:
                # Warp: the incoming gradient becomes the array's .grad (the daemon's too)
                if not is_weft_array(grad):
                    grad = _as_array_like(array, grad)
                array.grad = grad
                target = array.grad
            if not is_weft_array(grad):
                grad = _as_array_like(target, grad)
            seeds.append((array, grad))
            self.gradients[array] = target
        recording = self in _stack()      # backward() inside `with tape:` pauses recording
        begun = _begin_for_frameworks()
        if self._mode == "daemon":
            if recording:
                self._tape_command(exec_pb2.TapeCommand.END)
            self._tape_command(exec_pb2.TapeCommand.BACKWARD, loss=loss, seeds=seeds)
            for entry in reversed(self.launches):      # record_func callbacks, newest first
                if isinstance(entry, _RecordedFunc):
                    entry.backward()
                    self._tape_command(exec_pb2.TapeCommand.BACKWARD, marker=entry.marker)
            if recording:
                self._tape_command(exec_pb2.TapeCommand.BEGIN)
            self._note_gradients()
            self._reset_read_flags()
            _finish_for_frameworks(begun)
            return
        if loss is not None:
            loss.grad.fill_(1.0)
        for array, grad in seeds:
            _assign(array.grad, grad)
        rt = _runtime.get_runtime()
        for entry in reversed(self.launches):
            if isinstance(entry, _RecordedFunc):
                rt.flush()
                entry.backward()
                continue
            kernel = entry.kernel
            packed, _ = pack_arguments(kernel, entry.device, entry.args)
            adj = adjoint_arguments(kernel, entry.device, entry.args, [])
            compiled, info = module_mod.compile_kernel(kernel, entry.device, backward=True,
                                                       lanes=entry.lanes)
            command = exec_pb2.LaunchCommand(
                module_id=compiled.module_id, kernel=info.name or kernel.name,
                dim=entry.dims, args=packed, adjoint=True, adj_args=adj,
                device=entry.device)
            if entry.lanes > 1:
                command.block_dim = entry.lanes
            rt.submit(exec_pb2.Command(launch=command, origin=caller_origin()))
        self._note_gradients()
        self._reset_read_flags()
        _finish_for_frameworks(begun)

    def _note_gradients(self):
        for entry in self.launches:
            values = entry.args if isinstance(entry, _RecordedLaunch) else entry.arrays
            for value in values:
                if not is_weft_array(value):
                    continue
                try:
                    grad = value.grad
                except Exception:  # noqa: BLE001 - an array freed in the daemon (Describe
                    continue       # fails): the BACKWARD itself reports it at the next sync
                if grad is not None:
                    self.gradients.setdefault(value, grad)

    # --- clearing -----------------------------------------------------------------------
    def _arrays_with_grad(self) -> list:
        seen, out = set(), []

        def visit(value):
            if is_weft_array(value):
                grad = getattr(value, "grad", None)
                if grad is not None and id(grad) not in seen:
                    seen.add(id(grad))
                    out.append(grad)
            elif isinstance(value, StructInstance):
                for v in value._values.values():
                    visit(v)

        for entry in self.launches:
            for value in (entry.args if isinstance(entry, _RecordedLaunch) else entry.arrays):
                visit(value)
        for array, grad in list(self.gradients.items()):
            visit(array)
            if id(grad) not in seen:
                seen.add(id(grad))
                out.append(grad)
        return out

    def zero(self):
        """Sets every gradient array the tape has touched to zero."""
        if self._mode == "daemon":
            from weft.v1 import exec_pb2  # noqa: PLC0415

            self._tape_command(exec_pb2.TapeCommand.ZERO)
            for array, grad in list(self.gradients.items()):
                grad.zero_()
            return
        for grad in self._arrays_with_grad():
            grad.zero_()
        if self.loss is not None and getattr(self.loss, "grad", None) is not None:
            self.loss.grad.zero_()

    def _reset_read_flags(self):
        """wp.config.verify_autograd_array_access: a backward pass (or reset) consumes the
        reads recorded on this tape; the arrays (and those they view) are unmarked."""
        from .. import config as _config  # noqa: PLC0415

        if not _config.verify_autograd_array_access:
            return
        arrays = [a for entry in self.launches
                  for a in (entry.args if isinstance(entry, _RecordedLaunch) else entry.arrays)]
        for a in arrays + list(self.gradients):
            while is_weft_array(a):
                a.mark_init()
                a = a._view_of

    def reset(self):
        """Zeroes the gradients and forgets the recorded launches."""
        self._reset_read_flags()
        if self._mode == "daemon":
            from weft.v1 import exec_pb2  # noqa: PLC0415

            self._tape_command(exec_pb2.TapeCommand.RESET)
            for array, grad in list(self.gradients.items()):
                grad.zero_()
        else:
            self.zero()
        self.launches.clear()
        self._scopes.clear()
        self._open_scopes.clear()
        self.gradients.clear()
        self.loss = None


def _as_array_like(target, value):
    import weft  # noqa: PLC0415

    data = np.asarray(value)
    return weft.array(data.reshape(tuple(target.shape) + data.shape[len(target.shape):])
                      if data.size else data, dtype=target.dtype, device=target.device)


def _assign(target, value):
    import weft  # noqa: PLC0415

    if is_weft_array(value):
        weft.copy(target, value)
        return
    data = np.asarray(value)
    temp = weft.array(data.reshape(tuple(target.shape) + data.shape[len(target.shape):])
                      if data.size else data, dtype=target.dtype, device=target.device)
    weft.copy(target, temp)
