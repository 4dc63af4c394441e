"""Language: @wp.struct values as kernel arguments (scalar, vector, nested struct and array
members), struct locals constructed and modified in a kernel, struct fields read through
attribute chains, and Python-side instances with attribute access."""
import numpy as np
import pytest

import weft as wp


@wp.struct
class Material:
    stiffness: float
    color: wp.vec3


@wp.struct
class Body:
    mass: float
    material: Material
    positions: wp.array(dtype=wp.vec3)
    count: int


@wp.func
def weight(b: Body):
    return b.mass * 9.81


@wp.kernel
def use_struct(b: Body, out: wp.array(dtype=float, ndim=2)):
    i = wp.tid()
    p = b.positions[i]
    out[i, 0] = p[0] * b.material.stiffness
    out[i, 1] = wp.dot(b.material.color, p)
    out[i, 2] = weight(b) + float(b.count)
    b.positions[i] = p * 2.0


@wp.kernel
def local_struct(out: wp.array(dtype=float)):
    i = wp.tid()
    m = Material()
    m.stiffness = float(i) * 0.5
    m.color = wp.vec3(1.0, 2.0, 3.0)
    out[i] = m.stiffness + m.color[2]


def test_struct_argument(wp, rng):
    n = 100
    pos = rng.standard_normal((n, 3)).astype(np.float32)
    b = Body()
    b.mass = 2.5
    b.material.stiffness = 3.0
    b.material.color = wp.vec3(0.5, -1.0, 2.0)
    b.positions = wp.array(pos, dtype=wp.vec3)
    b.count = 7
    out = wp.zeros((n, 3), dtype=float)
    wp.launch(use_struct, dim=n, inputs=[b, out])
    p64 = pos.astype(np.float64)
    ref = np.stack([p64[:, 0] * 3.0, p64 @ np.array([0.5, -1.0, 2.0]),
                    np.full(n, 2.5 * 9.81 + 7)], axis=1)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(b.positions.numpy(), pos * 2)


def test_struct_constructed_in_kernel(wp):
    out = wp.zeros(10, dtype=float)
    wp.launch(local_struct, dim=10, outputs=[out])
    np.testing.assert_allclose(out.numpy(), np.arange(10) * 0.5 + 3.0)


def test_struct_instance_python_side():
    b = Body()
    assert b.mass == 0.0 and b.count == 0 and b.positions is None
    b.material.stiffness = 4.0
    assert b.material.stiffness == 4.0
    with pytest.raises(AttributeError):
        b.not_a_field = 1
