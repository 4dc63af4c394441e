"""Exceptions of the kernel API: compile errors carrying the daemon's diagnostics, and argument
errors raised before anything is sent."""
from __future__ import annotations

from weft.errors import WeftError


class WarpCodegenError(WeftError):
    """Warp's name for a kernel that failed to compile (a RuntimeError)."""


class WeftCompileError(WarpCodegenError):
    """A module failed to compile; the message holds the daemon's diagnostics (file:line)."""

    def __init__(self, message: str, diagnostics=()):
        self._text = message
        super().__init__(message, "INVALID_ARGUMENT")
        self.diagnostics = list(diagnostics)

    def __str__(self):
        # the diagnostics text alone (WeftError's own text appends the status code)
        return self._text


class WeftLaunchError(TypeError):
    """Wrong arguments to wp.launch (count, type, dtype, ndim), found before sending."""
