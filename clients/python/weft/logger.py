"""Warp's logging interface (wp.Logger, wp.set_logger, wp.get_logger; wp.ScopedLogger and
wp.ScopedLogLevel are in weft.utils): every message the client library gives goes to one
active logger, which a framework may replace by any object with Warp's four methods. The
default writes debug and info lines to the current stdout, warnings through Python's
`warnings` filters to the current stderr as "Warp <Category>: message" (with the caller's
file:line when wp.config.verbose_warnings is set), errors to stderr as "Warp Error: message".
Debug, info and warning messages are gated by wp.config.log_level; errors never are."""
from __future__ import annotations

import linecache
import sys
import warnings
from typing import Protocol, runtime_checkable

from . import config
from .config import LOG_DEBUG, LOG_ERROR, LOG_INFO, LOG_WARNING

__all__ = ["LOG_DEBUG", "LOG_ERROR", "LOG_INFO", "LOG_WARNING", "Logger", "LoggerBasic",
           "get_logger", "log_debug", "log_error", "log_info", "log_warning", "set_logger"]


@runtime_checkable
class Logger(Protocol):
    """What a logger is: any object with these four methods (a Protocol: it is not
    instantiated). `warning` receives a stacklevel already adjusted for a direct
    `warnings.warn(message, category, stacklevel=stacklevel)`."""

    def debug(self, message: str) -> None: ...

    def info(self, message: str) -> None: ...

    def warning(self, message: str, category=None, stacklevel: int = 1) -> None: ...

    def error(self, message: str) -> None: ...


def _validate(logger) -> None:
    # The Protocol's isinstance checks that the attributes exist, not that they are callable.
    if not isinstance(logger, Logger) or not all(
            callable(getattr(logger, name, None)) for name in ("debug", "info", "warning", "error")):
        raise TypeError("logger must implement the Logger protocol (debug(message), info(message), "
                        f"warning(message, category, stacklevel), error(message)), got {type(logger)!r}")


def _format_warning(message, category, filename, lineno, line=None) -> str:
    text = f"Warp {category.__name__}: {message}"
    if config.verbose_warnings:
        text += f" ({filename}:{lineno})"
        if line is None:
            try:
                line = linecache.getline(filename, lineno)
            except Exception:  # noqa: BLE001 - a missing source line only shortens the message
                line = None
        if line:
            text += f"\n  {line.strip()}"
    return text + "\n"


def _show_on_stderr(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(_format_warning(message, category, filename, lineno, line))


class LoggerBasic:
    """The default logger: debug and info to stdout, warnings through `warnings` (user filters
    apply) to stderr, errors to stderr."""

    def debug(self, message: str) -> None:
        sys.stdout.write(message + "\n")

    def info(self, message: str) -> None:
        sys.stdout.write(message + "\n")

    def warning(self, message: str, category=None, stacklevel: int = 1) -> None:
        with warnings.catch_warnings():
            warnings.showwarning = _show_on_stderr
            warnings.warn(message, category, stacklevel=stacklevel)

    def error(self, message: str) -> None:
        sys.stderr.write("Warp Error: " + message + "\n")


_active_logger = LoggerBasic()
_warnings_seen: set = set()


def set_logger(logger) -> None:
    """Makes `logger` (any object with Warp's four logger methods) the active logger; None
    restores the default one. TypeError for an object that is not a logger."""
    global _active_logger
    if logger is None:
        _active_logger = LoggerBasic()
        return
    _validate(logger)
    _active_logger = logger


def get_logger():
    """The active logger."""
    return _active_logger


def log_debug(message: str) -> None:
    if config.log_level <= LOG_DEBUG:
        _active_logger.debug(message)


def log_info(message: str) -> None:
    if config.log_level <= LOG_INFO:
        _active_logger.info(message)


def log_warning(message: str, category=None, stacklevel: int = 1, once: bool = False) -> None:
    """A warning at the caller of the function calling this one (stacklevel 1), when
    wp.config.log_level allows warnings. A DeprecationWarning (any warning with `once`) is
    given once per message and process."""
    if config.log_level > LOG_WARNING:
        return
    dedup = once or category is DeprecationWarning
    if dedup and (category, message) in _warnings_seen:
        return
    # +2: this function and the logger's own frame
    _active_logger.warning(message, category=category, stacklevel=stacklevel + 2)
    if dedup:
        _warnings_seen.add((category, message))


def log_error(message: str) -> None:
    """An error message; never silenced by wp.config.log_level."""
    _active_logger.error(message)
