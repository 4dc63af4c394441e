"""Kernel-side Python API of weft: @wp.kernel, @wp.func, @wp.struct, wp.launch, wp.Tape."""
