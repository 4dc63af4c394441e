"""Geometry objects: wp.Mesh build, refit and closest-point queries on a UV sphere, and wp.Bvh
build and box queries over random boxes, weft against warp-lang on the same device in the same
run.

    python bench/bench_geometry.py [--device cpu|cuda:0] [--quick]

Per mesh size: the build (wp.Mesh(...), synchronized), a refit after moving every point, and a
launch of Q closest-point queries (mesh_query_point_no_sign + mesh_eval_position, launch +
sync), median of several runs. The error column is the largest difference, over 64 of the
queries, between the distance to the closest point found and the float64 brute-force distance
to every triangle. Ratio = warp time / weft time (higher is better for weft). On a GPU both
build and refit on the device (docs/geometry.md): a linear BVH, Warp's default there.

Per Bvh size: the build (wp.Bvh(lowers, uppers), synchronized) and a launch of Q box queries
counting the boxes each overlaps (launch + sync); the error column counts the queries, of 64,
whose count differs from a NumPy brute force. Each size also as a grouped build (a random group
of BVH_GROUPS per box; the queries walk the whole tree).
"""
from __future__ import annotations

import sys

import numpy as np

import bench_common as bc

SOURCE = '''
@wp.kernel
def closest(mesh: wp.uint64, points: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    tid = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, points[tid], 1.0e6)
    if q.result:
        out[tid] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)


@wp.kernel
def box_counts(bvh: wp.uint64, lowers: wp.array(dtype=wp.vec3), uppers: wp.array(dtype=wp.vec3),
               counts: wp.array(dtype=int)):
    tid = wp.tid()
    query = wp.bvh_query_aabb(bvh, lowers[tid], uppers[tid])
    item = int(0)
    n = int(0)
    while wp.bvh_query_next(query, item):
        n += 1
    counts[tid] = n


@wp.kernel
def wobble(points: wp.array(dtype=wp.vec3), t: float):
    tid = wp.tid()
    p = points[tid]
    points[tid] = p * (1.0 + 0.01 * wp.sin(t + float(tid)))
'''

SPHERES = [(32, 64), (128, 256), (512, 1024)]   # latitude x longitude bands
QUERIES = 1 << 20


def uv_sphere(nlat: int, nlon: int):
    th = np.linspace(0.0, np.pi, nlat + 1)
    ph = np.linspace(0.0, 2.0 * np.pi, nlon, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    pts = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    idx = []
    for i in range(nlat):
        for j in range(nlon):
            a, b = i * nlon + j, i * nlon + (j + 1) % nlon
            c, d = a + nlon, b + nlon
            idx += [(a, c, b), (b, c, d)]
    return pts.astype(np.float32), np.asarray(idx, dtype=np.int32).reshape(-1)


def closest_distance_f64(p, tri):
    """Distance from p to the nearest of the triangles tri (m, 3, 3), float64 (Ericson's regions)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp, cp = p - b, p - c
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v, w = vb / denom, vc / denom
        q = a + ab * v[:, None] + ac * w[:, None]
        cands = [q]
        for x, y in ((a, b), (b, c), (a, c)):
            e = y - x
            s = np.clip(((p - x) * e).sum(1) / np.maximum((e * e).sum(1), 1e-300), 0.0, 1.0)
            cands.append(x + e * s[:, None])
    inside = (va >= 0) & (vb >= 0) & (vc >= 0)
    dist = np.stack([np.linalg.norm(cq - p, axis=1) for cq in cands])
    dist[0, ~inside] = np.inf
    return dist.min()


def run(lib, mod, pts, idx, queries, device):
    points = lib.array(pts, dtype=lib.vec3, device=device)
    indices = lib.array(idx, dtype=int, device=device)
    qarr = lib.array(queries, dtype=lib.vec3, device=device)
    out = lib.zeros(len(queries), dtype=lib.vec3, device=device)
    holder = {}

    def build():
        holder["mesh"] = lib.Mesh(points=points, indices=indices)
        lib.synchronize_device(device)

    build()   # first use: the device's built-in kernels load outside the timing
    t_build = bc.median_time(build, repeat=3)
    mesh = holder["mesh"]
    step = [0.0]

    def refit():
        step[0] += 1.0
        lib.launch(mod.wobble, dim=len(pts), inputs=[points, step[0]], device=device)
        mesh.refit()
        lib.synchronize_device(device)

    t_refit = bc.median_time(refit, repeat=5)
    lib.launch(mod.wobble, dim=len(pts), inputs=[points, 0.0], device=device)   # compile outside the timing
    mesh.refit()

    def query():
        lib.launch(mod.closest, dim=len(queries), inputs=[mesh.id, qarr, out], device=device)
        lib.synchronize_device(device)

    query()
    t_query = bc.median_time(query, repeat=5)
    got = out.numpy()
    cur = points.numpy().astype(np.float64)
    tri = cur[idx.reshape(-1, 3)]
    err = 0.0
    for k in range(0, len(queries), max(1, len(queries) // 64)):
        p = queries[k].astype(np.float64)
        err = max(err, abs(np.linalg.norm(got[k] - p) - closest_distance_f64(p, tri)))
    return t_build, t_refit, t_query, err


BVH_SIZES = [10_000, 1_000_000]
BVH_QUERIES = 1 << 18
BVH_GROUPS = 64


def run_bvh(lib, mod, lo, hi, qlo, qhi, device, groups=None):
    lowers = lib.array(lo, dtype=lib.vec3, device=device)
    uppers = lib.array(hi, dtype=lib.vec3, device=device)
    garr = None if groups is None else lib.array(groups, dtype=lib.int32, device=device)
    ql = lib.array(qlo, dtype=lib.vec3, device=device)
    qu = lib.array(qhi, dtype=lib.vec3, device=device)
    counts = lib.zeros(len(qlo), dtype=int, device=device)
    holder = {}

    def build():
        holder["bvh"] = lib.Bvh(lowers, uppers) if garr is None else lib.Bvh(lowers, uppers, groups=garr)
        lib.synchronize_device(device)

    build()
    t_build = bc.median_time(build, repeat=5)
    bvh = holder["bvh"]

    def query():
        lib.launch(mod.box_counts, dim=len(qlo), inputs=[bvh.id, ql, qu, counts], device=device)
        lib.synchronize_device(device)

    query()
    t_query = bc.median_time(query, repeat=5)
    got = counts.numpy()
    wrong = 0
    for k in range(0, len(qlo), max(1, len(qlo) // 64)):
        want = int((~((lo > qhi[k]) | (hi < qlo[k])).any(1)).sum())
        wrong += int(got[k] != want)
    return t_build, t_query, wrong


def bvh_table(weft, weft_mod, warp, warp_mod, device, quick, rng):
    rows = []
    nq = BVH_QUERIES // 16 if quick else BVH_QUERIES
    for n in BVH_SIZES[:1] if quick else BVH_SIZES:
        print(f"  bvh {n:,} boxes ...", file=sys.stderr, flush=True)
        side = np.cbrt(n) * 0.5
        c = rng.uniform(0.0, side, size=(n, 3))
        h = rng.uniform(0.05, 0.5, size=(n, 3))
        lo, hi = (c - h).astype(np.float32), (c + h).astype(np.float32)
        qc = rng.uniform(0.0, side, size=(nq, 3))
        qlo, qhi = (qc - 0.5).astype(np.float32), (qc + 0.5).astype(np.float32)
        for groups in (None, rng.integers(0, BVH_GROUPS, size=n).astype(np.int32)):
            label = f"{n:,}" if groups is None else f"{n:,}, {BVH_GROUPS} groups"
            wb, wq, we = run_bvh(weft, weft_mod, lo, hi, qlo, qhi, device, groups)
            xb = xq = xe = None
            if warp is not None:
                xb, xq, xe = run_bvh(warp, warp_mod, lo, hi, qlo, qhi, device, groups)
            rows.append([label, bc.fmt_time(wb), bc.fmt_time(xb), bc.fmt_ratio(wb, xb),
                         bc.fmt_time(wq), f"{nq / wq / 1e6:,.1f} M/s", f"{we}/64",
                         bc.fmt_time(xq), "n/a" if xe is None else f"{xe}/64", bc.fmt_ratio(wq, xq)])
    header = ["boxes", "build weft", "warp", "ratio", f"{nq:,} queries weft", "throughput", "wrong counts",
              "warp", "warp wrong", "ratio"]
    bc.print_table(f"wp.Bvh on {device}: build, box queries counting overlaps (launch + sync)", header, rows)


def main():
    import weft

    device = "cpu"
    if "--device" in sys.argv:
        device = sys.argv[sys.argv.index("--device") + 1]
    weft.init()
    weft_mod = bc.load_kernels(SOURCE, "weft", "geometry")
    warp = bc.import_warp()
    warp_mod = bc.load_kernels(SOURCE, "warp", "geometry") if warp is not None else None
    rng = np.random.default_rng(0)
    spheres = SPHERES[:2] if "--quick" in sys.argv else SPHERES
    nq = QUERIES // 16 if "--quick" in sys.argv else QUERIES
    queries = rng.uniform(-1.5, 1.5, size=(nq, 3)).astype(np.float32)
    rows = []
    for nlat, nlon in spheres:
        pts, idx = uv_sphere(nlat, nlon)
        print(f"  sphere {nlat} x {nlon} ...", file=sys.stderr, flush=True)
        wb, wr, wq, we = run(weft, weft_mod, pts, idx, queries, device)
        xb = xr = xq = xe = None
        if warp is not None:
            xb, xr, xq, xe = run(warp, warp_mod, pts, idx, queries, device)
        faces = len(idx) // 3
        print(f"  {faces:,} faces done", file=sys.stderr, flush=True)
        rows.append([f"{faces:,}", bc.fmt_time(wb), bc.fmt_time(xb), bc.fmt_ratio(wb, xb),
                     bc.fmt_time(wr), bc.fmt_time(xr), bc.fmt_ratio(wr, xr),
                     bc.fmt_time(wq), f"{nq / wq / 1e6:,.1f} M/s", f"{we:.1e}",
                     bc.fmt_time(xq), "n/a" if xe is None else f"{xe:.1e}", bc.fmt_ratio(wq, xq)])
    header = ["faces", "build weft", "warp", "ratio", "refit weft", "warp", "ratio",
              f"{nq:,} queries weft", "throughput", "abs err", "warp", "warp abs err", "ratio"]
    bc.print_table(f"wp.Mesh on {device}: build, refit (after a launch moving the points), "
                   "closest-point queries (launch + sync)", header, rows)
    bvh_table(weft, weft_mod, warp, warp_mod, device, "--quick" in sys.argv, rng)


if __name__ == "__main__":
    main()
