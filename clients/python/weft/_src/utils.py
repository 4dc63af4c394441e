"""`warp._src.utils`: helpers Warp's tests import from Warp's private utilities."""
from __future__ import annotations

from ..device import get_cuda_devices
from ..mempool import is_peer_access_supported


def check_p2p() -> bool:
    """True when every pair of CUDA devices can access each other's memory."""
    devices = get_cuda_devices()
    return all(is_peer_access_supported(a, b) for a in devices for b in devices if a != b)
