"""`wp.examples`: where example programs find their assets, as Warp's `warp.examples`.

weft's example programs live in clients/python/examples; the assets they and users' programs load
(meshes, volumes) live in weft/examples/assets. Warp's own asset files (its USD scenes) are not part
of weft: a program that opens one of them by name finds no such file here.
"""
from __future__ import annotations

import os


def get_asset_directory() -> str:
    """The directory of example assets."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), "assets")


def get_source_directory() -> str:
    """The directory of this package."""
    return os.path.dirname(os.path.abspath(__file__))
