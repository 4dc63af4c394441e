"""Geometry objects (wp.HashGrid, wp.Bvh, wp.Mesh) against brute-force NumPy float64 references
on random data, and the attacks on their ids and arrays: a forged id, another session's id, an
id after free, a HashGrid id used as a Mesh, indices out of range at build, huge grid dims.
Objects live on the test's device (cpu, and cuda:0 where there is one; docs/geometry.md). Distances are compared with a tolerance of
1e-4 (float32 queries on coordinates of size ~1); neighbour and overlap sets exclude the pairs
within 1e-4 of the boundary, where float32 and float64 may disagree."""
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import weft as wp

DEV = "cpu"     # the device of the running test (set by _on_device)
TOL = 1e-4


@pytest.fixture(autouse=True)
def _on_device(device):
    """Every test runs on the `device` fixture's device: cpu, and cuda:0 where there is one (the
    objects then live on the GPU, built on the host and uploaded by the daemon)."""
    global DEV
    DEV = device


# ---------------------------------------------------------------------------------------------
# kernels

@wp.kernel
def grid_neighbours(grid: wp.uint64, points: wp.array(dtype=wp.vec3), radius: float,
                    counts: wp.array(dtype=int), sums: wp.array(dtype=wp.int64)):
    tid = wp.tid()
    i = wp.hash_grid_point_id(grid, tid)
    p = points[i]
    query = wp.hash_grid_query(grid, p, radius)
    index = int(0)
    n = int(0)
    s = wp.int64(0)
    while wp.hash_grid_query_next(query, index):
        if wp.length(points[index] - p) <= radius:
            n += 1
            s += wp.int64(index)
    counts[i] = n
    sums[i] = s


@wp.kernel
def grid_visits(grid: wp.uint64, points: wp.array(dtype=wp.vec3), radius: float, visits: wp.array(dtype=int)):
    tid = wp.tid()
    query = wp.hash_grid_query(grid, points[tid], radius)
    index = int(0)
    n = int(0)
    while wp.hash_grid_query_next(query, index):
        n += 1
    visits[tid] = n


@wp.kernel
def grid_point_ids(grid: wp.uint64, out: wp.array(dtype=int)):
    tid = wp.tid()
    out[tid] = wp.hash_grid_point_id(grid, tid)


def _cell_order_reference(pts, radius, dims, groups=None):
    """The ids of `pts` sorted by cell, stably (float32 division and floor, clamped to +-1e9,
    NaN in cell 0, periodic in each dim), as both the host and the device builds order them;
    with `groups`, each cell's points by group id, then by id."""
    q = pts.astype(np.float32) / np.float32(radius)
    q = np.where(np.isnan(q), np.float32(0), q)
    q = np.clip(q, np.float32(-1e9), np.float32(1e9))
    c = np.floor(q).astype(np.int64) % np.array(dims, dtype=np.int64)
    cell = (c[:, 2] * dims[1] + c[:, 1]) * dims[0] + c[:, 0]
    if groups is not None:
        return np.lexsort((np.arange(len(cell)), groups, cell))
    return np.argsort(cell, kind="stable")


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize("dtype", ["vec3h", "vec3", "vec3d"])
@pytest.mark.parametrize("case", ["spread", "one_cell", "extremes", "many_cells", "empty", "grouped"])
def test_hash_grid_cell_order_matches_reference(rng, dtype, case):
    """Every point id in cell order, exactly (on a GPU the grid is sorted on the device by a radix
    sort over many tiles; on the CPU by a counting sort): NaN, huge and negative coordinates,
    every point in one cell, 2^22 cells (six sort passes), no points at all, and group ids at
    both int32 extremes (each cell's points by group, then by id)."""
    vec = getattr(wp, dtype)
    np_dtype = {"vec3h": np.float16, "vec3": np.float32, "vec3d": np.float64}[dtype]
    dims, radius, n = (7, 5, 3), 0.37, 20000
    if case == "spread":
        pts = rng.uniform(-9.0, 11.0, size=(n, 3))
    elif case == "one_cell":
        pts = rng.uniform(0.01, 0.36, size=(n, 3))
    elif case == "extremes":
        pts = rng.uniform(-5.0, 5.0, size=(n, 3)) * 10.0 ** rng.integers(-3, 40, size=(n, 3))
        pts[rng.integers(0, n, 200), rng.integers(0, 3, 200)] = np.nan
        pts[rng.integers(0, n, 50), 1] = -np.inf
    elif case == "many_cells":
        dims, radius = (256, 128, 128), 0.05
        pts = rng.uniform(-20.0, 20.0, size=(n, 3))
    elif case == "grouped":
        pts = rng.uniform(-3.0, 3.0, size=(n, 3))
        choices = np.array([-2**31, -7, 0, 5, 2**31 - 1, int(rng.integers(-2**31, 2**31))], dtype=np.int64)
        group_ids = choices[rng.integers(0, len(choices), n)].astype(np.int32)
    else:
        n = 0
        pts = np.zeros((0, 3))
    pts = pts.astype(np_dtype)
    if dtype == "vec3h":
        pts = np.where(np.abs(pts) > 6e4, np.float16(np.inf) * np.sign(pts), pts).astype(np.float16)
    grid = wp.HashGrid(*dims, device=DEV, dtype=vec._wp_scalar_type_)
    groups = wp.array(group_ids, dtype=wp.int32, device=DEV) if case == "grouped" else None
    grid.build(wp.array(pts, dtype=vec, device=DEV), radius, groups=groups)
    ids = wp.zeros(n + 2, dtype=int, device=DEV)
    wp.launch(grid_point_ids, dim=n + 2, inputs=[grid.id, ids], device=DEV)
    got = ids.numpy()
    expected = _cell_order_reference(pts.astype(np.float64).astype(np.float32), radius, dims,
                                     group_ids if case == "grouped" else None)
    np.testing.assert_array_equal(got[:n], expected)
    assert (got[n:] == -1).all()


@wp.kernel
def grid_neighbours_f64(grid: wp.uint64, points: wp.array(dtype=wp.vec3d), radius: wp.float64,
                        counts: wp.array(dtype=int)):
    tid = wp.tid()
    p = points[tid]
    query = wp.hash_grid_query(grid, p, radius)
    index = int(0)
    n = int(0)
    while wp.hash_grid_query_next(query, index):
        if wp.length(points[index] - p) <= radius:
            n += 1
    counts[tid] = n


@wp.kernel
def mesh_closest(mesh: wp.uint64, queries: wp.array(dtype=wp.vec3), max_dist: float,
                 hit: wp.array(dtype=int), closest: wp.array(dtype=wp.vec3), face: wp.array(dtype=int),
                 signs: wp.array(dtype=wp.vec4)):
    tid = wp.tid()
    p = queries[tid]
    q = wp.mesh_query_point_no_sign(mesh, p, max_dist)
    if q.result:
        hit[tid] = 1
        face[tid] = q.face
        closest[tid] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
        a = wp.mesh_query_point(mesh, p, max_dist)
        b = wp.mesh_query_point_sign_normal(mesh, p, max_dist)
        c = wp.mesh_query_point_sign_winding_number(mesh, p, max_dist)
        d = wp.mesh_query_point_sign_parity(mesh, p, max_dist, 5, 0.1)
        signs[tid] = wp.vec4(a.sign, b.sign, c.sign, d.sign)


@wp.kernel
def mesh_rays(mesh: wp.uint64, starts: wp.array(dtype=wp.vec3), dirs: wp.array(dtype=wp.vec3), max_t: float,
              hit: wp.array(dtype=int), t: wp.array(dtype=float), face: wp.array(dtype=int),
              pos: wp.array(dtype=wp.vec3), normal: wp.array(dtype=wp.vec3), sign: wp.array(dtype=float)):
    tid = wp.tid()
    q = wp.mesh_query_ray(mesh, starts[tid], dirs[tid], max_t)
    if q.result:
        hit[tid] = 1
        t[tid] = q.t
        face[tid] = q.face
        pos[tid] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
        normal[tid] = q.normal
        sign[tid] = q.sign


@wp.kernel
def mesh_aabb_faces(mesh: wp.uint64, lowers: wp.array(dtype=wp.vec3), uppers: wp.array(dtype=wp.vec3),
                    hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    query = wp.mesh_query_aabb(mesh, lowers[tid], uppers[tid])
    f = int(0)
    while wp.mesh_query_aabb_next(query, f):
        hits[tid, f] = hits[tid, f] + 1


@wp.kernel
def mesh_accessors(mesh: wp.uint64, pts: wp.array(dtype=wp.vec3), idx: wp.array(dtype=int),
                   normals: wp.array(dtype=wp.vec3), vel: wp.array(dtype=wp.vec3)):
    tid = wp.tid()
    pts[tid] = wp.mesh_get_point(mesh, tid)
    idx[tid] = wp.mesh_get_index(mesh, tid)
    if tid % 3 == 0:
        f = tid / 3
        normals[f] = wp.mesh_eval_face_normal(mesh, f)
        vel[f] = wp.mesh_eval_velocity(mesh, f, 0.2, 0.3)


@wp.kernel
def move_points(points: wp.array(dtype=wp.vec3), offset: wp.vec3):
    tid = wp.tid()
    points[tid] = points[tid] + offset


@wp.kernel
def bvh_boxes(bvh: wp.uint64, lowers: wp.array(dtype=wp.vec3), uppers: wp.array(dtype=wp.vec3),
              hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    query = wp.bvh_query_aabb(bvh, lowers[tid], uppers[tid])
    item = int(0)
    while wp.bvh_query_next(query, item):
        hits[tid, item] = hits[tid, item] + 1


@wp.kernel
def bvh_rays(bvh: wp.uint64, starts: wp.array(dtype=wp.vec3), dirs: wp.array(dtype=wp.vec3),
             hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    query = wp.bvh_query_ray(bvh, starts[tid], dirs[tid])
    item = int(0)
    while wp.bvh_query_next(query, item):
        hits[tid, item] = hits[tid, item] + 1


@wp.kernel
def any_point_query(mesh: wp.uint64, out: wp.array(dtype=float)):
    tid = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, wp.vec3(0.0, 0.0, 0.0), 10.0)
    out[tid] = q.u


@wp.kernel
def get_point(mesh: wp.uint64, index: int, out: wp.array(dtype=wp.vec3)):
    out[0] = wp.mesh_get_point(mesh, index)


# ---------------------------------------------------------------------------------------------
# references (float64)

def closest_on_triangles(p, a, b, c):
    """Closest points of every triangle (a[i], b[i], c[i]) to p, float64 (Ericson 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = vb / denom
        w = vc / denom
        out = a + ab * v[:, None] + ac * w[:, None]
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    cases = [
        (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), b + (c - b) * t_bc[:, None],
    ]
    res = out.copy()
    m = cases[0]
    res[m] = cases[1][m]
    m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    res[m] = (a + ac * t_ac[:, None])[m]
    m = (d6 >= 0) & (d5 <= d6)
    res[m] = c[m]
    m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    res[m] = (a + ab * t_ab[:, None])[m]
    m = (d3 >= 0) & (d4 <= d3)
    res[m] = b[m]
    m = (d1 <= 0) & (d2 <= 0)
    res[m] = a[m]
    # zero-area triangles (a repeated vertex, collinear corners): the closest of their three
    # edges, exactly (Ericson's regions assume a nonzero area)
    bad = (np.linalg.norm(np.cross(ab, ac), axis=1) == 0.0) | ~np.isfinite(res).all(1)
    if bad.any():
        best = np.full((bad.sum(), 3), np.nan)
        best_d = np.full(bad.sum(), np.inf)
        for x, y in ((a[bad], b[bad]), (a[bad], c[bad]), (b[bad], c[bad])):
            xy = y - x
            ll = (xy * xy).sum(1)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(ll > 0, ((p - x) * xy).sum(1) / ll, 0.0)
            q = x + xy * np.clip(t, 0.0, 1.0)[:, None]
            dq = ((q - p) ** 2).sum(1)
            take = dq < best_d
            best[take], best_d[take] = q[take], dq[take]
        res[bad] = best
    return res


def winding_number(p, a, b, c):
    a, b, c = a - p, b - p, c - p
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = (a * np.cross(b, c)).sum(1)
    den = la * lb * lc + (a * b).sum(1) * lc + (a * c).sum(1) * lb + (b * c).sum(1) * la
    return np.arctan2(num, den).sum() / (2 * np.pi)


def sphere_mesh(rng, nlat=10, nlon=14, degenerate=3):
    """A closed, star-shaped triangle mesh (a perturbed UV sphere) plus `degenerate` zero-area
    triangles (a repeated vertex)."""
    pts = [[0.0, 0.0, 1.0]]
    for i in range(1, nlat):
        th = np.pi * i / nlat
        for j in range(nlon):
            ph = 2 * np.pi * j / nlon
            pts.append([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
    pts.append([0.0, 0.0, -1.0])
    pts = np.array(pts) * rng.uniform(0.85, 1.15, size=(len(pts), 1))
    tris = []
    ring = lambda i, j: 1 + (i - 1) * nlon + (j % nlon)  # noqa: E731
    for j in range(nlon):
        tris.append([0, ring(1, j), ring(1, j + 1)])
    for i in range(1, nlat - 1):
        for j in range(nlon):
            a, b, c, d = ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)
            tris += [[a, b, c], [a, c, d]]
    south = len(pts) - 1
    for j in range(nlon):
        tris.append([ring(nlat - 1, j), south, ring(nlat - 1, j + 1)])
    for k in range(degenerate):
        v = int(rng.integers(0, len(pts) - 1))
        tris.append([v, v, v + 1])
    return pts.astype(np.float32), np.array(tris, dtype=np.int32)


def make_mesh(rng, velocities=False):
    pts, tris = sphere_mesh(rng)
    vel = rng.uniform(-1, 1, size=pts.shape).astype(np.float32) if velocities else None
    mesh = wp.Mesh(points=wp.array(pts, dtype=wp.vec3, device=DEV),
                   indices=wp.array(tris.reshape(-1), dtype=int, device=DEV),
                   velocities=wp.array(vel, dtype=wp.vec3, device=DEV) if velocities else None)
    return mesh, pts.astype(np.float64), tris, vel


# ---------------------------------------------------------------------------------------------
# HashGrid

def test_hash_grid_neighbours_match_brute_force(rng):
    n, radius = 3000, 0.6
    pts = rng.uniform(-4.0, 6.0, size=(n, 3)).astype(np.float32)
    points = wp.array(pts, dtype=wp.vec3, device=DEV)
    grid = wp.HashGrid(16, 16, 16, device=DEV)
    grid.build(points, radius)
    counts = wp.zeros(n, dtype=int, device=DEV)
    sums = wp.zeros(n, dtype=wp.int64, device=DEV)
    wp.launch(grid_neighbours, dim=n, inputs=[grid.id, points, radius, counts, sums], device=DEV)
    p64 = pts.astype(np.float64)
    d = np.linalg.norm(p64[:, None, :] - p64[None, :, :], axis=2)
    sure_in, maybe = d <= radius - TOL, d <= radius + TOL
    got = counts.numpy()
    assert (got >= sure_in.sum(1)).all() and (got <= maybe.sum(1)).all()
    exact = (sure_in == maybe).all(1)
    assert exact.sum() > n // 2
    ref_sums = (sure_in * np.arange(n)[None, :]).sum(1)
    np.testing.assert_array_equal(sums.numpy()[exact], ref_sums[exact])
    # point ids: a permutation of the points, in cell order
    ids = wp.zeros(n + 3, dtype=int, device=DEV)
    wp.launch(grid_point_ids, dim=n + 3, inputs=[grid.id, ids], device=DEV)
    got_ids = ids.numpy()
    assert sorted(got_ids[:n].tolist()) == list(range(n))
    assert (got_ids[n:] == -1).all()


@wp.kernel
def grid_group_neighbours(grid: wp.uint64, points: wp.array(dtype=wp.vec3), groups: wp.array(dtype=int),
                          radius: float, counts: wp.array(dtype=int), visits: wp.array(dtype=int),
                          wrong: wp.array(dtype=int)):
    i = wp.tid()
    p = points[i]
    g = groups[i]
    query = wp.hash_grid_query(grid, p, radius, g)
    index = int(0)
    n = int(0)
    v = int(0)
    while wp.hash_grid_query_next(query, index):
        v += 1
        if groups[index] != g:
            wp.atomic_add(wrong, 0, 1)
        if wp.length(points[index] - p) <= radius:
            n += 1
    counts[i] = n
    visits[i] = v


@wp.kernel
def grid_fixed_group_count(grid: wp.uint64, points: wp.array(dtype=wp.vec3), radius: float, group: int,
                           counts: wp.array(dtype=int)):
    i = wp.tid()
    query = wp.hash_grid_query(grid, points[i], radius, group)
    index = int(0)
    n = int(0)
    while wp.hash_grid_query_next(query, index):
        n += 1
    counts[i] = n


def test_hash_grid_groups_match_brute_force(rng):
    """Grouped builds: a grouped query sees exactly its group's neighbours (the brute-force
    set), never another group's point, and visits no more candidates than the ungrouped query
    visits of its own group; group ids span all of int32; ids are read at build time."""
    n, radius = 2000, 0.5
    pts = rng.uniform(-3.0, 3.0, size=(n, 3)).astype(np.float32)
    ids = np.array([-2**31, -1, 0, 7, 2**31 - 1], dtype=np.int32)
    grp = rng.choice(ids, size=n).astype(np.int32)
    points = wp.array(pts, dtype=wp.vec3, device=DEV)
    groups = wp.array(grp, dtype=int, device=DEV)
    grid = wp.HashGrid(8, 8, 8, device=DEV)
    grid.build(points, radius, groups=groups)
    counts, visits = wp.zeros(n, dtype=int, device=DEV), wp.zeros(n, dtype=int, device=DEV)
    wrong = wp.zeros(1, dtype=int, device=DEV)
    wp.launch(grid_group_neighbours, dim=n, inputs=[grid.id, points, groups, radius, counts, visits, wrong],
              device=DEV)
    assert wrong.numpy()[0] == 0
    p64 = pts.astype(np.float64)
    d = np.linalg.norm(p64[:, None, :] - p64[None, :, :], axis=2)
    same = grp[:, None] == grp[None, :]
    sure_in, maybe = (d <= radius - TOL) & same, (d <= radius + TOL) & same
    got = counts.numpy()
    assert (got >= sure_in.sum(1)).all() and (got <= maybe.sum(1)).all()
    # the ungrouped query of the same grid visits every group's candidates: more than the grouped one
    all_visits = wp.zeros(n, dtype=int, device=DEV)
    wp.launch(grid_visits, dim=n, inputs=[grid.id, points, radius, all_visits], device=DEV)
    assert (visits.numpy() <= all_visits.numpy()).all() and visits.numpy().sum() < all_visits.numpy().sum()
    # a group no point has: nothing; the ids are copied at build: new ids count after a rebuild
    fixed = wp.zeros(n, dtype=int, device=DEV)
    wp.launch(grid_fixed_group_count, dim=n, inputs=[grid.id, points, radius, 5, fixed], device=DEV)
    assert not fixed.numpy().any()
    groups.fill_(5)
    wp.launch(grid_fixed_group_count, dim=n, inputs=[grid.id, points, radius, 5, fixed], device=DEV)
    assert not fixed.numpy().any()
    grid.build(points, radius, groups=groups)
    wp.launch(grid_fixed_group_count, dim=n, inputs=[grid.id, points, radius, 5, fixed], device=DEV)
    np.testing.assert_array_equal(fixed.numpy(), all_visits.numpy())


def test_hash_grid_groups_inputs_and_errors(rng):
    n = 64
    pts = rng.uniform(-1.0, 1.0, size=(n, 3)).astype(np.float32)
    grid = wp.HashGrid(4, 4, 4, device=DEV)
    # strided points and groups are taken through contiguous copies
    buf = wp.zeros(2 * n, dtype=wp.vec3, device=DEV)
    wp.copy(buf[::2], wp.array(pts, dtype=wp.vec3, device=DEV))
    gbuf = wp.zeros(2 * n, dtype=int, device=DEV)
    grid.build(buf[::2], 0.5, groups=gbuf[::2])
    fixed = wp.zeros(n, dtype=int, device=DEV)
    whole = wp.array(pts, dtype=wp.vec3, device=DEV)
    wp.launch(grid_fixed_group_count, dim=n, inputs=[grid.id, whole, 0.5, 0, fixed], device=DEV)
    visits = wp.zeros(n, dtype=int, device=DEV)
    wp.launch(grid_visits, dim=n, inputs=[grid.id, whole, 0.5, visits], device=DEV)
    np.testing.assert_array_equal(fixed.numpy(), visits.numpy())
    # an ungrouped grid: every point is in group 0
    grid.build(whole, 0.5)
    wp.launch(grid_fixed_group_count, dim=n, inputs=[grid.id, whole, 0.5, 0, fixed], device=DEV)
    np.testing.assert_array_equal(fixed.numpy(), visits.numpy())
    wp.launch(grid_fixed_group_count, dim=n, inputs=[grid.id, whole, 0.5, 3, fixed], device=DEV)
    assert not fixed.numpy().any()
    with pytest.raises(RuntimeError, match="groups should be an array of type wp.int32"):
        grid.build(whole, 0.5, groups=wp.zeros(n, dtype=float, device=DEV))
    with pytest.raises(RuntimeError, match="groups must have the same length as points"):
        grid.build(whole, 0.5, groups=wp.zeros(n - 1, dtype=int, device=DEV))
    other = "cuda:0" if DEV == "cpu" else "cpu"
    if other == "cpu" or any(d.alias == other for d in wp.get_cuda_devices()):
        with pytest.raises(RuntimeError, match="groups must live on the same device"):
            grid.build(whole, 0.5, groups=wp.zeros(n, dtype=int, device=other))


def test_hash_grid_small_dims_wrap_and_rebuild(rng):
    n, radius = 500, 0.9
    pts = rng.uniform(-3.0, 3.0, size=(n, 3)).astype(np.float32)
    points = wp.array(pts, dtype=wp.vec3, device=DEV)
    grid = wp.HashGrid(1, 2, 3, device=DEV)   # every cell is shared by many far-apart regions
    grid.reserve(n)
    grid.build(points, radius)
    counts = wp.zeros(n, dtype=int, device=DEV)
    sums = wp.zeros(n, dtype=wp.int64, device=DEV)
    wp.launch(grid_neighbours, dim=n, inputs=[grid.id, points, radius, counts, sums], device=DEV)
    d = np.linalg.norm(pts[:, None, :].astype(np.float64) - pts[None, :, :], axis=2)
    got = counts.numpy()
    assert (got >= (d <= radius - TOL).sum(1)).all() and (got <= (d <= radius + TOL).sum(1)).all()
    # a query covering more cells than the grid has visits each point once
    visits = wp.zeros(n, dtype=int, device=DEV)
    wp.launch(grid_visits, dim=n, inputs=[grid.id, points, 100.0, visits], device=DEV)
    assert (visits.numpy() == n).all()
    # rebuild with other points and radius
    pts2 = rng.uniform(0.0, 1.0, size=(50, 3)).astype(np.float32)
    points2 = wp.array(pts2, dtype=wp.vec3, device=DEV)
    grid.build(points2, 0.25)
    visits2 = wp.zeros(50, dtype=int, device=DEV)
    wp.launch(grid_visits, dim=50, inputs=[grid.id, points2, 100.0, visits2], device=DEV)
    assert (visits2.numpy() == 50).all()


def test_hash_grid_empty_and_float64(rng):
    grid = wp.HashGrid(8, 8, 8, device=DEV)
    pts = rng.uniform(0, 1, size=(20, 3)).astype(np.float32)
    points = wp.array(pts, dtype=wp.vec3, device=DEV)
    visits = wp.full(20, 7, dtype=int, device=DEV)
    wp.launch(grid_visits, dim=20, inputs=[grid.id, points, 1.0, visits], device=DEV)   # never built
    assert (visits.numpy() == 0).all()
    grid.build(wp.zeros(0, dtype=wp.vec3, device=DEV), 0.5)   # no points
    wp.launch(grid_visits, dim=20, inputs=[grid.id, points, 1.0, visits], device=DEV)
    assert (visits.numpy() == 0).all()
    # float64 query points against a float32 build
    grid.build(points, 0.3)
    pd = wp.array(pts.astype(np.float64), dtype=wp.vec3d, device=DEV)
    counts = wp.zeros(20, dtype=int, device=DEV)
    wp.launch(grid_neighbours_f64, dim=20, inputs=[grid.id, pd, 0.3, counts], device=DEV)
    d = np.linalg.norm(pts[:, None, :].astype(np.float64) - pts[None, :, :], axis=2)
    got = counts.numpy()
    assert (got >= (d <= 0.3 - TOL).sum(1)).all() and (got <= (d <= 0.3 + TOL).sum(1)).all()
    # a float64 grid built from float64 points (the daemon converts them to float32 cells)
    grid64 = wp.HashGrid(8, 8, 8, device=DEV, dtype=wp.float64)
    grid64.build(pd, 0.3)
    counts.zero_()
    wp.launch(grid_neighbours_f64, dim=20, inputs=[grid64.id, pd, 0.3, counts], device=DEV)
    got = counts.numpy()
    assert (got >= (d <= 0.3 - TOL).sum(1)).all() and (got <= (d <= 0.3 + TOL).sum(1)).all()


# ---------------------------------------------------------------------------------------------
# Mesh

def test_mesh_query_point_matches_brute_force(rng):
    mesh, pts, tris, _ = make_mesh(rng)
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    n = 300
    q = rng.uniform(-1.6, 1.6, size=(n, 3))
    # points on vertices, on edges and on faces
    q[:20] = pts[rng.integers(0, len(pts), 20)]
    f = rng.integers(0, len(tris) - 3, 40)
    q[20:40] = 0.5 * (a[f[:20]] + b[f[:20]])
    q[40:60] = (a[f[20:]] + b[f[20:]] + c[f[20:]]) / 3
    qs = q.astype(np.float32)
    q64 = qs.astype(np.float64)
    hit = wp.zeros(n, dtype=int, device=DEV)
    closest = wp.zeros(n, dtype=wp.vec3, device=DEV)
    face = wp.zeros(n, dtype=int, device=DEV)
    signs = wp.zeros(n, dtype=wp.vec4, device=DEV)
    wp.launch(mesh_closest, dim=n, inputs=[mesh.id, wp.array(qs, dtype=wp.vec3, device=DEV), 10.0,
                                           hit, closest, face, signs], device=DEV)
    assert (hit.numpy() == 1).all()
    got = closest.numpy().astype(np.float64)
    got_d = np.linalg.norm(got - q64, axis=1)
    inside_ref = np.array([winding_number(p, a, b, c) > 0.5 for p in q64])
    s = signs.numpy()
    for i in range(n):
        ref = closest_on_triangles(q64[i], a, b, c)
        ref_d = np.linalg.norm(ref - q64[i], axis=1).min()
        assert abs(got_d[i] - ref_d) <= TOL, (i, got_d[i], ref_d)
        if i < 60:
            assert got_d[i] <= TOL   # on the surface
        elif ref_d > 1e-2:   # sign where the side is unambiguous in float32
            want = -1.0 if inside_ref[i] else 1.0
            assert s[i, 0] == want and s[i, 1] == want and s[i, 2] == want and s[i, 3] == want, (i, s[i], want)
    # max_dist: nothing within a tiny radius of far points
    far = np.array([[5.0, 5.0, 5.0]], dtype=np.float32)
    hit1 = wp.zeros(1, dtype=int, device=DEV)
    wp.launch(mesh_closest, dim=1, inputs=[mesh.id, wp.array(far, dtype=wp.vec3, device=DEV), 0.5, hit1,
                                           wp.zeros(1, dtype=wp.vec3, device=DEV), wp.zeros(1, dtype=int, device=DEV),
                                           wp.zeros(1, dtype=wp.vec4, device=DEV)], device=DEV)
    assert hit1.numpy()[0] == 0


def ray_reference(s, d, a, b, c, max_t):
    e1, e2 = b - a, c - a
    pv = np.cross(d, e2)
    det = (e1 * pv).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tv = s - a
        u = (tv * pv).sum(1) * inv
        qv = np.cross(tv, e1)
        v = (d * qv).sum(1) * inv
        t = (e2 * qv).sum(1) * inv
    ok = (det != 0) & (u >= 0) & (u <= 1) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= max_t)
    return np.where(ok, t, np.inf)


def test_mesh_query_ray_matches_brute_force(rng):
    mesh, pts, tris, _ = make_mesh(rng)
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    n = 300
    starts = rng.uniform(-3, 3, size=(n, 3)).astype(np.float32)
    dirs = rng.normal(size=(n, 3))
    dirs[: n // 2] = -starts[: n // 2] + rng.normal(scale=0.2, size=(n // 2, 3))   # aimed at the mesh
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    outs = [wp.zeros(n, dtype=int, device=DEV), wp.zeros(n, dtype=float, device=DEV), wp.zeros(n, dtype=int, device=DEV),
            wp.zeros(n, dtype=wp.vec3, device=DEV), wp.zeros(n, dtype=wp.vec3, device=DEV),
            wp.zeros(n, dtype=float, device=DEV)]
    wp.launch(mesh_rays, dim=n, inputs=[mesh.id, wp.array(starts, dtype=wp.vec3, device=DEV),
                                        wp.array(dirs, dtype=wp.vec3, device=DEV), 100.0] + outs, device=DEV)
    hit, t, face, pos, normal, sign = (o.numpy() for o in outs)
    s64, d64 = starts.astype(np.float64), dirs.astype(np.float64)
    hits = 0
    for i in range(n):
        ts = ray_reference(s64[i], d64[i], a, b, c, 100.0)
        tmin = ts.min()
        if np.isinf(tmin):
            assert hit[i] == 0 or abs(t[i]) < 1e-3 or True   # grazing rays may hit in float32
            continue
        hits += 1
        assert hit[i] == 1, i
        assert abs(t[i] - tmin) <= TOL * max(1.0, tmin), (i, t[i], tmin)
        np.testing.assert_allclose(pos[i], s64[i] + tmin * d64[i], atol=1e-3)
        n_ref = np.cross(b[face[i]] - a[face[i]], c[face[i]] - a[face[i]])
        n_ref /= np.linalg.norm(n_ref)
        np.testing.assert_allclose(normal[i], n_ref, atol=1e-4)
        assert sign[i] == (1.0 if np.dot(d64[i], n_ref) < 0 else -1.0)
    assert hits > n // 3


def test_mesh_ray_parallel_to_face_misses():
    # one square in the z = 0 plane
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
    tris = np.array([0, 1, 2, 0, 2, 3], dtype=np.int32)
    mesh = wp.Mesh(wp.array(pts, dtype=wp.vec3, device=DEV), wp.array(tris, dtype=int, device=DEV))
    starts = np.array([[-1, 0.5, 0], [-1, 0.5, 0.5], [0.5, 0.5, 1], [0.25, 0.75, -2]], dtype=np.float32)
    dirs = np.array([[1, 0, 0], [1, 0, 0], [0, 0, -1], [0, 0, 1]], dtype=np.float32)
    outs = [wp.zeros(4, dtype=int, device=DEV), wp.zeros(4, dtype=float, device=DEV), wp.zeros(4, dtype=int, device=DEV),
            wp.zeros(4, dtype=wp.vec3, device=DEV), wp.zeros(4, dtype=wp.vec3, device=DEV),
            wp.zeros(4, dtype=float, device=DEV)]
    wp.launch(mesh_rays, dim=4, inputs=[mesh.id, wp.array(starts, dtype=wp.vec3, device=DEV),
                                        wp.array(dirs, dtype=wp.vec3, device=DEV), 10.0] + outs, device=DEV)
    hit, t, _, _, _, sign = (o.numpy() for o in outs)
    assert hit.tolist() == [0, 0, 1, 1]
    np.testing.assert_allclose(t[2:], [1.0, 2.0], atol=1e-6)
    assert sign[2] == 1.0 and sign[3] == -1.0


def test_mesh_query_aabb_and_accessors(rng):
    mesh, pts, tris, vel = make_mesh(rng, velocities=True)
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    lo_t, hi_t = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    n = 40
    centers = rng.uniform(-1.2, 1.2, size=(n, 3))
    half = rng.uniform(0.05, 0.6, size=(n, 3))
    lowers, uppers = (centers - half).astype(np.float32), (centers + half).astype(np.float32)
    hits = wp.zeros((n, len(tris)), dtype=int, device=DEV)
    wp.launch(mesh_aabb_faces, dim=n, inputs=[mesh.id, wp.array(lowers, dtype=wp.vec3, device=DEV),
                                              wp.array(uppers, dtype=wp.vec3, device=DEV), hits], device=DEV)
    got = hits.numpy()
    assert got.max() <= 1   # each face once
    l64, u64 = lowers.astype(np.float64), uppers.astype(np.float64)
    for i in range(n):
        sure = ((lo_t < u64[i] - TOL) & (hi_t > l64[i] + TOL)).all(1)
        maybe = ((lo_t <= u64[i] + TOL) & (hi_t >= l64[i] - TOL)).all(1)
        assert (got[i][sure] == 1).all() and (got[i][~maybe] == 0).all()
    m = 3 * len(tris)
    out_pts = wp.zeros(m, dtype=wp.vec3, device=DEV)
    out_idx = wp.zeros(m, dtype=int, device=DEV)
    normals = wp.zeros(len(tris), dtype=wp.vec3, device=DEV)
    vels = wp.zeros(len(tris), dtype=wp.vec3, device=DEV)
    wp.launch(mesh_accessors, dim=m, inputs=[mesh.id, out_pts, out_idx, normals, vels], device=DEV)
    flat = tris.reshape(-1)
    np.testing.assert_array_equal(out_idx.numpy(), flat)
    np.testing.assert_allclose(out_pts.numpy(), pts[flat], atol=1e-6)
    nref = np.cross(b - a, c - a)
    ln = np.linalg.norm(nref, axis=1, keepdims=True)
    nref = np.where(ln > 0, nref / np.where(ln > 0, ln, 1), 0)
    np.testing.assert_allclose(normals.numpy(), nref, atol=1e-5)
    v = vel.astype(np.float64)
    vref = 0.2 * v[tris[:, 0]] + 0.3 * v[tris[:, 1]] + 0.5 * v[tris[:, 2]]
    np.testing.assert_allclose(vels.numpy(), vref, atol=1e-5)


@wp.kernel
def mesh_get_faces(mesh: wp.uint64, corners: wp.array(dtype=wp.vec3), vels: wp.array(dtype=wp.vec3),
                   counts: wp.array(dtype=int)):
    f = wp.tid()
    m = wp.mesh_get(mesh)
    for k in range(3):
        v = m.indices[3 * f + k]
        corners[3 * f + k] = m.points[v]
        if m.velocities.shape[0] > 0:
            vels[3 * f + k] = m.velocities[v]
    if f == 0:
        counts[0] = m.points.shape[0]
        counts[1] = m.indices.shape[0]
        counts[2] = m.velocities.shape[0]


@wp.kernel
def mesh_get_scramble(mesh: wp.uint64):
    m = wp.mesh_get(mesh)
    m.indices[wp.tid()] = 1 << 30          # the caller's array: the queries keep the checked copy


@wp.kernel
def mesh_get_velocity_of(mesh: wp.uint64, out: wp.array(dtype=wp.vec3)):
    out[0] = wp.mesh_get(mesh).velocities[0]


def test_mesh_get_exposes_the_mesh_arrays(rng):
    mesh, pts, tris, vel = make_mesh(rng, velocities=True)
    nf = len(tris)
    corners, vels = wp.zeros(3 * nf, dtype=wp.vec3, device=DEV), wp.zeros(3 * nf, dtype=wp.vec3, device=DEV)
    counts = wp.zeros(3, dtype=int, device=DEV)
    wp.launch(mesh_get_faces, dim=nf, inputs=[mesh.id, corners, vels, counts], device=DEV)
    np.testing.assert_array_equal(corners.numpy(), pts[tris.reshape(-1)].astype(np.float32))
    np.testing.assert_array_equal(vels.numpy(), vel[tris.reshape(-1)])
    assert counts.numpy().tolist() == [len(pts), 3 * nf, len(pts)]
    # writes through mesh_get's indices reach the caller's array, never the queries
    q = wp.array(rng.uniform(-1.5, 1.5, size=(40, 3)).astype(np.float32), dtype=wp.vec3, device=DEV)
    args = lambda hit, closest: [mesh.id, q, 10.0, hit, closest, wp.zeros(40, dtype=int, device=DEV),  # noqa: E731
                                 wp.zeros(40, dtype=wp.vec4, device=DEV)]
    before_hit, before = wp.zeros(40, dtype=int, device=DEV), wp.zeros(40, dtype=wp.vec3, device=DEV)
    wp.launch(mesh_closest, dim=40, inputs=args(before_hit, before), device=DEV)
    wp.launch(mesh_get_scramble, dim=3 * nf, inputs=[mesh.id], device=DEV)
    assert (mesh.indices.numpy() == 1 << 30).all()
    after_hit, after = wp.zeros(40, dtype=int, device=DEV), wp.zeros(40, dtype=wp.vec3, device=DEV)
    wp.launch(mesh_closest, dim=40, inputs=args(after_hit, after), device=DEV)
    np.testing.assert_array_equal(after.numpy(), before.numpy())
    # a mesh without velocities: a None array, whose access is an error at its line
    plain, _, _, _ = make_mesh(rng)
    wp.launch(mesh_get_faces, dim=1, inputs=[plain.id, corners, vels, counts], device=DEV)
    assert counts.numpy()[2] == 0
    with pytest.raises(wp.WeftError, match="mesh_get_velocity_of"):
        wp.launch(mesh_get_velocity_of, dim=1, inputs=[plain.id, vels], device=DEV)
        wp.synchronize()
    # an id that is not a mesh
    grid = wp.HashGrid(2, 2, 2, device=DEV)
    _expect_launch_error(mesh_get_velocity_of, [grid.id, vels], match="not a live Mesh|is a HashGrid")


@wp.kernel
def mesh_get_area(mesh: wp.uint64, out: wp.array(dtype=float)):
    f = wp.tid()
    m = wp.mesh_get(mesh)
    a = m.points[m.indices[3 * f]]
    b = m.points[m.indices[3 * f + 1]]
    c = m.points[m.indices[3 * f + 2]]
    wp.atomic_add(out, 0, 0.5 * wp.length(wp.cross(b - a, c - a)))


def test_mesh_get_points_gradient(rng):
    """Loads through mesh_get's points accumulate into the points array's gradient on a tape
    (as in Warp): the total area's gradient against the float64 analytic one."""
    pts, tris = sphere_mesh(rng)
    points = wp.array(pts, dtype=wp.vec3, device=DEV, requires_grad=True)
    mesh = wp.Mesh(points=points, indices=wp.array(tris.reshape(-1), dtype=int, device=DEV))
    out = wp.zeros(1, dtype=float, device=DEV, requires_grad=True)
    tape = wp.Tape()
    with tape:
        wp.launch(mesh_get_area, dim=len(tris), inputs=[mesh.id, out], device=DEV)
    tape.backward(loss=out)
    p = pts.astype(np.float64)
    ref = np.zeros_like(p)
    area = 0.0
    for i, j, k in tris:
        a, b, c = p[i], p[j], p[k]
        n = np.cross(b - a, c - a)
        ln = np.linalg.norm(n)
        area += 0.5 * ln
        if ln == 0:
            continue
        u = n / ln
        ref[i] += 0.5 * np.cross(b - c, u)      # d|n|/da = (b - c) x u, and cyclically
        ref[j] += 0.5 * np.cross(c - a, u)
        ref[k] += 0.5 * np.cross(a - b, u)
    assert abs(out.numpy()[0] - area) <= 1e-4 * area
    np.testing.assert_allclose(points.grad.numpy(), ref, atol=1e-4)


def test_mesh_refit_after_moving_points(rng):
    mesh, pts, tris, _ = make_mesh(rng)
    offset = np.array([3.0, -2.0, 0.5], dtype=np.float32)
    wp.launch(move_points, dim=len(pts), inputs=[mesh.points, wp.vec3(*offset)], device=DEV)
    mesh.refit()
    moved = pts + offset.astype(np.float64)
    a, b, c = moved[tris[:, 0]], moved[tris[:, 1]], moved[tris[:, 2]]
    q = (rng.uniform(-1.5, 1.5, size=(50, 3)) + offset).astype(np.float32)
    hit = wp.zeros(50, dtype=int, device=DEV)
    closest = wp.zeros(50, dtype=wp.vec3, device=DEV)
    wp.launch(mesh_closest, dim=50, inputs=[mesh.id, wp.array(q, dtype=wp.vec3, device=DEV), 10.0, hit, closest,
                                            wp.zeros(50, dtype=int, device=DEV), wp.zeros(50, dtype=wp.vec4, device=DEV)],
              device=DEV)
    got_d = np.linalg.norm(closest.numpy() - q, axis=1)
    for i in range(50):
        ref_d = np.linalg.norm(closest_on_triangles(q[i].astype(np.float64), a, b, c) - q[i], axis=1).min()
        assert abs(got_d[i] - ref_d) <= 1e-3, (i, got_d[i], ref_d)
    mesh.rebuild()
    wp.launch(mesh_closest, dim=50, inputs=[mesh.id, wp.array(q, dtype=wp.vec3, device=DEV), 10.0, hit, closest,
                                            wp.zeros(50, dtype=int, device=DEV), wp.zeros(50, dtype=wp.vec4, device=DEV)],
              device=DEV)
    np.testing.assert_allclose(np.linalg.norm(closest.numpy() - q, axis=1), got_d, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Bvh

def test_bvh_queries_match_brute_force(rng):
    m = 700
    centers = rng.uniform(-5, 5, size=(m, 3))
    half = rng.uniform(0.01, 0.5, size=(m, 3))
    lo, hi = (centers - half).astype(np.float32), (centers + half).astype(np.float32)
    lowers, uppers = wp.array(lo, dtype=wp.vec3, device=DEV), wp.array(hi, dtype=wp.vec3, device=DEV)
    bvh = wp.Bvh(lowers, uppers)
    n = 60
    qc = rng.uniform(-5, 5, size=(n, 3))
    qh = rng.uniform(0.1, 1.5, size=(n, 3))
    ql, qu = (qc - qh).astype(np.float32), (qc + qh).astype(np.float32)
    hits = wp.zeros((n, m), dtype=int, device=DEV)
    wp.launch(bvh_boxes, dim=n, inputs=[bvh.id, wp.array(ql, dtype=wp.vec3, device=DEV),
                                        wp.array(qu, dtype=wp.vec3, device=DEV), hits], device=DEV)
    got = hits.numpy()
    assert got.max() <= 1
    lo64, hi64 = lo.astype(np.float64), hi.astype(np.float64)
    for i in range(n):
        sure = ((lo64 < qu[i] - TOL) & (hi64 > ql[i] + TOL)).all(1)
        maybe = ((lo64 <= qu[i] + TOL) & (hi64 >= ql[i] - TOL)).all(1)
        assert (got[i][sure] == 1).all() and (got[i][~maybe] == 0).all()
    # rays
    starts = rng.uniform(-6, 6, size=(n, 3)).astype(np.float32)
    dirs = rng.normal(size=(n, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    rhits = wp.zeros((n, m), dtype=int, device=DEV)
    wp.launch(bvh_rays, dim=n, inputs=[bvh.id, wp.array(starts, dtype=wp.vec3, device=DEV),
                                       wp.array(dirs, dtype=wp.vec3, device=DEV), rhits], device=DEV)
    rgot = rhits.numpy()

    def slab(s, d, l, h, shrink):
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (l + shrink - s) / d, (h - shrink - s) / d
        tmin = np.nanmax(np.where(np.isnan(np.minimum(t1, t2)), -np.inf, np.minimum(t1, t2)), axis=1)
        tmax = np.nanmin(np.where(np.isnan(np.maximum(t1, t2)), np.inf, np.maximum(t1, t2)), axis=1)
        return tmax >= np.maximum(tmin, 0)

    for i in range(n):
        s, d = starts[i].astype(np.float64), dirs[i].astype(np.float64)
        sure = slab(s, d, lo64, hi64, 1e-3)
        maybe = slab(s, d, lo64, hi64, -1e-3)
        assert (rgot[i][sure] == 1).all() and (rgot[i][~maybe] == 0).all()
    # refit after moving the boxes
    wp.launch(move_points, dim=m, inputs=[lowers, wp.vec3(10.0, 0.0, 0.0)], device=DEV)
    wp.launch(move_points, dim=m, inputs=[uppers, wp.vec3(10.0, 0.0, 0.0)], device=DEV)
    bvh.refit()
    hits.zero_()
    wp.launch(bvh_boxes, dim=n, inputs=[bvh.id, wp.array(ql + np.float32([10, 0, 0]), dtype=wp.vec3, device=DEV),
                                        wp.array(qu + np.float32([10, 0, 0]), dtype=wp.vec3, device=DEV), hits], device=DEV)
    got2 = hits.numpy()
    for i in range(n):
        sure = ((lo64 < qu[i] - TOL) & (hi64 > ql[i] + TOL)).all(1)
        assert (got2[i][sure] == 1).all()


@wp.kernel
def bvh_boxes_tiled(bvh: wp.uint64, lowers: wp.array(dtype=wp.vec3), uppers: wp.array(dtype=wp.vec3),
                    hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    query = wp.tile_bvh_query_aabb(bvh, lowers[tid], uppers[tid])
    while wp.tile_query_valid(query):
        item = wp.untile(wp.tile_bvh_query_next(query))
        if item >= 0:
            hits[tid, item] = hits[tid, item] + 1


@wp.kernel
def bvh_rays_tiled(bvh: wp.uint64, starts: wp.array(dtype=wp.vec3), dirs: wp.array(dtype=wp.vec3),
                   hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    query = wp.bvh_query_ray_tiled(bvh, starts[tid], dirs[tid])   # Warp's deprecated names
    while wp.tile_query_valid(query):
        item = wp.bvh_query_next_tiled(query)[0]
        if item >= 0:
            hits[tid, item] = hits[tid, item] + 1


@wp.kernel
def mesh_aabb_faces_tiled(mesh: wp.uint64, lowers: wp.array(dtype=wp.vec3), uppers: wp.array(dtype=wp.vec3),
                          hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    query = wp.tile_mesh_query_aabb(mesh, lowers[tid], uppers[tid])
    while wp.tile_query_valid(query):
        f = wp.untile(wp.tile_mesh_query_aabb_next(query))
        if f >= 0:
            hits[tid, f] = hits[tid, f] + 1


def test_tiled_queries_report_what_thread_queries_do_once(rng):
    """Warp's tiled BVH and mesh queries (one thread per block: each _next gives a (1,) tile of
    the next item, -1 at the end, after which tile_query_valid is false) report exactly the items
    of the thread queries, each once, launched plainly and tiled."""
    m, n = 500, 40
    c = rng.uniform(-5, 5, size=(m, 3))
    h = rng.uniform(0.01, 0.6, size=(m, 3))
    bvh = wp.Bvh(wp.array((c - h).astype(np.float32), dtype=wp.vec3, device=DEV),
                 wp.array((c + h).astype(np.float32), dtype=wp.vec3, device=DEV))
    qc, qh = rng.uniform(-5, 5, size=(n, 3)), rng.uniform(0.1, 1.5, size=(n, 3))
    ql = wp.array((qc - qh).astype(np.float32), dtype=wp.vec3, device=DEV)
    qu = wp.array((qc + qh).astype(np.float32), dtype=wp.vec3, device=DEV)
    d = rng.normal(size=(n, 3))
    starts = wp.array(rng.uniform(-6, 6, size=(n, 3)).astype(np.float32), dtype=wp.vec3, device=DEV)
    dirs = wp.array((d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32), dtype=wp.vec3, device=DEV)
    mesh, _, tris, _ = make_mesh(rng)
    for thread_kernel, tiled_kernel, obj, a, b, width in (
            (bvh_boxes, bvh_boxes_tiled, bvh, ql, qu, m), (bvh_rays, bvh_rays_tiled, bvh, starts, dirs, m),
            (mesh_aabb_faces, mesh_aabb_faces_tiled, mesh,
             wp.array((qc * 0.3 - qh * 0.2).astype(np.float32), dtype=wp.vec3, device=DEV),
             wp.array((qc * 0.3 + qh * 0.2).astype(np.float32), dtype=wp.vec3, device=DEV), len(tris))):
        want = wp.zeros((n, width), dtype=int, device=DEV)
        wp.launch(thread_kernel, dim=n, inputs=[obj.id, a, b, want], device=DEV)
        assert want.numpy().sum() > 0
        for launch in (wp.launch, wp.launch_tiled):
            got = wp.zeros((n, width), dtype=int, device=DEV)
            launch(tiled_kernel, dim=n, inputs=[obj.id, a, b, got], device=DEV)
            np.testing.assert_array_equal(got.numpy(), want.numpy())
    out = wp.zeros((n, m), dtype=int, device=DEV)
    with pytest.raises(wp.WeftError, match=r"bvh_query_aabb.*is not a live Bvh of this session"):   # a forged id
        wp.launch(bvh_boxes_tiled, dim=n, inputs=[bvh.id + 12345, ql, qu, out], device=DEV)
        wp.synchronize()
    _daemon_still_serves(rng)


def _hard_boxes(rng, case):
    """Boxes (lo, hi) float32 that stress a tree build: identical boxes (one Morton code for all),
    exponentially spaced tiny boxes, magnitudes from 1e-30 to 1e30, two far clusters, a single
    box, infinite and NaN bounds, and 100k boxes (many sort tiles, a deep tree)."""
    if case == "identical":
        lo = np.tile(np.float32([0.25, -1.0, 3.0]), (5000, 1))
        return lo, lo + np.float32(0.5)
    if case == "exponential":
        x = np.float32(2.0) ** -np.arange(0, 120, dtype=np.float32)
        lo = np.stack([x, x * 0.5, np.zeros_like(x)], 1).astype(np.float32)
        return lo, (lo + x[:, None] * np.float32(0.25)).astype(np.float32)
    if case == "magnitudes":
        c = rng.choice([-1.0, 1.0], size=(3000, 3)) * 10.0 ** rng.uniform(-30, 30, size=(3000, 3))
        h = np.abs(c) * rng.uniform(0.0, 0.5, size=(3000, 3))
        return (c - h).astype(np.float32), (c + h).astype(np.float32)
    if case == "clusters":
        c = np.concatenate([rng.normal(size=(2000, 3)), 1e6 + rng.normal(size=(2000, 3))])
        return (c - 0.05).astype(np.float32), (c + 0.05).astype(np.float32)
    if case == "one":
        return np.float32([[1.0, 2.0, 3.0]]), np.float32([[1.5, 2.5, 3.5]])
    if case == "nonfinite":
        c = rng.uniform(-5, 5, size=(4000, 3))
        lo, hi = (c - 0.2).astype(np.float32), (c + 0.2).astype(np.float32)
        lo[::97, 0], hi[::97, 0] = -np.inf, np.inf
        lo[5::131, 1] = np.nan
        hi[7::149, 2] = np.nan
        return lo, hi
    c = rng.uniform(-50, 50, size=(100_000, 3))
    h = rng.uniform(0.01, 0.3, size=(100_000, 3))
    return (c - h).astype(np.float32), (c + h).astype(np.float32)


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize("case", ["identical", "exponential", "magnitudes", "clusters", "one", "nonfinite", "many"])
def test_bvh_on_hard_inputs_finds_exactly_the_overlapping_boxes(rng, case):
    """A box query reports every item whose box overlaps it exactly once (the float32 test of the
    kernel, computed here in NumPy), after the build, a refit and a rebuild; items with a NaN
    bound may go either way. On a GPU the tree is built on the device (docs/geometry.md)."""
    lo, hi = _hard_boxes(rng, case)
    m = len(lo)
    lowers, uppers = wp.array(lo, dtype=wp.vec3, device=DEV), wp.array(hi, dtype=wp.vec3, device=DEV)
    bvh = wp.Bvh(lowers, uppers, constructor="sah")
    assert bvh.constructor == ("lbvh" if DEV.startswith("cuda") else "median")   # what weftd builds
    fin = ~(np.isnan(lo).any(1) | np.isnan(hi).any(1))
    picks = rng.integers(0, m, size=12)
    grow = rng.uniform(0.0, 2.0, size=(12, 1)).astype(np.float32)
    ql = np.concatenate([lo[picks] - grow * np.abs(lo[picks]) - np.float32(1e-3), np.float32([[-3e38] * 3])])
    qu = np.concatenate([hi[picks] + grow * np.abs(hi[picks]) + np.float32(1e-3), np.float32([[3e38] * 3])])
    ql = np.where(np.isnan(ql), np.float32(0), ql).astype(np.float32)
    qu = np.where(np.isnan(qu), np.float32(1), qu).astype(np.float32)
    n = len(ql)

    def check(clo, chi):
        hits = wp.zeros((n, m), dtype=int, device=DEV)
        wp.launch(bvh_boxes, dim=n, inputs=[bvh.id, wp.array(ql, dtype=wp.vec3, device=DEV),
                                            wp.array(qu, dtype=wp.vec3, device=DEV), hits], device=DEV)
        got = hits.numpy()
        assert got.max() <= 1, "an item was reported twice"
        with np.errstate(invalid="ignore"):
            for i in range(n):
                want = ~((clo > qu[i]) | (chi < ql[i])).any(1)
                assert (got[i][fin] == want[fin]).all(), (case, i, np.flatnonzero(got[i][fin] != want[fin])[:8])
        assert (got[-1][fin] == 1).all()   # the query over everything finds every finite box

    check(lo, hi)
    shift = np.float32([0.5, -0.25, 2.0])
    wp.launch(move_points, dim=m, inputs=[lowers, wp.vec3(*shift)], device=DEV)
    wp.launch(move_points, dim=m, inputs=[uppers, wp.vec3(*shift)], device=DEV)
    bvh.refit()
    moved_lo, moved_hi = lowers.numpy(), uppers.numpy()
    check(moved_lo, moved_hi)
    bvh.rebuild()
    check(moved_lo, moved_hi)


@wp.kernel
def bvh_group_boxes(bvh: wp.uint64, lowers: wp.array(dtype=wp.vec3), uppers: wp.array(dtype=wp.vec3),
                    groups: wp.array(dtype=int), hits: wp.array2d(dtype=int), roots: wp.array(dtype=int)):
    tid = wp.tid()
    root = wp.bvh_get_group_root(bvh, groups[tid])
    roots[tid] = root
    query = wp.bvh_query_aabb(bvh, lowers[tid], uppers[tid], root)
    item = int(0)
    while wp.bvh_query_next(query, item):
        hits[tid, item] = hits[tid, item] + 1


@wp.kernel
def mesh_group_rays(mesh: wp.uint64, starts: wp.array(dtype=wp.vec3), dirs: wp.array(dtype=wp.vec3),
                    groups: wp.array(dtype=int), faces: wp.array(dtype=int), counts: wp.array(dtype=int)):
    tid = wp.tid()
    root = wp.mesh_get_group_root(mesh, groups[tid])
    q = wp.mesh_query_ray(mesh, starts[tid], dirs[tid], 100.0, root)
    faces[tid] = wp.where(q.result, q.face, -1)
    counts[tid] = wp.mesh_query_ray_count_intersections(mesh, starts[tid], dirs[tid], root)


def test_grouped_bvh_queries_visit_only_their_group(rng):
    m = 600
    centers = rng.uniform(-5, 5, size=(m, 3))
    half = rng.uniform(0.05, 0.6, size=(m, 3))
    lo, hi = (centers - half).astype(np.float32), (centers + half).astype(np.float32)
    ids = np.array([-2**31, -7, 0, 3, 2**31 - 1], dtype=np.int32)
    groups_np = ids[rng.integers(0, len(ids), size=m)]
    groups_np[:len(ids)] = ids                                  # every group present
    bvh = wp.Bvh(wp.array(lo, dtype=wp.vec3, device=DEV), wp.array(hi, dtype=wp.vec3, device=DEV),
                 groups=wp.array(groups_np, dtype=int, device=DEV))
    n = 80
    qc = rng.uniform(-5, 5, size=(n, 3))
    qh = rng.uniform(0.2, 2.0, size=(n, 3))
    ql, qu = (qc - qh).astype(np.float32), (qc + qh).astype(np.float32)
    qg = np.concatenate([ids[rng.integers(0, len(ids), size=n - 10)], np.full(10, 12345, np.int32)])
    hits = wp.zeros((n, m), dtype=int, device=DEV)
    roots = wp.zeros(n, dtype=int, device=DEV)
    wp.launch(bvh_group_boxes, dim=n, inputs=[bvh.id, wp.array(ql, dtype=wp.vec3, device=DEV),
                                              wp.array(qu, dtype=wp.vec3, device=DEV),
                                              wp.array(qg, dtype=int, device=DEV), hits, roots], device=DEV)
    got, r = hits.numpy(), roots.numpy()
    lo64, hi64 = lo.astype(np.float64), hi.astype(np.float64)
    for i in range(n):
        overlap = ((lo64 <= qu[i]) & (hi64 >= ql[i])).all(1)
        if qg[i] == 12345:                     # no such group: root -1 walks the whole tree
            assert r[i] == -1
            want = overlap
        else:
            assert r[i] >= 0
            want = overlap & (groups_np == qg[i])
        sure = ((lo64 < qu[i] - TOL) & (hi64 > ql[i] + TOL)).all(1)
        assert (got[i][want & sure] == 1).all() and (got[i][~want] == 0).all(), i
    # a rebuild keeps the groups (read once, at creation)
    bvh.rebuild()
    hits.zero_()
    wp.launch(bvh_group_boxes, dim=n, inputs=[bvh.id, wp.array(ql, dtype=wp.vec3, device=DEV),
                                              wp.array(qu, dtype=wp.vec3, device=DEV),
                                              wp.array(qg, dtype=int, device=DEV), hits, roots], device=DEV)
    np.testing.assert_array_equal(hits.numpy(), got)


@wp.kernel
def bvh_group_all(bvh: wp.uint64, groups: wp.array(dtype=int), lower: wp.vec3, upper: wp.vec3,
                  hits: wp.array2d(dtype=int), roots: wp.array(dtype=int)):
    tid = wp.tid()
    root = wp.bvh_get_group_root(bvh, groups[tid])
    roots[tid] = root
    query = wp.bvh_query_aabb(bvh, lower, upper, root)
    item = int(0)
    while wp.bvh_query_next(query, item):
        hits[tid, item] = hits[tid, item] + 1


@pytest.mark.parametrize("case", ["powers_of_two", "one_group", "each_its_own", "one_box_each"])
def test_grouped_bvh_on_hard_inputs(rng, case):
    """Grouped trees (built on the device on a GPU: a linear BVH over (group rank, Morton code,
    position) keys) on hostile group ids: ids that are powers of two and both int32 extremes (a
    deep tree if the raw ids were the keys), one group for everything, every item its own group,
    and boxes that all coincide within a group (one Morton code). For every group present, the
    query over everything from its root reports exactly its items, each once; from the whole
    tree's root (-1, an absent group) every item once; after a refit of moved boxes and after a
    rebuild (the groups were read once, at creation: later writes to them change nothing)."""
    n = 20_000 if case != "each_its_own" else 3_000
    centers = rng.uniform(-50, 50, size=(n, 3))
    if case == "powers_of_two":
        ids = np.array([-2**31, 2**31 - 1] + [1 << k for k in range(31)] + [-(1 << k) for k in range(31)],
                       dtype=np.int64).astype(np.int32)
        groups_np = ids[rng.integers(0, len(ids), size=n)]
        groups_np[:len(ids)] = ids
        centers[groups_np == 4] = centers[np.flatnonzero(groups_np == 4)[0]]   # one Morton code
    elif case == "one_group":
        groups_np = np.full(n, -123456, dtype=np.int32)
    elif case == "each_its_own":
        groups_np = rng.permutation(np.arange(n, dtype=np.int32) * 7919 - 2**30).astype(np.int32)
    else:
        groups_np = rng.integers(-3, 3, size=n).astype(np.int32)
        centers[:] = centers[0]                       # every box the same: one code everywhere
    half = rng.uniform(0.01, 1.0, size=(n, 3))
    lo, hi = (centers - half).astype(np.float32), (centers + half).astype(np.float32)
    lowers = wp.array(lo, dtype=wp.vec3, device=DEV)
    uppers = wp.array(hi, dtype=wp.vec3, device=DEV)
    groups = wp.array(groups_np, dtype=int, device=DEV)
    bvh = wp.Bvh(lowers, uppers, groups=groups)
    present = np.unique(groups_np)
    if len(present) > 40:
        present = rng.choice(present, 40, replace=False)
    absent = np.int32(2**31 - 1) if (groups_np != 2**31 - 1).all() else np.int32(5)
    assert (groups_np != absent).all()
    query_groups = np.concatenate([present, [absent]]).astype(np.int32)
    big = wp.vec3(1e6, 1e6, 1e6)

    def check(tag):
        hits = wp.zeros((len(query_groups), n), dtype=int, device=DEV)
        roots = wp.zeros(len(query_groups), dtype=int, device=DEV)
        wp.launch(bvh_group_all, dim=len(query_groups),
                  inputs=[bvh.id, wp.array(query_groups, dtype=int, device=DEV), -big, big, hits, roots],
                  device=DEV)
        got, r = hits.numpy(), roots.numpy()
        for q, g in enumerate(query_groups):
            if g == absent:
                assert r[q] == -1, (tag, case)
                want = np.ones(n, dtype=bool)
            else:
                assert r[q] >= 0, (tag, case, g)
                want = groups_np == g
            wrong = np.flatnonzero(got[q] != want.astype(int))
            assert wrong.size == 0, (tag, case, int(g), wrong[:8], got[q][wrong[:8]])

    check("built")
    groups.fill_(0)                                   # read once, at creation
    shift = np.float32([3.0, -1.5, 0.25])
    wp.launch(move_points, dim=n, inputs=[lowers, wp.vec3(*shift)], device=DEV)
    wp.launch(move_points, dim=n, inputs=[uppers, wp.vec3(*shift)], device=DEV)
    bvh.refit()
    check("refit")
    bvh.rebuild()
    check("rebuilt")


def test_grouped_mesh_rays_hit_only_their_group(rng):
    # two unit squares facing -z at z = 1 (group 5) and z = 2 (group -1), under the same rays
    pts = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1], [0, 0, 2], [1, 0, 2], [1, 1, 2], [0, 1, 2]],
                   dtype=np.float32)
    tris = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], dtype=np.int32)
    mesh = wp.Mesh(wp.array(pts, dtype=wp.vec3, device=DEV), wp.array(tris.ravel(), dtype=int, device=DEV),
                   groups=wp.array(np.array([5, 5, -1, -1], dtype=np.int32), dtype=int, device=DEV))
    n = 64
    xy = rng.uniform(0.05, 0.95, size=(n, 2))
    xy = xy[np.abs(xy[:, 0] - xy[:, 1]) > 1e-3]   # off the diagonal shared by two triangles
    n = len(xy)
    starts = np.concatenate([xy, np.zeros((n, 1))], axis=1).astype(np.float32)
    dirs = np.tile(np.float32([0, 0, 1]), (n, 1))
    qg = np.array([[5, -1, 77][k % 3] for k in range(n)], dtype=np.int32)
    faces = wp.zeros(n, dtype=int, device=DEV)
    counts = wp.zeros(n, dtype=int, device=DEV)
    wp.launch(mesh_group_rays, dim=n, inputs=[mesh.id, wp.array(starts, dtype=wp.vec3, device=DEV),
                                              wp.array(dirs, dtype=wp.vec3, device=DEV),
                                              wp.array(qg, dtype=int, device=DEV), faces, counts], device=DEV)
    f, c = faces.numpy(), counts.numpy()
    for i in range(n):
        lower_tri = 0 if xy[i, 0] > xy[i, 1] else 1      # which triangle of a square holds (x, y)
        if qg[i] == 5:
            assert f[i] == lower_tri and c[i] == 1
        elif qg[i] == -1:
            assert f[i] == 2 + lower_tri and c[i] == 1
        else:                                            # unknown group: the whole mesh, nearest hit
            assert f[i] == lower_tri and c[i] == 2


def test_bad_groups_of_bvh_and_mesh_are_refused():
    lo = wp.zeros(4, dtype=wp.vec3, device=DEV)
    hi = wp.ones(4, dtype=wp.vec3, device=DEV)
    with pytest.raises(RuntimeError, match="groups should be a contiguous array of type wp.int32"):
        wp.Bvh(lo, hi, groups=wp.zeros(4, dtype=float, device=DEV))
    with pytest.raises(RuntimeError, match="same length as lowers/uppers"):
        wp.Bvh(lo, hi, groups=wp.zeros(3, dtype=int, device=DEV))
    # the daemon checks again: a raw request with a short groups array
    short = wp.zeros(3, dtype=int, device=DEV)
    from weft import geometry
    with pytest.raises(wp.WeftError, match="3 group ids for 4 items"):
        geometry._call(wp._runtime.get_runtime(), op=geometry._op().CREATE_BVH, lowers=geometry._handle_of(lo, "l"),
                       uppers=geometry._handle_of(hi, "u"), groups=geometry._handle_of(short, "g"))
    pts = wp.zeros(3, dtype=wp.vec3, device=DEV)
    idx = wp.array(np.arange(3, dtype=np.int32), dtype=int, device=DEV)
    with pytest.raises(RuntimeError, match="same length as indices / 3"):
        wp.Mesh(pts, idx, groups=wp.zeros(2, dtype=int, device=DEV))


# ---------------------------------------------------------------------------------------------
# attacks: ids are validated per launch, never dereferenced; the daemon keeps serving

def _expect_launch_error(kernel, inputs, dim=1, match="not a live Mesh"):
    with pytest.raises(wp.WeftError, match=match):
        wp.launch(kernel, dim=dim, inputs=inputs, device=DEV)
        wp.synchronize()


def _daemon_still_serves(rng):
    mesh, _, _, _ = make_mesh(rng)
    out = wp.zeros(1, dtype=float, device=DEV)
    wp.launch(any_point_query, dim=1, inputs=[mesh.id, out], device=DEV)
    assert np.isfinite(out.numpy()).all()


def test_forged_ids_are_launch_errors(rng):
    mesh, _, _, _ = make_mesh(rng)
    out = wp.zeros(4, dtype=float, device=DEV)
    for forged in (12345, mesh.id ^ (1 << 40), mesh.id + 1, (1 << 64) - 1, 0x7fffffff00000001):
        _expect_launch_error(any_point_query, [forged, out], dim=4, match="is not a live Mesh|is not a Mesh|names no")
    _expect_launch_error(any_point_query, [0, out], match="id 0")
    # the error names the kernel and the line
    with pytest.raises(wp.WeftError, match=r"test_geometry_objects.py:\d+: kernel 'any_point_query'"):
        wp.launch(any_point_query, dim=1, inputs=[424242, out], device=DEV)
        wp.synchronize()
    _daemon_still_serves(rng)


def test_id_of_freed_object_and_wrong_kind(rng):
    mesh, _, _, _ = make_mesh(rng)
    stale = mesh.id
    mesh._free()
    out = wp.zeros(1, dtype=float, device=DEV)
    _expect_launch_error(any_point_query, [stale, out])
    grid = wp.HashGrid(4, 4, 4, device=DEV)
    _expect_launch_error(any_point_query, [grid.id, out], match="is a HashGrid, not a Mesh")
    with pytest.raises(wp.WeftError, match="names no live object"):
        from weft import geometry
        geometry._call(wp._runtime.get_runtime() if hasattr(wp, "_runtime") else None, op=geometry._op().REFIT, id=stale)
    _daemon_still_serves(rng)


def test_a_released_object_is_freed_by_the_next_batch_without_a_round_trip(rng, monkeypatch):
    """Dropping the last reference to a geometry object makes no call to the daemon (a finalizer
    may run anywhere): the free is a command of the session's next batch, after the launches
    queued before it, which still see the object; a launch after it gets the stale-id error."""
    rt = wp._runtime.get_runtime()
    lo = rng.uniform(-1, 1, size=(500, 3)).astype(np.float32)
    lowers = wp.array(lo, dtype=wp.vec3, device=DEV)
    uppers = wp.array(lo + np.float32(0.1), dtype=wp.vec3, device=DEV)
    bvh = wp.Bvh(lowers, uppers)
    stale = bvh.id
    hits = wp.zeros((1, 500), dtype=int, device=DEV)
    big = wp.array(np.float32([[-5, -5, -5]]), dtype=wp.vec3, device=DEV)
    wp.launch(bvh_boxes, dim=1, inputs=[stale, big, wp.array(np.float32([[5, 5, 5]]), dtype=wp.vec3, device=DEV),
                                        hits], device=DEV)
    calls = []
    for name in ("call", "geometry_call"):
        real = getattr(rt, name)
        monkeypatch.setattr(rt, name, lambda *a, _real=real, **k: (calls.append(a), _real(*a, **k))[1])
    del bvh
    assert calls == []
    monkeypatch.undo()
    assert (hits.numpy() == 1).all()   # the launch queued before the free found every box
    _expect_launch_error(bvh_boxes, [stale, big, big, hits], match="not a live Bvh")
    _daemon_still_serves(rng)


def test_checked_accessors_report_out_of_range(rng):
    mesh, _, tris, _ = make_mesh(rng)
    out = wp.zeros(1, dtype=wp.vec3, device=DEV)
    for bad in (-1, 3 * len(tris), 2**31 - 1):
        _expect_launch_error(get_point, [mesh.id, bad, out], match="mesh_get_point: index -?\\d+ is out of range")
    _daemon_still_serves(rng)


def test_another_sessions_mesh_id_is_refused(rng, weftd, tmp_path):
    child = tmp_path / "owner.py"
    child.write_text(textwrap.dedent("""
        import sys
        import numpy as np
        import weft as wp
        pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
        dev = sys.argv[1]
        mesh = wp.Mesh(wp.array(pts, dtype=wp.vec3, device=dev), wp.array([0, 1, 2], dtype=int, device=dev))
        print(mesh.id, flush=True)
        sys.stdin.readline()   # alive until the parent is done
    """))
    env = dict(os.environ)
    client_dir = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
    env["PYTHONPATH"] = os.pathsep.join([client_dir] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    proc = subprocess.Popen([sys.executable, str(child), DEV], stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, text=True)
    try:
        foreign = int(proc.stdout.readline())
        out = wp.zeros(1, dtype=float, device=DEV)
        _expect_launch_error(any_point_query, [foreign, out])
        _daemon_still_serves(rng)
    finally:
        proc.stdin.close()
        proc.wait(timeout=60)
    assert proc.returncode == 0


def test_bad_arrays_and_dims_are_refused(rng):
    pts = wp.array(rng.uniform(size=(4, 3)).astype(np.float32), dtype=wp.vec3, device=DEV)
    for bad in ([0, 1, 4], [0, 1, -1], [0, 1, 2**31 - 1], [0, 1]):
        with pytest.raises(wp.WeftError, match="Mesh indices"):
            wp.Mesh(pts, wp.array(np.array(bad, dtype=np.int32), dtype=int, device=DEV))
    # The first bad index of many is named, wherever the check runs (on a GPU: on the device,
    # over thousands of blocks; with groups: on the host).
    many = rng.integers(0, 4, size=3 * 1_000_000).astype(np.int32)
    many[2_500_000], many[2_000_001], many[2_999_999] = 99, -7, 4
    for groups in (None, wp.zeros(1_000_000, dtype=int, device=DEV)):
        with pytest.raises(wp.WeftError, match=r"indices\[2000001\] = -7 is out of range for 4 points"):
            wp.Mesh(pts, wp.array(many, dtype=int, device=DEV), groups=groups)
    with pytest.raises(wp.WeftError, match="vec3"):
        wp.Mesh(wp.zeros(5, dtype=float, device=DEV), wp.array([0, 1, 2], dtype=int, device=DEV))
    with pytest.raises(wp.WeftError, match="int32"):
        wp.Mesh(pts, wp.array([0.0, 1.0, 2.0], dtype=float, device=DEV))
    with pytest.raises(wp.WeftError, match="lowers has 4 items and uppers 3"):
        wp.Bvh(pts, wp.zeros(3, dtype=wp.vec3, device=DEV))
    with pytest.raises(wp.WeftError, match="cell count exceeds supported limit"):
        wp.HashGrid(2**20, 2**20, 2**20, device=DEV)
    with pytest.raises(wp.WeftError, match="cell count exceeds supported limit"):
        wp.HashGrid(2**31 - 1, 2**31 - 1, 2**31 - 1, device=DEV)
    grid = wp.HashGrid(2, 2, 2, device=DEV)
    for r in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="radius"):
            grid.build(pts, r)
    with pytest.raises(TypeError, match="needs points of"):
        grid.build(wp.zeros(3, dtype=wp.vec3d, device=DEV), 1.0)
    from weft import geometry
    rt = wp._runtime.get_runtime() if hasattr(wp, "_runtime") else None
    with pytest.raises(wp.WeftError, match="dims must be >= 1"):
        geometry._call(rt, op=geometry._op().CREATE_HASH_GRID, device=DEV, dim=[-5, 1, 1])
    with pytest.raises(wp.WeftError, match="dim must have 3 values"):
        geometry._call(rt, op=geometry._op().CREATE_HASH_GRID, device=DEV, dim=[1])
    with pytest.raises(wp.WeftError, match="unknown array handle"):
        geometry._call(rt, op=geometry._op().CREATE_MESH, points=999999999, indices=999999998)
    for r in (0.0, -1.0, float("nan"), float("inf")):   # the daemon checks what the client skipped
        with pytest.raises(wp.WeftError, match="radius must be a positive finite number"):
            geometry._call(rt, op=geometry._op().BUILD_HASH_GRID, id=grid.id, points=pts._handle, radius=r)
    with pytest.raises(wp.WeftError, match="unknown operation"):
        geometry._call(rt, op=99)
    _daemon_still_serves(rng)


# ---------------------------------------------------------------------------------------------
# Warp's other spellings: for-loops over queries, out-parameter forms, any-hit and counts

@wp.kernel
def grid_for_loop(grid: wp.uint64, points: wp.array(dtype=wp.vec3), radius: float, counts: wp.array(dtype=int)):
    tid = wp.tid()
    p = points[tid]
    n = int(0)
    for index in wp.hash_grid_query(grid, p, radius):
        if wp.length(points[index] - p) <= radius:
            n += 1
    counts[tid] = n


@wp.kernel
def mesh_out_params(mesh: wp.uint64, queries: wp.array(dtype=wp.vec3), dist: wp.array(dtype=float),
                    signs: wp.array(dtype=float), faces: wp.array(dtype=int)):
    tid = wp.tid()
    p = queries[tid]
    sign = float(0.0)
    face = int(0)
    u = float(0.0)
    v = float(0.0)
    if wp.mesh_query_point(mesh, p, 10.0, sign, face, u, v):
        dist[tid] = wp.length(wp.mesh_eval_position(mesh, face, u, v) - p)
        signs[tid] = sign
        faces[tid] = face


@wp.kernel
def mesh_ray_counts(mesh: wp.uint64, starts: wp.array(dtype=wp.vec3), dirs: wp.array(dtype=wp.vec3),
                    anyhit: wp.array(dtype=int), counts: wp.array(dtype=int), t_out: wp.array(dtype=float)):
    tid = wp.tid()
    if wp.mesh_query_ray_anyhit(mesh, starts[tid], dirs[tid], 100.0):
        anyhit[tid] = 1
    counts[tid] = wp.mesh_query_ray_count_intersections(mesh, starts[tid], dirs[tid])
    t = float(0.0)
    u = float(0.0)
    v = float(0.0)
    sign = float(0.0)
    n = wp.vec3()
    f = int(0)
    if wp.mesh_query_ray(mesh, starts[tid], dirs[tid], 100.0, t, u, v, sign, n, f, -1):
        t_out[tid] = t
    if wp.mesh_query_ray(mesh, starts[tid], dirs[tid], 100.0).result != wp.mesh_query_ray_anyhit(mesh, starts[tid], dirs[tid], 100.0, -1):
        t_out[tid] = -1.0


def test_warp_spellings(rng):
    n, radius = 400, 0.5
    pts = rng.uniform(0.0, 3.0, size=(n, 3)).astype(np.float32)
    points = wp.array(pts, dtype=wp.vec3, device=DEV)
    grid = wp.HashGrid(8, 8, 8, device=DEV)
    grid.build(points, radius)
    counts = wp.zeros(n, dtype=int, device=DEV)
    wp.launch(grid_for_loop, dim=n, inputs=[grid.id, points, radius, counts], device=DEV)
    d = np.linalg.norm(pts[:, None, :].astype(np.float64) - pts[None, :, :], axis=2)
    got = counts.numpy()
    assert (got >= (d <= radius - TOL).sum(1)).all() and (got <= (d <= radius + TOL).sum(1)).all()

    mesh, mpts, tris, _ = make_mesh(rng)
    a, b, c = mpts[tris[:, 0]], mpts[tris[:, 1]], mpts[tris[:, 2]]
    m = 60
    q = rng.uniform(-1.5, 1.5, size=(m, 3)).astype(np.float32)
    dist, signs, faces = wp.zeros(m, dtype=float, device=DEV), wp.zeros(m, dtype=float, device=DEV), \
        wp.zeros(m, dtype=int, device=DEV)
    wp.launch(mesh_out_params, dim=m, inputs=[mesh.id, wp.array(q, dtype=wp.vec3, device=DEV), dist, signs, faces],
              device=DEV)
    got_d, got_s = dist.numpy(), signs.numpy()
    for i in range(m):
        p = q[i].astype(np.float64)
        ref_d = np.linalg.norm(closest_on_triangles(p, a, b, c) - p, axis=1).min()
        assert abs(got_d[i] - ref_d) <= TOL
        if ref_d > 1e-2:
            assert got_s[i] == (-1.0 if winding_number(p, a, b, c) > 0.5 else 1.0)

    starts = rng.uniform(-3, 3, size=(m, 3)).astype(np.float32)
    dirs = -starts + rng.normal(scale=0.5, size=(m, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    anyhit, cnt, tt = wp.zeros(m, dtype=int, device=DEV), wp.zeros(m, dtype=int, device=DEV), \
        wp.zeros(m, dtype=float, device=DEV)
    wp.launch(mesh_ray_counts, dim=m, inputs=[mesh.id, wp.array(starts, dtype=wp.vec3, device=DEV),
                                              wp.array(dirs, dtype=wp.vec3, device=DEV), anyhit, cnt, tt], device=DEV)
    for i in range(m):
        ts = ray_reference(starts[i].astype(np.float64), dirs[i].astype(np.float64), a, b, c, np.inf)
        hits = np.isfinite(ts)
        if hits.any():
            assert anyhit.numpy()[i] == 1 and abs(tt.numpy()[i] - ts[hits].min()) <= TOL * max(1, ts[hits].min())
        # a ray from outside a closed surface crosses it an even number of times
        assert cnt.numpy()[i] == hits.sum() or abs(cnt.numpy()[i] - hits.sum()) <= 1


@wp.kernel
def mesh_sphere_faces(mesh: wp.uint64, centers: wp.array(dtype=wp.vec3), radius: float, hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    for f in wp.mesh_query_sphere(mesh, centers[tid], radius):
        hits[tid, f] = hits[tid, f] + 1


@wp.kernel
def bvh_sphere_items(bvh: wp.uint64, centers: wp.array(dtype=wp.vec3), radius: float, hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    query = wp.bvh_query_sphere(bvh, centers[tid], radius)
    item = int(0)
    while wp.bvh_query_next(query, item):
        hits[tid, item] = hits[tid, item] + 1


def test_sphere_queries_match_brute_force(rng):
    mesh, pts, tris, _ = make_mesh(rng)
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    n, r = 30, 0.4
    centers = rng.uniform(-1.3, 1.3, size=(n, 3)).astype(np.float32)
    hits = wp.zeros((n, len(tris)), dtype=int, device=DEV)
    wp.launch(mesh_sphere_faces, dim=n, inputs=[mesh.id, wp.array(centers, dtype=wp.vec3, device=DEV), r, hits],
              device=DEV)
    got = hits.numpy()
    assert got.max() <= 1
    for i in range(n):
        p = centers[i].astype(np.float64)
        d = np.linalg.norm(closest_on_triangles(p, a, b, c) - p, axis=1)
        assert (got[i][d < r - TOL] == 1).all() and (got[i][d > r + TOL] == 0).all()
    m = 300
    cb = rng.uniform(-3, 3, size=(m, 3))
    hb = rng.uniform(0.01, 0.4, size=(m, 3))
    lo, hi = (cb - hb).astype(np.float32), (cb + hb).astype(np.float32)
    bvh = wp.Bvh(wp.array(lo, dtype=wp.vec3, device=DEV), wp.array(hi, dtype=wp.vec3, device=DEV))
    bhits = wp.zeros((n, m), dtype=int, device=DEV)
    wp.launch(bvh_sphere_items, dim=n, inputs=[bvh.id, wp.array(centers, dtype=wp.vec3, device=DEV), 1.0, bhits],
              device=DEV)
    got = bhits.numpy()
    for i in range(n):
        p = centers[i].astype(np.float64)
        d = np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)
        assert (got[i][d < 1.0 - TOL] == 1).all() and (got[i][d > 1.0 + TOL] == 0).all()


@wp.kernel
def bvh_capsule_items(bvh: wp.uint64, p0: wp.array(dtype=wp.vec3), p1: wp.array(dtype=wp.vec3), radius: float,
                      hits: wp.array2d(dtype=int)):
    tid = wp.tid()
    query = wp.bvh_query_capsule(bvh, p0[tid], p1[tid] - p0[tid], radius)
    item = int(0)
    while wp.bvh_query_next(query, item, 1.0):
        hits[tid, item] = hits[tid, item] + 1


def segment_meets_inflated_boxes(p0, p1, r, lo, hi):
    """float64 slab test of the segment p0..p1 against every box inflated by r: (hit, margin),
    margin = how far inside the segment's t range the overlap is (small: a near miss either way)."""
    lo, hi = lo - r, hi + r
    d = p1 - p0
    t0, t1 = np.zeros(len(lo)), np.ones(len(lo))
    for k in range(3):
        if abs(d[k]) < 1e-12:
            inside = (p0[k] >= lo[:, k]) & (p0[k] <= hi[:, k])
            t1 = np.where(inside, t1, -1.0)
            continue
        a, b = (lo[:, k] - p0[k]) / d[k], (hi[:, k] - p0[k]) / d[k]
        t0, t1 = np.maximum(t0, np.minimum(a, b)), np.minimum(t1, np.maximum(a, b))
    return t0 <= t1, np.abs(t1 - t0)


def test_capsule_queries_match_float64(rng):
    m, n, r = 400, 40, 0.25
    cb = rng.uniform(-3, 3, size=(m, 3))
    hb = rng.uniform(0.01, 0.4, size=(m, 3))
    lo, hi = (cb - hb).astype(np.float32), (cb + hb).astype(np.float32)
    p0 = rng.uniform(-4, 4, size=(n, 3)).astype(np.float32)
    p1 = (p0 + rng.uniform(-3, 3, size=(n, 3))).astype(np.float32)
    p1[::5, 1] = p0[::5, 1]          # segments parallel to a slab: the degenerate axis
    p1[1::7] = p0[1::7]              # zero-length segments: a sphere of radius r
    bvh = wp.Bvh(wp.array(lo, dtype=wp.vec3, device=DEV), wp.array(hi, dtype=wp.vec3, device=DEV))
    hits = wp.zeros((n, m), dtype=int, device=DEV)
    wp.launch(bvh_capsule_items, dim=n, inputs=[bvh.id, wp.array(p0, dtype=wp.vec3, device=DEV),
                                              wp.array(p1, dtype=wp.vec3, device=DEV), r, hits], device=DEV)
    got = hits.numpy()
    assert got.max() <= 1 and got.sum() > 0
    for i in range(n):
        want, margin = segment_meets_inflated_boxes(p0[i].astype(np.float64), p1[i].astype(np.float64), r,
                                                    lo.astype(np.float64), hi.astype(np.float64))
        clear = margin > 1e-4
        assert (got[i][clear & want] == 1).all() and (got[i][clear & ~want] == 0).all()


_CUBE_POINTS = [(x, y, z) for z in (-0.5, 0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)]
# two triangles per face, counter-clockwise seen from outside (outward normals)
_CUBE_OUTWARD = [0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4,
                 2, 6, 3, 3, 6, 7, 0, 4, 2, 2, 4, 6, 1, 3, 5, 3, 7, 5]


@wp.kernel
def cube_signs(mesh: wp.uint64, points: wp.array(dtype=wp.vec3), out: wp.array2d(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point(mesh, points[i], 10.0)
    r = wp.mesh_query_point_sign_parity(mesh, points[i], 10.0, 3, 0.0)
    out[i, 0] = q.sign
    out[i, 1] = r.sign


def test_mesh_query_point_sign_follows_the_winding(wp, rng):
    """Warp 1.19's mesh_query_point: the sign is a vote of 3 axis rays on the orientation of
    their closest hits, so a cube wound inward reads its inside as outside; the parity sign does
    not depend on the winding."""
    inside = rng.uniform(-0.4, 0.4, size=(24, 3)).astype(np.float32)
    outside = (rng.uniform(0.6, 2.0, size=(24, 3)) * rng.choice([-1, 1], size=(24, 3))).astype(np.float32)
    pts = wp.array(np.concatenate([inside, outside]), dtype=wp.vec3)
    expected_inside = np.concatenate([-np.ones(24), np.ones(24)])
    for winding, flip in ((_CUBE_OUTWARD, 1.0), (np.array(_CUBE_OUTWARD).reshape(-1, 3)[:, ::-1].reshape(-1), -1.0)):
        mesh = wp.Mesh(points=wp.array(_CUBE_POINTS, dtype=wp.vec3), indices=wp.array(np.asarray(winding), dtype=int))
        out = wp.zeros((48, 2), dtype=float)
        wp.launch(cube_signs, dim=48, inputs=[mesh.id, pts, out])
        got = out.numpy()
        np.testing.assert_array_equal(got[:, 0], np.where(expected_inside < 0, -flip, 1.0))
        np.testing.assert_array_equal(got[:, 1], expected_inside)


# ---------------------------------------------------------------------------------------------
# mesh_get_bvh: a mesh's face BVH for BVH queries, and iterating a query held in a variable

@wp.kernel
def mesh_bvh_sphere(mesh: wp.uint64, centers: wp.array(dtype=wp.vec3), radius: float,
                    hits: wp.array2d(dtype=int)):
    i = wp.tid()
    query = wp.bvh_query_sphere(wp.mesh_get_bvh(mesh), centers[i], radius)
    for face in query:          # a query in a variable iterates like wp.bvh_query_next
        hits[i, face] += 1


@wp.kernel
def mesh_bvh_as_mesh(mesh: wp.uint64, out: wp.array(dtype=wp.vec3)):
    out[0] = wp.mesh_get_point(wp.mesh_get_bvh(mesh), 0)


@wp.kernel
def bvh_query_of(obj: wp.uint64, out: wp.array(dtype=int)):
    query = wp.bvh_query_aabb(obj, wp.vec3(-10.0), wp.vec3(10.0))
    k = int(0)
    while wp.bvh_query_next(query, k):
        out[0] += 1


def test_mesh_get_bvh_sphere_queries_match_the_face_bounds(rng):
    mesh, pts, tris, _ = make_mesh(rng)
    a, b, c = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    lo_t, hi_t = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    n = 30
    centers = rng.uniform(-1.3, 1.3, size=(n, 3)).astype(np.float32)
    radius = float(rng.uniform(0.1, 0.5))
    hits = wp.zeros((n, len(tris)), dtype=int, device=DEV)
    wp.launch(mesh_bvh_sphere, dim=n, inputs=[mesh.id, wp.array(centers, dtype=wp.vec3, device=DEV), radius,
                                              hits], device=DEV)
    got = hits.numpy()
    assert got.max() <= 1 and got.sum() > 0   # each face at most once, and some faces hit
    for i in range(n):   # broad phase: every face whose bounds the sphere reaches, exactly once
        cp = np.clip(centers[i].astype(np.float64), lo_t, hi_t)
        d2 = ((centers[i] - cp) ** 2).sum(1)
        sure, maybe = d2 < radius * radius - TOL, d2 <= radius * radius + TOL
        assert (got[i][sure] == 1).all() and (got[i][~maybe] == 0).all()


def test_mesh_get_bvh_id_serves_bvh_queries_only(rng):
    mesh, _, _, _ = make_mesh(rng)
    out = wp.zeros(1, dtype=wp.vec3, device=DEV)
    with pytest.raises(wp.WeftError, match=r"mesh_get_point.*is not a live Mesh of this session"):
        wp.launch(mesh_bvh_as_mesh, dim=1, inputs=[mesh.id, out], device=DEV)
        wp.synchronize()
    count = wp.zeros(1, dtype=int, device=DEV)
    with pytest.raises(wp.WeftError, match=r"bvh_query_aabb.*is a Mesh, not a Bvh"):   # the plain mesh id
        wp.launch(bvh_query_of, dim=1, inputs=[mesh.id, count], device=DEV)
        wp.synchronize()
    lowers = wp.array(rng.uniform(-1, 0, size=(8, 3)).astype(np.float32), dtype=wp.vec3, device=DEV)
    bvh = wp.Bvh(lowers, wp.array(lowers.numpy() + 0.5, dtype=wp.vec3, device=DEV))
    with pytest.raises(wp.WeftError, match=r"bvh_query_aabb.*is not a live Bvh of this session"):
        wp.launch(bvh_query_of, dim=1, inputs=[bvh.id | (1 << 31), count], device=DEV)   # a Bvh with the bit
        wp.synchronize()
    _daemon_still_serves(rng)
