"""Marching cubes (wp.geometry.IsoSurfaceMarchingCubes, weft/iso_surface.py) against a float64
NumPy extraction that walks the same tables, on random fields with values across many orders of
magnitude and values equal to the threshold; the meshes' topology (every triangle side shared by
exactly one other triangle, wound the other way; Euler characteristic 2 for a sphere); a sphere's
area, volume and the derivative of its area with respect to the radius through a Tape; the
field gradient of the vertex positions against the float64 derivative of the interpolation; the
tables themselves (every case alone in a grid gives a closed, outward-wound surface); Warp's
errors for bad fields and arguments.

Tolerances: vertex positions within 2e-5 of the grid's extent (float32 interpolation of float32
values; the reference interpolates the same values in float64); gradients within 1e-3 relative;
a sphere of radius 8 cells: area within 1.5 %, volume within 1.5 % (the discretisation, not the
arithmetic)."""
from __future__ import annotations

import collections
import types
from pathlib import Path
import warnings

import numpy as np
import pytest

import weft as wp
import weft.geometry
from weft import _mc_tables as tables

MC = wp.geometry.IsoSurfaceMarchingCubes


def reference_mesh(field: np.ndarray, threshold: float, lower=(0.0, 0.0, 0.0), upper=None):
    """float64 marching cubes over the same tables, vertices in the daemon's order (node-major,
    then +x, +y, +z edges), triangles in cell order."""
    f = field.astype(np.float64)
    nx, ny, nz = f.shape
    upper = (nx - 1, ny - 1, nz - 1) if upper is None else upper
    lower = np.array(lower, dtype=np.float64)
    delta = (np.array(upper, dtype=np.float64) - lower) / np.array([nx - 1, ny - 1, nz - 1])
    inside = f < threshold
    vid, verts = {}, []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                for axis, step in enumerate(((1, 0, 0), (0, 1, 0), (0, 0, 1))):
                    b = (i + step[0], j + step[1], k + step[2])
                    if b[0] < nx and b[1] < ny and b[2] < nz and inside[i, j, k] != inside[b]:
                        s = (threshold - f[i, j, k]) / (f[b] - f[i, j, k])
                        vid[(i, j, k, axis)] = len(verts)
                        verts.append(lower + (np.array((i, j, k)) + s * np.array(step)) * delta)
    edge_nodes = tables.edge_nodes()
    faces = []
    for i in range(nx - 1):
        for j in range(ny - 1):
            for k in range(nz - 1):
                case = sum(int(inside[i + o[0], j + o[1], k + o[2]]) << c
                           for c, o in enumerate(tables.CUBE_CORNER_OFFSETS))
                for e in tables.TRI_LOCAL_INDICES[tables.CASE_TO_TRI_RANGE[case]:
                                                  tables.CASE_TO_TRI_RANGE[case + 1]]:
                    ox, oy, oz, axis = edge_nodes[4 * e:4 * e + 4]
                    faces.append(vid[(i + ox, j + oy, k + oz, axis)])
    return np.array(verts, dtype=np.float64).reshape(-1, 3), np.array(faces, dtype=np.int64)


def half_edges(faces: np.ndarray) -> collections.Counter:
    count = collections.Counter()
    for a, b, c in faces.reshape(-1, 3):
        for x, y in ((a, b), (b, c), (c, a)):
            count[(int(x), int(y))] += 1
    return count


def assert_closed_and_oriented(faces: np.ndarray):
    """Every triangle side appears once in each direction: a closed 2-manifold, consistently
    wound."""
    count = half_edges(faces)
    assert all(n == 1 for n in count.values()), "a triangle side is used twice in one direction"
    assert all(count[(y, x)] == 1 for (x, y) in count), "a triangle side has no opposite side"


def signed_volume(verts: np.ndarray, faces: np.ndarray) -> float:
    t = verts[faces.reshape(-1, 3)]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def area(verts: np.ndarray, faces: np.ndarray) -> float:
    t = verts[faces.reshape(-1, 3)]
    return float(np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum() / 2.0)


def hard_field(rng, shape, closed: bool) -> np.ndarray:
    """Random values of magnitudes 1e-20 .. 1e20 and both signs, some exactly at the threshold
    (0); with `closed`, the grid's boundary nodes are outside so that the surface is closed."""
    f = rng.standard_normal(shape) * 10.0 ** rng.uniform(-20, 20, shape)
    f[rng.random(shape) < 0.05] = 0.0
    if closed:
        f[0], f[-1], f[:, 0], f[:, -1], f[:, :, 0], f[:, :, -1] = 1.0, 1.0, 1.0, 1.0, 1.0, 1.0
    return f.astype(np.float32)


def sphere_field(n: int, radius: float, center) -> np.ndarray:
    g = np.arange(n, dtype=np.float64)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    return (np.sqrt((x - center[0]) ** 2 + (y - center[1]) ** 2 + (z - center[2]) ** 2) - radius).astype(np.float32)


def test_tables_every_case_alone_is_closed_and_outward(device):
    assert len(MC.CASE_TO_TRI_RANGE) == 257 and MC.CASE_TO_TRI_RANGE[0] == 0
    assert MC.CASE_TO_TRI_RANGE[256] == len(MC.TRI_LOCAL_INDICES)
    assert all(r % 3 == 0 for r in MC.CASE_TO_TRI_RANGE)
    assert MC.CASE_TO_TRI_RANGE[1] == 0 and MC.CASE_TO_TRI_RANGE[2] == 3 and MC.CASE_TO_TRI_RANGE[255] == MC.CASE_TO_TRI_RANGE[256]
    for a, b in MC.EDGE_TO_CORNERS:
        diff = np.abs(np.subtract(MC.CUBE_CORNER_OFFSETS[a], MC.CUBE_CORNER_OFFSETS[b]))
        assert diff.sum() == 1
    for case in range(256):
        f = np.full((4, 4, 4), 1.0, dtype=np.float32)
        for c, o in enumerate(MC.CUBE_CORNER_OFFSETS):
            f[1 + o[0], 1 + o[1], 1 + o[2]] = -1.0 - 0.37 * c if (case >> c) & 1 else 1.0 + 0.21 * c
        verts, faces = reference_mesh(f, 0.0)
        assert_closed_and_oriented(faces)
        if faces.size:
            assert signed_volume(verts, faces) > 0.0, f"case {case} is wound inward"


@pytest.mark.parametrize("shape", [(2, 2, 2), (5, 7, 6), (13, 9, 11)])
def test_random_fields_match_float64_reference(device, rng, shape):
    field_np = hard_field(rng, shape, closed=False)
    lower, upper = (-3.0, 0.5, 2.0), (4.0, 2.5, -1.0)   # a flipped z axis
    verts, indices = MC.extract(wp.array(field_np, dtype=wp.float32, device=device), 0.0,
                                lower=lower, upper=upper)
    assert verts.dtype == wp.vec3 and indices.dtype == wp.int32 and verts.device == device
    ref_verts, ref_faces = reference_mesh(field_np, 0.0, lower, upper)
    np.testing.assert_array_equal(indices.numpy(), ref_faces)
    extent = np.abs(np.subtract(upper, lower)).max()
    np.testing.assert_allclose(verts.numpy(), ref_verts, rtol=0, atol=2e-5 * extent)


def test_closed_random_surfaces_are_manifolds(device, rng):
    for _ in range(4):
        shape = tuple(int(n) for n in rng.integers(4, 10, 3))
        field_np = hard_field(rng, shape, closed=True)
        threshold = 0.0
        verts, indices = MC.extract(wp.array(field_np, device=device), threshold)
        faces = indices.numpy()
        assert faces.size and faces.size % 3 == 0
        assert_closed_and_oriented(faces)
        assert signed_volume(verts.numpy().astype(np.float64), faces) > 0.0
        assert np.array_equal(np.unique(faces), np.arange(len(verts.numpy())))


def test_sphere_stateful_interface(device, rng):
    n, radius = 24, 8.0
    center = 11.5 + rng.uniform(-0.5, 0.5, 3)
    iso = MC(nx=n, ny=n, nz=n, lower=(0.0, 0.0, 0.0), upper=(n - 1.0, n - 1.0, n - 1.0))
    iso.surface(wp.array(sphere_field(n, radius, center), device=device), threshold=0.0)
    verts, faces = iso.verts.numpy().astype(np.float64), iso.indices.numpy()
    assert_closed_and_oriented(faces)
    edges = len(half_edges(faces)) // 2
    assert len(verts) - edges + len(faces) // 3 == 2, "not a sphere's Euler characteristic"
    assert np.abs(np.linalg.norm(verts - center, axis=1) - radius).max() < 0.1
    assert area(verts, faces) == pytest.approx(4 * np.pi * radius ** 2, rel=0.015)
    assert signed_volume(verts, faces) == pytest.approx(4 / 3 * np.pi * radius ** 3, rel=0.015)
    # the same context on a field of another size after resize
    iso.resize(10, 12, 14)
    iso.surface(wp.array(hard_field(rng, (10, 12, 14), closed=True), device=device), 0.0)
    assert_closed_and_oriented(iso.indices.numpy())



def test_repeated_surface_calls_reuse_their_temporaries(device, rng):
    """surface() keeps its temporaries (one int32 block) for the next call of the same size and
    device: every call's mesh still equals the float64 reference (fresh fields, new thresholds),
    the block is allocated once, and a resize allocates a new one."""
    shape = (9, 7, 8)
    iso = MC(*shape)
    blocks = []
    for threshold in (0.0, 0.25, -0.3):
        field_np = hard_field(rng, shape, closed=False)
        iso.surface(wp.array(field_np, dtype=wp.float32, device=device), threshold)
        ref_verts, ref_faces = reference_mesh(field_np, threshold)
        np.testing.assert_array_equal(iso.indices.numpy(), ref_faces)
        np.testing.assert_allclose(iso.verts.numpy(), ref_verts, rtol=0, atol=2e-5 * max(shape))
        blocks.append(next(iter(iso._scratch.values())))
    assert blocks[0] is blocks[1] is blocks[2] and len(iso._scratch) == 1
    iso.resize(5, 6, 7)
    iso.surface(wp.array(hard_field(rng, (5, 6, 7), closed=True), device=device), 0.0)
    assert_closed_and_oriented(iso.indices.numpy())
    assert len(iso._scratch) == 1 and next(iter(iso._scratch.values())) is not blocks[0]

def test_threshold_and_ties(device, rng):
    """A node exactly at the threshold is outside (not below it), in the count, the vertices and
    the faces alike."""
    field_np = rng.choice(np.array([0.25, 0.5, 0.75], dtype=np.float32), size=(7, 6, 5))
    for threshold in (0.25, 0.5, 0.75, 0.6):
        verts, indices = MC.extract(wp.array(field_np, device=device), threshold)
        ref_verts, ref_faces = reference_mesh(field_np, threshold)
        np.testing.assert_array_equal(indices.numpy(), ref_faces)
        np.testing.assert_allclose(verts.numpy(), ref_verts, rtol=0, atol=1e-5 * 6)


def test_empty_output(device):
    field = wp.array(np.linspace(-1, 1, 4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6), device=device)
    verts, indices = MC.extract(field, threshold=1000.0)
    assert verts.shape == (0,) and indices.shape == (0,)
    iso = MC(4, 5, 6)
    iso.surface(field, -1000.0)
    assert iso.verts.shape == (0,) and iso.indices.shape == (0,)


def test_vertex_gradients_match_float64_derivative(device, rng):
    """d(sum w . verts)/d field: each vertex p0 + s (p1 - p0), s = (t - f0) / (f1 - f0), gives
    ds/df0 = (s - 1) / (f1 - f0) and ds/df1 = -s / (f1 - f0)."""
    shape = (6, 5, 7)
    field_np = (rng.standard_normal(shape) + 0.2).astype(np.float32)
    threshold = 0.1
    field = wp.array(field_np, device=device, requires_grad=True)
    tape = wp.Tape()
    with tape:
        verts, _ = MC.extract(field, threshold)
    weights = rng.standard_normal((len(verts.numpy()), 3))
    tape.backward(grads={verts: wp.array(weights.astype(np.float32), dtype=wp.vec3, device=device)})

    f = field_np.astype(np.float64)
    expected = np.zeros(shape)
    v = 0
    for i in range(shape[0]):
        for j in range(shape[1]):
            for k in range(shape[2]):
                for step in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
                    b = (i + step[0], j + step[1], k + step[2])
                    if b[0] < shape[0] and b[1] < shape[1] and b[2] < shape[2] and \
                            (f[i, j, k] < threshold) != (f[b] < threshold):
                        d = f[b] - f[i, j, k]
                        s = (threshold - f[i, j, k]) / d
                        along = float(np.dot(weights[v], step))
                        expected[i, j, k] += along * (s - 1.0) / d
                        expected[b] += along * -s / d
                        v += 1
    assert v == len(weights)
    np.testing.assert_allclose(field.grad.numpy(), expected, rtol=1e-3, atol=1e-3 * np.abs(expected).max())


def test_sphere_area_derivative_through_tape(device):
    """Warp's documented use: the derivative of the surface area with respect to a sphere's
    radius, through a field made by a kernel, the extraction and an area kernel (8 pi r)."""
    n, radius = 48, 0.5
    radius_wp = wp.full((1,), value=radius, dtype=wp.float32, device=device, requires_grad=True)
    field = wp.zeros((n, n, n), dtype=float, device=device, requires_grad=True)
    total = wp.zeros(1, dtype=float, device=device, requires_grad=True)
    with wp.Tape() as tape:
        wp.launch(_unit_sphere_sdf, dim=field.shape, inputs=[field, radius_wp], device=device)
        verts, faces = MC.extract(field, 0.0, lower=(-1.0, -1.0, -1.0), upper=(1.0, 1.0, 1.0))
        wp.launch(_triangle_areas, dim=faces.shape[0] // 3, inputs=[verts, faces, total], device=device)
    assert total.numpy()[0] == pytest.approx(4 * np.pi * radius ** 2, rel=0.01)
    tape.backward(total)
    assert radius_wp.grad.numpy()[0] == pytest.approx(8 * np.pi * radius, rel=0.01)


@wp.kernel
def _unit_sphere_sdf(field: wp.array3d[float], radius: wp.array[float]):
    i, j, k = wp.tid()
    n = float(field.shape[0] - 1)
    p = wp.vec3(2.0 * float(i) / n - 1.0, 2.0 * float(j) / n - 1.0, 2.0 * float(k) / n - 1.0)
    field[i, j, k] = wp.length(p) - radius[0]


@wp.kernel
def _triangle_areas(verts: wp.array[wp.vec3], faces: wp.array[wp.int32], total: wp.array[float]):
    t = wp.tid()
    p0, p1, p2 = verts[faces[3 * t]], verts[faces[3 * t + 1]], verts[faces[3 * t + 2]]
    wp.atomic_add(total, 0, 0.5 * wp.length(wp.cross(p1 - p0, p2 - p0)))


def test_bad_fields_and_arguments(device):
    for shape in ((1, 8, 8), (8, 1, 8), (8, 8, 1), (0, 8, 8)):
        field = wp.zeros(shape, dtype=wp.float32, device=device)
        with pytest.raises(ValueError, match="at least 2 nodes on each axis"):
            MC.extract(field)
        with pytest.raises(ValueError, match="at least 2 nodes on each axis"):
            MC(*shape).surface(field, 0.0)
    with pytest.raises(ValueError, match="Expected a 3D array"):
        MC.extract(wp.zeros((4, 4), dtype=wp.float32, device=device))
    with pytest.raises(TypeError, match="dtype of wp.float32"):
        MC.extract(wp.zeros((4, 4, 4), dtype=wp.float64, device=device))
    with pytest.raises(ValueError, match="does not match context grid dimensions"):
        MC(4, 4, 4).surface(wp.zeros((4, 4, 5), dtype=wp.float32, device=device), 0.0)
    with pytest.raises(TypeError, match="Cannot specify both"):
        MC(4, 4, 4, lower=(0, 0, 0), domain_bounds_lower_corner=(1, 1, 1))


def test_deprecated_names(device, rng, capsys):
    """Warp's deprecated names work and say so on stderr as Warp does (once per message)."""
    from weft import logger as _log

    field_np = hard_field(rng, (5, 5, 5), closed=True)
    _log._warnings_seen.clear()
    with warnings.catch_warnings():
        warnings.simplefilter("always", DeprecationWarning)
        assert wp.MarchingCubes is MC
        iso = MC(5, 5, 5, domain_bounds_upper_corner=(1.0, 1.0, 1.0))
        assert iso.upper == (1.0, 1.0, 1.0) and iso.domain_bounds_upper_corner == (1.0, 1.0, 1.0)
        verts, faces = MC.extract_surface_marching_cubes(wp.array(field_np, device=device), 0.0, None,
                                                         (1.0, 1.0, 1.0))
        assert wp.MarchingCubes is MC
    err = capsys.readouterr().err
    assert err.count("Warp DeprecationWarning: wp.MarchingCubes is deprecated") == 1, err
    assert "argument `domain_bounds_upper_corner` is deprecated" in err
    assert "IsoSurfaceMarchingCubes.domain_bounds_upper_corner is deprecated" in err
    assert "extract_surface_marching_cubes() is deprecated" in err
    ref_verts, ref_faces = reference_mesh(field_np, 0.0, upper=(1.0, 1.0, 1.0))
    np.testing.assert_array_equal(faces.numpy(), ref_faces)
    np.testing.assert_allclose(verts.numpy(), ref_verts, rtol=0, atol=2e-5)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        MC(5, 5, 5, lower=(0.0, 0.0, 0.0))   # the current names warn of nothing
    assert capsys.readouterr().err == ""
    with pytest.raises(TypeError):
        wp.geometry.IsoSurfaceBase(4, 4, 4)   # the interface alone is abstract


def test_index_count_overflow_is_refused():
    """More triangles or grid edges than int32 indices can address is a clear error before any
    allocation."""
    from weft.iso_surface import _exclusive_offsets

    counts = np.full(1 << 20, 1 << 10, dtype=np.int32)   # 2^30 triangles -> 3 * 2^30 indices
    with pytest.raises(ValueError, match="more than int32 indices can address"):
        _exclusive_offsets(counts, "triangles")
    offsets, total = _exclusive_offsets(np.array([3, 0, 2], dtype=np.int32), "vertices")
    assert offsets.tolist() == [0, 3, 3] and total == 5
    # a grid with more edges than int32 names (3 per node): refused before anything runs
    huge = types.SimpleNamespace(shape=(1300, 1300, 1300), dtype=wp.float32, device="cpu")
    with pytest.raises(ValueError, match="more grid edges than int32 indices can address"):
        MC.extract(huge)


def test_kernels_compile_for_the_gpu(device):
    """The extraction's module compiles with NVRTC for sm_90 on any machine (no GPU needed)."""
    from weft import iso_surface

    report = wp.compile(iso_surface._mc_faces, device="cuda", arch=90)
    for name in ("_mc_count", "_mc_vertices", "_mc_faces"):
        assert report.kernel(name).code_bytes > 0, report


def test_example_writes_a_picture_of_a_closed_surface(device, run_script, tmp_path):
    """examples/iso_surface.py on a 40^3 grid: exits 0 only when its mesh is closed and wound
    consistently and its volume is within 2 % of a float64 Monte Carlo estimate; writes a PNG."""
    if device != "cpu":
        pytest.skip("the example runs on the daemon's preferred device; once is enough")
    example = Path(__file__).resolve().parents[2] / "examples" / "iso_surface.py"
    proc = run_script(f"""
        import os, runpy, sys
        os.chdir({str(tmp_path)!r})
        sys.argv = ["iso_surface.py", "40"]
        runpy.run_path({str(example)!r}, run_name="__main__")
    """)
    assert "closed, consistently wound: True" in proc.stdout, proc.stdout
    png = (tmp_path / "out" / "iso_surface" / "iso_surface.png").read_bytes()
    assert png.startswith(b"\x89PNG") and len(png) > 10_000
