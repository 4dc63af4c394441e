"""Public names of the kernel API, re-exported by weft/__init__.py."""
__all__ = []
