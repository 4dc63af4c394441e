"""Warp's transform helpers that are @wp.func in Warp itself (not native builtins), for
float16/32/64: wp.transform_compose(p, q, s) -> 4x4 matrix [s-scaled rotation | p],
wp.transform_decompose(m) -> (p, q, s), wp.transform_from_matrix(m) -> transform,
wp.transform_to_matrix(t) -> 4x4 matrix. Kernels reach them as wp.<name> (the client sends them
with the module like any @wp.func, so the daemon differentiates them)."""

from .. import types as _t
from .api import func


def _make(dtype):
    # The bodies name no closure values (each dtype's overload shares these names): result
    # types come from the arguments, literals adapt to them.
    vec3 = _t.vector(3, dtype)
    mat44 = _t.matrix((4, 4), dtype)
    quat = _t.quaternion(dtype)
    transform = _t.transformation(dtype)

    def transform_compose(position: vec3, rotation: quat, scale: vec3) -> mat44:
        r = _wp.quat_to_matrix(rotation)
        return _wp.types.matrix(scale[0] * r[0, 0], scale[1] * r[0, 1], scale[2] * r[0, 2], position[0],
                                scale[0] * r[1, 0], scale[1] * r[1, 1], scale[2] * r[1, 2], position[1],
                                scale[0] * r[2, 0], scale[1] * r[2, 1], scale[2] * r[2, 2], position[2],
                                0.0, 0.0, 0.0, 1.0, shape=(4, 4))

    def transform_decompose(m: mat44):
        position = _wp.types.vector(m[0, 3], m[1, 3], m[2, 3])
        sx = _wp.sqrt(m[0, 0] * m[0, 0] + m[1, 0] * m[1, 0] + m[2, 0] * m[2, 0])
        sy = _wp.sqrt(m[0, 1] * m[0, 1] + m[1, 1] * m[1, 1] + m[2, 1] * m[2, 1])
        sz = _wp.sqrt(m[0, 2] * m[0, 2] + m[1, 2] * m[1, 2] + m[2, 2] * m[2, 2])
        ix = sx * 0.0 + 1.0
        iy = ix
        iz = ix
        if sx != 0.0:
            ix = 1.0 / sx
        if sy != 0.0:
            iy = 1.0 / sy
        if sz != 0.0:
            iz = 1.0 / sz
        rot = _wp.types.matrix(m[0, 0] * ix, m[0, 1] * iy, m[0, 2] * iz,
                               m[1, 0] * ix, m[1, 1] * iy, m[1, 2] * iz,
                               m[2, 0] * ix, m[2, 1] * iy, m[2, 2] * iz, shape=(3, 3))
        return position, _wp.quat_from_matrix(rot), _wp.types.vector(sx, sy, sz)

    def transform_from_matrix(mat: mat44) -> transform:
        p = _wp.types.vector(mat[0, 3], mat[1, 3], mat[2, 3])
        return _wp.transformation(p, _wp.quat_from_matrix(mat))

    def transform_to_matrix(xform: transform) -> mat44:
        p = _wp.transform_get_translation(xform)
        r = _wp.quat_to_matrix(_wp.transform_get_rotation(xform))
        return _wp.types.matrix(r[0, 0], r[0, 1], r[0, 2], p[0],
                                r[1, 0], r[1, 1], r[1, 2], p[1],
                                r[2, 0], r[2, 1], r[2, 2], p[2],
                                0.0, 0.0, 0.0, 1.0, shape=(4, 4))

    return transform_compose, transform_decompose, transform_from_matrix, transform_to_matrix


import weft as _wp  # noqa: E402 - the kernel code above names builtins as _wp.<name>

for _dtype in (_t.float32, _t.float16, _t.float64):
    _fns = [func(f) for f in _make(_dtype)]
transform_compose, transform_decompose, transform_from_matrix, transform_to_matrix = _fns
del _dtype, _fns
