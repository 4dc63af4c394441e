"""The marching cubes lookup tables, derived at import from the cube's geometry (no stored table).

Corner `i` of a cell sits at CUBE_CORNER_OFFSETS[i] and is bit `i` of the cell's case code; a
corner is set ("inside") when its field value is below the threshold. For each of the 256 cases
the crossed edges (one endpoint inside, one outside) are joined into closed cycles on the cube's
surface: on each face the crossings pair up, and on an ambiguous face (two diagonal corners
inside) each inside corner is cut off on its own. That rule depends only on the face's four
values, so the two cells sharing a face cut it the same way and the surface is closed across
cells. Each cycle is cut into triangles wound counter-clockwise seen from outside (the side
where the field is above the threshold), the convention of Warp's iso-surface backends. No
triangle side inside a cell joins two crossings of one face: the cell across that face could
use the same side, and four triangles would meet along it (a surface that is not a manifold).
"""
from __future__ import annotations

CUBE_CORNER_OFFSETS: tuple[tuple[int, int, int], ...] = (
    (0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
    (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1),
)

EDGE_TO_CORNERS: tuple[tuple[int, int], ...] = (
    (0, 1), (1, 2), (2, 3), (3, 0),
    (4, 5), (5, 6), (6, 7), (7, 4),
    (0, 4), (1, 5), (2, 6), (3, 7),
)


def _faces() -> list[tuple[int, int, int, int]]:
    """The six faces, each as its four corners in cyclic order."""
    faces = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for side in (0, 1):
            ring = []
            for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                want = [0, 0, 0]
                want[axis], want[u], want[v] = side, du, dv
                ring.append(CUBE_CORNER_OFFSETS.index(tuple(want)))
            faces.append(tuple(ring))
    return faces


def _edge_index() -> dict[frozenset, int]:
    return {frozenset(pair): e for e, pair in enumerate(EDGE_TO_CORNERS)}


def _cycles(case: int, faces, edge_of) -> list[list[int]]:
    """The crossed edges of `case` joined into closed cycles (lists of edge indices)."""
    inside = [(case >> c) & 1 for c in range(8)]
    links: dict[int, list[int]] = {}
    for ring in faces:
        edges = [edge_of[frozenset((ring[k], ring[(k + 1) % 4]))] for k in range(4)]
        crossed = [edges[k] for k in range(4) if inside[ring[k]] != inside[ring[(k + 1) % 4]]]
        if len(crossed) == 2:
            pairs = [tuple(crossed)]
        elif len(crossed) == 4:  # diagonal corners inside: cut off each inside corner
            pairs = [(edges[(k - 1) % 4], edges[k]) for k in range(4) if inside[ring[k]]]
        else:
            pairs = []
        for a, b in pairs:
            links.setdefault(a, []).append(b)
            links.setdefault(b, []).append(a)
    cycles, seen = [], set()
    for start in sorted(links):
        if start in seen:
            continue
        cycle, prev, cur = [start], None, start
        seen.add(start)
        while True:
            nxt = links[cur][0] if links[cur][0] != prev else links[cur][1]
            if nxt == start:
                break
            cycle.append(nxt)
            seen.add(nxt)
            prev, cur = cur, nxt
        cycles.append(cycle)
    return cycles


def _midpoint(e: int) -> tuple[float, float, float]:
    a, b = (CUBE_CORNER_OFFSETS[c] for c in EDGE_TO_CORNERS[e])
    return tuple((a[i] + b[i]) * 0.5 for i in range(3))


def _oriented(cycle: list[int], case: int) -> list[int]:
    """The cycle in the order whose polygon normal (Newell's) points from the inside corners to
    the outside ones."""
    pts = [_midpoint(e) for e in cycle]
    normal = [0.0, 0.0, 0.0]
    for k, p in enumerate(pts):
        q = pts[(k + 1) % len(pts)]
        normal[0] += (p[1] - q[1]) * (p[2] + q[2])
        normal[1] += (p[2] - q[2]) * (p[0] + q[0])
        normal[2] += (p[0] - q[0]) * (p[1] + q[1])
    outward = [0.0, 0.0, 0.0]
    for e in cycle:
        c0, c1 = EDGE_TO_CORNERS[e]
        lo, hi = (c0, c1) if (case >> c0) & 1 else (c1, c0)  # lo inside, hi outside
        for i in range(3):
            outward[i] += CUBE_CORNER_OFFSETS[hi][i] - CUBE_CORNER_OFFSETS[lo][i]
    if sum(normal[i] * outward[i] for i in range(3)) < 0.0:
        return [cycle[0]] + cycle[:0:-1]
    return cycle


def _triangulated(poly: list[int], on_one_face) -> list[tuple[int, int, int]] | None:
    """Triangles covering the polygon `poly` (edge indices, in order) whose inner sides never join
    two edges of one cube face; None when there is no such triangulation."""
    n = len(poly)
    if n == 3:
        return [tuple(poly)]
    for m in range(n - 2, 0, -1):  # the triangle on the side (poly[n-1], poly[0]) has apex poly[m]
        if m > 1 and on_one_face(poly[0], poly[m]):
            continue
        if m < n - 2 and on_one_face(poly[m], poly[n - 1]):
            continue
        left = _triangulated(poly[:m + 1], on_one_face) if m > 1 else []
        right = _triangulated(poly[m:], on_one_face) if m < n - 2 else []
        if left is not None and right is not None:
            return left + [(poly[0], poly[m], poly[n - 1])] + right
    return None


def _build() -> tuple[tuple[int, ...], tuple[int, ...]]:
    faces, edge_of = _faces(), _edge_index()
    face_edges = [{edge_of[frozenset((r[k], r[(k + 1) % 4]))] for k in range(4)} for r in faces]

    def on_one_face(a: int, b: int) -> bool:
        return any(a in f and b in f for f in face_edges)

    ranges, tris = [0], []
    for case in range(256):
        for cycle in _cycles(case, faces, edge_of):
            found = _triangulated(_oriented(cycle, case), on_one_face)
            if found is None:  # the geometry of the cube always allows one; checked at import
                raise AssertionError(f"marching cubes case {case}: no manifold triangulation")
            for tri in found:
                tris.extend(tri)
        ranges.append(len(tris))
    return tuple(ranges), tuple(tris)


CASE_TO_TRI_RANGE, TRI_LOCAL_INDICES = _build()


def edge_nodes() -> tuple[int, ...]:
    """For each edge: the offset of its lower corner from the cell origin and its axis, as
    (ox, oy, oz, axis) flattened; a grid edge is named by its lower node and its axis."""
    out = []
    for c0, c1 in EDGE_TO_CORNERS:
        a, b = CUBE_CORNER_OFFSETS[c0], CUBE_CORNER_OFFSETS[c1]
        axis = next(i for i in range(3) if a[i] != b[i])
        low = a if a[axis] < b[axis] else b
        out.extend((*low, axis))
    return tuple(out)
