"""weft: Warp-compatible Python client of the weftd compute daemon."""
