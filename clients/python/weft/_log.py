"""The library's own warnings: through the active logger (weft.logger: Warp's "Warp <Category>:
message" on the current stderr through Python's `warnings` filters by default); a
DeprecationWarning is given once per message and process. Silenced when `wp.config.log_level`
is above LOG_WARNING."""
from __future__ import annotations

from . import logger as _logger


def log_warning(message: str, category=UserWarning, stacklevel: int = 1) -> None:
    """Warns at the caller of the function that calls this (stacklevel 1)."""
    # +2: this function and the function calling it (weft.logger adds its own frames)
    _logger.log_warning(message, category=category, stacklevel=stacklevel + 2)
