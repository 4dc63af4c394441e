"""Interoperability with other array frameworks (NumPy, DLPack, PyTorch, JAX, Paddle): one
module per framework, re-exported from `weft` with Warp's names. See docs/interop.md.

Submodules: memory (weft memory behind foreign addresses; memory shared with frameworks),
external (foreign arrays as weft arrays, launch arguments), dlpack, torch, jax, paddle. The
framework modules import their framework only when called.
"""
