"""Warnings as Warp gives them: through Python's `warnings` filters, written to the current
stderr as `Warp <Category>: message` (with the caller's file:line when
`wp.config.verbose_warnings` is set); a DeprecationWarning is given once per message and
process. Silenced when `wp.config.log_level` is above LOG_WARNING."""
from __future__ import annotations

import sys
import warnings

from . import config

_warnings_seen: set = set()


def _show(message, category, filename, lineno, file=None, line=None):
    text = f"Warp {category.__name__}: {message}"
    if config.verbose_warnings:
        text += f" ({filename}:{lineno})"
    sys.stderr.write(text + "\n")


def log_warning(message: str, category=UserWarning, stacklevel: int = 1) -> None:
    """Warns at the caller of the function that calls this (stacklevel 1)."""
    if config.log_level > config.LOG_WARNING:
        return
    if category is DeprecationWarning and (category, message) in _warnings_seen:
        return
    with warnings.catch_warnings():
        warnings.showwarning = _show
        warnings.warn(message, category, stacklevel=stacklevel + 2)
    if category is DeprecationWarning:
        _warnings_seen.add((category, message))
