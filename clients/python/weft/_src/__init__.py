"""Warp's private module names (`warp._src.X`) that Warp programs and Warp's tests import.

Each module here gives the names under Warp's private path from weft's own implementation, for
programs that reach past Warp's public API; a name weft cannot honour (Warp's code generator's
internals) raises a clear error when used. A package that re-exports weft as `warp` reaches these
as `warp._src.X` (see weft/_aliases.py).
"""
