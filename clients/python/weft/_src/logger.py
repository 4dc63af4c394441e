"""`warp._src.logger`: Warp's logging module under its private path (weft.logger)."""
from __future__ import annotations

from ..logger import (LOG_DEBUG, LOG_ERROR, LOG_INFO, LOG_WARNING, Logger,  # noqa: F401
                      LoggerBasic, _warnings_seen, get_logger, log_debug, log_error, log_info,
                      log_warning, set_logger)
