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


class WarpCodegenTypeError(WeftCompileError, TypeError):
    """A compile error about a value of the wrong type (also a TypeError, as Warp's)."""


class WarpCodegenValueError(WeftCompileError, ValueError):
    """A compile error about a value outside the allowed set (also a ValueError, as Warp's)."""


class WarpCodegenAttributeError(WeftCompileError, AttributeError):
    """A compile error about a missing attribute (also an AttributeError, as Warp's)."""


class WarpCodegenIndexError(WeftCompileError, IndexError):
    """A compile error about an index out of range (also an IndexError, as Warp's)."""


class WarpCodegenKeyError(WeftCompileError, KeyError):
    """A compile error about an unknown key (also a KeyError, as Warp's)."""


_BY_KIND = {"type": WarpCodegenTypeError, "value": WarpCodegenValueError,
            "attribute": WarpCodegenAttributeError, "index": WarpCodegenIndexError,
            "key": WarpCodegenKeyError}


def compile_error(message: str, diagnostics=()) -> WeftCompileError:
    """The exception for a failed compile: the class named by the last error diagnostic's
    `kind` (the one whose message ends the text), WeftCompileError when it names none."""
    errors = [d for d in diagnostics if getattr(d, "severity", 0) == 0]
    kind = getattr(errors[-1], "kind", "") if errors else ""
    return _BY_KIND.get(kind, WeftCompileError)(message, diagnostics)


class WeftLaunchError(TypeError, RuntimeError):
    """Wrong arguments to wp.launch (count, type, dtype, ndim), found before sending. A
    TypeError, and a RuntimeError as Warp raises for an array argument that does not match."""
