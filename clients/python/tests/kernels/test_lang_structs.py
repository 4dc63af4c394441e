"""Language: @wp.struct values as kernel arguments (scalar, vector, nested struct and array
members), struct locals constructed and modified in a kernel, struct fields read through
attribute chains, Python-side instances with attribute access, and Warp's `.to(device)` of
instances (array members moved, indexed arrays as identity views, a field named "to" kept)."""
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


@wp.struct
class Indexed:
    values: wp.indexedarray(dtype=float)
    scale: float


@wp.struct
class Holder:
    body: Body
    picked: Indexed
    to: int                      # a field named like the method: reads stay the field's


@wp.kernel
def read_indexed(h: Holder, out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = h.picked.values[i] * h.picked.scale + float(h.to)


def test_struct_to_moves_array_members(wp, rng):
    devices = ["cpu"] + [d.alias for d in wp.get_cuda_devices() if d.is_compute_supported][:1]
    values = rng.standard_normal(12).astype(np.float32)
    index = np.sort(rng.choice(12, 5, replace=False)).astype(np.int32)
    h = Holder()
    h.body.positions = wp.array(rng.standard_normal((4, 3)), dtype=wp.vec3, device="cpu")
    h.body.material.color = wp.vec3(1.0, 2.0, 3.0)
    h.picked.values = wp.indexedarray(wp.array(values, device="cpu"), [wp.array(index, dtype=int, device="cpu")])
    h.picked.scale = 2.0
    h.to = 3
    assert h.to == 3
    same = h._to("cpu")          # (Holder has a field named "to": the method is _to)
    assert same.body.positions is h.body.positions and same.picked.values is h.picked.values
    assert same.body.material.color is not h.body.material.color
    for device in devices[1:]:
        moved = h._to(device)
        assert moved.body.positions.device == device
        np.testing.assert_array_equal(moved.body.positions.numpy(), h.body.positions.numpy())
        assert isinstance(moved.picked.values, wp.indexedarray)
        assert all(i is None for i in moved.picked.values.indices)
        out = wp.zeros(5, dtype=float, device=device)
        wp.launch(read_indexed, dim=5, inputs=[moved, out], device=device)
        np.testing.assert_allclose(out.numpy(), values[index] * 2.0 + 3.0, rtol=1e-6)
    plain = Body()
    plain.positions = wp.zeros(2, dtype=wp.vec3, device="cpu")
    assert plain.to("cpu").positions is plain.positions     # no field "to": the method
