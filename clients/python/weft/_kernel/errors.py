"""Exceptions of the kernel API: compile errors carrying the daemon's diagnostics, and argument
errors raised before anything is sent."""
from __future__ import annotations


def _weft_error_base():
    """weft.WeftError (engineer B1's base class) when it exists, else RuntimeError."""
    try:
        from weft.errors import WeftError  # noqa: PLC0415 - engineer B1's base class
        return WeftError
    except Exception:  # noqa: BLE001 - the runtime layer may not define it (yet)
        pass
    try:
        import weft  # noqa: PLC0415
        base = getattr(weft, "WeftError", None)
        if isinstance(base, type) and issubclass(base, Exception):
            return base
    except Exception:  # noqa: BLE001
        pass
    return RuntimeError


class WeftCompileError(_weft_error_base()):
    """A module failed to compile; the message holds the daemon's diagnostics (file:line)."""

    def __init__(self, message: str, diagnostics=()):
        self._text = message
        try:
            super().__init__(message, "INVALID_ARGUMENT")
        except TypeError:
            super().__init__(message)
        self.diagnostics = list(diagnostics)

    def __str__(self):
        # the diagnostics text alone (B1's WeftError appends the status code)
        return self._text


class WeftLaunchError(TypeError):
    """Wrong arguments to wp.launch (count, type, dtype, ndim), found before sending."""
