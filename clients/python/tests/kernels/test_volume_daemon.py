"""The daemon side of wp.Volume (docs/geometry.md, "Volumes"), driven through the raw
CREATE_VOLUME operation (independent of the client's NanoVDB and allocation code): lookups,
closest and trilinear sampling, spatial gradients, stores, voxel indices and index sampling, the
transforms and the adjoints, against a float64 NumPy reference on random sparse leaves (negative
coordinates, gaps between leaves, values spanning 1e-3..1e3, a rotated anisotropic transform);
and the attacks: malformed or mismatched leaves, masks, values, backgrounds and transforms at
creation, other objects' ids, value-type mismatches and a voxel_data array too short for the
volume's indices in kernels. Tolerances: float32 lookups exact, trilinear samples 1e-5 relative
to the largest value involved, gradients 1e-3 relative."""
import struct

import numpy as np
import pytest

import weft as wp
from weft import geometry

DEV = "cpu"


@pytest.fixture(autouse=True)
def _on_device(device):
    global DEV
    DEV = device


def _rt():
    from weft import _runtime
    return _runtime.get_runtime() if hasattr(_runtime, "get_runtime") else _runtime.current_runtime()


def _h(a):
    return geometry._handle_of(a, "array")


class RawVolume:
    """A volume made with CREATE_VOLUME from NumPy leaves, masks and values, with the float64
    reference lookups used to check kernels."""

    def __init__(self, origins, masks, values=None, value_type=1, background=b"", transform=None, dtype=wp.float32):
        self.origins = np.asarray(origins, dtype=np.int32).reshape(-1, 3)
        self.masks = np.asarray(masks, dtype=np.uint64).reshape(-1, 8)
        self.values = values
        self.transform = np.asarray(transform if transform is not None else np.eye(3).ravel().tolist() + [0, 0, 0],
                                    dtype=np.float64)
        self.leaves = wp.array(self.origins, dtype=wp.int32, device=DEV)
        self.mask_array = wp.array(self.masks, dtype=wp.uint64, device=DEV)
        self.value_array = None if values is None else wp.array(values, dtype=dtype, device=DEV)
        self.id = geometry._call(_rt(), op=8, leaves=_h(self.leaves), masks=_h(self.mask_array),
                                 values=0 if values is None else _h(self.value_array), value_type=value_type,
                                 background=background, transform=self.transform.tolist())
        self.key = {tuple(o // 8): n for n, o in enumerate(self.origins)}

    def leaf_of(self, ijk):
        return self.key.get(tuple(np.floor_divide(np.asarray(ijk), 8)), -1)

    def offset(self, ijk):
        i, j, k = (int(c) & 7 for c in ijk)
        return i * 64 + j * 8 + k

    def __del__(self):
        try:
            _rt().free_geometry_later(self.id)
        except Exception:  # noqa: BLE001 - session gone at interpreter exit
            pass


def _random_leaves(rng, n_keys=40):
    keys = set()
    while len(keys) < n_keys:
        keys.add(tuple(int(c) for c in rng.integers(-3, 3, size=3)))
    return np.array(sorted(keys), dtype=np.int32) * 8


def _random_transform(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    scale = np.diag(rng.uniform(0.1, 2.0, size=3))
    m = q @ scale
    return m, rng.uniform(-5, 5, size=3)


@wp.kernel
def sample_scalar(vol: wp.uint64, uvw: wp.array(dtype=wp.vec3), closest: wp.array(dtype=float),
                  linear: wp.array(dtype=float), grads: wp.array(dtype=wp.vec3), looked: wp.array(dtype=float)):
    t = wp.tid()
    p = uvw[t]
    closest[t] = wp.volume_sample(vol, p, wp.Volume.CLOSEST, dtype=float)
    linear[t] = wp.volume_sample_f(vol, p, wp.Volume.LINEAR)
    g = wp.vec3()
    v = wp.volume_sample_grad_f(vol, p, wp.Volume.LINEAR, g)
    grads[t] = g
    wp.expect_eq(v, linear[t])
    looked[t] = wp.volume_lookup_f(vol, int(wp.floor(p[0])), int(wp.floor(p[1])), int(wp.floor(p[2])))


def _reference(vol, background, p):
    """Closest value, trilinear value and gradient at p (float64)."""
    def value(ijk):
        leaf = vol.leaf_of(ijk)
        return background if leaf < 0 else float(vol.values[leaf * 512 + vol.offset(ijk)])
    closest = value(np.sign(p) * np.floor(np.abs(p) + 0.5))   # roundf: half away from zero
    base = np.floor(p)
    f = p - base
    val, grad = 0.0, np.zeros(3)
    for c in range(8):
        o = np.array([(c >> 2) & 1, (c >> 1) & 1, c & 1])
        w = np.where(o == 1, f, 1 - f)
        v = value(base + o)
        val += w.prod() * v
        for d in range(3):
            grad[d] += (1 if o[d] else -1) * np.prod(np.delete(w, d)) * v
    return closest, val, grad, value(base)


def test_scalar_sampling_matches_float64_reference(rng):
    origins = _random_leaves(rng)
    n = len(origins)
    values = (rng.uniform(1e-3, 1e3, size=n * 512) * rng.choice([-1, 1], size=n * 512)).astype(np.float32)
    bg = float(rng.uniform(-10, 10))
    vol = RawVolume(origins, np.full((n, 8), np.uint64(2**64 - 1)), values, 1, struct.pack("<f", bg))
    pts = rng.uniform(-28, 28, size=(300, 3))
    pts[:20] = np.round(pts[:20]) + 0.5            # exact halves: round away from zero
    pts[20:40] = np.round(pts[20:40])               # on voxel centres
    uvw = wp.array(pts.astype(np.float32), dtype=wp.vec3, device=DEV)
    outs = [wp.zeros(len(pts), dtype=float, device=DEV) for _ in range(2)]
    grads = wp.zeros(len(pts), dtype=wp.vec3, device=DEV)
    looked = wp.zeros(len(pts), dtype=float, device=DEV)
    wp.launch(sample_scalar, dim=len(pts), inputs=[vol.id, uvw, outs[0], outs[1], grads, looked], device=DEV)
    p32 = pts.astype(np.float32).astype(np.float64)
    for t in range(len(pts)):
        closest, val, grad, corner = _reference(vol, bg, p32[t])
        scale = max(abs(bg), np.abs(values).max())
        assert outs[0].numpy()[t] == np.float32(closest)
        assert looked.numpy()[t] == np.float32(corner)
        assert abs(outs[1].numpy()[t] - val) <= 1e-5 * scale, (t, p32[t])
        np.testing.assert_allclose(grads.numpy()[t], grad, atol=1e-5 * scale)


@wp.kernel
def typed_roundtrip_v3d(vol: wp.uint64, ijk: wp.array(dtype=wp.vec3i), new: wp.array(dtype=wp.vec3d),
                        before: wp.array(dtype=wp.vec3d), after: wp.array(dtype=wp.vec3d)):
    t = wp.tid()
    c = ijk[t]
    before[t] = wp.volume_lookup(vol, c[0], c[1], c[2], dtype=wp.vec3d)
    wp.volume_store(vol, c[0], c[1], c[2], new[t])


@wp.kernel
def typed_read_v3d(vol: wp.uint64, ijk: wp.array(dtype=wp.vec3i), after: wp.array(dtype=wp.vec3d)):
    t = wp.tid()
    c = ijk[t]
    after[t] = wp.volume_lookup(vol, c[0], c[1], c[2], dtype=wp.vec3d)


def test_vec3d_stores_land_in_leaves_only(rng):
    origins = _random_leaves(rng, 10)
    n = len(origins)
    values = rng.uniform(-1e3, 1e3, size=(n * 512, 3))
    bg = np.array([1.5, -2.5, 1e-3])
    vol = RawVolume(origins, np.zeros((n, 8), dtype=np.uint64), values, 7, struct.pack("<3d", *bg),
                    dtype=wp.vec3d)
    ijk = rng.integers(-30, 30, size=(200, 3)).astype(np.int32)
    new = rng.uniform(-1e3, 1e3, size=(200, 3))
    _, first = np.unique(ijk, axis=0, return_index=True)     # one store per voxel
    ijk, new = ijk[np.sort(first)], new[np.sort(first)]
    m = len(ijk)
    a_ijk = wp.array(ijk, dtype=wp.vec3i, device=DEV)
    before = wp.zeros(m, dtype=wp.vec3d, device=DEV)
    after = wp.zeros(m, dtype=wp.vec3d, device=DEV)
    wp.launch(typed_roundtrip_v3d, dim=m, inputs=[vol.id, a_ijk, wp.array(new, dtype=wp.vec3d, device=DEV), before,
                                                  after], device=DEV)
    wp.launch(typed_read_v3d, dim=m, inputs=[vol.id, a_ijk, after], device=DEV)
    stored = vol.value_array.numpy()
    for t in range(m):
        leaf = vol.leaf_of(ijk[t])
        if leaf < 0:
            np.testing.assert_array_equal(before.numpy()[t], bg)
            np.testing.assert_array_equal(after.numpy()[t], bg)   # a store outside the leaves does nothing
        else:
            np.testing.assert_array_equal(before.numpy()[t], values[leaf * 512 + vol.offset(ijk[t])])
            np.testing.assert_array_equal(after.numpy()[t], new[t])
            np.testing.assert_array_equal(stored[leaf * 512 + vol.offset(ijk[t])], new[t])


@wp.kernel
def index_lookup(vol: wp.uint64, ijk: wp.array(dtype=wp.vec3i), out: wp.array(dtype=int), count: wp.array(dtype=int)):
    t = wp.tid()
    c = ijk[t]
    out[t] = wp.volume_lookup_index(vol, c[0], c[1], c[2])
    count[0] = wp.volume_voxel_count(vol)


@wp.kernel
def index_sample(vol: wp.uint64, xyz: wp.array(dtype=wp.vec3), data: wp.array(dtype=float), out: wp.array(dtype=float)):
    t = wp.tid()
    p = wp.volume_world_to_index(vol, xyz[t])
    g = wp.vec3()
    v = wp.volume_sample_grad_index(vol, p, wp.Volume.LINEAR, data, -7.0, g)
    out[t] = v + 0.5 * wp.volume_sample_index(vol, p, wp.Volume.LINEAR, data, -7.0)


@pytest.mark.parametrize("value_type", [19, 20])   # Index, OnIndex
def test_index_grids_and_gradients_into_voxel_data(rng, value_type):
    origins = _random_leaves(rng, 12)
    n = len(origins)
    masks = rng.integers(0, 2**63, size=(n, 8), dtype=np.int64).astype(np.uint64) * np.uint64(2) + \
        rng.integers(0, 2, size=(n, 8)).astype(np.uint64)
    m, t = _random_transform(rng)
    vol = RawVolume(origins, masks, None, value_type, b"", m.ravel().tolist() + t.tolist())
    bits = np.unpackbits(masks.view(np.uint8).reshape(n, 8, 8)[:, :, ::-1], axis=2)[:, :, ::-1].reshape(n, 512)
    rank = np.cumsum(bits.ravel()) - 1
    def ref_index(ijk):
        leaf = vol.leaf_of(ijk)
        if leaf < 0:
            return -1
        b = leaf * 512 + vol.offset(ijk)
        if value_type == 19:
            return b
        return int(rank[b]) if bits.ravel()[b] else -1
    ijk = rng.integers(-26, 26, size=(400, 3)).astype(np.int32)
    out = wp.zeros(len(ijk), dtype=int, device=DEV)
    count = wp.zeros(1, dtype=int, device=DEV)
    wp.launch(index_lookup, dim=len(ijk), inputs=[vol.id, wp.array(ijk, dtype=wp.vec3i, device=DEV), out, count],
              device=DEV)
    assert count.numpy()[0] == (n * 512 if value_type == 19 else int(bits.sum()))
    np.testing.assert_array_equal(out.numpy(), [ref_index(c) for c in ijk])
    # sampling an external array through the indices, and its adjoint into that array
    data_np = rng.uniform(-1e2, 1e2, size=count.numpy()[0]).astype(np.float32)
    data = wp.array(data_np, dtype=float, device=DEV, requires_grad=True)
    idx_pts = rng.uniform(-20, 20, size=(50, 3))
    xyz = (idx_pts @ m.T + t).astype(np.float32)
    out = wp.zeros(len(xyz), dtype=float, device=DEV, requires_grad=True)
    xyz_a = wp.array(xyz, dtype=wp.vec3, device=DEV, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(index_sample, dim=len(xyz), inputs=[vol.id, xyz_a, data, out], device=DEV)
    tape.backward(grads={out: wp.ones(len(xyz), dtype=float, device=DEV)})
    want_grad = np.zeros(len(data_np))
    inv = np.linalg.inv(m)
    for q in range(len(xyz)):
        p = inv @ (xyz[q].astype(np.float64) - t)
        base = np.floor(p)
        f = p - base
        val = 0.0
        for c in range(8):
            o = np.array([(c >> 2) & 1, (c >> 1) & 1, c & 1])
            w = np.where(o == 1, f, 1 - f).prod()
            k = ref_index((base + o).astype(np.int64))
            val += w * (data_np[k] if k >= 0 else -7.0)
            if k >= 0:
                want_grad[k] += 1.5 * w
        assert abs(out.numpy()[q] - 1.5 * val) <= 2e-3 * 1e2, q
    np.testing.assert_allclose(data.grad.numpy(), want_grad, atol=2e-3)


@wp.kernel
def world_sample(vol: wp.uint64, xyz: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    t = wp.tid()
    p = wp.volume_world_to_index(vol, xyz[t])
    d = wp.volume_index_to_world_dir(vol, wp.vec3(1.0, 0.0, 0.0))
    out[t] = wp.volume_sample_f(vol, p, wp.Volume.LINEAR) + wp.dot(d, xyz[t])


def test_gradient_through_transform_matches_finite_differences(rng):
    origins = _random_leaves(rng, 30)
    n = len(origins)
    values = rng.uniform(-10, 10, size=n * 512).astype(np.float32)
    m, t = _random_transform(rng)
    vol = RawVolume(origins, np.zeros((n, 8), dtype=np.uint64), values, 1, struct.pack("<f", 0.25),
                    m.ravel().tolist() + t.tolist())
    idx_pts = rng.uniform(-20, 20, size=(40, 3))
    idx_pts = np.floor(idx_pts) + rng.uniform(0.2, 0.8, size=idx_pts.shape)   # away from cell faces
    xyz = (idx_pts @ m.T + t).astype(np.float32)
    xyz_a = wp.array(xyz, dtype=wp.vec3, device=DEV, requires_grad=True)
    out = wp.zeros(len(xyz), dtype=float, device=DEV, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(world_sample, dim=len(xyz), inputs=[vol.id, xyz_a, out], device=DEV)
    tape.backward(grads={out: wp.ones(len(xyz), dtype=float, device=DEV)})
    got = xyz_a.grad.numpy()
    inv = np.linalg.inv(m)
    for q in range(len(xyz)):
        p = inv @ (xyz[q].astype(np.float64) - t)
        _, _, g_idx, _ = _reference(vol, 0.25, p)
        want = inv.T @ g_idx + m[:, 0]
        np.testing.assert_allclose(got[q], want, rtol=1e-3, atol=1e-3 * np.abs(values).max())


# ---------------------------------------------------------------------------------------------
# attacks

def _create(**fields):
    base = dict(op=8, value_type=1, background=struct.pack("<f", 0.0), transform=[1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0])
    base.update(fields)
    return geometry._call(_rt(), **base)


def test_malformed_volumes_are_refused():
    leaves = wp.array(np.array([[0, 0, 0], [8, 0, 0]], dtype=np.int32), dtype=wp.int32, device=DEV)
    masks = wp.zeros((2, 8), dtype=wp.uint64, device=DEV)
    values = wp.zeros(2 * 512, dtype=float, device=DEV)
    keep = []   # the arrays stay alive until the requests ran (a handle alone does not hold one)

    def _k(a):
        keep.append(a)
        return _h(a)

    good = dict(leaves=_h(leaves), masks=_h(masks), values=_h(values))
    assert _create(**good) != 0
    cases = [
        (dict(good, values=_k(wp.zeros(2 * 512 - 1, dtype=float, device=DEV))), "needs 1024 values"),
        (dict(good, values=_k(wp.zeros(2 * 512, dtype=wp.int32, device=DEV))), "expected float32 values"),
        (dict(good, values=_k(wp.zeros(2 * 512, dtype=float, device=DEV)), value_type=6), "needs 1024 values"),
        (dict(good, values=0), "needs its values array"),
        (dict(good, value_type=20, background=b""), "has no values array"),
        (dict(good, masks=_k(wp.zeros((2, 7), dtype=wp.uint64, device=DEV))), "8 words per leaf"),
        (dict(good, leaves=_k(wp.array(np.array([[0, 0, 0], [0, 0, 0]], dtype=np.int32), dtype=wp.int32,
                                       device=DEV))), "same origin"),
        (dict(good, leaves=_k(wp.array(np.array([[0, 0, 0], [9, 0, 0]], dtype=np.int32), dtype=wp.int32,
                                       device=DEV))), "multiples of 8"),
        (dict(good, leaves=_k(wp.zeros(7, dtype=wp.int32, device=DEV))), "3 int32 each"),
        (dict(good, leaves=_k(wp.zeros((2, 3), dtype=float, device=DEV))), "expected int32"),
        (dict(good, leaves=987654321), "unknown array handle"),
        (dict(good, background=b"\0" * 8), "background value has 8 bytes"),
        (dict(good, background=b"\0" * 100), "too long"),
        (dict(good, transform=[1, 2, 3, 2, 4, 6, 1, 1, 1, 0, 0, 0]), "singular"),
        (dict(good, transform=[1.0] * 13), "more than 12"),
        (dict(good, transform=[float("nan")] + [1.0] * 11), "not finite"),
        (dict(good, value_type=13), "not supported"),
        (dict(good, value_type=-1), "not supported"),
    ]
    for fields, match in cases:
        with pytest.raises(wp.WeftError, match=match):
            _create(**fields)
    assert _create(**good) != 0   # the daemon keeps serving


@wp.kernel
def sample_vec(vol: wp.uint64, out: wp.array(dtype=wp.vec3)):
    out[0] = wp.volume_sample_v(vol, wp.vec3(0.5), wp.Volume.LINEAR)


@wp.kernel
def short_data(vol: wp.uint64, data: wp.array(dtype=float), out: wp.array(dtype=float)):
    out[0] = wp.volume_sample_index(vol, wp.vec3(3.0, 3.0, 3.0), wp.Volume.CLOSEST, data, 0.0)


def test_kernel_misuse_is_a_launch_error_with_the_line():
    vol = RawVolume([[0, 0, 0]], np.zeros((1, 8), dtype=np.uint64), np.ones(512, dtype=np.float32), 1,
                    struct.pack("<f", 0.0))
    out = wp.zeros(1, dtype=wp.vec3, device=DEV)
    with pytest.raises(wp.WeftError, match=r"test_volume_daemon.py:\d+.*holds float values, not Vec3f"):
        wp.launch(sample_vec, dim=1, inputs=[vol.id, out], device=DEV)
        wp.synchronize()
    grid = wp.HashGrid(2, 2, 2, device=DEV)
    with pytest.raises(wp.WeftError, match="is a HashGrid, not a Volume"):
        wp.launch(sample_vec, dim=1, inputs=[grid.id, out], device=DEV)
        wp.synchronize()
    with pytest.raises(wp.WeftError, match="not a live Volume"):
        wp.launch(sample_vec, dim=1, inputs=[vol.id ^ (1 << 40), out], device=DEV)
        wp.synchronize()
    # voxel (3, 3, 3) has index 3*64 + 3*8 + 3 = 219: past the end of a 100-value array
    with pytest.raises(wp.WeftError, match="voxel index 219 is out of range for voxel_data of 100 values"):
        wp.launch(short_data, dim=1, inputs=[vol.id, wp.zeros(100, dtype=float, device=DEV),
                                             wp.zeros(1, dtype=float, device=DEV)], device=DEV)
        wp.synchronize()
    out1 = wp.zeros(1, dtype=float, device=DEV)
    wp.launch(short_data, dim=1, inputs=[vol.id, wp.full(512, 4.0, dtype=float, device=DEV), out1], device=DEV)
    assert out1.numpy()[0] == 4.0
