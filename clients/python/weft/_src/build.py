"""`warp._src.build`: the kernel cache helper Warp's build module holds."""
from __future__ import annotations

from .._kernel.module import clear_kernel_cache  # noqa: F401
