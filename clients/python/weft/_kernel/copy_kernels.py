"""Copies recorded on a wp.Tape: while a tape records, wp.copy / wp.clone / array.assign of
differentiable arrays run as these generic kernels (one per dimension count), so the tape
replays their adjoint like any launch: the source's gradient receives the destination's."""
from __future__ import annotations

from typing import Any

import weft as wp


@wp.kernel
def copy_1d(dst: wp.array(dtype=Any), src: wp.array(dtype=Any)):
    i = wp.tid()
    dst[i] = src[i]


@wp.kernel
def copy_2d(dst: wp.array2d(dtype=Any), src: wp.array2d(dtype=Any)):
    i, j = wp.tid()
    dst[i, j] = src[i, j]


@wp.kernel
def copy_3d(dst: wp.array3d(dtype=Any), src: wp.array3d(dtype=Any)):
    i, j, k = wp.tid()
    dst[i, j, k] = src[i, j, k]


@wp.kernel
def copy_4d(dst: wp.array4d(dtype=Any), src: wp.array4d(dtype=Any)):
    i, j, k, m = wp.tid()
    dst[i, j, k, m] = src[i, j, k, m]


_BY_NDIM = {1: copy_1d, 2: copy_2d, 3: copy_3d, 4: copy_4d}
for _k in _BY_NDIM.values():
    _k.__dict__["_weft_internal"] = True    # wp.copy checks array access itself (as a copy)


def launch_copy(dst, src) -> None:
    """dst = src (equal shapes) as a kernel launch, recorded on the active tape."""
    wp.launch(_BY_NDIM[dst.ndim], dim=dst.shape, inputs=[dst, src], device=dst.device)
