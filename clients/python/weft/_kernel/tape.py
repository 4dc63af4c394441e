"""wp.Tape: records the launches made inside `with wp.Tape() as tape:` and replays their
adjoint kernels in reverse order on backward(); zero(), reset(), gradients[a] as in Warp.
The recording is kept per client process (= per daemon session); each backward step is an
adjoint LaunchCommand in the session's batch, so the daemon runs them in order."""
from __future__ import annotations

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


def active_tape():
    stack = _stack()
    return stack[-1] if stack else None


class _RecordedLaunch:
    def __init__(self, kernel, dims, args, device, temps):
        self.kernel = kernel
        self.dims = list(dims)
        self.args = list(args)
        self.device = device
        self.temps = list(temps)       # keeps temporary arrays alive for the backward pass


class _RecordedFunc:
    def __init__(self, backward, arrays):
        self.backward = backward
        self.arrays = list(arrays)


class _Gradients(dict):
    """tape.gradients: array -> its gradient array (arrays are keyed by identity)."""

    def __missing__(self, array):
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
        self.gradients = _Gradients()
        self.loss = None

    def __enter__(self):
        if self in _stack():
            raise RuntimeError("this wp.Tape is already recording")
        _stack().append(self)
        return self

    def __exit__(self, exc_type, exc, tb):
        stack = _stack()
        if stack and stack[-1] is self:
            stack.pop()
        elif self in stack:
            stack.remove(self)
        return False

    # --- recording ----------------------------------------------------------------------
    def record_launch(self, kernel, dims, args, device, temps=()):
        self.launches.append(_RecordedLaunch(kernel, dims, args, device, temps))

    def record_func(self, backward, arrays):
        """Records a Python callback to run at its place in the backward pass (Warp's API)."""
        self.launches.append(_RecordedFunc(backward, arrays))

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
            loss.grad.fill_(1.0)
        for array, grad in (grads or {}).items():
            target = getattr(array, "grad", None)
            if target is None:
                raise RuntimeError("backward(grads=...): an array in grads has no gradient; "
                                   "create it with requires_grad=True")
            _assign(target, grad)
            self.gradients[array] = target
        rt = _runtime.get_runtime()
        for entry in reversed(self.launches):
            if isinstance(entry, _RecordedFunc):
                rt.flush()
                entry.backward()
                continue
            kernel = entry.kernel
            packed, _ = pack_arguments(kernel, entry.device, entry.args)
            adj = adjoint_arguments(kernel, entry.device, entry.args, [])
            compiled, info = module_mod.compile_kernel(kernel, entry.device, backward=True)
            rt.submit(exec_pb2.Command(
                launch=exec_pb2.LaunchCommand(
                    module_id=compiled.module_id, kernel=info.name or kernel.name,
                    dim=entry.dims, args=packed, adjoint=True, adj_args=adj,
                    device=entry.device),
                origin=caller_origin()))
            for value in entry.args:
                if is_weft_array(value) and getattr(value, "grad", None) is not None:
                    self.gradients.setdefault(value, value.grad)

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
        for grad in self._arrays_with_grad():
            grad.zero_()

    def reset(self):
        """Zeroes the gradients and forgets the recorded launches."""
        self.zero()
        self.launches.clear()
        self.gradients.clear()
        self.loss = None


def _assign(target, value):
    import weft  # noqa: PLC0415

    if is_weft_array(value):
        weft.copy(target, value)
        return
    data = np.asarray(value)
    temp = weft.array(data.reshape(tuple(target.shape) + data.shape[len(target.shape):])
                      if data.size else data, dtype=target.dtype, device=target.device)
    weft.copy(target, temp)
