"""Warp's math helpers that are @wp.func in Warp itself (warp.math), written in the kernel
language: vector norms (L1, L2, Huber, pseudo-Huber) and smooth normalization; swing-twist
helpers, Euler angles of quaternions (roll-pitch-yaw, any axis sequence) and the rotation between
two directions (quat_between_vectors, a warp.utils helper in Warp); twists and wrenches
moved between frames; the velocity of a point of a rigid body. Kernels reach them as wp.<name>
(sent with the module like any @wp.func, so the daemon differentiates them); Python calls them
like other @wp.func (eager evaluation where the client supports it)."""
from typing import Any

from .. import types as _t
from .api import func

_vec3 = _t.vector(3, _t.float32)
_vec4 = _t.vector(4, _t.float32)
_quat = _t.quaternion(_t.float32)
_transform = _t.transformation(_t.float32)
_spatial_vector = _t.vector(6, _t.float32)


def norm_l1(v: Any):
    """Sum of the absolute values of the components of v."""
    n = _wp.abs(v[0])
    for i in range(1, len(v)):
        n = n + _wp.abs(v[i])
    return n


def norm_l2(v: Any):
    """Euclidean length of v."""
    return _wp.length(v)


def norm_huber(v: Any, delta: float = 1.0):
    """Huber norm: |v|^2 / 2 while |v| <= delta, then delta * (|v| - delta / 2)."""
    a = _wp.length(v)
    if a <= delta:
        return 0.5 * a * a
    return delta * (a - 0.5 * delta)


def norm_pseudo_huber(v: Any, delta: float = 1.0):
    """Pseudo-Huber norm: delta * sqrt(1 + |v|^2 / delta^2) (smooth everywhere)."""
    return delta * _wp.sqrt(1.0 + _wp.dot(v, v) / (delta * delta))


def smooth_normalize(v: Any, delta: float = 1.0):
    """v divided by its pseudo-Huber norm: a normalization that is smooth at v = 0."""
    return v / norm_pseudo_huber(v, delta)


def quat_twist(axis: _vec3, q: _quat) -> _quat:
    """The twist of q about the unit vector axis (swing-twist decomposition)."""
    along = _wp.dot(_wp.vec3(q[0], q[1], q[2]), axis) * axis
    return _wp.normalize(_wp.quat(along[0], along[1], along[2], q[3]))


def quat_twist_angle(axis: _vec3, q: _quat) -> float:
    """The unsigned angle (radians) of the twist of q about axis."""
    return 2.0 * _wp.atan2(_wp.abs(_wp.dot(axis, _wp.vec3(q[0], q[1], q[2]))), q[3])


def quat_twist_angle_signed(axis: _vec3, q: _quat) -> float:
    """The signed angle (radians, right-hand rule about axis) of the twist of q about axis."""
    return 2.0 * _wp.atan2(_wp.dot(axis, _wp.vec3(q[0], q[1], q[2])), q[3])


def quat_to_rpy(q: _quat) -> _vec3:
    """Roll, pitch, yaw (radians) of q: the inverse of wp.quat_rpy (extrinsic x-y-z)."""
    x = q[0]
    y = q[1]
    z = q[2]
    w = q[3]
    roll = _wp.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = _wp.asin(_wp.clamp(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = _wp.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return _wp.vec3(roll, pitch, yaw)


def quat_from_euler(e: _vec3, i: int, j: int, k: int) -> _quat:
    """The rotation by e[i] about axis i, then e[j] about axis j, then e[k] about axis k (fixed
    axes): qk * qj * qi. For i == k, e[i] is the angle of both the first and the third rotation."""
    vi = _wp.vec3(0.0)
    vi[i] = _wp.sin(0.5 * e[i])
    vj = _wp.vec3(0.0)
    vj[j] = _wp.sin(0.5 * e[j])
    vk = _wp.vec3(0.0)
    vk[k] = _wp.sin(0.5 * e[k])
    qi = _wp.quat(vi[0], vi[1], vi[2], _wp.cos(0.5 * e[i]))
    qj = _wp.quat(vj[0], vj[1], vj[2], _wp.cos(0.5 * e[j]))
    qk = _wp.quat(vk[0], vk[1], vk[2], _wp.cos(0.5 * e[k]))
    return _wp.mul(qk, _wp.mul(qj, qi))


def quat_to_euler(q: _quat, i: int, j: int, k: int) -> _vec3:
    """Euler angles (radians) of q for the fixed-axis sequence i, j, k, as quat_from_euler takes
    them. Tait-Bryan sequences (i != k): e is indexed by axis, the second angle in [-pi/2, pi/2].
    Proper Euler sequences (i == k): e[i] holds the first angle, e[j] the second (in [0, pi]),
    e[3 - i - j] the third. At gimbal lock the first angle is 0. Computed from the quaternion
    directly (Bernardes and Viollet's method), without a rotation matrix."""
    w = _wp.vec4(q[3], q[0], q[1], q[2])    # scalar first: w[1 + axis] is the axis component
    a1 = i + 1
    a2 = j + 1
    a3 = k + 1
    proper = a1 == a3
    if proper:
        a3 = 6 - a1 - a2
    eps = float((a1 - a2) * (a2 - a3) * (a3 - a1)) * 0.5
    a = w[0]
    b = w[a1]
    c = w[a2]
    d = w[a3] * eps
    if not proper:
        a = w[0] - w[a2]
        b = w[a1] + w[a3] * eps
        c = w[a2] + w[0]
        d = w[a3] * eps - w[a1]
    second = 2.0 * _wp.atan2(_wp.sqrt(c * c + d * d), _wp.sqrt(a * a + b * b))
    half_sum = _wp.atan2(b, a)
    half_diff = _wp.atan2(d, c)
    first = half_sum - half_diff
    third = half_sum + half_diff
    if _wp.abs(second) < 1.0e-6:
        first = 0.0
        third = 2.0 * half_sum
    elif _wp.abs(second - _wp.pi) < 1.0e-6:
        first = 0.0
        third = 2.0 * half_diff
    out = _wp.vec3(0.0)
    if proper:
        out[i] = first
        out[j] = second
        out[3 - i - j] = third
    else:
        out[i] = first
        out[j] = second - 0.5 * _wp.pi
        out[k] = eps * third
    return out


def transform_twist(t: _transform, x: _spatial_vector) -> _spatial_vector:
    """The twist x = (angular w, linear v) of the source frame in t's destination frame:
    (R w, R v + p x R w)."""
    q = _wp.transform_get_rotation(t)
    w = _wp.quat_rotate(q, _wp.spatial_top(x))
    v = _wp.quat_rotate(q, _wp.spatial_bottom(x)) + _wp.cross(_wp.transform_get_translation(t), w)
    return _wp.spatial_vector(w, v)


def transform_wrench(t: _transform, x: _spatial_vector) -> _spatial_vector:
    """The wrench x = (torque tau, force f) of the source frame in t's destination frame:
    (R tau + p x R f, R f)."""
    q = _wp.transform_get_rotation(t)
    f = _wp.quat_rotate(q, _wp.spatial_bottom(x))
    tau = _wp.quat_rotate(q, _wp.spatial_top(x)) + _wp.cross(_wp.transform_get_translation(t), f)
    return _wp.spatial_vector(tau, f)


def quat_between_vectors(a: _vec3, b: _vec3) -> _quat:
    """The shortest-arc rotation taking the direction of a onto the direction of b (Warp's
    warp.utils helper; opposite directions are not handled, as in Warp)."""
    a = _wp.normalize(a)
    b = _wp.normalize(b)
    c = _wp.cross(a, b)
    d = _wp.dot(a, b)
    q = _wp.quat(c[0], c[1], c[2], 1.0 + d)
    return _wp.normalize(q)


def velocity_at_point(qd: _spatial_vector, r: _vec3) -> _vec3:
    """Velocity of the point at offset r of a body moving with twist qd = (angular, linear)."""
    return _wp.cross(_wp.spatial_top(qd), r) + _wp.spatial_bottom(qd)


import weft as _wp  # noqa: E402 - the kernel code above names builtins as _wp.<name>

(norm_l1, norm_l2, norm_huber, norm_pseudo_huber, smooth_normalize, quat_twist, quat_twist_angle,
 quat_twist_angle_signed, quat_to_rpy, quat_from_euler, quat_to_euler, quat_between_vectors,
 transform_twist, transform_wrench, velocity_at_point) = (
    func(f) for f in (norm_l1, norm_l2, norm_huber, norm_pseudo_huber, smooth_normalize, quat_twist,
                      quat_twist_angle, quat_twist_angle_signed, quat_to_rpy, quat_from_euler,
                      quat_to_euler, quat_between_vectors, transform_twist, transform_wrench,
                      velocity_at_point))
